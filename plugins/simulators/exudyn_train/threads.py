"""One BLAS thread for small dense products: moved to :mod:`suspid.threads` (shared by the pipeline)."""

from suspid.threads import single_blas_thread  # noqa: F401
