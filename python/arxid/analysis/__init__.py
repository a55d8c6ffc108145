"""The one analysis pipeline (:func:`analyse`, :class:`Analysis`) and what renders it: the verdict
sentences, the HTML report (``report``), the command line (``cli``) and the demo (``demo``); and the
analysis of a fleet of logs on a Dask cluster (``fleet_analysis``, ``arxid fleet`` in ``fleet_cli``)."""

from . import fleet_analysis as _fleet_analysis  # noqa: F401  (provides analyse(logs, client=...))
from .pipeline import DEFAULT_SPLIT, Analysis, Choice, analyse, choose, grid_of

__all__ = ["analyse", "Analysis", "Choice", "choose", "grid_of", "DEFAULT_SPLIT"]
