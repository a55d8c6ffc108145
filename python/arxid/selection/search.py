"""Exhaustive ARX order sweeps: :func:`sweep` fits and validates every (na, nb, nk) structure of a
grid from one factorization in the Rust core and ranks them in a :class:`SweepResult`."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import numbers
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from .._base import _core, metrics
from .._base.formatting import json_safe
from .._base.limits import available_memory, check_order
from .._base.optional import optional
from ..data.iodata import IOData
from ..exceptions import ArxidError, ArxidWarning, DataError, OrderError
from ..fleet import cluster
from ..fleet import logs as fleet
from ..fleet import sweep as fleet_sweep
from ..models.arguments import check_same_signals
from ..models.arx_model import ArxModel
from ..models.effects import compile_effects
from . import stages
from .grid_edges import Edge, edge_text, grid_edges, grown_grid
from .integrator import VOTERS, IntegratorTest, integrator_test, pole_excess, slowest_time_constant, unit_root_t
from .parsimony import DM_CRITICAL, diebold_mariano
from .sanity import (
    EXPECTATIONS,
    SanityLimits,
    StepSanity,
    check_responses,
    output_range,
    step_sanity,
    typical_amplitudes,
)

if TYPE_CHECKING:
    from ..models.pem import RefinedSweep

__all__ = ["sweep", "SweepResult", "Selection", "DEFAULT_GRID", "SORT_KEYS"]

#: Ranking criteria. ``aic`` and ``mdl`` are MATLAB ``selstruc``'s, on the validation loss when there are
#: validation data; ``est_aic`` and ``est_bic`` (alias ``bic``) are MATLAB ``aic``'s on the estimation fit.
SORT_KEYS = ("val_sim", "val_one_step", "est_sim", "est_one_step", "fpe", "aic", "mdl", "est_aic", "est_bic", "bic")

#: How :meth:`SweepResult.select` picks among the structures that qualify.
SELECTION_RULES = ("lowest", "smallest-within-noise")

#: Criteria that judge a free-run (or k-step) simulation: only these move diverged structures last.
FREE_RUN_KEYS = ("val_sim", "est_sim")

#: The order grid every sweep uses unless told otherwise: the API's :func:`sweep`, :func:`arxid.analyse`
#: and every CLI command. na 1..4 poles, nb 1..3 input coefficients, nk 0..5 samples of delay.
DEFAULT_GRID: dict[str, range] = {"na": range(1, 5), "nb": range(1, 4), "nk": range(0, 6)}


# ---------------------------------------------------------------------------------------------- grid
def _order_range(name: str, value) -> Sequence[int]:
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
    """Smallest order of a range from :func:`_order_range` (O(1) for a ``range``)."""
    return r[0] if isinstance(r, range) else min(r)


def _highest(r: Sequence[int]) -> int:
    """Largest order of a range from :func:`_order_range` (O(1) for a ``range``)."""
    return r[-1] if isinstance(r, range) else max(r)


def _per_input_ranges(name: str, value, m: int) -> list[Sequence[int]]:
    """One shared range for every input, or a list of ranges (one per input)."""
    if isinstance(value, (list, tuple)) and value and all(not isinstance(v, numbers.Integral) for v in value):
        if len(value) != m:
            raise OrderError(
                f"{name} gives {len(value)} ranges but the data have {m} inputs; give one range per input "
                f"or a single shared range"
            )
        return [_order_range(f"{name}[{i}]", v) for i, v in enumerate(value)]
    r = _order_range(name, value)
    return [r] * m


def _gib(b: float) -> str:
    return f"{b / 2**30:.2f} GiB" if b >= 2**28 else f"{b / 2**20:.1f} MiB"


# ---------------------------------------------------------------------------------------------- result
@dataclass(frozen=True)
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


@dataclass(frozen=True, eq=False)
class SweepResult:
    """Every structure of a sweep, ranked (row 0 is the best).

    Attributes
    ----------
    na : ndarray of shape (S,)
    nb, nk : ndarray of shape (S, n_inputs)
    parameters : list of ndarray
        Parameters per structure (a's, b's per input, effect terms), ranked order.
    n_params : ndarray of shape (S,)
    rms_est_one_step, rms_val_one_step : ndarray of shape (S,)
        One-step prediction RMS on estimation and validation rows.
    rms_est, rms_val : ndarray of shape (S,)
        Free-run (or k-step, see ``horizon``) RMS on estimation and validation data; NaN when diverged.
    fit_val : ndarray of shape (S,)
        Validation fit in percent, 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖), of the same simulation.
    fpe, aic, bic : ndarray of shape (S,)
        Akaike's FPE, AIC and BIC of the estimation fit (MATLAB ``fpe`` / ``aic``; also
        ``est_aic`` / ``est_bic``).
    selstruc_aic, selstruc_mdl : ndarray of shape (S,)
        MATLAB ``selstruc``'s criteria ``V (1 + 2d/N)`` and ``V (1 + d log N / N)``, V the one-step
        loss on the validation data (estimation data without them), d the parameters, N the
        estimation rows (see docs/selection.md).
    stable : ndarray of bool, max_pole : ndarray (properties, computed on first use)
        All poles inside the unit circle; largest pole magnitude.
    diverged_est, diverged_val : ndarray of bool
        The simulation left a plausible range and was stopped (its RMS is NaN, not a number).
    errors : tuple of (str or None)
        Why a structure could not be fitted (collinear regressors), else None.
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction (integrating plants).
    integrating : bool
        The plant was expected or detected to integrate.
    integrating_reason : str
        Why it was (or was not) called integrating, with the unit-root test's numbers.
    integrator : IntegratorTest or None
        The unit-root test of the best structures (None when ``expect`` decided).
    grid : dict
        The orders swept: ``{"na": tuple, "nb": [tuple per input], "nk": [tuple per input]}``.
    settings : dict
        The other arguments of :func:`sweep` (what :meth:`extend` re-runs with).
    sort_by : str
    first_lag : int
        The grid's largest lag: every structure uses rows from here on.
    row_orders : tuple (na, nb, nk)
        Orders (per effect-layout column) of the grid's envelope, the largest regressor: rows where
        it touches a NaN are left out for every structure.
    n_est, n_val : int
        Regression rows of estimation and validation data.
    stage : ndarray of shape (S,)
        Which stage ranked each row: 2 = fitted by QR and simulated, 1 = ranked by its one-step
        error only (two-stage sweeps of grids larger than ``top``; its simulation columns are NaN).
    estimation_factor : ndarray of shape (q, q) or None
        Upper-triangular factor R of the envelope's regressor ``[Φ | y]`` on the estimation rows:
        every structure's parameters and their covariance follow from it without the data.
    """

    na: np.ndarray
    nb: np.ndarray
    nk: np.ndarray
    parameters: Sequence
    n_params: np.ndarray
    rms_est_one_step: np.ndarray
    rms_val_one_step: np.ndarray
    rms_est: np.ndarray
    rms_val: np.ndarray
    fit_val: np.ndarray
    fpe: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
    selstruc_aic: np.ndarray
    selstruc_mdl: np.ndarray
    diverged_est: np.ndarray
    diverged_val: np.ndarray
    errors: tuple
    horizon: int | None
    integrating: bool
    integrating_reason: str
    sort_by: str
    first_lag: int
    row_orders: tuple
    n_est: int
    n_val: int
    effects: tuple[str, ...]
    expect: str | None
    limits: SanityLimits
    estimation: IOData = field(repr=False)
    validation: IOData | None = field(repr=False)
    integrator: IntegratorTest | None = None
    grid: dict = field(default_factory=dict, repr=False)
    settings: dict = field(default_factory=dict, repr=False)
    stage: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.uint8), repr=False)
    estimation_factor: np.ndarray | None = field(default=None, repr=False)
    _cache: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------------ basics
    def __len__(self) -> int:
        return len(self.na)

    def structure_name(self, i: int) -> str:
        """``ARX(na,nb,nk)`` of ranked structure ``i`` (per-input lists for MISO).

        Parameters
        ----------
        i : int
            Rank of the structure (0 is the best).

        Returns
        -------
        str
            E.g. ``ARX(2,1,1)`` or ``ARX(2,[1, 2],[1, 0]) + const``; effect terms are appended.
        """
        nb, nk = self.nb[i], self.nk[i]
        b = int(nb[0]) if len(set(nb.tolist())) == 1 else list(map(int, nb))
        k = int(nk[0]) if len(set(nk.tolist())) == 1 else list(map(int, nk))
        return f"ARX({int(self.na[i])},{b},{k})" + (" + " + " + ".join(self.effects) if self.effects else "")

    @property
    def ranking_text(self) -> str:
        """What the ranking sorts by, in words (e.g. ``validation RMS (free-run simulation)``)."""
        return f"{_SORT_TEXT[self.sort_by]} ({self.measure})"

    def summary(self, top: int = 20) -> dict:
        """JSON-ready summary: size, measure, ranking, integrator verdict and the best ``top`` rows.

        Parameters
        ----------
        top : int
            Ranked rows to include (with their step sanity verdicts).

        Returns
        -------
        dict
        """
        out = self.to_dict(sanity=False)
        out["n_structures"] = len(self)
        out["structures"] = self._rows(top, sanity=True)
        return out

    @property
    def measure(self) -> str:
        """What ``rms_est`` / ``rms_val`` measure."""
        return "free-run simulation" if self.horizon is None else f"{self.horizon}-step-ahead prediction"

    def _index(self, i: int) -> int:
        if isinstance(i, bool) or not isinstance(i, numbers.Integral) or not -len(self) <= i < len(self):
            raise ArxidError(f"rank {i!r} is outside the sweep (0..{len(self) - 1})")
        return int(i) % len(self)

    @property
    def max_pole(self) -> np.ndarray:
        """Largest pole magnitude of every structure, shape (S,)."""
        if "max_pole" not in self._cache:
            theta = np.full((len(self), max(int(self.na.max()), 1)), np.nan)
            for i, (th, k) in enumerate(zip(self.parameters, self.na)):
                theta[i, :k] = th[:k]
            self._cache["max_pole"] = _max_poles(self.na, theta)
        return self._cache["max_pole"]

    @property
    def stable(self) -> np.ndarray:
        """All poles strictly inside the unit circle, shape (S,)."""
        return self.max_pole < 1.0

    # ------------------------------------------------------------------ models
    def model(self, i: int = 0) -> ArxModel:
        """The ranked structure ``i`` as a fitted :class:`~arxid.ArxModel`, refitted on the sweep's rows
        (``first_lag``), so its parameters equal the sweep's.

        Parameters
        ----------
        i : int
            Rank of the structure (0 is the best; negative counts from the worst).

        Returns
        -------
        ArxModel
            The fitted model (cached: the same object on every call).

        Raises
        ------
        ArxidError
            When ``i`` is outside the sweep.
        """
        i = self._index(i)
        key = ("model", i)
        if key not in self._cache:
            nb = tuple(int(v) for v in self.nb[i])
            nk = tuple(int(v) for v in self.nk[i])
            self._cache[key] = ArxModel(na=int(self.na[i]), nb=nb, nk=nk, effects=self.effects).fit(
                self.estimation, first_lag=self.first_lag, rows_like=self.row_orders
            )
        return self._cache[key]

    def sanity(self, i: int) -> StepSanity:
        """Step sanity verdict of ranked structure ``i`` (computed on first use, then cached).

        Parameters
        ----------
        i : int
            Rank of the structure (0 is the best).

        Returns
        -------
        StepSanity
            The checks of its step responses on the validation data (estimation data without it);
            a structure that could not be fitted is flagged ``not-fitted``.
        """
        i = self._index(i)
        key = ("sanity", i)
        if key not in self._cache:
            self._cache[key] = self._compute_sanity(i)
        return self._cache[key]

    def _compute_sanity(self, i: int) -> StepSanity:
        data = self.validation if self.validation is not None else self.estimation
        expect = self.expectation
        name = self.structure_name(i)
        if self.errors[i] is not None:
            return StepSanity(name, ("not-fitted",), (self.errors[i],), math.nan, output_range(data), (), 0, expect)
        if self.effects:
            return step_sanity(self.model(i), data, expect=expect, limits=self.limits)
        # Linear structure: the step response is a filter of a constant (exactly antisymmetric).
        from scipy.signal import lfilter

        theta, na = self.parameters[i], int(self.na[i])
        a = np.concatenate([[1.0], theta[:na]])
        amps = typical_amplitudes(data)
        horizon = data.n_samples
        pos, neg = [], []
        c = na
        with np.errstate(all="ignore"):
            for j, (b, k) in enumerate(zip(self.nb[i], self.nk[i])):
                b, k = int(b), int(k)
                if b == 0:
                    continue
                num = np.concatenate([np.zeros(k), theta[c : c + b]])
                c += b
                s = lfilter(num, a, np.full(horizon, amps[j]))
                pos.append(s)
                neg.append(-s)
        poles = np.roots(a) if na else np.zeros(0)
        return check_responses(
            name,
            pos,
            neg,
            poles,
            out_range=output_range(data),
            amplitudes=amps,
            expect=expect,
            limits=self.limits,
            pole_excess=self._pole_excess(i, poles),
            record=self.n_est,
        )

    @property
    def expectation(self) -> str:
        """What the step sanity checks assume: ``expect`` when given, else ``"integrating"`` for a
        detected integrator and ``"stable"`` otherwise (so a sane model of a plant that is not
        integrating has every pole inside the unit circle)."""
        if self.expect is not None:
            return self.expect
        return "integrating" if self.integrating else "stable"

    def _pole_excess(self, i: int, poles: np.ndarray) -> float | None:
        """Standard errors by which the largest pole lies outside the unit circle (only computed
        when it does; needs the structure's parameter covariance)."""
        if not poles.size or np.max(np.abs(poles)) <= 1.0 or self.expectation == "stable":
            return None
        m = self.model(i)
        return pole_excess(m.parameters_, m.covariance_, m.na_)[1]

    def _unusable(self, i: int) -> str | None:
        """Why structure ``i`` cannot be chosen at all (None when it can)."""
        if self.errors[i] is not None:
            return f"could not be fitted: {self.errors[i]}"
        if not np.isfinite(self.ranking_score()[i]):
            return f"its {_SORT_TEXT[self.sort_by]} is not a finite number"
        return None

    def _diverged(self, i: int) -> str | None:
        if self.diverged_val[i] or self.diverged_est[i]:
            where = "validation" if self.diverged_val[i] else "estimation"
            return f"its {self.measure} diverged on the {where} data"
        return None

    def select(self, sane: bool = True, rule: str = "lowest") -> Selection:
        """The best-ranked usable structure; with ``sane``, the best one whose step sanity passes.

        Parameters
        ----------
        sane : bool
            Also skip structures whose step sanity checks fail (which include stability for a
            plant that is not integrating, and a free run that diverged); without it, only
            structures that were not fitted or have no finite ranking error are skipped (and, for
            a free-run criterion, those whose simulation diverged).
        rule : {"lowest", "smallest-within-noise"}
            ``"lowest"``: the best-ranked one. ``"smallest-within-noise"``: then the structure with
            the fewest parameters (that also qualifies) whose validation error is not
            significantly worse than that one's (Diebold–Mariano test, :mod:`arxid.parsimony`).

        Returns
        -------
        Selection
            The chosen rank and structure, and the better-ranked structures skipped for failed checks.

        Raises
        ------
        ArxidError
            When no structure qualifies (the message lists why the best ones were rejected).
        """
        if rule not in SELECTION_RULES:
            raise ArxidError(f"rule must be one of {SELECTION_RULES}, got {rule!r}")
        skipped: list[tuple[int, str, tuple[str, ...]]] = []
        for i in range(len(self)):
            hard = self._unusable(i)
            if hard is None and self.sort_by in FREE_RUN_KEYS:
                hard = self._diverged(i)
            if hard is not None:
                skipped.append((i, self.structure_name(i), (hard,)))
                continue
            if sane:
                reasons = self._sane_reasons(i)
                if reasons:
                    skipped.append((i, self.structure_name(i), reasons))
                    continue
            sel = Selection(i, self.structure_name(i), tuple(skipped))
            if rule == "smallest-within-noise":
                sel = self._smallest_within_noise(sel, sane)
            return dataclasses.replace(sel, grid_edge=self.grid_edge_text(sel.rank))
        why = "; ".join(f"{n}: {', '.join(r)}" for _, n, r in skipped[:5])
        raise ArxidError(
            f"no structure of the sweep passes {'the step sanity checks' if sane else 'validation'} ({why}); "
            f"widen the grid, check expect={self.expect!r}, or relax SanityLimits"
        )

    def _sane_reasons(self, i: int) -> tuple[str, ...]:
        return tuple(r for r in (self._diverged(i),) if r) + self.sanity(i).reasons

    def _prediction_errors(self, i: int) -> np.ndarray:
        """Validation errors of ranked structure ``i`` at the ranking's own measure (free run from
        rest or one step by filtering the data with its polynomials when the structure is linear
        and the data complete; else the model's own prediction)."""
        from scipy.signal import lfilter

        from ..checks import prediction_error

        data = self.validation if self.validation is not None else self.estimation
        horizon = self.horizon if self.sort_by in FREE_RUN_KEYS else 1
        linear = not self.effects and np.isfinite(data.y).all() and np.isfinite(data.u).all()
        if not linear or horizon not in (None, 1):
            err = prediction_error(self.model(i), data, horizon)[1]
        else:
            theta, na = self.parameters[i], int(self.na[i])
            a = np.concatenate([[1.0], theta[:na]])
            c, out = na, np.zeros(data.n_samples)
            for j, (nb, nk) in enumerate(zip(self.nb[i], self.nk[i])):
                b = np.concatenate([np.zeros(int(nk)), theta[c : c + int(nb)]])
                c += int(nb)
                out += lfilter(b, a if horizon is None else [1.0], data.u[:, j])
            with np.errstate(all="ignore"):
                err = data.y - out if horizon is None else lfilter(a, [1.0], data.y) - out
        err = np.array(err, dtype=float)
        err[: self.first_lag] = np.nan  # the sweep scores from its first row on
        return err

    def _smallest_within_noise(self, sel: Selection, sane: bool) -> Selection:
        best_err = self._prediction_errors(sel.rank)
        n_best = int(self.n_params[sel.rank])
        order = sorted(
            (i for i in range(len(self)) if self.n_params[i] < n_best), key=lambda i: (int(self.n_params[i]), i)
        )
        for i in order:
            if self._unusable(i) or (self.sort_by in FREE_RUN_KEYS and self._diverged(i)):
                continue
            cmp = diebold_mariano(self._prediction_errors(i), best_err)
            if not cmp.worse and not (sane and self._sane_reasons(i)):
                note = (
                    f"the fewest parameters ({int(self.n_params[i])} against {n_best} of the best-ranked "
                    f"{sel.structure}) with a validation error not significantly worse (Diebold-Mariano "
                    f"{cmp.statistic:.2f} <= {DM_CRITICAL} on {cmp.n} samples)"
                )
                return Selection(i, self.structure_name(i), sel.skipped, "smallest-within-noise", note)
        note = "no structure with fewer parameters is as good (Diebold-Mariano test at 5%)"
        return dataclasses.replace(sel, rule="smallest-within-noise", note=note)

    def grid_edges(self, i: int) -> tuple[Edge, ...]:
        """The grid edges ranked structure ``i`` touches (see :mod:`arxid.grid_edges`).

        Parameters
        ----------
        i : int
            Rank of the structure.

        Returns
        -------
        tuple of Edge
            Empty when it lies inside the grid.
        """
        i = self._index(i)
        if not self.grid:
            return ()
        return grid_edges(self.grid, int(self.na[i]), self.nb[i].tolist(), self.nk[i].tolist(), self.nb.shape[1] > 1)

    def grid_edge_text(self, i: int) -> str:
        """One sentence when ranked structure ``i`` sits on a grid edge, with the ranges to try; else "".

        Parameters
        ----------
        i : int
            Rank of the structure.

        Returns
        -------
        str
        """
        return edge_text(self.structure_name(i), self.grid_edges(i))

    def extend(self, max_rounds: int = 3, limit: int = 30, sane: bool = True) -> SweepResult:
        """Grow the grid past the edges the chosen structure sits on, until it is inside or a limit.

        Each round re-runs :func:`sweep` with the same data and settings on the grid whose edge
        ranges are grown by ``max(2, ⌈len/2⌉)`` values (:func:`arxid.grid_edges.grown_grid`).

        Parameters
        ----------
        max_rounds : int
            Largest number of re-runs.
        limit : int
            Largest na, nb or nk tried.
        sane : bool
            Judge the choice as :meth:`select` with ``sane`` does.

        Returns
        -------
        SweepResult
            The last sweep (this one when the choice is already inside the grid).
        """
        res = self
        for _ in range(max_rounds):
            rank = res._choice_rank(sane)
            new = grown_grid(res.grid, res.grid_edges(rank), limit)
            if new is None:
                break
            res = sweep(res.estimation, na=new["na"], nb=new["nb"], nk=new["nk"], **res.settings)
        return res

    def _choice_rank(self, sane: bool) -> int:
        try:
            return self.select(sane).rank
        except ArxidError:
            return self.select(False).rank

    def best(self, sane: bool = False, *, rule: str = "lowest", explain: bool = True) -> ArxModel:
        """The best-ranked structure as a fitted :class:`~arxid.ArxModel`.

        Parameters
        ----------
        sane : bool
            Skip structures flagged by the step sanity checks (see :mod:`arxid.sanity`).
        rule : {"lowest", "smallest-within-noise"}
            See :meth:`select`. For control design prefer ``"smallest-within-noise"`` when the
            top of the ranking is flat: the fewest parameters whose validation error the data
            cannot tell from the best's give a controller fewer states and a model less fitted to
            noise. ``"lowest"`` is the default: it is MATLAB's ``selstruc`` pick, and parsimony
            trades structure for parameters without regard to what a controller needs most, the
            delay (on the simulated quadrotor roll axis it gives ARX(3,1,9) for ARX(3,2,8), one
            coefficient fewer and one sample more dead time than the plant has).
        explain : bool
            With ``sane``, warn (:class:`~arxid.ArxidWarning`) which better-ranked structures were
            skipped and why.
            The same is in the model's attribute ``selection_`` (a :class:`Selection`).

        Returns
        -------
        ArxModel
            The chosen structure, fitted on the sweep's rows, with ``selection_`` set.

        Raises
        ------
        ArxidError
            When no structure qualifies (see :meth:`select`).
        """
        sel = self.select(sane, rule)
        if sane and explain and sel.skipped:
            warnings.warn(f"arxid.sweep best(sane=True): {sel}", ArxidWarning, stacklevel=2)
        model = self.model(sel.rank)
        model.selection_ = sel
        return model

    # ------------------------------------------------------------------ tables
    def ranking_score(self) -> np.ndarray:
        """The column the ranking sorts by (``sort_by``), shape (S,).

        Returns
        -------
        ndarray
        """
        return _ranking_column(self, self.sort_by)

    def _rows(self, n: int | None, sanity: bool):
        n = len(self) if n is None else min(n, len(self))
        rows = []
        for i in range(n):
            sv = self.sanity(i) if sanity else None
            rows.append(
                {
                    "rank": i + 1,
                    "structure": self.structure_name(i),
                    "na": int(self.na[i]),
                    "nb": [int(v) for v in self.nb[i]],
                    "nk": [int(v) for v in self.nk[i]],
                    "n_params": int(self.n_params[i]),
                    "rms_est": _num(self.rms_est[i]),
                    "rms_val": _num(self.rms_val[i]),
                    "rms_est_one_step": _num(self.rms_est_one_step[i]),
                    "rms_val_one_step": _num(self.rms_val_one_step[i]),
                    "fit_val": _num(self.fit_val[i]),
                    "fpe": _num(self.fpe[i]),
                    "aic": _num(self.aic[i]),
                    "bic": _num(self.bic[i]),
                    "stable": bool(self.stable[i]),
                    "max_pole": _num(self.max_pole[i]),
                    "diverged_est": bool(self.diverged_est[i]),
                    "diverged_val": bool(self.diverged_val[i]),
                    "horizon": self.horizon,
                    "stage": int(self.stage[i]),
                    "error": self.errors[i],
                    "step_sanity": None if sv is None else ("ok" if sv.ok else ",".join(sv.flags)),
                    "parameters": [float(x) for x in self.parameters[i]],
                }
            )
        return rows

    def to_pandas(self, sanity: bool = True):
        """One row per structure in ranked order.

        Parameters
        ----------
        sanity : bool
            Run the step sanity checks for the ``step_sanity`` column (one step response per
            structure); False leaves it None.

        Returns
        -------
        pandas.DataFrame
            S rows indexed by ``rank`` (1 is the best): orders, errors, criteria, poles, parameters.

        Raises
        ------
        ImportError
            When pandas is not installed.
        """
        try:
            import pandas as pd
        except ImportError:  # pragma: no cover
            raise ImportError("to_pandas needs pandas: pip install 'arxid[pandas]'") from None
        df = pd.DataFrame(self._rows(None, sanity))
        return df.set_index("rank")

    def to_dict(self, sanity: bool = True) -> dict:
        """JSON-ready dict of the sweep: measure, horizon, integrator verdict and every ranked structure.

        Parameters
        ----------
        sanity : bool
            Run the step sanity checks for each structure's ``step_sanity`` entry (else None).

        Returns
        -------
        dict
            ``format``, ``measure``, ``horizon``, ... and ``structures``, a list of S row dicts in
            ranked order; NaN errors are None.
        """
        return {
            "format": "arxid.SweepResult",
            "measure": self.measure,
            "horizon": self.horizon,
            "integrating": self.integrating,
            "integrating_reason": self.integrating_reason,
            "sort_by": self.sort_by,
            "first_lag": self.first_lag,
            "n_est": self.n_est,
            "n_val": self.n_val,
            "effects": list(self.effects),
            "expect": self.expect,
            "structures": self._rows(None, sanity),
        }

    def to_json(self, path=None, indent: int | None = None, sanity: bool = True) -> str:
        """JSON of :meth:`to_dict`; NaN (diverged or not fitted) becomes null.

        Parameters
        ----------
        path : str or path-like, optional
            File to write the JSON to as well.
        indent : int, optional
            Indentation of the JSON; None writes one line.
        sanity : bool
            Run the step sanity checks (see :meth:`to_dict`).

        Returns
        -------
        str
            The JSON text.
        """
        text = json.dumps(json_safe(self.to_dict(sanity)), indent=indent, allow_nan=False)
        if path is not None:
            with open(path, "w") as fh:
                fh.write(text)
        return text

    def table(self, n: int = 12, sanity: bool = True, more_hint: str = ".to_pandas() has all") -> str:
        """The top ``n`` rows as text, like Sarıoğlu & Kural's Table 1 plus more columns.

        Parameters
        ----------
        n : int
            Ranked rows to show.
        sanity : bool
            Run the step sanity checks for the ``step`` column (else ``-``).
        more_hint : str
            How to see the rows left out, printed after their count (the CLI names ``--all``).

        Returns
        -------
        str
            A header line (sizes, ranking measure, horizon), then an aligned table, one row per structure.
        """
        k = "" if self.horizon is None else f" k={self.horizon}"
        head = [
            "#",
            "structure",
            f"RMS est{k}",
            f"RMS val{k}",
            "fit val %",
            "RMS val 1-step",
            "FPE",
            "AIC",
            "BIC",
            "p",
            "stable",
            "step",
            "stage",
        ]
        lines = []
        for i in range(min(n, len(self))):
            if self.errors[i] is not None:
                cells = [str(i + 1), self.structure_name(i), "not fitted", "not fitted"] + ["-"] * 7 + ["collinear"]
                cells.append(str(int(self.stage[i])))
            else:
                sv = self.sanity(i) if sanity else None
                cells = [
                    str(i + 1),
                    self.structure_name(i),
                    "diverged" if self.diverged_est[i] else _fmt(self.rms_est[i]),
                    "diverged" if self.diverged_val[i] else _fmt(self.rms_val[i]),
                    "-" if self.diverged_val[i] else _fmt(self.fit_val[i], ".1f"),
                    _fmt(self.rms_val_one_step[i]),
                    _fmt(self.fpe[i]),
                    _fmt(self.aic[i], ".4g"),
                    _fmt(self.bic[i], ".4g"),
                    str(int(self.n_params[i])),
                    "yes" if self.stable[i] else "no",
                    "-" if sv is None else ("ok" if sv.ok else ",".join(sv.flags)),
                    str(int(self.stage[i])),
                ]
            lines.append(cells)
        widths = [max(len(h), *(len(r[j]) for r in lines)) if lines else len(h) for j, h in enumerate(head)]
        out = [
            f"ARX sweep: {len(self)} structures, {self.n_est} estimation rows, {self.n_val} validation rows, "
            f"ranked by {_SORT_TEXT[self.sort_by]} ({self.measure}"
            + (f", horizon {self.horizon} samples = {self.horizon * self.estimation.ts:g} s" if self.horizon else "")
            + ")",
        ]
        if stages.stages_text(self.stage, self.validation is not None):
            out.append(stages.stages_text(self.stage, self.validation is not None))
        if self.integrating:
            out.append(
                f"integrating plant ({self.integrating_reason}): free-run error is meaningless, "
                f"RMS columns are {self.horizon}-step-ahead prediction errors"
            )
        out.append("  ".join(h.ljust(w) for h, w in zip(head, widths)))
        out += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in lines]
        if len(self) > n:
            out.append(f"... {len(self) - n} more structures ({more_hint})")
        return "\n".join(out)

    def __str__(self) -> str:
        return self.table()

    def __repr__(self) -> str:
        return f"<SweepResult {len(self)} structures, best {self.structure_name(0)}, {self.measure}>"

    def plot(self, nb_input: int = 0, chosen: int | None = None) -> Any:
        """Heat map of the ranking error over (na, nk) for each nb.

        Parameters
        ----------
        nb_input : int
            For several inputs: whose nb and nk span the panels.
        chosen : int, optional
            Rank of the chosen structure, marked with a star.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.sweep import plot_sweep

        m = self.nb.shape[1]
        if isinstance(nb_input, bool) or not isinstance(nb_input, numbers.Integral) or not 0 <= nb_input < m:
            raise DataError(f"nb_input {nb_input!r} does not exist: the sweep has {m} input(s), numbered 0 to {m - 1}")
        return plot_sweep(self, nb_input=nb_input, chosen=chosen)


_SORT_TEXT = {
    "val_sim": "validation RMS",
    "val_one_step": "validation one-step RMS",
    "est_sim": "estimation RMS",
    "est_one_step": "estimation one-step RMS",
    "fpe": "FPE",
    "aic": "AIC (MATLAB selstruc, validation loss)",
    "mdl": "MDL (MATLAB selstruc, validation loss)",
    "est_aic": "AIC of the estimation fit",
    "est_bic": "BIC of the estimation fit",
    "bic": "BIC of the estimation fit",
}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _fmt(x, spec: str = ".4g") -> str:
    x = float(x)
    return format(x, spec) if math.isfinite(x) else "nan"


def _ranking_column(r, key: str) -> np.ndarray:
    """The column ``key`` of a :class:`SweepResult` (or of the builder's columns)."""
    one = {"val_one_step": "rms_val_one_step", "est_one_step": "rms_est_one_step"}
    if isinstance(r, _Columns):
        one = {"val_one_step": "val_one_step", "est_one_step": "est_one_step"}
    name = {
        "val_sim": "rms_val",
        "est_sim": "rms_est",
        **one,
        "fpe": "fpe",
        "aic": "selstruc_aic",
        "mdl": "selstruc_mdl",
        "est_aic": "aic",
        "est_bic": "bic",
        "bic": "bic",
    }[key]
    return getattr(r, name)


# ---------------------------------------------------------------------------------------------- sweep
def _parameters_and_covariance(result: SweepResult, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Parameters and covariance of ranked structure ``i``: from the sweep's estimation factor
    (microseconds), or by refitting where there is none or effect columns change the layout."""
    if result.estimation_factor is None or result.effects:
        m = result.model(i)
        return m.parameters_, m.covariance_
    orders = (int(result.na[i]), [int(v) for v in result.nb[i]], [int(v) for v in result.nk[i]])
    na_env, nb_env, nk_env = result.row_orders
    envelope = (int(na_env), list(nb_env), list(nk_env))
    fit = _core.fit_from_factor(result.estimation_factor, result.n_est, envelope, orders, [])
    return np.asarray(fit.theta), metrics.parameter_covariance(fit.inv_gram, fit.rss, fit.n_rows)


def _integrator_verdict(result: SweepResult) -> IntegratorTest:
    """Unit-root test (:mod:`arxid.integrator`) of the best structures by FPE of a free-run sweep."""
    fpe = np.where(np.isfinite(result.fpe), result.fpe, np.inf)
    names: list[str] = []
    t_values: list[float] = []
    taus: list[float] = []
    for i in np.argsort(fpe, kind="stable"):
        if len(names) == VOTERS or not np.isfinite(fpe[i]):
            break
        if result.errors[i] is not None or result.na[i] == 0:
            continue
        theta, covariance = _parameters_and_covariance(result, int(i))
        names.append(result.structure_name(int(i)))
        t_values.append(unit_root_t(theta, covariance, int(result.na[i])))
        taus.append(slowest_time_constant(theta, int(result.na[i])))
    return integrator_test(names, t_values, taus, result.n_est)


@overload
def sweep(
    data: IOData,
    na=...,
    nb=...,
    nk=...,
    *,
    validation=...,
    sort_by: str = ...,
    n_threads: int = ...,
    progress: bool = ...,
    effects: Sequence[str] = ...,
    expect: str | None = ...,
    horizon: int | None = ...,
    max_memory: int | None = ...,
    limits: SanityLimits | None = ...,
    simulate_estimation: bool = ...,
    auto_extend: bool = ...,
    refine: None = None,
    refine_top: int = ...,
    top: int | None = ...,
    max_seconds: float | None = ...,
    client: Any = ...,
    per_experiment: bool = ...,
    read: Any = ...,
) -> SweepResult: ...


@overload
def sweep(
    data: IOData,
    na=...,
    nb=...,
    nk=...,
    *,
    validation=...,
    sort_by: str = ...,
    n_threads: int = ...,
    progress: bool = ...,
    effects: Sequence[str] = ...,
    expect: str | None = ...,
    horizon: int | None = ...,
    max_memory: int | None = ...,
    limits: SanityLimits | None = ...,
    simulate_estimation: bool = ...,
    auto_extend: bool = ...,
    refine: Literal["oe"],
    refine_top: int = ...,
    top: int | None = ...,
    max_seconds: float | None = ...,
    client: Any = ...,
    per_experiment: bool = ...,
    read: Any = ...,
) -> RefinedSweep: ...


def sweep(
    data: IOData,
    na=DEFAULT_GRID["na"],
    nb=DEFAULT_GRID["nb"],
    nk=DEFAULT_GRID["nk"],
    *,
    validation=None,
    sort_by: str = "val_sim",
    n_threads: int = 0,
    progress: bool = True,
    effects: Sequence[str] = (),
    expect: str | None = None,
    horizon: int | None = None,
    max_memory: int | None = None,
    limits: SanityLimits | None = None,
    simulate_estimation: bool = True,
    auto_extend: bool = False,
    refine: Literal["oe"] | None = None,
    refine_top: int = 5,
    top: int | None = stages.DEFAULT_TOP,
    max_seconds: float | None = 3600.0,
    client: Any = None,
    per_experiment: bool = False,
    read: Any = None,
) -> Any:
    """Fit and validate every ARX structure of a grid (MATLAB ``arxstruc`` / ``selstruc``, faster).

    Parameters
    ----------
    data : IOData
        Estimation data.
    na : int or iterable of int
        Numbers of poles to try.
    nb, nk : int, iterable of int, or list of iterables (one per input)
        Input orders and delays to try. One iterable is shared by every input (each input still
        ranges over it independently); the grid is the cartesian product of all ranges.
    validation : None, IOData or float
        Validation data, or the fraction of ``data`` (its end) to hold out. None validates on the
        estimation data only (``sort_by="val_sim"`` then ranks by estimation error).
    sort_by : {"val_sim", "val_one_step", "est_sim", "est_one_step", "fpe", "aic", "bic"}
        Ranking measure. ``*_sim`` is the free-run RMS (the k-step RMS for integrating plants).
    n_threads : int
        Threads (0 = all cores). Results are identical for any number of threads.
    progress : bool
        Show a tqdm progress bar (only when stderr is a terminal).
    effects : sequence of str
        Effect terms added to every structure; input-derived terms take the orders of their input.
    expect : {None, "stable", "integrating", "double-integrating"}
        What the physics says. Integrating expectations rank by k-step prediction error; None
        detects integrators (a pole at 1 in most of the 5 best structures by FPE).
    horizon : int, optional
        Rank by the k-step-ahead prediction error with this k instead of free run. Integrating
        plants use k-step prediction anyway, by default with ``k = max(10, 2 × largest lag)``.
    max_memory : int, optional
        Refuse grids needing more bytes than this (default: half the available memory).
    limits : SanityLimits, optional
        Thresholds of the step sanity checks.
    simulate_estimation : bool
        Also simulate every structure on the estimation data (``rms_est``).
    auto_extend : bool
        When the best sane structure sits on an edge of the grid, grow the grid past it and sweep
        again (:meth:`SweepResult.extend`, at most 3 rounds, orders up to 30).
    refine : {None, "oe"}
        ``"oe"`` refits the ``refine_top`` best ARX structures (and a small grid of nb, nf, nk) as
        output-error models and ranks all of them by validation free-run error
        (:func:`arxid.refine`); the table says which model class each row is.
    refine_top : int
        Number of best ARX structures refined when ``refine`` is given.

    top : int or None
        Grids larger than this run in two stages (see :mod:`arxid.stages`): every structure is
        ranked by its one-step validation error (MATLAB ``arxstruc``), and only the best ``top`` are
        fitted again and simulated; ``stage`` says which rows. None simulates every structure.
    max_seconds : float or None
        Refuse grids whose estimated run time exceeds this many seconds, before anything is
        allocated (None: no limit).
    client : dask.distributed.Client, optional
        With a list of logs as ``data``: run on this Dask cluster, where the workers read the logs
        (see :mod:`arxid.fleet_sweep`). The client reads none during the sweep; the result's
        ``estimation`` and ``validation`` are read on the client when first needed
        (:class:`arxid.cluster.LogsOnDemand`). Effects are computed by the workers, within each log.
    per_experiment : bool
        With a list of logs: sweep each log separately and return a :class:`arxid.fleet.FleetSweep`.
    read : dict or callable, optional
        With file paths in ``data``: how to read them (see :func:`arxid.fleet.load_experiment`).

    Returns
    -------
    SweepResult
        For a list of logs, the sweep of all of them at once (a :class:`arxid.fleet.FleetSweep`
        with ``per_experiment=True``); a RefinedSweep when ``refine`` is given.

    Notes
    -----
    Every structure uses the regression rows from the grid's largest lag on (as ``arxstruc``), and
    its free-run simulation starts there from measured outputs, so all errors compare on the same
    samples. The Rust core reduces ``[Φ_max | y]`` once to a triangular R by Householder QR and
    solves each structure from its columns of R; the simulation of linear structures runs several
    structures of neighbouring ``na`` side by side in SIMD lanes. A simulation that leaves
    ±``DIVERGENCE_FACTOR`` (1000) times the largest measured output of its data set is stopped and
    reported as diverged (the one divergence rule, see :mod:`arxid._metrics`).

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(3000)
    >>> y = np.zeros(3000)
    >>> for t in range(3, 3000):
    ...     y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 3] + 0.01 * rng.standard_normal()
    >>> res = arxid.sweep(arxid.IOData(y, u, ts=0.01), na=range(1, 4), nb=range(1, 3), nk=range(0, 5),
    ...                   validation=0.3, sort_by="bic", progress=False)
    >>> res.structure_name(0)
    'ARX(2,1,3)'
    """
    workers = None  # a fleet's logs on a Dask cluster
    if isinstance(data, (list, tuple)):
        options = dict(na=na, nb=nb, nk=nk, sort_by=sort_by, n_threads=n_threads, progress=progress, effects=effects)
        options.update(expect=expect, horizon=horizon, max_memory=max_memory, limits=limits, top=top)
        options.update(simulate_estimation=simulate_estimation, max_seconds=max_seconds, auto_extend=auto_extend)
        fraction = fleet.check_validation(validation)
        if per_experiment:
            return fleet.sweep_each(data, client, read, fraction, sweep, options)
        workers, (data, validation) = _fleet_parts(client, data, read, fraction)
    if not isinstance(data, IOData):
        raise DataError(
            f"sweep needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
        )
    if sort_by not in SORT_KEYS:
        raise ArxidError(f"sort_by must be one of {SORT_KEYS}, got {sort_by!r}")
    if expect not in EXPECTATIONS:
        raise ArxidError(f"expect must be one of {EXPECTATIONS}, got {expect!r}")
    if refine not in (None, "oe"):
        raise ArxidError(f"refine must be None or 'oe' (output-error refinement), got {refine!r}")
    est, val = _validation_split(data, validation)
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, numbers.Integral) or horizon < 1):
        raise OrderError(f"horizon must be an integer >= 1, got {horizon!r}")
    horizon = None if horizon is None else check_order("horizon", horizon)
    if isinstance(n_threads, bool) or not isinstance(n_threads, numbers.Integral) or n_threads < 0:
        raise OrderError(f"n_threads must be an integer >= 0 (0 = all cores), got {n_threads!r}")
    n_threads = check_order("n_threads", n_threads)
    m = est.n_inputs
    nas, nbs, nks = _order_range("na", na), _per_input_ranges("nb", nb, m), _per_input_ranges("nk", nk, m)
    effects = tuple(effects)
    top = _check_top(top)
    n_structures, p_max, q = _check_memory(est, val, nas, nbs, nks, effects, int(n_threads), max_memory)
    n_val = val.n_samples if val is not None else 0
    n_sim = n_val + (est.n_samples if simulate_estimation else 0)
    seconds = stages.estimated_seconds(n_structures, top, p_max, q, est.n_samples + n_val, n_sim, int(n_threads))
    stages.check_time_budget(n_structures, top, seconds, max_seconds)
    g = _Grid.build(est, nas, nbs, nks, effects)
    # A fleet on a cluster: the workers hold the samples and compute the effect columns, the client none.
    inputs = _core_inputs(est, val, g, effects) if workers is None else None
    engine = _fleet_engine(workers, est, g, effects) if workers is not None else None
    terms = inputs.terms if inputs is not None else engine.terms
    first_lag, _ = _core.grid_envelope(g.layout, terms)
    _check_validation_length(val, first_lag)
    run = _Runner(est, val, g, inputs, int(n_threads), progress, simulate_estimation, top, engine)
    # Integrating plants: an expectation decides the measure up front; otherwise the free-run sweep
    # runs first and, when the unit-root test calls the plant integrating, is redone with k steps.
    integrating = expect in ("integrating", "double-integrating")
    reason = f"expect={expect!r}: declared" + (" integrating" if integrating else " (not tested)")
    k_default = int(horizon) if horizon is not None else max(10, 2 * first_lag)
    k_step = k_default if integrating else (int(horizon) if horizon is not None else None)
    grid = {"na": nas, "nb": nbs, "nk": nks}
    settings = dict(
        validation=val,
        sort_by=sort_by,
        n_threads=n_threads,
        progress=progress,
        effects=effects,
        expect=expect,
        horizon=horizon,
        max_memory=max_memory,
        limits=limits,
        simulate_estimation=simulate_estimation,
        top=top,
        max_seconds=max_seconds,
    )
    build = _ResultBuilder(g, terms, est, val, sort_by, effects, expect, limits or SanityLimits(), m, grid, settings)
    result = build(run(k_step), k_step, integrating, reason)
    if expect is None:
        verdict = _integrator_verdict(result)
        if verdict.integrating and k_step is None:
            result = build(run(k_default), k_default, True, verdict.reason, verdict)
        else:
            result = dataclasses.replace(
                result, integrating=verdict.integrating, integrating_reason=verdict.reason, integrator=verdict
            )
    result = result.extend() if auto_extend else result
    return result if refine is None else _refined(result, refine, refine_top)


def _refined(result: SweepResult, structure: str, top: int) -> RefinedSweep:
    """The sweep's best ARX structures refitted as ``structure`` models (output error) and ranked."""
    from ..models.pem import refine

    return refine(result, structure, top=top)


def _fleet_parts(client: Any, logs: Sequence, read: Any, fraction: float | None) -> tuple[Any, tuple]:
    """The merged parts of a fleet's logs, and the logs on the workers of ``client`` (None in process).

    With a client the workers read the logs; the parts are :class:`arxid.cluster.LogsOnDemand`
    (shapes now, samples read on the client only when a result needs them)."""
    if client is None:
        return None, fleet.merged_parts(logs, read, fraction)
    on_workers = cluster.WorkerLogs(client, logs, read, fraction)
    return on_workers, on_workers.on_demand()


def _fleet_engine(workers: Any, est: IOData, g: _Grid, effects: tuple[str, ...]) -> fleet_sweep.DaskEngine:
    """The engine that sweeps a fleet where its logs are, with the effect columns and output terms
    the in-process sweep would use (the terms follow from the first samples alone)."""
    columns = fleet_sweep.EffectColumns(effects, tuple(g.user_nb[0]), tuple(g.user_nk[0]))
    head = est[: min(est.n_samples, 8)]
    terms = list(compile_effects(effects, head, columns.nb, columns.nk).output_terms) if effects else []
    return fleet_sweep.DaskEngine(workers, terms, columns)


def _validation_split(data: IOData, validation: Any) -> tuple[IOData, IOData | None]:
    if isinstance(validation, IOData):
        if validation.n_inputs != data.n_inputs:
            raise DataError(f"validation data have {validation.n_inputs} inputs, the estimation data {data.n_inputs}")
        check_same_signals(data.ts, data.output_name, data.input_names, validation, "the validation data")
        return data, validation
    if validation is None:
        return data, None
    if isinstance(validation, numbers.Real) and not isinstance(validation, bool):
        fraction = float(validation)
        if not 0 < fraction < 1:
            raise DataError(f"validation as a fraction must be between 0 and 1, got {validation}")
        return data.split(1 - fraction)
    raise DataError(f"validation must be None, an IOData or a fraction, got {type(validation).__name__}")


def _check_memory(
    est: IOData,
    val: IOData | None,
    nas: Sequence[int],
    nbs: list,
    nks: list,
    effects: tuple[str, ...],
    n_threads: int,
    max_memory: int | None,
) -> tuple[int, int, int]:
    """Size and memory before building anything (the core's own estimate); returns the number of
    structures, the largest number of parameters and the columns of the largest regressor."""
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


def _check_top(top: Any) -> int | None:
    if top is None:
        return None
    if isinstance(top, bool) or not isinstance(top, numbers.Integral) or top < 1:
        raise OrderError(
            f"top must be an integer >= 1 (structures simulated after the one-step ranking) or None, got {top!r}"
        )
    return int(top)


@dataclass(frozen=True)
class _Grid:
    """Every structure as the user wrote it (per input) and as the core sees it (per layout column)."""

    layout: np.ndarray  # (S, 1 + 2 n_columns): na, nb per column, nk per column
    user_nb: Any  # per structure (nb per input): a list of tuples, or an (S, m) array
    user_nk: Any
    n_columns: int

    @classmethod
    def build(cls, est: IOData, nas: Sequence[int], nbs: list, nks: list, effects: tuple[str, ...]) -> _Grid:
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


@dataclass(frozen=True)
class _CoreInputs:
    u_est: np.ndarray
    u_val: np.ndarray | None
    terms: list


def _core_inputs(est: IOData, val: IOData | None, g: _Grid, effects: tuple[str, ...]) -> _CoreInputs:
    """Inputs with the effect columns; without effects the core reads the inputs in place (no copy)."""
    if not effects:
        return _CoreInputs(
            np.ascontiguousarray(est.u, dtype=float),
            None if val is None else np.ascontiguousarray(val.u, dtype=float),
            [],
        )
    nb0, nk0 = list(g.user_nb[0]), list(g.user_nk[0])
    lay_est = compile_effects(effects, est, nb0, nk0)
    u_val = None if val is None else compile_effects(effects, val, nb0, nk0).u
    return _CoreInputs(lay_est.u, u_val, list(lay_est.output_terms))


def _check_validation_length(val: IOData | None, first_lag: int) -> None:
    if val is None:
        return
    if sum(max(0, b - a - first_lag) for a, b in val.segments) == 0:
        raise DataError(
            f"the validation data have {val.n_samples} samples, but every structure starts at the grid's largest lag "
            f"{first_lag} into each experiment, which leaves none to validate on; use longer validation data or "
            f"smaller orders"
        )
    if not val.output_measured:
        raise DataError(
            "the validation data hold no finite output sample (all NaN); pass validation data with a measured output"
        )


class _Runner:
    """One call of the core's sweep at a given horizon, with an optional progress bar."""

    def __init__(
        self,
        est: IOData,
        val: IOData | None,
        g: _Grid,
        inputs: _CoreInputs | None,
        n_threads: int,
        progress: bool,
        simulate_estimation: bool,
        top: int | None = None,
        engine: Any = None,
    ):
        self.est, self.val, self.g, self.inputs = est, val, g, inputs
        self.n_threads, self.progress, self.simulate_estimation = n_threads, progress, simulate_estimation
        self.top, self.engine = top, engine

    def __call__(self, k: int | None) -> Any:
        if self.inputs is None:  # a fleet on a cluster: the engine runs where the logs are
            return self.engine(self.g.layout, self.top, k, bool(self.simulate_estimation))
        inputs = self.inputs
        n = len(self.g.layout)
        bar = _progress_bar(n, k) if self.progress else None
        report = None
        if bar is not None:
            progress_bar = bar

            def report(done: int) -> None:
                if done > progress_bar.n:  # reports may arrive out of order from the worker threads
                    progress_bar.update(done - progress_bar.n)

        val = self.val
        try:
            return _core.sweep(
                np.ascontiguousarray(self.est.y),
                inputs.u_est,
                list(self.est.experiment_starts),
                self.g.layout,
                inputs.terms,
                yv=np.ascontiguousarray(val.y) if val is not None else None,
                uv=inputs.u_val,
                starts_v=list(val.experiment_starts) if val is not None else None,
                simulate_estimation=bool(self.simulate_estimation),
                horizon=k,
                n_threads=self.n_threads,
                chunk=max(64, n // 100),
                progress=report,
                top=self.top,
            )
        finally:
            if bar is not None:
                bar.close()


def _progress_bar(n: int, k: int | None) -> Any:
    """A tqdm bar on an interactive terminal; None when stderr is not a terminal or tqdm is not
    installed (then one ArxidWarning per process names the extra)."""
    if not sys.stderr.isatty():
        return None
    auto = optional("tqdm.auto", "the progress bar of arxid.sweep")
    if auto is None:
        return None
    return auto.tqdm(total=n, desc="arxid.sweep" + (f" ({k}-step)" if k else ""), unit="structure", leave=False)


def _scored_norm(d: IOData, lag: int) -> float:
    """‖y − ȳ‖ over the samples a sweep scores (from ``lag`` into each experiment, finite)."""
    n, _, m2 = metrics.scored_moments(d.y, d.segments, lag)
    return math.sqrt(m2) if n else math.nan


def _max_poles(na: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Largest pole magnitude of every structure (companion matrices, batched per na)."""
    out = np.zeros(len(na))
    for k in np.unique(na):
        idx = np.flatnonzero(na == k)
        if k == 0:
            continue
        a = theta[idx, :k]
        ok = np.isfinite(a).all(axis=1)
        comp = np.zeros((len(idx), k, k))
        comp[:, 0, :] = -np.where(ok[:, None], a, 0.0)
        if k > 1:
            comp[:, np.arange(1, k), np.arange(k - 1)] = 1.0
        mags = np.abs(np.linalg.eigvals(comp)).max(axis=1)
        out[idx] = np.where(ok, mags, np.nan)
    return out


def _validation_fit(res: _core.SweepOutput, rms_val: np.ndarray, val: IOData | None, first_lag: int) -> np.ndarray:
    """Validation fit percent of every structure from the core's error and output norms."""
    if val is None:
        return np.full(len(rms_val), np.nan)
    # With missing validation samples the core scores a subset per structure and gives its norm.
    per_structure = res.norm_sim_val
    # Structures that scored every finite sample share one norm; computed only when one needs it
    # (a fleet on a cluster gives every norm, and its client holds no samples).
    shared = ~np.isfinite(per_structure) & np.isfinite(rms_val)
    norm = np.where(shared, _scored_norm(val, first_lag) if shared.any() else np.nan, per_structure)
    with np.errstate(all="ignore"):
        return np.asarray(metrics.fit_percent_from_norms(rms_val * np.sqrt(res.n_sim_val), norm))


@dataclass(frozen=True)
class _ResultBuilder:
    """Everything but the core's output a :class:`SweepResult` needs."""

    g: _Grid
    terms: list
    est: IOData
    val: IOData | None
    sort_by: str
    effects: tuple[str, ...]
    expect: str | None
    limits: SanityLimits
    m: int
    grid: dict
    settings: dict

    def __call__(
        self,
        res: _core.SweepOutput,
        k_step: int | None,
        integrating: bool,
        reason: str,
        verdict: IntegratorTest | None = None,
    ) -> SweepResult:
        return _build_result(self, res, k_step, integrating, reason, verdict)


def _criteria(res: _core.SweepOutput, p: np.ndarray) -> dict[str, np.ndarray]:
    """Every ranking column but the simulations (one definition each in :mod:`arxid._metrics`)."""
    s = len(p)
    n_est, n_val = res.n_est, res.n_val
    with np.errstate(all="ignore"):
        v_val = res.rss_val / n_val if n_val else res.rss_est / n_est  # arxstruc's V
        return {
            "est_one_step": np.sqrt(res.rss_est / n_est),
            "val_one_step": np.sqrt(res.rss_val / n_val) if n_val else np.full(s, np.nan),
            "fpe": np.asarray(metrics.fpe(res.rss_est, n_est, p)),
            "aic": np.asarray(metrics.aic(res.rss_est, n_est, p)),
            "bic": np.asarray(metrics.bic(res.rss_est, n_est, p)),
            "selstruc_aic": np.asarray(metrics.selstruc(v_val, n_est, p, 2.0)),
            "selstruc_mdl": np.asarray(metrics.selstruc(v_val, n_est, p, math.log(n_est))),
        }


def _ranking_order(score: np.ndarray, bad: np.ndarray) -> np.ndarray:
    """Best first; ties keep grid order (stable); structures in ``bad`` last."""
    s = len(score)
    return np.lexsort((np.arange(s), np.where(bad | ~np.isfinite(score), np.inf, score), bad))


def _ranked_errors(errors: list, failed: np.ndarray, order: np.ndarray) -> tuple:
    """``errors`` in ranked ``order``, touching only the ``failed`` structures (a million-row grid)."""
    ranked: list = [None] * len(order)
    rank = np.empty(len(order), dtype=np.intp)
    rank[order] = np.arange(len(order))
    for i in failed:
        ranked[rank[i]] = errors[i]
    return tuple(ranked)


def _build_result(
    b: _ResultBuilder,
    res: _core.SweepOutput,
    k_step: int | None,
    integrating: bool,
    reason: str,
    verdict: IntegratorTest | None,
) -> SweepResult:
    grid, m = b.g.layout, b.m
    s = len(grid)
    mc = (grid.shape[1] - 1) // 2
    na = grid[:, 0].copy()
    p = na + grid[:, 1 : 1 + mc].sum(axis=1) + len(b.terms)
    crit = _criteria(res, p)
    div_est, div_val = res.diverged_est, res.diverged_val
    rms_est = np.where(div_est, np.nan, res.rms_sim_est)
    rms_val = np.where(div_val, np.nan, res.rms_sim_val)
    errors = res.errors
    failed = np.array([i for i, e in enumerate(errors) if e is not None], dtype=np.intp)
    fit_val = _validation_fit(res, rms_val, b.val, res.first_lag)
    key = _effective_key(b.sort_by, b.val is not None)
    score = _ranking_column(_Columns(rms_val=rms_val, rms_est=rms_est, **crit), key)
    bad = np.zeros(s, dtype=bool)
    bad[failed] = True
    if key in FREE_RUN_KEYS:  # a diverged simulation has no free-run error to rank by
        bad = bad | div_val | div_est
    # Stage-1 rows of a two-stage sweep (not simulated) follow the ranked ones, by one-step error.
    order = stages.rank_order(
        score, bad | ~np.isfinite(score), res.stage, crit["val_one_step" if b.val is not None else "est_one_step"]
    )
    nbm = np.array(b.g.user_nb, dtype=int).reshape(s, m)
    nkm = np.array(b.g.user_nk, dtype=int).reshape(s, m)
    return SweepResult(
        na=na[order],
        nb=nbm[order],
        nk=nkm[order],
        parameters=stages.RankedParameters(res.theta, p, order),
        n_params=p[order],
        rms_est_one_step=crit["est_one_step"][order],
        rms_val_one_step=crit["val_one_step"][order],
        rms_est=rms_est[order],
        rms_val=rms_val[order],
        fit_val=fit_val[order],
        fpe=crit["fpe"][order],
        aic=crit["aic"][order],
        bic=crit["bic"][order],
        selstruc_aic=crit["selstruc_aic"][order],
        selstruc_mdl=crit["selstruc_mdl"][order],
        diverged_est=div_est[order],
        diverged_val=div_val[order],
        errors=_ranked_errors(errors, failed, order),
        horizon=k_step,
        integrating=integrating,
        integrating_reason=reason,
        sort_by=key,
        first_lag=res.first_lag,
        row_orders=res.envelope,
        n_est=res.n_est,
        n_val=res.n_val,
        effects=b.effects,
        expect=b.expect,
        limits=b.limits,
        estimation=b.est,
        validation=b.val,
        integrator=verdict,
        grid=b.grid,
        settings=b.settings,
        stage=res.stage[order],
        estimation_factor=getattr(res, "r_est", None),
    )


def _effective_key(sort_by: str, has_validation: bool) -> str:
    """``bic`` is ``est_bic``; without validation data the validation keys rank the estimation data."""
    if sort_by == "bic":
        return "est_bic"
    if not has_validation and sort_by in ("val_sim", "val_one_step"):
        return "est_sim" if sort_by == "val_sim" else "est_one_step"
    return sort_by


@dataclass(frozen=True)
class _Columns:
    rms_val: np.ndarray
    rms_est: np.ndarray
    est_one_step: np.ndarray
    val_one_step: np.ndarray
    fpe: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
    selstruc_aic: np.ndarray
    selstruc_mdl: np.ndarray
