"""Where a model fails: its error located in time (rolling RMS, worst segments) and by operating
point (RMS of the one-step residual binned by each signal, with a significance test).

:func:`where_it_fails` returns a :class:`FailureAnalysis`. It tells *where* a model is wrong;
:func:`arxid.diagnose` tells *which effect* is missing.
"""

from __future__ import annotations

import math
import weakref
from typing import Any

import numpy as np

from .._base import metrics
from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from .._base.probabilities import f_sf
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arguments import check_data, check_horizon, check_predictor
from ..models.arx_model import ArxModel
from ..models.state_space import StateSpaceModel
from .binning import SignalBins, SquaredRanks, bin_signal
from .comparison import prediction_error
from .state_space import PerOutput, in_model_order, state_space_label, state_space_prediction

__all__ = ["where_it_fails", "FailureAnalysis", "WorstSegment", "SignalBins"]


@record
class WorstSegment:
    """A stretch of time where the error is largest.

    ``start_time``/``end_time`` in seconds from the first sample of the data (experiments laid end
    to end), ``start``/``end`` sample indices (half open), ``rms`` the error RMS inside, ``ratio``
    that RMS over the RMS of the whole record.

    ``p_value`` asks whether the one-step residual is larger inside the window than outside: a
    one-sided F test of the two variances (the one-step residual, unlike the free-run error, has
    nearly independent samples), Bonferroni-corrected for the ``n / window`` windows the search
    looked at. ``significant`` compares it with the analysis' ``alpha``.
    """

    start: int
    end: int
    start_time: float
    end_time: float
    rms: float
    ratio: float
    p_value: float = math.nan
    significant: bool = False


@record(eq=False)
class FailureAnalysis:
    """Where in time and at which operating points a model's error is large.

    Attributes
    ----------
    time : ndarray of shape (n_samples,)
    error : ndarray of shape (n_samples,)
        ``y − prediction`` at ``horizon`` (None: free run).
    residual : ndarray of shape (n_samples,)
        One-step residual (used for the binning, where samples are close to independent).
    rolling_rms : ndarray of shape (n_samples,)
        RMS of ``error`` over a centred window of ``window`` samples.
    window : int
    rms : float
        RMS of ``error`` over the record.
    worst_segments : tuple of WorstSegment
        Non-overlapping windows with the largest error, worst first.
    by_signal : tuple of SignalBins
        Sorted by p-value (most significant first).
    horizon : int or None
    alpha : float
    """

    time: np.ndarray
    error: np.ndarray
    residual: np.ndarray
    rolling_rms: np.ndarray
    window: int
    rms: float
    worst_segments: tuple
    by_signal: tuple
    horizon: int | None
    alpha: float = 0.01
    model_name: str = ""

    @property
    def significant_signals(self) -> tuple[str, ...]:
        """Signals whose binned residual differs significantly (p < alpha, Bonferroni over signals)."""
        k = max(len(self.by_signal), 1)
        return tuple(b.signal for b in self.by_signal if b.p_value * k < self.alpha)

    def bins(self, signal: str) -> SignalBins:
        """The binned one-step residual of one signal.

        Parameters
        ----------
        signal : str
            Name as in ``by_signal`` (e.g. ``u1``, ``y``, ``dy``).

        Returns
        -------
        SignalBins

        Raises
        ------
        ArxidError
            When ``signal`` was not binned.
        """
        for b in self.by_signal:
            if b.signal == signal:
                return b
        raise ArxidError(f"no binned signal {signal!r}; have {[b.signal for b in self.by_signal]}")

    def __str__(self) -> str:
        lines = [
            f"where {self.model_name or 'the model'} fails ({horizon_label(self.horizon)} error, rms {self.rms:.4g})",
            f"worst segments (window {self.window} samples):",
        ]
        lines.append(
            text_table(
                ["from [s]", "to [s]", "rms", "× overall", "p-value", "significant"],
                [
                    (s.start_time, s.end_time, s.rms, s.ratio, s.p_value, "yes" if s.significant else "")
                    for s in self.worst_segments
                ],
            )
        )
        k = max(len(self.by_signal), 1)
        lines.append("one-step residual binned by signal (Bonferroni over signals):")
        rows = []
        for b in self.by_signal:
            i = int(np.nanargmax(b.rms))
            rows.append(
                (
                    b.signal,
                    b.ratio,
                    f"{b.edges[i]:.4g}..{b.edges[i + 1]:.4g}",
                    b.p_value,
                    "yes" if b.p_value * k < self.alpha else "",
                )
            )
        lines.append(text_table(["signal", "max/overall", "worst bin", "p-value", "significant"], rows, digits=3))
        return "\n".join(lines)

    def to_pandas(self):
        """One row per (signal, bin): edges, centre, count, residual RMS and mean, p-value.

        Returns
        -------
        pandas.DataFrame
            Columns ``signal``, ``low``, ``high``, ``center``, ``count``, ``rms``, ``mean``, ``p_value``.
        """
        pd = require_pandas()
        rows = []
        for b in self.by_signal:
            for i in range(len(b.centers)):
                rows.append(
                    {
                        "signal": b.signal,
                        "low": b.edges[i],
                        "high": b.edges[i + 1],
                        "center": b.centers[i],
                        "count": int(b.counts[i]),
                        "rms": b.rms[i],
                        "mean": b.mean[i],
                        "p_value": b.p_value,
                    }
                )
        return pd.DataFrame(rows)

    def to_dict(self) -> dict:
        """JSON-ready dict: overall RMS, the worst segments and the binned residual per signal.

        Returns
        -------
        dict
            ``horizon``, ``rms``, ``window``, ``worst_segments``, ``by_signal`` and
            ``significant_signals``; NaN becomes None.
        """
        return {
            "horizon": self.horizon,
            "rms": finite_or_none(self.rms),
            "window": self.window,
            "worst_segments": [
                {
                    "start_time": s.start_time,
                    "end_time": s.end_time,
                    "start": s.start,
                    "end": s.end,
                    "rms": s.rms,
                    "ratio": s.ratio,
                    "p_value": finite_or_none(s.p_value),
                    "significant": s.significant,
                }
                for s in self.worst_segments
            ],
            "by_signal": [
                {
                    "signal": b.signal,
                    "ratio": b.ratio,
                    "p_value": b.p_value,
                    "edges": b.edges.tolist(),
                    "rms": [finite_or_none(x) for x in b.rms],
                    "counts": b.counts.tolist(),
                }
                for b in self.by_signal
            ],
            "significant_signals": list(self.significant_signals),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.

        Returns
        -------
        str
        """
        import json

        return json.dumps(self.to_dict(), indent=indent)

    def plot(self, ax: Any = None) -> Any:
        """Rolling RMS of the error in time, worst segments shaded.

        Parameters
        ----------
        ax : Axes, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_failures

        return plot_failures(self, ax=ax)


#: Per IOData (weakly held: an entry goes with its data): the bins of each operating-point signal
#: over the samples used, (signal, shift, bins, samples) → (source array, edges, bin of each sample
#: as uint8). Where it fails is asked of several models on the same validation data; their bins
#: are the same when their residuals exist on the same samples (2 MB per signal at 2M samples).
_BINS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _segment_p_value(res: np.ndarray, lo: int, hi: int, n_windows: int, total: tuple[int, float]) -> float:
    """One-sided F test: is the one-step residual variance in [lo, hi) larger than outside it?
    ``total``: the count and the sum of squares of the finite residuals (the outside's are the
    total's less the inside's)."""
    inside = res[lo:hi]
    inside = inside[np.isfinite(inside)]
    n_out = total[0] - inside.size
    if inside.size < 2 or n_out < 2:
        return math.nan
    with np.errstate(over="ignore"):
        sq_in = float(np.einsum("i,i->", inside, inside))
    v_out = max(total[1] - sq_in, 0.0) / n_out
    if v_out == 0:
        return math.nan
    f = (sq_in / inside.size) / v_out
    return float(min(1.0, f_sf(f, inside.size, n_out) * n_windows))


def where_it_fails(
    model: ArxModel | StateSpaceModel,
    data: IOData,
    horizon: int | None = None,
    *,
    window: int | None = None,
    n_worst: int = 3,
    n_bins: int = 8,
    alpha: float = 0.01,
    initial: str = "zero",
) -> Any:
    """Locate a model's error in time and by operating point.

    Parameters
    ----------
    model : ArxModel, PolynomialModel or StateSpaceModel
    data : IOData
        Preferably validation data.
    horizon : int or None
        Error used in time: None (default) free-run simulation, k k-step prediction.
    window : int, optional
        Rolling-RMS window in samples (default: 1/50 of the record, at least 10).
    n_worst : int
        Number of worst segments to report.
    n_bins : int
        Quantile bins per signal.
    alpha : float
        Level for calling a signal significant (Bonferroni over the signals).
    initial : {"zero", "estimate"}
        Initial conditions of the error in time (see :func:`compare`).

    Returns
    -------
    FailureAnalysis
        ``worst_segments`` with their time ranges and ``by_signal``: residual RMS binned by each
        input (at t − nk), the output (at t − 1), the output rate and each extra signal, with a
        p-value, most significant first. ``.plot()`` and ``.to_pandas()`` give figure and table.
        For a state-space model of several outputs, one FailureAnalysis per output (by name); the
        one-step residual is then the innovation form's, from an initial state fitted to ``data``,
        and the inputs are binned without a delay.
    """
    if not isinstance(model, StateSpaceModel):
        model = check_predictor(model)
    data = check_data(data)
    horizon = check_horizon(horizon)
    n = data.n_samples
    window = max(10, n // 50) if window is None else int(window)
    if window < 2 or window > n:
        raise ArxidError(f"window must be between 2 and the number of samples ({n}), got {window}")
    search = (window, int(n_worst), n_bins, alpha, horizon)
    if isinstance(model, StateSpaceModel):
        return _state_space_failures(model, data, initial, search)
    _, err, diverged = prediction_error(model, data, horizon, initial)
    if diverged:
        err = np.where(np.isfinite(err), err, np.nan)
    _, res, _ = prediction_error(model, data, 1)
    return _located(err, res, data, tuple(model.nk_), model.structure_name(), search)


def _state_space_failures(model: StateSpaceModel, data: IOData, initial: str, search: tuple) -> Any:
    """:func:`where_it_fails` of each output of a state-space model."""
    ordered = in_model_order(model, data, "the data to locate the error in")
    simulated = state_space_prediction(model, ordered, search[-1], initial)
    one_step = state_space_prediction(model, ordered, 1, "estimate")
    results = {}
    for name in data.output_names:
        one = data.output(name) if data.n_outputs > 1 else data
        i = model.output_names.index(name)
        with np.errstate(all="ignore"):
            err, res = one.y - simulated[:, i], one.y - one_step[:, i]
        err = np.where(np.isfinite(err), err, np.nan)
        label = f"{state_space_label(model)}, output {name}"
        results[name] = _located(err, res, one, (0,) * one.n_inputs, label, search)
    return results[data.output_names[0]] if data.n_outputs == 1 else PerOutput(results)


def _located(
    err: np.ndarray, res: np.ndarray, data: IOData, delays: tuple[int, ...], model_name: str, search: tuple
) -> FailureAnalysis:
    """The worst segments of ``err`` and the one-step residual ``res`` binned by each signal of
    single-output ``data`` (inputs at t − their delay)."""
    window, n_worst, n_bins, alpha, horizon = search
    n = data.n_samples
    t = np.arange(n) * data.ts
    roll = np.full(n, np.nan)
    for a, b in data.segments:
        if b - a >= 2:
            roll[a:b] = metrics.rolling_rms(err[a:b], min(window, b - a))
    overall = metrics.rms(err)
    # Greedy non-overlapping picks of the largest rolling RMS.
    worst = []
    r = roll.copy()
    half = window // 2
    finite_res = res[np.isfinite(res)]
    # einsum, not dot: a multithreaded BLAS dot leaves threads spinning on the cores others need
    with np.errstate(over="ignore"):
        total = (finite_res.size, float(np.einsum("i,i->", finite_res, finite_res)))
    del finite_res
    for _ in range(n_worst):
        if not np.isfinite(r).any():
            break
        i = int(np.nanargmax(r))
        lo, hi = max(0, i - half), min(n, i - half + window)
        rms = metrics.rms(err[lo:hi])
        p = _segment_p_value(res, lo, hi, max(1, n // window), total)
        worst.append(
            WorstSegment(
                lo,
                hi,
                float(t[lo]),
                float(t[hi - 1] + data.ts),
                rms,
                rms / overall if overall > 0 else math.nan,
                p,
                bool(p < alpha),
            )
        )
        r[max(0, lo - half) : min(n, hi + half)] = np.nan
    # Operating points: (name, samples, (name, shift, the data's array they come from)).
    signals = []
    for i, name in enumerate(data.input_names):
        x = np.full(n, np.nan)
        k = delays[i]
        for a, b in data.segments:
            if b - a > k:
                x[a + k : b] = data.u[a : b - k, i]
        signals.append((name, x, (name, k, data.u)))
    y1 = np.full(n, np.nan)
    dy1 = np.full(n, np.nan)
    for a, b in data.segments:
        y1[a + 1 : b] = data.y[a : b - 1]
        dy1[a + 2 : b] = (data.y[a + 1 : b - 1] - data.y[a : b - 2]) / data.ts
    signals.append((data.output_name, y1, (data.output_name, 1, data.y)))
    signals.append((f"d{data.output_name}", dy1, (f"d{data.output_name}", 1, data.y)))
    signals += [(k, np.asarray(v, dtype=float), (k, 0, v)) for k, v in data.extra.items()]
    ranked = SquaredRanks(res)
    memo = _BINS.setdefault(data, {})
    bins = [b for b in (bin_signal(nm, x, res, n_bins, ranked, memo, tag) for nm, x, tag in signals) if b is not None]
    bins.sort(key=lambda b: (b.p_value, -b.ratio))
    return FailureAnalysis(t, err, res, roll, window, overall, tuple(worst), tuple(bins), horizon, alpha, model_name)
