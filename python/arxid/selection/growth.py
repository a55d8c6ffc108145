"""Growing a sweep's grid until it fits the plant: :meth:`arxid.SweepResult.extend` and
:func:`arxid.analyse` re-sweep on a larger grid while the chosen structure sits on an edge of the
grid, within a time budget, and record every grid tried (:class:`GridGrowth`).

The stopping rule. After a growth, the grown sweep is not kept, and growing stops, when:

1. **integrates**: the sweep ranks by free run (the plant was not found integrating) and the
   grown grid's choice has a pole at z = 1 by its own unit-root vote
   (:func:`.integrator.structure_integrates`, the rule by which the diagnosis switches to k-step
   prediction) while the previous choice had none: larger orders then fit a slow drift, such as
   an unmodelled effect leaves, not the plant's dynamics;
2. **insane**: the previous grid had a structure that passes the step sanity checks and the grown
   grid has none (its best fails them): a larger grid must not turn an answer into a refusal;
3. **no-gain**: the growth chose the same structure again, or one whose validation error is
   lower by less than ``min_gain`` (default 1 %), compared on the grown sweep's own rows and
   measure: a larger structure is never taken for a gain within the noise, and a choice that
   growing did not change keeps the numbers of the smaller grid (its rows: a larger grid starts
   every structure at its largest lag).

Before a growth, in this order, growing stops when:

4. **inside**: the chosen structure lies inside the grid (no edge, :mod:`.grid_edges`);
5. **rounds**: ``max_rounds`` growths were made (default: no limit; **off** when it is 0);
6. **order-cap**: no edge range can grow below the largest order (default 30);
7. **refused**: the grown grid would not fit in memory (or, after it, :func:`arxid.sweep`
   refuses it);
8. **budget**: the next sweep would take the search past ``max_seconds`` (default 30 s) in
   total. Its time is predicted before it starts, from the measured time of the last sweep scaled
   by the work of the grown grid (the larger of the ratios of structures and of the core's work,
   :func:`arxid.selection.stages.estimated_seconds`), so a round that would exceed the budget is
   never started.

The re-sweeps keep the first sweep's measure and integrator verdict
(:meth:`arxid.SweepResult.extend`), so every grid compares like with like.

Each growth grows every edge range by ``max(2, ⌈len/2⌉)`` values, poles and zeros together
(:func:`.grid_edges.grown_grid`): na 1..4, nb 1..3 become na 1..6, nb 1..5, then 1..9 and 1..8,
then 1..14 and 1..12. The result is the last sweep kept: its choice is the best of the largest
grid kept, a superset of every smaller one.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from .._base.records import record
from ..exceptions import ArxidError, DataError
from . import choice, stages
from .grid import check_grid_size
from .grid_edges import grown_grid
from .integrator import structure_integrates
from .table import SweepTable

__all__ = [
    "DEFAULT_GROWTH_SECONDS",
    "GROWTH_ORDER_LIMIT",
    "MIN_GROWTH_GAIN",
    "STOP_REASONS",
    "GridGrowth",
    "GridRound",
    "grid_text",
    "grow",
    "grows",
]

#: Seconds of sweeping (the first sweep included) after which no larger grid is started.
DEFAULT_GROWTH_SECONDS = 30.0

#: Largest na, nb or nk a grown grid reaches.
GROWTH_ORDER_LIMIT = 30

#: Smallest relative fall of the choice's validation error for which growing goes on (1 %).
MIN_GROWTH_GAIN = 0.01

#: Why growth stopped, as :attr:`GridGrowth.stop` names it.
STOP_REASONS = ("integrates", "insane", "no-gain", "inside", "rounds", "off", "order-cap", "refused", "budget")

# Criteria on a logarithmic scale (N log V + penalty): a difference, not a ratio, compares them.
_LOG_KEYS = ("est_aic", "est_bic", "bic")


def grows(grow: bool | None, default_grid: bool) -> bool:
    """Whether a sweep grows its grid, the one rule of :func:`arxid.sweep`, :func:`arxid.analyse`
    and the command line: as asked (True or False), else (None) the default grid grows and a given
    one is swept as it is.

    Parameters
    ----------
    grow : bool or None
    default_grid : bool
        No order range was given.

    Returns
    -------
    bool
    """
    return default_grid if grow is None else bool(grow)


def grid_text(grid: dict) -> str:
    """A swept grid in words, e.g. ``na 1..4, nb 1..3, nk 0..5`` (per input when the inputs differ).

    Parameters
    ----------
    grid : dict
        ``{"na": range, "nb": [range per input], "nk": [range per input]}`` as a sweep holds it.

    Returns
    -------
    str
    """

    def one(name: str, r: Any) -> str:
        values = list(r)
        return f"{name} {min(values)}..{max(values)}" if len(values) > 1 else f"{name} {values[0]}"

    parts = [one("na", grid["na"])]
    for key in ("nb", "nk"):
        ranges = [tuple(r) for r in grid[key]]
        if len(set(ranges)) == 1:
            parts.append(one(key, ranges[0]))
        else:
            parts += [one(f"{key}[{j}]", r) for j, r in enumerate(ranges)]
    return ", ".join(parts)


@record
class GridRound:
    """One grid swept while growing.

    Attributes
    ----------
    grid : dict
        ``{"na": tuple, "nb": [tuple per input], "nk": [tuple per input]}``.
    n_structures : int
        Structures in the grid.
    seconds : float
        Time of the sweep and of the choice in it.
    structure : str
        The structure chosen in it (best-ranked that passes the step sanity check).
    error : float
        Its ranking error (the validation RMS of ``measure`` for the default ranking).
    measure : str
        What ``error`` is, in words (e.g. ``validation RMS (free-run simulation)``).
    edge : str
        Which edge of the grid the choice sits on ("" when it is inside).
    unit : str
        Unit of ``error`` (the output's, "" when unknown or for a criterion without one).
    """

    grid: dict
    n_structures: int
    seconds: float
    structure: str
    error: float
    measure: str
    edge: str
    unit: str = ""

    @property
    def error_text(self) -> str:
        """``error`` with its unit, e.g. ``0.163 m/s^2``."""
        return f"{self.error:.4g}" + (f" {self.unit}" if self.unit else "")

    @property
    def text(self) -> str:
        """The grid in words (see :func:`grid_text`)."""
        return grid_text(self.grid)

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
        """
        return {
            "grid": {k: [list(r) for r in v] if k != "na" else list(v) for k, v in self.grid.items()},
            "grid_text": self.text,
            "n_structures": self.n_structures,
            "seconds": self.seconds,
            "structure": self.structure,
            "error": self.error,
            "measure": self.measure,
            "unit": self.unit,
            "on_edge": bool(self.edge),
        }


@record
class GridGrowth:
    """Every grid a sweep tried while growing past the edges its choice sat on, and why it stopped.

    Attributes
    ----------
    rounds : tuple of GridRound
        The first grid, then each grown one, in order (``kept`` says whose sweep is the result).
    stop : str
        Why growth stopped, one of :data:`STOP_REASONS`.
    reason : str
        The same in a plain sentence.
    max_seconds : float or None
        The time budget of the whole search (None: no budget).
    kept : int
        Index in ``rounds`` of the grid whose sweep is the result: the last one, or the one before
        when the last growth was not kept (``stop`` ``"integrates"``, ``"insane"`` or ``"no-gain"``).
    min_gain : float
        Smallest relative fall of the error for which growing went on.
    """

    rounds: tuple[GridRound, ...]
    stop: str
    reason: str
    max_seconds: float | None
    kept: int = -1
    min_gain: float = MIN_GROWTH_GAIN

    @property
    def chosen(self) -> GridRound:
        """The round whose sweep is the result."""
        return self.rounds[self.kept]

    @property
    def grew(self) -> bool:
        """More than one grid was swept."""
        return len(self.rounds) > 1

    @property
    def seconds(self) -> float:
        """Total time of every sweep."""
        return float(sum(r.seconds for r in self.rounds))

    @property
    def n_structures(self) -> int:
        """Structures fitted over every grid."""
        return int(sum(r.n_structures for r in self.rounds))

    def lines(self) -> list[str]:
        """What was tried, in plain words: one line per grid, then why it stopped.

        Returns
        -------
        list of str
        """
        if not self.grew:
            return [f"Grid {self.rounds[0].text}: {self.reason}"]
        first = self.rounds[0]
        head = (
            f"The first choice {first.structure} sat on an edge of the grid, so {len(self.rounds) - 1} larger "
            f"grid{'s were' if len(self.rounds) > 2 else ' was'} tried: {self.n_structures:,} structures in all, "
            f"{_seconds(self.seconds)}"
            + ("" if self.max_seconds is None else f" (budget {self.max_seconds:g} s)")
            + f"; chosen {self.chosen.structure} of the grid {self.chosen.text}."
        )
        rows = [
            f"  {r.text}: {r.n_structures:,} structures, {r.seconds:.2f} s, best {r.structure} "
            f"({r.measure} {r.error_text}{', on an edge' if r.edge else ''})"
            + (
                " <- kept"
                if i == self.kept % len(self.rounds) and self.kept % len(self.rounds) < len(self.rounds) - 1
                else ""
            )
            for i, r in enumerate(self.rounds)
        ]
        return [head, *rows, f"  Stopped: {self.reason}"]

    def edge_note(self, structure: str, edges: str) -> str:
        """The grid-edge sentence of a choice on an edge of a grid whose growth was not kept
        (``stop`` ``"integrates"``, ``"insane"`` or ``"no-gain"``): what the larger grid gave.

        Parameters
        ----------
        structure : str
            The chosen structure.
        edges : str
            Its edges in words.

        Returns
        -------
        str
        """
        tried = self.rounds[-1]
        if tried.structure == structure:
            found = "chose it again"
        elif self.stop == "insane":
            found = f"none of its structures passes the step sanity checks (its best is {tried.structure})"
        elif self.stop == "integrates":
            found = f"its best, {tried.structure}, has a pole at z = 1 (a fitted drift, not the plant's dynamics)"
        else:
            found = f"its best, {tried.structure}, did not lower the error by {100 * self.min_gain:g} % or more"
        edge = f"{structure} sits on the edge of the grid ({edges})"
        return f"{edge}, but the larger grid {tried.text} was tried and {found}"

    def __str__(self) -> str:
        return "\n".join(self.lines())

    def to_dict(self) -> dict:
        """JSON-ready: every grid tried, the totals, which grid's sweep is the result (``kept``,
        0-based index in ``rounds``) and why growth stopped.

        Returns
        -------
        dict
        """
        return {
            "grew": self.grew,
            "rounds": [r.to_dict() for r in self.rounds],
            "n_structures": self.n_structures,
            "seconds": self.seconds,
            "max_seconds": self.max_seconds,
            "kept": self.kept % len(self.rounds),
            "stop": self.stop,
            "reason": self.reason,
        }


def _round(table: SweepTable, seconds: float, sane: bool) -> tuple[GridRound, int]:
    """The record of one sweep and the rank of its choice."""
    rank = choice.choice_rank(table, sane)
    grid = {"na": tuple(table.grid["na"]), **{k: [tuple(r) for r in table.grid[k]] for k in ("nb", "nk")}}
    score = float(table.ranking_score()[rank])
    unit = table.estimation.output_unit if "RMS" in table.ranking_text else ""
    name, edge = table.structure_name(rank), table.grid_edge_text(rank)
    return GridRound(grid, len(table), seconds, name, score, table.ranking_text, edge, unit), rank


def _fall(table: SweepTable, rank: int, previous: SweepTable, previous_rank: int) -> float:
    """Relative fall of the ranking error from the previous choice to ``rank``, compared in
    ``table`` (its rows and measure) when the previous choice was scored there."""
    score = table.ranking_score()
    same = (table.na == previous.na[previous_rank]) & (table.nb == previous.nb[previous_rank]).all(axis=1)
    same &= (table.nk == previous.nk[previous_rank]).all(axis=1)
    hits = np.flatnonzero(same)
    before = float(score[hits[0]]) if hits.size and np.isfinite(score[hits[0]]) else np.nan
    if not math.isfinite(before):
        before = float(previous.ranking_score()[previous_rank])
    after = float(score[rank])
    if not (math.isfinite(before) and math.isfinite(after)):
        return 0.0
    if table.sort_by in _LOG_KEYS:
        return 1.0 - math.exp(max(-700.0, min(700.0, (after - before) / max(table.n_est, 1))))
    return 1.0 - after / before if before > 0 else 0.0


def _integrates(table: SweepTable, rank: int) -> bool:
    """The chosen model's own integrator vote (:func:`.integrator.structure_integrates`)."""
    m = table.model(rank)
    return structure_integrates(m.parameters_, m.covariance_, int(m.na_), int(m.n_rows_))


def _turns_integrating(previous: SweepTable, previous_rank: int, grown: SweepTable, rank: int) -> bool:
    """A free-run sweep of a plant not found integrating whose grown choice integrates while the
    previous one did not: the diagnosis would judge it by k-step prediction, not as it was chosen."""
    if previous.integrating or previous.horizon is not None:
        return False
    return _integrates(grown, rank) and not _integrates(previous, previous_rank)


def _work(table: SweepTable, grid: dict) -> tuple[int, float]:
    """Structures of ``grid`` and the core's work for them (seconds of a fast core); raises
    DataError when the grid does not fit in memory."""
    s = table.settings
    est, val = table.estimation, table.validation
    n_threads = int(s.get("n_threads", 0))
    n, p_max, q = check_grid_size(
        est, val, grid["na"], grid["nb"], grid["nk"], tuple(table.effects), n_threads, s.get("max_memory")
    )
    n_val = val.n_samples if val is not None else 0
    n_sim = n_val + (est.n_samples if s.get("simulate_estimation", True) else 0)
    return n, stages.estimated_seconds(n, s.get("top"), p_max, q, est.n_samples + n_val, n_sim, n_threads)


def _predicted_seconds(table: SweepTable, seconds: float, new: dict) -> tuple[int, float]:
    """Structures of the grown grid and its predicted time: the last sweep's measured time scaled
    by the larger of the ratios of structures and of work."""
    n_old, work_old = _work(table, table.grid)
    n_new, work_new = _work(table, new)
    scale = max(n_new / max(n_old, 1), work_new / work_old if work_old > 0 else 1.0, 1.0)
    return n_new, seconds * scale


def _say(table: SweepTable, text: str) -> None:
    """Tell a user who watches the progress bars what the search does next."""
    if table.settings.get("progress") and sys.stderr.isatty():
        print(f"arxid: {text}", file=sys.stderr, flush=True)


def grow(
    result: SweepTable,
    rerun: Callable[[dict], SweepTable],
    *,
    first_seconds: float,
    max_rounds: int | None = None,
    limit: int = GROWTH_ORDER_LIMIT,
    sane: bool = True,
    max_seconds: float | None = DEFAULT_GROWTH_SECONDS,
    min_gain: float = MIN_GROWTH_GAIN,
) -> tuple[SweepTable, GridGrowth]:
    """Re-sweep on grown grids while the choice sits on an edge and improves (the stopping rule of
    this module's docstring).

    Parameters
    ----------
    result : SweepTable
        The first sweep.
    rerun : callable
        Sweeps the same data with the same settings on a grid ``{"na", "nb", "nk"}``.
    first_seconds : float
        Measured time of the first sweep (NaN: unknown, counted as 0).
    max_rounds : int or None
        Largest number of growths (None: no limit; 0: none).
    limit : int
        Largest na, nb or nk tried.
    sane : bool
        Judge the choice as :meth:`arxid.SweepResult.select` with ``sane`` does.
    max_seconds : float or None
        Time budget of the whole search, the first sweep included (None: none).
    min_gain : float
        Smallest relative fall of the choice's error for which growing goes on.

    Returns
    -------
    result : SweepTable
        The last sweep kept (the one before the last growth when it was not kept).
    growth : GridGrowth
    """
    t0 = time.perf_counter()
    res = result
    rec, rank = _round(res, 0.0, sane)
    spent = (first_seconds if math.isfinite(first_seconds) else 0.0) + time.perf_counter() - t0
    rounds = [_with_seconds(rec, spent)]
    while True:
        step = _next_grid(res, rank, rounds, max_rounds, limit, max_seconds)
        if isinstance(step, _Stop):
            return res, GridGrowth(tuple(rounds), step.stop, step.reason, max_seconds, len(rounds) - 1, min_gain)
        new, n_new, predicted = step
        _say(
            res,
            f"{rounds[-1].structure} is on an edge of the grid; sweeping {n_new:,} structures "
            f"({grid_text(new)}, about {_seconds(predicted)})",
        )
        t0 = time.perf_counter()
        try:
            grown = rerun(new)
        except DataError as exc:  # too slow or too large by the sweep's own limits
            why = f"the next grid ({grid_text(new)}) cannot be swept: {exc}."
            return res, GridGrowth(tuple(rounds), "refused", why, max_seconds, len(rounds) - 1, min_gain)
        new_rec, new_rank = _round(grown, 0.0, sane)
        rounds.append(_with_seconds(new_rec, time.perf_counter() - t0))
        if _turns_integrating(res, rank, grown, new_rank):
            why = (
                f"the grid {new_rec.text} chose {new_rec.structure}, whose model has a pole at z = 1 (its unit root "
                f"is not rejected) while the plant was not found integrating: the larger orders fit a slow drift, "
                f"not the plant's dynamics (an unmodelled effect can cause one, see the diagnosis), so "
                f"{rounds[-2].structure} of the grid {rounds[-2].text} stands."
            )
            return res, GridGrowth(tuple(rounds), "integrates", why, max_seconds, len(rounds) - 2, min_gain)
        if sane and not _passes(grown) and _passes(res):
            why = (
                f"no structure of the grid {new_rec.text} passes the step sanity checks (its best, "
                f"{new_rec.structure}, fails them), so {rounds[-2].structure} of the grid {rounds[-2].text} stands."
            )
            return res, GridGrowth(tuple(rounds), "insane", why, max_seconds, len(rounds) - 2, min_gain)
        same = new_rec.structure == rounds[-2].structure
        gain = 0.0 if same else _fall(grown, new_rank, res, rank)
        if gain < min_gain:  # not worth a larger grid: the smaller grid's sweep, and so its numbers, stand
            found = (
                f"chose {new_rec.structure} again"
                if same
                else f"lowered the {new_rec.measure} of the choice by only {100 * max(gain, 0.0):.1f} % (less than "
                f"{100 * min_gain:g} %)"
            )
            why = f"the grid {new_rec.text} {found}, so {rounds[-2].structure} of the grid {rounds[-2].text} stands."
            return res, GridGrowth(tuple(rounds), "no-gain", why, max_seconds, len(rounds) - 2, min_gain)
        res, rank = grown, new_rank


def _passes(table: SweepTable) -> bool:
    """Some structure of the sweep passes the step sanity checks."""
    try:
        choice.select(table, True)
    except ArxidError:
        return False
    return True


def _seconds(s: float) -> str:
    return f"{s:.0f} s" if s >= 10 else (f"{s:.1f} s" if s >= 1 else f"{s:.2g} s")


def _with_seconds(rec: GridRound, seconds: float) -> GridRound:
    return dataclasses.replace(rec, seconds=seconds)


@record
class _Stop:
    stop: str
    reason: str


def _next_grid(
    res: SweepTable,
    rank: int,
    rounds: list[GridRound],
    max_rounds: int | None,
    limit: int,
    max_seconds: float | None,
) -> _Stop | tuple[dict, int, float]:
    """Why growth stops before another sweep, or the grown grid with its size and predicted time."""
    last = rounds[-1]
    if not last.edge:
        return _Stop("inside", f"{last.structure} lies inside the grid: no edge to grow past.")
    if max_rounds is not None and len(rounds) - 1 >= max_rounds:
        if max_rounds == 0:
            return _Stop("off", "the grid was not grown (it was given, or growing was turned off).")
        return _Stop("rounds", f"{max_rounds} growth{'s' if max_rounds > 1 else ''} made (max_rounds).")
    new = grown_grid(res.grid, res.grid_edges(rank), limit, together=True)
    if new is None:
        return _Stop(
            "order-cap", f"the orders reached the largest allowed ({limit}); the choice still sits on an edge."
        )
    try:
        n_new, predicted = _predicted_seconds(res, last.seconds, new)
    except DataError as exc:
        return _Stop("refused", f"the next grid ({grid_text(new)}) cannot be swept: {exc}.")
    spent = sum(r.seconds for r in rounds)
    if max_seconds is not None and spent + predicted > max_seconds:
        return _Stop(
            "budget",
            (
                f"the next grid ({grid_text(new)}, {n_new:,} structures) would take about {_seconds(predicted)}, past "
                f"the budget of {max_seconds:g} s for the search ({_seconds(spent)} spent; max_seconds raises it); the "
                f"choice still sits on an edge."
            ),
        )
    return new, n_new, predicted
