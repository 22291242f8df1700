"""Infrastructure that the workflows share: the run ledger, seeded random streams, BLAS threads, files."""
