"""Run small dense linear algebra on one BLAS thread.

The frequency solver multiplies matrices of a few dozen rows by a few
thousand columns. OpenBLAS splits such products over all cores; on a busy
machine (the optimiser's workers, a CI runner) its threads wait for each
other and a 2 ms product takes 20 ms. :class:`single_blas_thread` sets every
loaded OpenBLAS library to one thread for the duration of a block and
restores the previous count afterwards. It finds the libraries in
``/proc/self/maps`` (Linux); elsewhere, or if anything fails, it does
nothing (the results are the same, only the speed differs).
"""

from __future__ import annotations

import ctypes
import sys

_SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
            "openblas_set_num_threads64_", "openblas_set_num_threads")
_GETTERS = ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
            "openblas_get_num_threads64_", "openblas_get_num_threads")

_libraries: list[tuple[object, object]] | None = None


def _find() -> list[tuple[object, object]]:
    """(getter, setter) of every loaded OpenBLAS library."""
    found: list[tuple[object, object]] = []
    if not sys.platform.startswith("linux"):
        return found
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and ".so" in line}
        for path in sorted(paths):
            lib = ctypes.CDLL(path)
            getter = next((getattr(lib, n) for n in _GETTERS if hasattr(lib, n)), None)
            setter = next((getattr(lib, n) for n in _SETTERS if hasattr(lib, n)), None)
            if getter is not None and setter is not None:
                getter.restype = ctypes.c_int
                found.append((getter, setter))
    except Exception:  # best effort: never fail a simulation for this
        return []
    return found


class single_blas_thread:
    """Context manager: OpenBLAS on one thread inside the block (see the module docstring)."""

    def __enter__(self) -> "single_blas_thread":
        global _libraries
        if _libraries is None:
            _libraries = _find()
        self.saved = []
        for getter, setter in _libraries:
            try:
                n = int(getter())
                if n != 1:
                    setter(ctypes.c_int(1))
                    self.saved.append((setter, n))
            except Exception:
                pass
        return self

    def __exit__(self, *exc) -> None:
        for setter, n in self.saved:
            try:
                setter(ctypes.c_int(n))
            except Exception:
                pass
