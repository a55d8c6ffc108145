"""Finding the missing physical effect: candidate terms, their added-variable scores and validated
refits (:func:`diagnose`, :class:`Diagnosis`), and the ladder that adds them one at a time
(:class:`Ladder`). One procedure wherever the records are (:func:`~arxid.diagnosis.suspects.diagnose`):
one record in this process, or a fleet's logs on a Dask cluster, scored and refitted from statistics
computed where they are (:mod:`~arxid.diagnosis.cluster_records`)."""

from .ladder import Ladder
from .result import Diagnosis
from .suspects import diagnose

__all__ = ["diagnose", "Diagnosis", "Ladder"]
