"""Exhaustive ARX order sweeps: :func:`sweep` fits and validates every (na, nb, nk) structure of a
grid from one factorization in the Rust core and ranks them in a :class:`SweepResult`."""

from __future__ import annotations

import itertools
import json
import math
import numbers
import sys
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import _core
from . import _metrics as metrics
from ._optional import optional
from .data import IOData
from .effects import compile_effects
from .exceptions import ArxidError, ArxidWarning, DataError, OrderError
from .model import ArxModel
from .sanity import (
    EXPECTATIONS,
    SanityLimits,
    StepSanity,
    check_responses,
    output_range,
    step_sanity,
    typical_amplitudes,
)

__all__ = ["sweep", "SweepResult", "Selection", "DEFAULT_GRID", "SORT_KEYS"]

SORT_KEYS = ("val_sim", "val_one_step", "est_sim", "est_one_step", "fpe", "aic", "bic")

#: The order grid every sweep uses unless told otherwise: the API's :func:`sweep`, :func:`arxid.analyse`
#: and every CLI command. na 1..4 poles, nb 1..3 input coefficients, nk 0..5 samples of delay.
DEFAULT_GRID: dict[str, range] = {"na": range(1, 5), "nb": range(1, 4), "nk": range(0, 6)}

#: A pole this close to 1 (or |A(1)| below this share of sum |a_i|) marks an integrating plant.
INTEGRATOR_TOLERANCE = 1e-3


# ---------------------------------------------------------------------------------------------- grid
def _order_range(name: str, value) -> tuple[int, ...]:
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
        out.append(int(v))
    return tuple(dict.fromkeys(out))


def _per_input_ranges(name: str, value, m: int) -> list[tuple[int, ...]]:
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


def _available_memory() -> int:
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 4 * 2**30


def _gib(b: float) -> str:
    return f"{b / 2**30:.2f} GiB" if b >= 2**28 else f"{b / 2**20:.1f} MiB"


# ---------------------------------------------------------------------------------------------- result
@dataclass(frozen=True)
class Selection:
    """Which structure :meth:`SweepResult.best` chose, and which better-ranked ones it skipped and why."""

    rank: int
    structure: str
    skipped: tuple[tuple[int, str, tuple[str, ...]], ...]

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
        lines = [f"chose {self.structure} (rank {self.rank + 1})"]
        shown = self.skipped if limit is None else self.skipped[:limit]
        for rank, name, reasons in shown:
            lines.append(f"  skipped {name} (rank {rank + 1}): " + "; ".join(reasons))
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
        Akaike's FPE, AIC and BIC of the estimation fit (MATLAB's definitions).
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
    sort_by : str
    first_lag : int
        The grid's largest lag: every structure uses rows from here on.
    row_orders : tuple (na, nb, nk)
        Orders (per effect-layout column) of the grid's envelope, the largest regressor: rows where
        it touches a NaN are left out for every structure.
    n_est, n_val : int
        Regression rows of estimation and validation data.
    """

    na: np.ndarray
    nb: np.ndarray
    nk: np.ndarray
    parameters: list
    n_params: np.ndarray
    rms_est_one_step: np.ndarray
    rms_val_one_step: np.ndarray
    rms_est: np.ndarray
    rms_val: np.ndarray
    fit_val: np.ndarray
    fpe: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
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
        # A detected integrator is checked as one (growth, no upper amplitude bound).
        expect = self.expect if self.expect is not None or not self.integrating else "integrating"
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
            name, pos, neg, poles, out_range=output_range(data), amplitudes=amps, expect=expect, limits=self.limits
        )

    def _usable(self, i: int) -> bool:
        return (
            self.errors[i] is None
            and not self.diverged_val[i]
            and not self.diverged_est[i]
            and np.isfinite(self.ranking_score()[i])
        )

    def select(self, sane: bool = True) -> Selection:
        """The best-ranked usable structure; with ``sane``, the best one whose step sanity passes.

        Parameters
        ----------
        sane : bool
            Also skip structures whose step sanity checks fail; without it, only structures that were
            not fitted, diverged or have no finite ranking error are skipped.

        Returns
        -------
        Selection
            The chosen rank and structure, and the better-ranked structures skipped for failed checks.

        Raises
        ------
        ArxidError
            When no structure qualifies (the message lists why the best ones were rejected).
        """
        skipped = []
        for i in range(len(self)):
            if not self._usable(i):
                continue
            if sane:
                verdict = self.sanity(i)
                if not verdict.ok:
                    skipped.append((i, self.structure_name(i), verdict.reasons))
                    continue
            return Selection(i, self.structure_name(i), tuple(skipped))
        why = "; ".join(f"{n}: {', '.join(r)}" for _, n, r in skipped[:5])
        if not why:
            n_err = sum(e is not None for e in self.errors)
            first = next((f"{self.structure_name(i)}: {e}" for i, e in enumerate(self.errors) if e is not None), None)
            why = f"{len(self) - n_err} structures diverged or have no finite error, {n_err} could not be fitted" + (
                f", e.g. {first}" if first else ""
            )
        raise ArxidError(
            f"no structure of the sweep passes {'the step sanity checks' if sane else 'validation'} ({why}); "
            f"widen the grid, check expect={self.expect!r}, or relax SanityLimits"
        )

    def best(self, sane: bool = False, *, explain: bool = True) -> ArxModel:
        """The best-ranked structure as a fitted :class:`~arxid.ArxModel`.

        Parameters
        ----------
        sane : bool
            Skip structures flagged by the step sanity checks (see :mod:`arxid.sanity`).
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
        sel = self.select(sane)
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
        text = json.dumps(self.to_dict(sanity), indent=indent, allow_nan=False)
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
        ]
        lines = []
        for i in range(min(n, len(self))):
            if self.errors[i] is not None:
                cells = [str(i + 1), self.structure_name(i), "not fitted", "not fitted"] + ["-"] * 7 + ["collinear"]
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
                ]
            lines.append(cells)
        widths = [max(len(h), *(len(r[j]) for r in lines)) if lines else len(h) for j, h in enumerate(head)]
        out = [
            f"ARX sweep: {len(self)} structures, {self.n_est} estimation rows, {self.n_val} validation rows, "
            f"ranked by {_SORT_TEXT[self.sort_by]} ({self.measure}"
            + (f", horizon {self.horizon} samples = {self.horizon * self.estimation.ts:g} s" if self.horizon else "")
            + ")",
        ]
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
        from .plots.sweep import plot_sweep

        return plot_sweep(self, nb_input=nb_input, chosen=chosen)


_SORT_TEXT = {
    "val_sim": "validation RMS",
    "val_one_step": "validation one-step RMS",
    "est_sim": "estimation RMS",
    "est_one_step": "estimation one-step RMS",
    "fpe": "FPE",
    "aic": "AIC",
    "bic": "BIC",
}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _fmt(x, spec: str = ".4g") -> str:
    x = float(x)
    return format(x, spec) if math.isfinite(x) else "nan"


def _ranking_column(r, key: str) -> np.ndarray:
    col = {
        "val_sim": r.rms_val,
        "val_one_step": r.rms_val_one_step,
        "est_sim": r.rms_est,
        "est_one_step": r.rms_est_one_step,
        "fpe": r.fpe,
        "aic": r.aic,
        "bic": r.bic,
    }[key]
    return col


# ---------------------------------------------------------------------------------------------- sweep
def _detect_integrator(na, theta, order) -> tuple[bool, str]:
    """Integrating if most of the best structures have A(1) ≈ 0 or a pole on/outside the unit circle
    near z = 1."""
    votes, looked = 0, 0
    for i in order[:5]:
        a = np.concatenate([[1.0], theta[i][: na[i]]])
        if na[i] == 0 or not np.isfinite(a).all():
            continue
        looked += 1
        a1 = abs(a.sum()) / np.abs(a).sum()
        poles = np.roots(a)
        near = poles[(np.abs(poles.imag) < 1e-9) & (poles.real >= 1 - INTEGRATOR_TOLERANCE)]
        if a1 < INTEGRATOR_TOLERANCE or near.size:
            votes += 1
    if looked and votes * 2 > looked:
        return True, f"detected: {votes} of the {looked} best structures by FPE have a pole at z = 1 (A(1) ~ 0)"
    return False, ""


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
) -> SweepResult:
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

    Returns
    -------
    SweepResult

    Notes
    -----
    Every structure uses the regression rows from the grid's largest lag on (as ``arxstruc``), and
    its free-run simulation starts there from measured outputs, so all errors compare on the same
    samples. The Rust core reduces ``[Φ_max | y]`` once to a triangular R by Householder QR and
    solves each structure from its columns of R; the simulation of linear structures runs several
    structures with the same ``na`` side by side in SIMD lanes. A simulation that leaves
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
    if not isinstance(data, IOData):
        raise DataError(
            f"sweep needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
        )
    if sort_by not in SORT_KEYS:
        raise ArxidError(f"sort_by must be one of {SORT_KEYS}, got {sort_by!r}")
    if expect not in EXPECTATIONS:
        raise ArxidError(f"expect must be one of {EXPECTATIONS}, got {expect!r}")
    est, val = _validation_split(data, validation)
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, numbers.Integral) or horizon < 1):
        raise OrderError(f"horizon must be an integer >= 1, got {horizon!r}")
    if isinstance(n_threads, bool) or not isinstance(n_threads, numbers.Integral) or n_threads < 0:
        raise OrderError(f"n_threads must be an integer >= 0 (0 = all cores), got {n_threads!r}")
    m = est.n_inputs
    nas, nbs, nks = _order_range("na", na), _per_input_ranges("nb", nb, m), _per_input_ranges("nk", nk, m)
    effects = tuple(effects)
    _check_memory(est, val, nas, nbs, nks, effects, int(n_threads), max_memory)
    g = _Grid.build(est, nas, nbs, nks, effects)
    inputs = _core_inputs(est, val, g, effects)
    first_lag, _ = _core.grid_envelope(g.layout, inputs.terms)
    _check_validation_length(val, first_lag)
    run = _Runner(est, val, g, inputs, int(n_threads), progress, simulate_estimation)
    # Integrating plants: an expectation decides the measure up front; otherwise the free-run sweep
    # runs first and, when its best structures by FPE have a pole at 1, is redone with k steps.
    integrating = expect in ("integrating", "double-integrating")
    reason = f"expect={expect!r}" if integrating else ""
    k_default = int(horizon) if horizon is not None else max(10, 2 * first_lag)
    k_step = k_default if integrating else (int(horizon) if horizon is not None else None)
    res = run(k_step)
    if expect is None and k_step is None:
        p = g.layout[:, 0] + g.layout[:, 1 : 1 + g.n_columns].sum(axis=1) + len(inputs.terms)
        fpe_pre = metrics.fpe(res.rss_est, res.n_est, p)
        order_pre = np.argsort(np.where(np.isfinite(fpe_pre), fpe_pre, np.inf), kind="stable")
        integrating, reason = _detect_integrator(g.layout[:, 0], res.theta, order_pre)
        if integrating:
            k_step = k_default
            res = run(k_step)
    return _build_result(
        res,
        g.layout,
        g.user_nb,
        g.user_nk,
        inputs.terms,
        est,
        val,
        k_step,
        integrating,
        reason,
        sort_by,
        effects,
        expect,
        limits or SanityLimits(),
        m,
    )


def _validation_split(data: IOData, validation: Any) -> tuple[IOData, IOData | None]:
    if isinstance(validation, IOData):
        if validation.n_inputs != data.n_inputs:
            raise DataError(f"validation data have {validation.n_inputs} inputs, the estimation data {data.n_inputs}")
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
    nas: tuple[int, ...],
    nbs: list,
    nks: list,
    effects: tuple[str, ...],
    n_threads: int,
    max_memory: int | None,
) -> None:
    """Size and memory before building anything (the core's own estimate)."""
    n_structures = len(nas) * math.prod(len(r) for r in nbs) * math.prod(len(r) for r in nks)
    probe = compile_effects(effects, est[: min(est.n_samples, 8)], [max(r) for r in nbs], [max(r) for r in nks])
    n_cols, n_terms = len(probe.nb), len(probe.output_terms)
    span = max(max(k) + max(b) - 1 - min(k) + 1 for b, k in zip(nbs, nks))
    p_max = max(nas) + n_cols * max(max(b) for b in nbs) + n_terms
    q = max(nas) + n_cols * span + n_terms + 1
    need = _core.sweep_memory(
        n_structures, p_max, q, est.n_samples, val.n_samples if val is not None else 0, n_cols, n_threads
    )
    limit = int(max_memory) if max_memory is not None else _available_memory() // 2
    if need > limit:
        raise DataError(
            f"the grid is too large: {n_structures:,} structures with up to {p_max} parameters and a largest regressor of "  # noqa: E501
            f"{q} columns need about {_gib(need)}, more than the limit of {_gib(limit)} (max_memory); "
            f"narrow the ranges or split the sweep into parts"
        )


@dataclass(frozen=True)
class _Grid:
    """Every structure as the user wrote it (per input) and as the core sees it (per layout column)."""

    layout: np.ndarray  # (S, 1 + 2 n_columns): na, nb per column, nk per column
    user_nb: list
    user_nk: list
    n_columns: int

    @classmethod
    def build(cls, est: IOData, nas: tuple[int, ...], nbs: list, nks: list, effects: tuple[str, ...]) -> _Grid:
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
    if not np.isfinite(val.y).any():
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
        inputs: _CoreInputs,
        n_threads: int,
        progress: bool,
        simulate_estimation: bool,
    ):
        self.est, self.val, self.g, self.inputs = est, val, g, inputs
        self.n_threads, self.progress, self.simulate_estimation = n_threads, progress, simulate_estimation

    def __call__(self, k: int | None) -> Any:
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
                self.inputs.u_est,
                list(self.est.experiment_starts),
                self.g.layout,
                self.inputs.terms,
                yv=np.ascontiguousarray(val.y) if val is not None else None,
                uv=self.inputs.u_val,
                starts_v=list(val.experiment_starts) if val is not None else None,
                simulate_estimation=bool(self.simulate_estimation),
                horizon=k,
                n_threads=self.n_threads,
                chunk=max(64, n // 100),
                progress=report,
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
    parts = [d.y[a + lag : b] for a, b in d.segments if b > a + lag]
    if not parts:
        return math.nan
    if all(np.isfinite(p).all() for p in parts):
        # Σy² − nȳ² on views (no copy of the data), unless cancellation would cost accuracy.
        n = sum(len(p) for p in parts)
        total = sum(float(p.sum()) for p in parts)
        # einsum, not dot: a multithreaded BLAS call here leaves its threads spinning on the cores
        # the next sweep's Rust threads need.
        sq = sum(float(np.einsum("i,i->", p, p)) for p in parts)
        centred = sq - total * total / n
        if centred > 1e-6 * sq:
            return math.sqrt(centred)
    y = np.concatenate(parts)
    y = y[np.isfinite(y)]
    return float(np.linalg.norm(y - y.mean())) if y.size else math.nan


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
    norm = np.where(np.isfinite(per_structure), per_structure, _scored_norm(val, first_lag))
    with np.errstate(all="ignore"):
        return np.asarray(metrics.fit_percent_from_norms(rms_val * np.sqrt(res.n_sim_val), norm))


def _build_result(
    res: _core.SweepOutput,
    grid,
    user_nb,
    user_nk,
    terms,
    est,
    val,
    k_step,
    integrating,
    reason,
    sort_by,
    effects,
    expect,
    limits,
    m,
) -> SweepResult:
    s = len(grid)
    mc = (grid.shape[1] - 1) // 2
    na = grid[:, 0].copy()
    p = na + grid[:, 1 : 1 + mc].sum(axis=1) + len(terms)
    theta_all = res.theta
    n_est, n_val, first_lag = res.n_est, res.n_val, res.first_lag
    rss_est, rss_val = res.rss_est, res.rss_val
    with np.errstate(all="ignore"):
        loss = rss_est / n_est
        rms_est_one = np.sqrt(loss)
        rms_val_one = np.sqrt(rss_val / n_val) if n_val else np.full(s, np.nan)
        fpe, aic, bic = (np.asarray(f(rss_est, n_est, p)) for f in (metrics.fpe, metrics.aic, metrics.bic))
    div_est, div_val = res.diverged_est, res.diverged_val
    rms_est = np.where(div_est, np.nan, res.rms_sim_est)
    rms_val = np.where(div_val, np.nan, res.rms_sim_val)
    errors = tuple(res.errors)
    fit_val = _validation_fit(res, rms_val, val, first_lag)
    key = sort_by
    if val is None and key in ("val_sim", "val_one_step"):
        key = "est_sim" if key == "val_sim" else "est_one_step"
    columns = dict(val_sim=rms_val, val_one_step=rms_val_one, est_sim=rms_est, est_one_step=rms_est_one)
    score = {**columns, "fpe": fpe, "aic": aic, "bic": bic}[key]
    bad = ~np.isfinite(score) | div_val | div_est | np.array([e is not None for e in errors])
    # Diverged and unfitted structures go last; ties keep grid order (stable sort).
    order = np.lexsort((np.arange(s), np.where(bad, np.inf, score), bad))
    nbm = np.array(user_nb, dtype=int).reshape(s, m)
    nkm = np.array(user_nk, dtype=int).reshape(s, m)
    params = [theta_all[i, : p[i]].copy() for i in order]
    return SweepResult(
        na=na[order],
        nb=nbm[order],
        nk=nkm[order],
        parameters=params,
        n_params=p[order],
        rms_est_one_step=rms_est_one[order],
        rms_val_one_step=rms_val_one[order],
        rms_est=rms_est[order],
        rms_val=rms_val[order],
        fit_val=fit_val[order],
        fpe=fpe[order],
        aic=aic[order],
        bic=bic[order],
        diverged_est=div_est[order],
        diverged_val=div_val[order],
        errors=tuple(errors[i] for i in order),
        horizon=k_step,
        integrating=integrating,
        integrating_reason=reason,
        sort_by=key,
        first_lag=first_lag,
        row_orders=res.envelope,
        n_est=n_est,
        n_val=n_val,
        effects=effects,
        expect=expect,
        limits=limits,
        estimation=est,
        validation=val,
    )
