"""Choosing the structure to design with from a sweep's ranking: the best-ranked one that can be used
and, with ``sane``, passes the step sanity checks (:func:`select`), then by the ``rule`` the one with
the fewest parameters the data cannot tell from it. :class:`Selection` says which, and which
better-ranked structures were skipped and why (see docs/selection.md)."""

from __future__ import annotations

import dataclasses

import numpy as np

from .._base.digital_filter import lfilter
from .._base.records import record
from ..exceptions import ArxidError
from .parsimony import DM_CRITICAL, diebold_mariano
from .ranking import FREE_RUN_KEYS, SORT_TEXT
from .table import SweepTable

__all__ = ["SELECTION_RULES", "Selection", "choice_rank", "select"]

#: How :meth:`SweepResult.select` picks among the structures that qualify.
SELECTION_RULES = ("lowest", "smallest-within-noise")


@record
class Selection:
    """Which structure :meth:`SweepResult.best` chose, and which better-ranked ones it skipped and why."""

    rank: int
    structure: str
    skipped: tuple[tuple[int, str, tuple[str, ...]], ...]
    rule: str = "lowest"
    note: str = ""
    grid_edge: str = ""

    def __str__(self) -> str:
        return self.describe()

    def describe(self, limit: int | None = 8) -> str:
        """The choice and the skipped structures, as text.

        Parameters
        ----------
        limit : int or None
            Skipped structures to list (the best-ranked first); None lists all of them.

        Returns
        -------
        str
            One line for the chosen structure, then one per skipped structure with its failed checks.
        """
        lines = [f"chose {self.structure} (rank {self.rank + 1})" + (f": {self.note}" if self.note else "")]
        shown = self.skipped if limit is None else self.skipped[:limit]
        for rank, name, reasons in shown:
            lines.append(f"  skipped {name} (rank {rank + 1}): " + "; ".join(reasons))
        if self.grid_edge:
            lines.append(f"  {self.grid_edge}")
        if len(shown) < len(self.skipped):
            lines.append(
                f"  ... and {len(self.skipped) - len(shown)} more skipped (model.selection_.describe(None) lists all)"
            )
        return "\n".join(lines)


def select(table: SweepTable, sane: bool = True, rule: str = "lowest") -> Selection:
    """The best-ranked usable structure of a sweep; with ``sane``, the best one whose step sanity
    passes (:meth:`arxid.SweepResult.select`, which documents the rules).

    Parameters
    ----------
    table : SweepTable
        The sweep.
    sane : bool
        Also skip structures whose step sanity checks fail.
    rule : {"lowest", "smallest-within-noise"}
        Then take that one, or the one with the fewest parameters not significantly worse.

    Returns
    -------
    Selection

    Raises
    ------
    ArxidError
        When no structure qualifies (the message lists why the best ones were rejected).
    """
    if rule not in SELECTION_RULES:
        raise ArxidError(f"rule must be one of {SELECTION_RULES}, got {rule!r}")
    skipped: list[tuple[int, str, tuple[str, ...]]] = []
    for i in range(len(table)):
        hard = _unusable(table, i)
        if hard is None and table.sort_by in FREE_RUN_KEYS:
            hard = _diverged(table, i)
        if hard is not None:
            skipped.append((i, table.structure_name(i), (hard,)))
            continue
        if sane:
            reasons = _sane_reasons(table, i)
            if reasons:
                skipped.append((i, table.structure_name(i), reasons))
                continue
        sel = Selection(i, table.structure_name(i), tuple(skipped))
        if rule == "smallest-within-noise":
            sel = _smallest_within_noise(table, sel, sane)
        return dataclasses.replace(sel, grid_edge=table.grid_edge_text(sel.rank))
    why = "; ".join(f"{n}: {', '.join(r)}" for _, n, r in skipped[:5])
    raise ArxidError(
        f"no structure of the sweep passes {'the step sanity checks' if sane else 'validation'} ({why}); "
        f"widen the grid, check expect={table.expect!r}, or relax SanityLimits"
    )


def choice_rank(table: SweepTable, sane: bool) -> int:
    """Rank of the structure :func:`select` chooses; without a sane one, the best usable one.

    Parameters
    ----------
    table : SweepTable
        The sweep.
    sane : bool
        Try the step sanity checks first.

    Returns
    -------
    int
    """
    try:
        return select(table, sane).rank
    except ArxidError:
        return select(table, False).rank


def _unusable(table: SweepTable, i: int) -> str | None:
    """Why structure ``i`` cannot be chosen at all (None when it can)."""
    if table.errors[i] is not None:
        return f"could not be fitted: {table.errors[i]}"
    if not np.isfinite(table.ranking_score()[i]):
        return f"its {SORT_TEXT[table.sort_by]} is not a finite number"
    return None


def _diverged(table: SweepTable, i: int) -> str | None:
    if table.diverged_val[i] or table.diverged_est[i]:
        where = "validation" if table.diverged_val[i] else "estimation"
        return f"its {table.measure} diverged on the {where} data"
    return None


def _sane_reasons(table: SweepTable, i: int) -> tuple[str, ...]:
    return tuple(r for r in (_diverged(table, i),) if r) + table.sanity(i).reasons


def _prediction_errors(table: SweepTable, i: int) -> np.ndarray:
    """Validation errors of ranked structure ``i`` at the ranking's own measure (free run from
    rest or one step by filtering the data with its polynomials when the structure is linear
    and the data complete; else the model's own prediction)."""
    from ..checks import prediction_error

    data = table.validation if table.validation is not None else table.estimation
    horizon = table.horizon if table.sort_by in FREE_RUN_KEYS else 1
    linear = not table.effects and np.isfinite(data.y).all() and np.isfinite(data.u).all()
    if not linear or horizon not in (None, 1):
        err = prediction_error(table.model(i), data, horizon)[1]
    else:
        theta, na = table.parameters[i], int(table.na[i])
        a = np.concatenate([[1.0], theta[:na]])
        c, out = na, np.zeros(data.n_samples)
        for j, (nb, nk) in enumerate(zip(table.nb[i], table.nk[i])):
            b = np.concatenate([np.zeros(int(nk)), theta[c : c + int(nb)]])
            c += int(nb)
            out += lfilter(b, a if horizon is None else [1.0], data.u[:, j])
        with np.errstate(all="ignore"):
            err = data.y - out if horizon is None else lfilter(a, [1.0], data.y) - out
    err = np.array(err, dtype=float)
    err[: table.first_lag] = np.nan  # the sweep scores from its first row on
    return err


def _smallest_within_noise(table: SweepTable, sel: Selection, sane: bool) -> Selection:
    best_err = _prediction_errors(table, sel.rank)
    n_best = int(table.n_params[sel.rank])
    order = sorted(
        (i for i in range(len(table)) if table.n_params[i] < n_best), key=lambda i: (int(table.n_params[i]), i)
    )
    for i in order:
        if _unusable(table, i) or (table.sort_by in FREE_RUN_KEYS and _diverged(table, i)):
            continue
        cmp = diebold_mariano(_prediction_errors(table, i), best_err)
        if not cmp.worse and not (sane and _sane_reasons(table, i)):
            note = (
                f"the fewest parameters ({int(table.n_params[i])} against {n_best} of the best-ranked "
                f"{sel.structure}) with a validation error not significantly worse (Diebold-Mariano "
                f"{cmp.statistic:.2f} <= {DM_CRITICAL} on {cmp.n} samples)"
            )
            return Selection(i, table.structure_name(i), sel.skipped, "smallest-within-noise", note)
    note = "no structure with fewer parameters is as good (Diebold-Mariano test at 5%)"
    return dataclasses.replace(sel, rule="smallest-within-noise", note=note)
