"""Sweeps: many evaluations of the model on Dask (``chewbot sweep``; docs/sweeps.md)."""
