"""Choosing a structure: the (na, nb, nk) sweep from one factorization (:func:`sweep`,
:class:`SweepResult`, :data:`DEFAULT_GRID`) with its grid, engine, ranking, table and choice
(:class:`Selection`), the output-error refinement of a sweep (:func:`refine`, :class:`RefinedSweep`),
two-stage sweeps, step sanity checks, the integrator verdict, grid edges and parsimony tests."""

from .choice import Selection
from .grid import DEFAULT_GRID
from .refine import RefinedSweep, refine
from .search import SweepResult, sweep

__all__ = ["sweep", "SweepResult", "Selection", "DEFAULT_GRID", "refine", "RefinedSweep"]
