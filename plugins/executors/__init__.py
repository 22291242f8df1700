"""Built-in executors: serial, a local process pool, dask.distributed."""
