"""Many logs at once: one fit per log with the spread of its parameters, one sweep per log, and
sweeps and fits on a Dask cluster where the logs stay on the workers. Reading and merging logs is
the data layer's (:mod:`arxid.data.logs`). Importing this package provides the models with their
fits of many logs (:mod:`arxid.models.many_logs`)."""

from .cluster import LogShape, LogsOnDemand, WorkerLogs
from .fit import ClusterLogs, FleetModels, ParameterSpread, fit_each, outlier_logs
from .logs import FleetSweep, sweep_each
from .sweep import DaskEngine, EffectColumns

__all__ = [
    "ClusterLogs",
    "DaskEngine",
    "EffectColumns",
    "FleetModels",
    "FleetSweep",
    "LogShape",
    "LogsOnDemand",
    "ParameterSpread",
    "WorkerLogs",
    "fit_each",
    "outlier_logs",
    "sweep_each",
]
