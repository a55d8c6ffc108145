"""Finding the missing physical effect: candidate terms, their added-variable scores and validated
refits (:func:`diagnose`, :class:`Diagnosis`), and the ladder that adds them one at a time
(:class:`Ladder`); the same over a fleet of logs kept on a Dask cluster, from statistics computed where
the logs are (:mod:`~arxid.diagnosis.fleet_diagnose`)."""

from .ladder import Ladder
from .result import Diagnosis
from .suspects import diagnose

__all__ = ["diagnose", "Diagnosis", "Ladder"]
