"""Evaluation campaigns: ``stats`` (pure metrics), ``campaign`` (jobs on a pool or Dask),
``report`` (results.json, report.md, figures), ``cli`` (argument parsing only)."""
