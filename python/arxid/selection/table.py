"""The table of a sweep (:class:`SweepTable`, the columns and reading of :class:`~arxid.SweepResult`):
every structure ranked, each one's name, fitted model, step sanity and grid edges, and the whole as
text, JSON or a pandas DataFrame."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import field
from typing import Any

import numpy as np

from .._base.digital_filter import lfilter
from .._base.formatting import json_safe
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.arx_model import ArxModel
from ..models.iv import IvModel
from . import stages
from .grid_edges import Edge, edge_text, grid_edges
from .integrator import IntegratorTest, pole_excess
from .ranking import SORT_TEXT, max_poles, ranking_column
from .sanity import SanityLimits, StepSanity, check_responses, output_range, step_sanity, typical_amplitudes

__all__ = ["SweepTable"]


@record(eq=False)
class SweepTable:
    """The columns of a sweep's ranking and how to read them: each structure's name, fitted model,
    step sanity and grid edges, and the whole as text, JSON or a pandas DataFrame.

    :class:`~arxid.SweepResult` adds the choice of a structure and documents the columns.
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
            E.g. ``ARX(2,1,1)`` or ``ARX(2,[1, 2],[1, 0]) + const``; effect terms are appended;
            ``IV(2,1,1)`` in a sweep by instrumental variables.
        """
        nb, nk = self.nb[i], self.nk[i]
        b = int(nb[0]) if len(set(nb.tolist())) == 1 else list(map(int, nb))
        k = int(nk[0]) if len(set(nk.tolist())) == 1 else list(map(int, nk))
        kind = "IV" if self.settings.get("method") == "iv" else "ARX"  # fitted by instrumental variables
        return f"{kind}({int(self.na[i])},{b},{k})" + (" + " + " + ".join(self.effects) if self.effects else "")

    @property
    def ranking_text(self) -> str:
        """What the ranking sorts by, in words (e.g. ``validation RMS (free-run simulation)``)."""
        return f"{SORT_TEXT[self.sort_by]} ({self.measure})"

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
            self._cache["max_pole"] = self._max_poles_of(np.arange(len(self)))
        return self._cache["max_pole"]

    def max_pole_of(self, rows: Sequence[int]) -> np.ndarray:
        """Largest pole magnitude of the ranked structures ``rows`` (as :attr:`max_pole`), computed
        for those rows alone and remembered: a verdict that reads a few structures of a grid of
        hundreds of thousands solves a few companion matrices, not all of them.

        Parameters
        ----------
        rows : sequence of int
            Ranks of the structures (0 is the best).

        Returns
        -------
        ndarray of shape (len(rows),)
            0 for a structure without poles, NaN where a coefficient is not finite.
        """
        if "max_pole" in self._cache or 2 * len(rows) >= len(self):  # most rows: the whole column at once
            return self.max_pole[np.asarray(rows, dtype=np.intp)]
        known = self._cache.setdefault("max_pole_rows", {})
        new = np.array(sorted({int(i) for i in rows} - known.keys()), dtype=np.intp)
        if new.size:
            known.update(zip(new.tolist(), self._max_poles_of(new).tolist()))
        return np.array([known[int(i)] for i in rows], dtype=float)

    def _max_poles_of(self, rows: np.ndarray) -> np.ndarray:
        na = self.na[rows]
        theta = np.full((len(rows), max(int(na.max(initial=0)), 1)), np.nan)
        for j, i in enumerate(rows):
            theta[j, : na[j]] = self.parameters[i][: na[j]]
        return max_poles(na, theta)

    @property
    def stable(self) -> np.ndarray:
        """All poles strictly inside the unit circle, shape (S,)."""
        return self.max_pole < 1.0

    # ------------------------------------------------------------------ models
    def model(self, i: int = 0) -> ArxModel:
        """The ranked structure ``i`` as a fitted :class:`~arxid.ArxModel` on the sweep's rows
        (``first_lag``), so its parameters equal the sweep's: solved from the sweep's estimation
        factor when it kept one, else refitted.

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
            if self.settings.get("method") == "iv":  # the sweep's first IV step, on its rows
                instruments = self.settings.get("instruments")
                model: ArxModel = IvModel(na=int(self.na[i]), nb=nb, nk=nk, instruments=instruments, iterations=0)
            else:
                model = ArxModel(na=int(self.na[i]), nb=nb, nk=nk, effects=self.effects)
            self._cache[key] = self._from_factor(model) or model.fit(
                self.estimation, first_lag=self.first_lag, rows_like=self.row_orders
            )
        return self._cache[key]

    def _from_factor(self, model: ArxModel) -> ArxModel | None:
        """``model`` solved from the sweep's estimation factor (its numbers, no pass over a long
        record) when the sweep kept one for a linear least-squares grid; else None."""
        if self.estimation_factor is None or self.effects or type(model) is not ArxModel:
            return None
        try:
            return model.fit_from_factor(
                self.estimation, self.estimation_factor, self.n_est, self.row_orders, self.first_lag
            )
        except ArxidError:  # the refit says why, in the user's words
            return None

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
            return StepSanity(name, ("not-fitted",), (self.errors[i],), math.nan, self._output_range(), (), 0, expect)
        if self.effects:
            return step_sanity(self.model(i), data, expect=expect, limits=self.limits)
        # Linear structure: the step response is a filter of a constant (exactly antisymmetric).
        theta, na = self.parameters[i], int(self.na[i])
        a = np.concatenate([[1.0], theta[:na]])
        if "amplitudes" not in self._cache:  # the data's, the same for every structure
            self._cache["amplitudes"] = typical_amplitudes(data)
        amps = self._cache["amplitudes"]
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
            out_range=self._output_range(),
            amplitudes=amps,
            expect=expect,
            limits=self.limits,
            pole_excess=self._pole_excess(i, poles),
            record=self.n_est,
        )

    def _output_range(self) -> float:
        """:func:`output_range` of the data the step sanity reads (two percentiles, found once)."""
        if "output_range" not in self._cache:
            data = self.validation if self.validation is not None else self.estimation
            self._cache["output_range"] = output_range(data)
        return self._cache["output_range"]

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

    # ------------------------------------------------------------------ tables
    def ranking_score(self) -> np.ndarray:
        """The column the ranking sorts by (``sort_by``), shape (S,).

        Returns
        -------
        ndarray
        """
        return ranking_column(self, self.sort_by)

    def _rows(self, n: int | None, sanity: bool):
        n = len(self) if n is None else min(n, len(self))
        max_pole = self.max_pole_of(range(n))  # the rows shown only (a grid may hold a million)
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
                    "stable": bool(max_pole[i] < 1.0),
                    "max_pole": _num(max_pole[i]),
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
        import json

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
        max_pole = self.max_pole_of(range(min(n, len(self))))
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
                    "yes" if max_pole[i] < 1.0 else "no",
                    "-" if sv is None else ("ok" if sv.ok else ",".join(sv.flags)),
                    str(int(self.stage[i])),
                ]
            lines.append(cells)
        widths = [max(len(h), *(len(r[j]) for r in lines)) if lines else len(h) for j, h in enumerate(head)]
        out = [
            f"ARX sweep: {len(self)} structures, {self.n_est} estimation rows, {self.n_val} validation rows, "
            f"ranked by {SORT_TEXT[self.sort_by]} ({self.measure}"
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


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _fmt(x, spec: str = ".4g") -> str:
    x = float(x)
    return format(x, spec) if math.isfinite(x) else "nan"
