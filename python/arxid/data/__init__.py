"""Measured data: :class:`IOData` (validated float64 samples, experiments, NaN gaps, names, units,
sample time), the CSV reader behind :meth:`IOData.from_csv`, and logs read and merged into one
IOData with one experiment per log (:func:`load_experiment`, :func:`merge_logs`), flight logs (PX4
ULog :meth:`IOData.from_ulog`, module ``ulog``; Betaflight/INAV blackbox
:meth:`IOData.from_blackbox`, module ``blackbox``; ArduPilot DataFlash :meth:`IOData.from_dataflash`,
module ``dataflash``), the one resampler they and ``from_csv(resample=True)`` share (module
``resample``), the signals of one multirotor axis in each kind of log (module ``presets``), and the
checks of sample arrays and sampling times (module ``samples``)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._base.lazy import lazy_package

if TYPE_CHECKING:  # the names of _PUBLIC, imported on first use (PEP 562)
    from .iodata import IOData
    from .logs import load_experiment, merge_logs

_PUBLIC = {"IOData": "iodata", "load_experiment": "logs", "merge_logs": "logs"}

__all__ = ["IOData", "load_experiment", "merge_logs"]

lazy_package(__name__)
