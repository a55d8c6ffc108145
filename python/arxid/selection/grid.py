"""The order grid of a sweep: the default ranges (:data:`DEFAULT_GRID`), the user's ranges checked
(:func:`order_range`, :func:`per_input_ranges`), every structure as the Rust core sees it
(:class:`Grid`) and the size check before any of it is built (:func:`check_grid_size`)."""

from __future__ import annotations

import itertools
import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base import _core
from .._base.limits import available_memory, check_order
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError, OrderError
from ..models.effects import compile_effects
from . import stages

__all__ = ["DEFAULT_GRID", "Grid", "check_grid_size", "check_top", "order_range", "per_input_ranges"]

#: The order grid every sweep uses unless told otherwise: the API's :func:`sweep`, :func:`arxid.analyse`
#: and every CLI command. na 1..4 poles, nb 1..3 input coefficients, nk 0..5 samples of delay.
DEFAULT_GRID: dict[str, range] = {"na": range(1, 5), "nb": range(1, 4), "nk": range(0, 6)}


def order_range(name: str, value: Any) -> Sequence[int]:
    """The orders one argument of :func:`arxid.sweep` asks for, checked.

    Parameters
    ----------
    name : str
        The argument (``na``, ``nb[0]``, ...), for the messages.
    value : int, range or iterable of int
        The orders given.

    Returns
    -------
    range or tuple of int
        An ascending ``range`` (kept lazy, so a huge one costs nothing before the size check), else
        the distinct orders in the order given.

    Raises
    ------
    OrderError
        When it is empty, holds a negative or non-integer order, or one beyond the limits.
    """
    if isinstance(value, range):
        # Kept lazy: its size is checked against the memory before any structure is built.
        if len(value) == 0:
            raise OrderError(f"{name} is an empty range: give at least one order")
        ascending = value if value.step > 0 else value[::-1]
        check_order(name, ascending[0])
        check_order(name, ascending[-1])
        return ascending
    if isinstance(value, numbers.Integral) and not isinstance(value, bool):
        vals = (int(value),)
    else:
        try:
            vals = tuple(value)
        except TypeError:
            raise OrderError(f"{name} must be an integer or a range of integers, got {value!r}") from None
    if not vals:
        raise OrderError(f"{name} is an empty range: give at least one order")
    out: list[int] = []
    for v in vals:
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or int(v) < 0:
            raise OrderError(f"{name} must hold non-negative integers, got {v!r}")
        out.append(check_order(name, v))
    return tuple(dict.fromkeys(out))


def _lowest(r: Sequence[int]) -> int:
    """Smallest order of a range from :func:`order_range` (O(1) for a ``range``)."""
    return r[0] if isinstance(r, range) else min(r)


def _highest(r: Sequence[int]) -> int:
    """Largest order of a range from :func:`order_range` (O(1) for a ``range``)."""
    return r[-1] if isinstance(r, range) else max(r)


def per_input_ranges(name: str, value: Any, m: int) -> list[Sequence[int]]:
    """The orders of ``nb`` or ``nk`` per input: one shared range, or a list of ranges (one per input).

    Parameters
    ----------
    name : str
        ``"nb"`` or ``"nk"``, for the messages.
    value : int, iterable of int, or list of iterables
        One range shared by every input, or one per input.
    m : int
        Inputs of the data.

    Returns
    -------
    list
        ``m`` ranges, as :func:`order_range` checks them.
    """
    if isinstance(value, (list, tuple)) and value and all(not isinstance(v, numbers.Integral) for v in value):
        if len(value) != m:
            raise OrderError(
                f"{name} gives {len(value)} ranges but the data have {m} inputs; give one range per input "
                f"or a single shared range"
            )
        return [order_range(f"{name}[{i}]", v) for i, v in enumerate(value)]
    r = order_range(name, value)
    return [r] * m


def _gib(b: float) -> str:
    return f"{b / 2**30:.2f} GiB" if b >= 2**28 else f"{b / 2**20:.1f} MiB"


def check_grid_size(
    est: IOData,
    val: IOData | None,
    nas: Sequence[int],
    nbs: list,
    nks: list,
    effects: tuple[str, ...],
    n_threads: int,
    max_memory: int | None,
) -> tuple[int, int, int]:
    """Size and memory of a grid before anything is built (the core's own estimate).

    Parameters
    ----------
    est, val : IOData, IOData or None
        Estimation and validation data.
    nas, nbs, nks : sequence, list of sequences
        The orders: na, and nb and nk per input.
    effects : tuple of str
        Effect terms added to every structure.
    n_threads : int
        Threads of the sweep (each holds its own work space).
    max_memory : int or None
        Bytes the sweep may take (None: half the available memory).

    Returns
    -------
    tuple of int
        The number of structures, the largest number of parameters and the columns of the largest
        regressor (output included).

    Raises
    ------
    DataError
        When the sweep would need more memory than the limit.
    """
    n_structures = len(nas) * math.prod(len(r) for r in nbs) * math.prod(len(r) for r in nks)
    top_nb, top_nk = [_highest(r) for r in nbs], [_highest(r) for r in nks]
    probe = compile_effects(effects, est[: min(est.n_samples, 8)], top_nb, top_nk)
    n_cols, n_terms = len(probe.nb), len(probe.output_terms)
    span = max(k + b - _lowest(ks) for b, k, ks in zip(top_nb, top_nk, nks))
    p_max = _highest(nas) + n_cols * max(top_nb) + n_terms
    q = _highest(nas) + n_cols * span + n_terms + 1
    need = _core.sweep_memory(
        n_structures, p_max, q, est.n_samples, val.n_samples if val is not None else 0, n_cols, n_threads
    )
    limit = int(max_memory) if max_memory is not None else available_memory() // 2
    if need > limit:
        raise DataError(
            f"the grid is too large: {n_structures:,} structures with up to {p_max} parameters and a largest regressor of "  # noqa: E501
            f"{q} columns need about {_gib(need)}, more than the limit of {_gib(limit)} (max_memory); "
            f"narrow the ranges or split the sweep into parts"
        )
    return n_structures, p_max, q


def check_top(top: Any) -> int | None:
    """The ``top`` of a two-stage sweep, checked (see :mod:`arxid.selection.stages`).

    Parameters
    ----------
    top : int or None
        Structures simulated after the one-step ranking; None simulates every one.

    Returns
    -------
    int or None
    """
    if top is None:
        return None
    if isinstance(top, bool) or not isinstance(top, numbers.Integral) or top < 1:
        raise OrderError(
            f"top must be an integer >= 1 (structures simulated after the one-step ranking) or None, got {top!r}"
        )
    return int(top)


@record
class Grid:
    """Every structure as the user wrote it (per input) and as the core sees it (per layout column)."""

    layout: np.ndarray  # (S, 1 + 2 n_columns): na, nb per column, nk per column
    user_nb: Any  # per structure (nb per input): a list of tuples, or an (S, m) array
    user_nk: Any
    n_columns: int

    @classmethod
    def build(cls, est: IOData, nas: Sequence[int], nbs: list, nks: list, effects: tuple[str, ...]) -> Grid:
        """Every structure of the product of the ranges; effect terms set the core's column layout.

        Parameters
        ----------
        est : IOData
            Estimation data (their first samples tell how the effects expand).
        nas, nbs, nks : sequence, list of sequences
            The orders: na, and nb and nk per input.
        effects : tuple of str
            Effect terms added to every structure.

        Returns
        -------
        Grid
            Structures without a parameter are left out.
        """
        if not effects:
            layout, nb_rows, nk_rows = stages.product_layout(nas, nbs, nks)
            if not len(layout):
                raise OrderError("the grid has no structure with a parameter: use na >= 1 or nb >= 1")
            return cls(layout, nb_rows, nk_rows, len(nbs))
        head = est[: min(est.n_samples, 8)]
        layouts: dict = {}
        n_terms = len(compile_effects(effects, head, [max(r) for r in nbs], [max(r) for r in nks]).output_terms)
        rows, user_nb, user_nk = [], [], []
        for nbv in itertools.product(*nbs):
            for nkv in itertools.product(*nks):
                if (nbv, nkv) not in layouts:
                    lay = compile_effects(effects, head, list(nbv), list(nkv)) if effects else None
                    layouts[(nbv, nkv)] = (tuple(lay.nb), tuple(lay.nk)) if lay else (nbv, nkv)
        for a in nas:
            for nbv in itertools.product(*nbs):
                for nkv in itertools.product(*nks):
                    lnb, lnk = layouts[(nbv, nkv)]
                    if a + sum(lnb) + n_terms == 0:
                        continue
                    rows.append((a, *lnb, *lnk))
                    user_nb.append(nbv)
                    user_nk.append(nkv)
        if not rows:
            raise OrderError("the grid has no structure with a parameter: use na >= 1 or nb >= 1")
        grid = np.array(rows, dtype=np.int64)
        return cls(grid, user_nb, user_nk, (grid.shape[1] - 1) // 2)
