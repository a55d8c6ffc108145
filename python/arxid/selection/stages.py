"""Two-stage sweeps for large grids (MATLAB ``arxstruc`` first, free run for the best).

Stage 1 ranks every structure of the grid by its one-step prediction error on the validation data
(the estimation data without them), computed in the Rust core from the triangular factors of the
grid's largest regressor: no simulation, about a microsecond per structure, and only a summary per
structure is kept (parameters and two losses). Stage 2 fits the best ``top`` of them exactly (QR)
and simulates them in free run, and :func:`arxid.sweep` ranks those as an exhaustive sweep would.
``SweepResult.stage`` says which stage ranked each row.

Before anything is allocated, :func:`check_time_budget` refuses a sweep whose estimated run time
exceeds the stated budget, naming its size.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence

import numpy as np

from ..exceptions import DataError

__all__ = ["DEFAULT_TOP", "RankedParameters", "check_time_budget", "estimated_seconds", "product_layout", "rank_order"]

#: Structures fitted exactly and simulated in free run after the one-step ranking (``top=``).
DEFAULT_TOP = 1000

#: Core-seconds per unit of work, deliberately optimistic (a fast core), so that a refusal means
#: the sweep would certainly take longer than the budget: one multiply-add of the free run (per
#: parameter, sample and structure), one stage-1 structure, one QR flop of the factorization.
SECONDS_PER_SIMULATED_TERM = 1e-10
SECONDS_PER_RANKED_STRUCTURE = 5e-7
SECONDS_PER_QR_FLOP = 1e-10


def estimated_seconds(
    n_structures: int,
    top: int | None,
    p_max: int,
    q: int,
    n_samples: int,
    n_simulated_samples: int,
    n_threads: int,
) -> float:
    """Lower estimate of a sweep's run time in seconds.

    Parameters
    ----------
    n_structures : int
        Structures in the grid.
    top : int or None
        Structures simulated after the one-step ranking; None simulates every structure.
    p_max : int
        Largest number of parameters of a structure.
    q : int
        Columns of the grid's largest regressor, output included.
    n_samples : int
        Estimation plus validation samples (each is reduced once by QR).
    n_simulated_samples : int
        Samples every simulated structure runs over (validation, plus estimation when simulated).
    n_threads : int
        Threads of the sweep (0 = all cores).

    Returns
    -------
    float
        Seconds, assuming every thread runs at the speed of a fast core.
    """
    threads = n_threads if n_threads > 0 else max(1, _cores())
    simulated = n_structures if top is None else min(top, n_structures)
    ranked = 0 if top is None or top >= n_structures else n_structures
    work = (
        simulated * n_simulated_samples * (p_max + 2) * SECONDS_PER_SIMULATED_TERM
        + ranked * SECONDS_PER_RANKED_STRUCTURE
        + 2.0 * n_samples * q * q * SECONDS_PER_QR_FLOP
    )
    return work / threads


def _cores() -> int:
    import os

    return os.cpu_count() or 1


def check_time_budget(n_structures: int, top: int | None, seconds: float, max_seconds: float | None) -> None:
    """Refuses a sweep whose estimated time (:func:`estimated_seconds`) exceeds ``max_seconds``.

    Parameters
    ----------
    n_structures : int
        Structures in the grid.
    top : int or None
        As for :func:`arxid.sweep`.
    seconds : float
        The estimate.
    max_seconds : float or None
        The budget; None accepts any grid.

    Raises
    ------
    DataError
        When the estimate exceeds the budget (the message gives the grid's size and how to fit it in).
    """
    if max_seconds is None or seconds <= max_seconds:
        return
    how = "rank in two stages (top=1000)" if top is None else "lower top"
    raise DataError(
        f"the grid is too slow to sweep: {n_structures:,} structures "
        f"({'all' if top is None else f'the best {min(top, n_structures):,}'} simulated in free run) need at least "
        f"{_duration(seconds)}, more than the budget of {_duration(max_seconds)} (max_seconds); {how}, narrow the "
        f"ranges, or raise max_seconds"
    )


def _duration(s: float) -> str:
    if s >= 7200:
        return f"{s / 3600:.1f} h"
    if s >= 120:
        return f"{s / 60:.0f} min"
    return f"{s:.3g} s"


def product_layout(
    nas: Sequence[int], nbs: Sequence[Sequence[int]], nks: Sequence[Sequence[int]]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every structure of a grid without effects, built with numpy (a million rows in milliseconds).

    Parameters
    ----------
    nas : sequence of int
        Numbers of poles.
    nbs, nks : sequence of sequences of int
        Orders and delays of each input.

    Returns
    -------
    layout : ndarray of shape (S, 1 + 2m), int64
        Rows (na, nb_1..nb_m, nk_1..nk_m) in the order of ``arxid.sweep``'s grid (na outermost, then
        the orders, then the delays, the last input fastest), structures without parameters left out.
    nb, nk : ndarray of shape (S, m)
        The orders and delays of each row.
    """
    m = len(nbs)
    axes = [np.asarray(nas, dtype=np.int64)] + [np.asarray(r, dtype=np.int64) for r in (*nbs, *nks)]
    mesh = np.meshgrid(*axes, indexing="ij")
    layout = np.stack([g.ravel() for g in mesh], axis=1)
    layout = layout[layout[:, 0] + layout[:, 1 : 1 + m].sum(axis=1) > 0]
    return np.ascontiguousarray(layout), layout[:, 1 : 1 + m], layout[:, 1 + m :]


def rank_order(score: np.ndarray, bad: np.ndarray, stage: np.ndarray, one_step: np.ndarray) -> np.ndarray:
    """Ranked order of a sweep's structures.

    Parameters
    ----------
    score : ndarray of shape (S,)
        The ranking measure (NaN where it does not exist).
    bad : ndarray of bool, shape (S,)
        No finite score, diverged or not fitted.
    stage : ndarray of shape (S,)
        2 for structures simulated, 1 for structures ranked by their one-step error only.
    one_step : ndarray of shape (S,)
        The one-step error that ranked stage 1 (validation, else estimation).

    Returns
    -------
    ndarray of int, shape (S,)
        Structures with a finite score first, by score; then the structures of stage 1 that the
        measure could not score (not simulated), by their one-step error; then the diverged and
        unfitted ones. Ties keep grid order.
    """
    unscored = bad & (stage == 1) & np.isfinite(one_step)
    parts = []
    for members, key in ((~bad, score), (unscored, one_step), (bad & ~unscored, None)):
        idx = np.flatnonzero(members)
        parts.append(idx if key is None else idx[np.argsort(key[idx], kind="stable")])
    return np.concatenate(parts)


class RankedParameters(Sequence):
    """The parameters of every structure in ranked order, read from the sweep's parameter matrix
    on demand (a list of a million small arrays would cost seconds and hundreds of MiB).

    Parameters
    ----------
    theta : ndarray of shape (S, p_max)
        Parameters in grid order, NaN-padded.
    n_params : ndarray of shape (S,)
        Parameters of each structure (grid order).
    order : ndarray of shape (S,)
        Grid index of each rank.
    """

    def __init__(self, theta: np.ndarray, n_params: np.ndarray, order: np.ndarray):
        self._theta = np.asarray(theta, dtype=float).view()
        self._theta.flags.writeable = False  # a read-only view: rows cannot be changed through it
        self._p = np.asarray(n_params)
        self._order = np.asarray(order)

    def __len__(self) -> int:
        return len(self._order)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        j = self._order[i]
        return self._theta[j, : self._p[j]]

    def __iter__(self) -> Iterator[np.ndarray]:
        for j in self._order:
            yield self._theta[j, : self._p[j]]

    def __repr__(self) -> str:
        return f"<{len(self)} parameter vectors in ranked order>"


def stages_text(stage: np.ndarray, validated: bool) -> str:
    """One line on how a two-stage sweep ranked its rows (empty when every row was simulated).

    Parameters
    ----------
    stage : ndarray of shape (S,)
        The sweep's ``stage`` column.
    validated : bool
        The sweep had validation data (stage 1 ranked by their one-step error).

    Returns
    -------
    str
    """
    n, n2 = len(stage), int(np.count_nonzero(stage == 2))
    if n2 >= n:
        return ""
    on = "validation" if validated else "estimation"
    pct = 100.0 * n2 / n if n else math.nan
    return (
        f"two stages: all {n:,} structures ranked by one-step {on} error (stage 1); the best {n2:,} "
        f"({pct:.2g} %) fitted again and simulated (stage 2); rows marked 1 were not simulated"
    )
