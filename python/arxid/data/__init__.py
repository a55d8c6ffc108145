"""Measured data: :class:`IOData` (validated float64 samples, experiments, NaN gaps, names, units,
sample time) and the CSV reader behind :meth:`IOData.from_csv`."""

from .iodata import IOData

__all__ = ["IOData"]
