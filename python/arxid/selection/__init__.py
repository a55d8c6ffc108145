"""Choosing a structure: the (na, nb, nk) sweep from one factorization (:func:`sweep`,
:class:`SweepResult`, :data:`DEFAULT_GRID`) with its grid, engine, ranking, table and choice
(:class:`Selection`), the output-error refinement of a sweep (:func:`refine`, :class:`RefinedSweep`),
two-stage sweeps, step sanity checks, the integrator verdict, grid edges and parsimony tests."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._base.lazy import lazy_package

if TYPE_CHECKING:  # the names of _PUBLIC, imported on first use (PEP 562)
    from .choice import Selection
    from .grid import DEFAULT_GRID
    from .refine import RefinedSweep, refine
    from .search import SweepResult, sweep

_PUBLIC = {
    **dict.fromkeys(["sweep", "SweepResult"], "search"),
    "Selection": "choice",
    "DEFAULT_GRID": "grid",
    **dict.fromkeys(["refine", "RefinedSweep"], "refine"),
}

__all__ = ["sweep", "SweepResult", "Selection", "DEFAULT_GRID", "refine", "RefinedSweep"]

lazy_package(__name__)
