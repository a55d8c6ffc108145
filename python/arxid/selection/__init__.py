"""Choosing a structure: the (na, nb, nk) sweep from one factorization (:func:`sweep`,
:class:`SweepResult`, :data:`DEFAULT_GRID`), two-stage sweeps, step sanity checks, the integrator
verdict, grid edges and parsimony tests."""

from .search import DEFAULT_GRID, Selection, SweepResult, sweep

__all__ = ["sweep", "SweepResult", "Selection", "DEFAULT_GRID"]
