"""The one analysis pipeline (:func:`analyse`, :class:`Analysis`) and what renders it: the verdict
sentences, the HTML report (``report``), the command line (``cli``) and the demo (``demo``); and the
analysis of a fleet of logs on a Dask cluster (``fleet_analysis``, ``arxid fleet`` in ``fleet_cli``).

The names below load on first use, so that the command line (``arxid --help``) starts without the
pipeline; :func:`analyse` finds the fleet's analysis itself when given ``client=``."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .pipeline import DEFAULT_SPLIT, Analysis, Choice, analyse, choose, grid_of

__all__ = ["analyse", "Analysis", "Choice", "choose", "grid_of", "DEFAULT_SPLIT"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        pipeline = importlib.import_module("arxid.analysis.pipeline")
        globals().update((n, getattr(pipeline, n)) for n in __all__)
        return globals()[name]
    raise AttributeError(f"module 'arxid.analysis' has no attribute {name!r}")
