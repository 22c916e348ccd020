"""Batches of jobs: manifests, a local process pool or Dask, resume after a crash."""
