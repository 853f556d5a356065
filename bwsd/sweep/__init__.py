"""Design sweeps: the twin across a grid or a random sample of parameters, on Dask.

``spec`` reads a sweep's TOML spec into candidates, ``candidate`` generates, simulates and
measures one candidate (pure: no Dask, no files), ``store`` streams the rows to disk and
merges them into Parquet, ``engine`` runs the candidates on a Dask cluster (a local one by
default), ``plot`` draws a metric against a parameter. See docs/sweeps.md.
"""
