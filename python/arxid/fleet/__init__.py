"""Many logs at once: reading and merging logs, one fit per log with the spread of its parameters,
and sweeps and fits on a Dask cluster where the logs stay on the workers."""
