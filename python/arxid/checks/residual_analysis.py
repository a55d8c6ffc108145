"""Model checks against measurements: :func:`compare`, :func:`residuals`, :func:`where_it_fails`.

* :func:`compare` — measured output against the free-run simulation (or k-step prediction) of one or
  more models, with fit percent and RMS (MATLAB ``compare``).
* :func:`residuals` — whiteness of the one-step residual and its independence of every input and
  logged signal, with 99% bounds and the Ljung–Box test (MATLAB ``resid``).
* :func:`where_it_fails` — the error located in time (rolling RMS, worst segments) and by operating
  point (RMS of the residual binned by each signal, with a significance test).

These tell *that* and *where* a model is wrong; :func:`arxid.diagnose` tells *which effect* is
missing.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._base import metrics
from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from ..models.arguments import check_data, check_horizon, check_model, check_same_signals
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel, as_polynomial, check_initial

__all__ = [
    "compare",
    "Comparison",
    "residuals",
    "ResidualAnalysis",
    "where_it_fails",
    "FailureAnalysis",
    "WorstSegment",
    "SignalBins",
    "prediction_error",
]

#: Two-sided 99% point of the standard normal distribution.
Z99 = 2.5758293035489004


def prediction_error(model: ArxModel, data: IOData, horizon: int | None = None, initial: str = "zero"):
    """Prediction, error and a divergence flag.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    data : IOData
        Measured data.
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    initial : {"zero", "estimate"}
        ``"estimate"``: each run's initial state is fitted to ``data`` first (see
        :meth:`arxid.PolynomialModel.predict`; an ARX model is taken in its polynomial form).

    Returns
    -------
    pred : ndarray of shape (n_samples,)
        Output predicted with ``horizon``; NaN where no prediction exists.
    error : ndarray of shape (n_samples,)
        ``y - pred`` (NaN where either is missing).
    diverged : bool
        The prediction diverged (see :mod:`arxid._metrics`: inf, or beyond
        ``DIVERGENCE_FACTOR`` times the largest measured |y|); its RMS is reported as infinite.
    """
    with np.errstate(all="ignore"):
        if check_initial(initial) == "estimate":
            pred = np.asarray(as_polynomial(model).predict(data, horizon, initial="estimate"), dtype=float)
        else:
            pred = np.asarray(model.predict(data, horizon), dtype=float)
        err = data.y - pred
    return pred, err, metrics.diverged(data.y, pred)


def error_rms(model: ArxModel, data: IOData, horizon: int | None = None) -> float:
    """RMS of ``y - prediction`` at ``horizon``; ``inf`` when the prediction diverges.

    Parameters
    ----------
    model : ArxModel
    data : IOData
    horizon : int or None
        None: free run; k: k-step-ahead prediction.

    Returns
    -------
    float
    """
    return model.rms(data, horizon)


# ---------------------------------------------------------------------------------------------
# compare
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Comparison:
    """Measured output against several models' predictions.

    Attributes
    ----------
    names : tuple of str
        One label per model.
    fit_percent, rms : tuple of float
        NRMSE fit in percent and RMS of the error, per model (``rms`` is ``inf`` for a simulation
        that diverges).
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    time, y : ndarray of shape (n_samples,)
        Sample times and the measured output.
    predictions : tuple of ndarray of shape (n_samples,)
        Each model's prediction (NaN where it has none).
    diverged : tuple of bool
    output_name : str
    """

    names: tuple[str, ...]
    fit_percent: tuple[float, ...]
    rms: tuple[float, ...]
    horizon: int | None
    time: np.ndarray
    y: np.ndarray
    predictions: tuple[np.ndarray, ...]
    diverged: tuple[bool, ...]
    output_name: str = "y"
    output_unit: str = ""

    @property
    def best(self) -> str:
        """Name of the model with the lowest RMS."""
        return self.names[int(np.nanargmin(np.where(np.isfinite(self.rms), self.rms, np.inf)))]

    def __str__(self) -> str:
        rows = [
            (n, f, r, "diverged" if d else "")
            for n, f, r, d in zip(self.names, self.fit_percent, self.rms, self.diverged)
        ]
        return f"compare ({horizon_label(self.horizon)}), output {self.output_name}\n" + text_table(
            ["model", "fit %", "rms", ""], rows
        )

    def to_dict(self) -> dict:
        """JSON-ready dict: the horizon and, per model, its fit, RMS and divergence flag.

        Returns
        -------
        dict
            ``{"horizon": int or None, "models": [{"name", "fit_percent", "rms", "diverged"}, ...]}``;
            non-finite numbers are None.
        """
        return {
            "horizon": self.horizon,
            "models": [
                {"name": n, "fit_percent": finite_or_none(f), "rms": finite_or_none(r), "diverged": bool(d)}
                for n, f, r, d in zip(self.names, self.fit_percent, self.rms, self.diverged)
            ],
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
        return json.dumps(self.to_dict(), indent=indent)

    def to_pandas(self):
        """One row per model: fit, RMS and divergence flag.

        Returns
        -------
        pandas.DataFrame
            Indexed by model name, columns ``fit_percent``, ``rms``, ``diverged``.
        """
        pd = require_pandas()
        return pd.DataFrame(
            {"fit_percent": self.fit_percent, "rms": self.rms, "diverged": self.diverged},
            index=pd.Index(self.names, name="model"),
        )

    def plot(self, ax: Any = None) -> Any:
        """Measured against predicted output, with the error underneath.

        Parameters
        ----------
        ax : pair of Axes, optional
            Where to draw (output, error); default a new figure.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_comparison

        return plot_comparison(self, ax=ax)


def _model_list(models) -> tuple[list[str], list[ArxModel]]:
    if isinstance(models, (ArxModel, PolynomialModel)):
        models = [models]
    if isinstance(models, Mapping):
        names, ms = [str(k) for k in models], list(models.values())
    else:
        try:
            ms = list(models)
        except TypeError:
            raise ArxidError(
                f"compare takes a model, a list of models or a dict name -> model, got {type(models).__name__}"
            ) from None
        names = []
        for m in ms:
            check_model(m)
            base = m.structure_name()
            name, i = base, 2
            while name in names:
                name, i = f"{base} #{i}", i + 1
            names.append(name)
    if not ms:
        raise ArxidError("compare needs at least one model")
    for m in ms:
        check_model(m)
    return names, ms


def compare(models, data: IOData, horizon: int | None = None, initial: str = "zero") -> Comparison:
    """Compare models with measured data.

    Parameters
    ----------
    models : ArxModel, sequence of ArxModel or mapping of str to ArxModel
        The models (a mapping gives them names).
    data : IOData
        Measured data, preferably not the estimation data.
    horizon : int or None
        None (default): free-run simulation, as MATLAB ``compare``; 1: one-step prediction;
        k: k-step-ahead prediction (for plants with an integrator, whose free run drifts).
    initial : {"zero", "estimate"}
        ``"zero"`` (default): each model starts at rest in each run of the data. ``"estimate"``:
        each run's initial state is fitted to the data first, as MATLAB ``compare`` does, so a
        record that starts mid-transient is not held against the model (OE, ARMAX, BJ and ARX
        models without effect terms).

    Returns
    -------
    Comparison
        ``fit_percent`` and ``rms`` per model; ``.plot()`` draws measured against predicted output.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(400); y = np.zeros(400)
    >>> for t in range(1, 400):
    ...     y[t] = 0.9 * y[t - 1] + u[t - 1]
    >>> d = arxid.IOData(y, u, ts=1.0)
    >>> c = arxid.compare(arxid.arx(d, 1, 1, 1), d)
    >>> round(c.fit_percent[0], 6)
    100.0
    """
    data = check_data(data)
    horizon = check_horizon(horizon)
    names, ms = _model_list(models)
    for m in ms:
        inputs = m.input_names if data.input_names == m.input_names else m.measured_input_names
        check_same_signals(m.ts, m.output_name, inputs, data, "the data to compare with")
    fits, rmss, preds, divs = [], [], [], []
    for m in ms:
        pred, _, diverged = prediction_error(m, data, horizon, initial)
        fits.append(metrics.fit_percent(data.y, pred))
        rmss.append(metrics.prediction_rms(data.y, pred))
        preds.append(pred)
        divs.append(diverged)
    t = np.arange(data.n_samples) * data.ts
    return Comparison(
        tuple(names),
        tuple(fits),
        tuple(rmss),
        horizon,
        t,
        data.y.copy(),
        tuple(preds),
        tuple(divs),
        data.output_name,
        data.output_unit,
    )


# ---------------------------------------------------------------------------------------------
# residual analysis
# ---------------------------------------------------------------------------------------------
def _centered(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float).copy()
    ok = np.isfinite(x)
    if ok.any():
        x[ok] -= x[ok].mean()
    return x


def _correlation(a: np.ndarray, b: np.ndarray, lags: np.ndarray, segments) -> np.ndarray:
    """corr(a(t), b(t − k)) for each lag k, over pairs inside one experiment where both exist.

    Normalised by √(Σa² Σb²) over the valid samples of each, as MATLAB ``resid`` and ``xcorr``
    with the biased estimator do.
    """
    av = np.where(np.isfinite(a), a, 0.0)
    bv = np.where(np.isfinite(b), b, 0.0)
    den = math.sqrt(float(np.sum(av * av)) * float(np.sum(bv * bv)))
    out = np.zeros(len(lags))
    if den == 0:
        return out
    for i, k in enumerate(lags):
        s = 0.0
        for lo, hi in segments:
            n = hi - lo
            if abs(k) >= n:
                continue
            if k >= 0:
                s += float(np.dot(av[lo + k : hi], bv[lo : hi - k]))
            else:
                s += float(np.dot(av[lo : hi + k], bv[lo - k : hi]))
        out[i] = s / den
    return out


def _prewhiten(x: np.ndarray, segments, max_order: int) -> np.ndarray:
    """Innovations of an AR model of ``x`` (order by AIC, 0..max_order), NaN where none exists.

    Lags stay inside one experiment and skip missing samples. Used for the independence test:
    the cross-correlations of two whitened series at different lags are nearly uncorrelated, so
    their sum of squares is χ² (Haugh 1976); those of a coloured signal are not.
    """
    x = _centered(x)
    n = len(x)
    starts = [np.arange(lo + max_order, hi) for lo, hi in segments]
    rows = np.concatenate(starts) if starts else np.zeros(0, dtype=int)
    if rows.size == 0:
        return x
    lagged = np.column_stack([x[rows - k] for k in range(max_order + 1)])
    ok = np.all(np.isfinite(lagged), axis=1)
    rows, lagged = rows[ok], lagged[ok]
    m = len(rows)
    if m <= 2 * max_order + 2:
        return x
    best_aic, best = math.log(max(metrics.mean_square(lagged[:, 0]), 1e-300)), (0, np.zeros(0))
    for p in range(1, max_order + 1):
        a, *_ = np.linalg.lstsq(lagged[:, 1 : p + 1], lagged[:, 0], rcond=None)
        rss = metrics.mean_square(lagged[:, 0] - lagged[:, 1 : p + 1] @ a)
        aic = math.log(max(rss, 1e-300)) + 2.0 * p / m
        if aic < best_aic:
            best_aic, best = aic, (p, a)
    p, a = best
    if p == 0:
        return x
    out = np.full(n, np.nan)
    for lo, hi in segments:
        if hi - lo > p:
            out[lo + p : hi] = x[lo + p : hi] - sum(a[i] * x[lo + p - 1 - i : hi - 1 - i] for i in range(p))
    return out


@dataclass(frozen=True, eq=False)
class ResidualAnalysis:
    """Whiteness and independence tests of a model's one-step residual (MATLAB ``resid``).

    Attributes
    ----------
    residual : ndarray of shape (n_samples,)
        One-step prediction error ``y − ŷ(t|t−1)`` (NaN where no prediction exists).
    n_samples : int
        Samples with a residual.
    lags : ndarray of shape (max_lag + 1,)
        0..L for the autocorrelation.
    autocorrelation : ndarray of shape (max_lag + 1,)
        Normalised autocorrelation of the residual (1 at lag 0).
    autocorrelation_bound : float
        99% bound ``z₀.₉₉₅ / √N`` for lags ≥ 1 under the hypothesis of a white residual.
    cross_lags : ndarray of shape (2 max_lag + 1,)
        −L..L. Positive lag k: the residual at t against the signal at t − k (the signal leads);
        significant values at negative lags point to feedback.
    cross_correlation : dict of str to ndarray of shape (2 max_lag + 1,)
        Normalised cross-correlation with every input and extra signal.
    cross_bounds : dict of str to float
        99% bound of each cross-correlation under independence, with Bartlett's correction for the
        colour of both signals: ``z₀.₉₉₅ √(Σ_k ρ_ee(k) ρ_ss(k) / N)``, k = −L..L.
    cross_p_values : dict of str to float
        Test of independence per signal (Haugh 1976): residual and signal are each prewhitened by
        an AR model (order by AIC, at most min(L, 10)), and ``S = N² Σ_k r_k² / (N − |k|)`` over the
        2L + 1 cross-correlations r_k of the whitened series is compared with χ² with 2L + 1
        degrees of freedom. (Checking each lag against its own 99% bound would flag an independent
        signal about 40% of the time at L = 25; summing the raw cross-correlations of a coloured
        signal, whose neighbouring lags are nearly equal, would flag it far more often than 1%.)
        NaN when the signal has too few numbers where the residual exists (untested).
    ljung_box_statistic, ljung_box_p_value : float
        ``Q = N (N + 2) Σ_{k=1..L} ρ_ee(k)² / (N − k)`` and its χ² tail probability with
        ``ljung_box_dof = L − n`` degrees of freedom, n the estimated noise-model parameters (na for
        ARX and ARMAX plus nc, nc + nd for Box–Jenkins, none for output-error).
    whiteness_expected : bool
        False for an output-error model: it has no noise model, so its residual is the output noise
        itself, white only if that noise is. MATLAB's ``resid`` draws the same test; what judges an
        OE model is the residual's independence of the inputs.
    """

    residual: np.ndarray
    n_samples: int
    lags: np.ndarray
    autocorrelation: np.ndarray
    autocorrelation_bound: float
    cross_lags: np.ndarray
    cross_correlation: dict
    cross_bounds: dict
    ljung_box_statistic: float
    ljung_box_p_value: float
    ljung_box_dof: int
    cross_p_values: dict = field(default_factory=dict)
    alpha: float = 0.01
    model_name: str = ""
    whiteness_expected: bool = True

    @property
    def whiteness_text(self) -> str:
        """The Ljung–Box verdict in words: ``white``, ``NOT white (...)``, or for an output-error model
        why a coloured residual is expected."""
        if self.is_white:
            return "white"
        if not self.whiteness_expected:
            return (
                "not white, which an output-error model allows: it models no noise, so coloured output noise "
                "stays in its residual; its test is the independence of the inputs"
            )
        return "NOT white (the model misses dynamics or an effect)"

    @property
    def is_white(self) -> bool:
        """True when the Ljung–Box test does not reject whiteness at level ``alpha``."""
        return bool(self.ljung_box_p_value >= self.alpha)

    @property
    def autocorrelation_outside(self) -> np.ndarray:
        """Lags ≥ 1 where the autocorrelation leaves its 99% bound."""
        return self.lags[1:][np.abs(self.autocorrelation[1:]) > self.autocorrelation_bound]

    def cross_outside(self, name: str) -> np.ndarray:
        """Lags where the cross-correlation with ``name`` leaves its 99% bound.

        Parameters
        ----------
        name : str
            An input or extra signal, a key of ``cross_correlation``.

        Returns
        -------
        ndarray of int
            The lags (−L..L, positive: the signal leads) outside ``cross_bounds[name]``.
        """
        return self.cross_lags[np.abs(self.cross_correlation[name]) > self.cross_bounds[name]]

    @property
    def independent(self) -> dict[str, bool]:
        """Per tested signal: True when the independence test does not reject at ``alpha``.

        Signals that could not be tested (no numbers where the residual exists) are left out.
        """
        return {k: bool(p >= self.alpha) for k, p in self.cross_p_values.items() if math.isfinite(p)}

    def to_dict(self) -> dict:
        """JSON-ready summary of the tests: Ljung–Box, autocorrelation and per-signal cross-correlation.

        Returns
        -------
        dict
            ``n_samples``, ``max_lag``, ``ljung_box`` (statistic, dof, p-value, white),
            ``autocorrelation`` (bound, lags outside) and ``cross_correlation`` per signal (largest
            value and its lag, bound, lags outside, p-value, independent); NaN becomes None.
        """
        cross = {}
        for k, r in self.cross_correlation.items():
            i = int(np.argmax(np.nan_to_num(np.abs(r), nan=-1.0)))
            cross[k] = {
                "max_abs": finite_or_none(float(abs(r[i]))),
                "lag_of_max": int(self.cross_lags[i]),
                "bound": finite_or_none(float(self.cross_bounds[k])),
                "lags_outside": [int(x) for x in self.cross_outside(k)],
                "p_value": finite_or_none(float(self.cross_p_values[k])),
                "independent": self.independent.get(k),
            }
        return {
            "n_samples": int(self.n_samples),
            "max_lag": int(self.lags[-1]),
            "ljung_box": {
                "statistic": float(self.ljung_box_statistic),
                "dof": int(self.ljung_box_dof),
                "p_value": float(self.ljung_box_p_value),
                "white": self.is_white,
                "whiteness_expected": self.whiteness_expected,
            },
            "autocorrelation": {
                "bound": float(self.autocorrelation_bound),
                "lags_outside": [int(x) for x in self.autocorrelation_outside],
            },
            "cross_correlation": cross,
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
        return json.dumps(self.to_dict(), indent=indent)

    def to_pandas(self):
        """Correlations by lag: column ``residual`` (autocorrelation) and one per signal.

        Returns
        -------
        pandas.DataFrame
            Indexed by ``lag`` (−L..L); ``residual`` is NaN at negative lags.
        """
        pd = require_pandas()
        df = pd.DataFrame(
            {name: r for name, r in self.cross_correlation.items()}, index=pd.Index(self.cross_lags, name="lag")
        )
        auto = pd.Series(self.autocorrelation, index=self.lags)
        df.insert(0, "residual", auto.reindex(df.index))
        return df

    def __str__(self) -> str:
        lb = (
            f"Ljung–Box Q = {self.ljung_box_statistic:.4g} with {self.ljung_box_dof} dof, p = {self.ljung_box_p_value:.3g}: "  # noqa: E501
            + self.whiteness_text
        )
        lines = [
            f"residual analysis{' of ' + self.model_name if self.model_name else ''} ({self.n_samples} samples, "
            f"99% bounds)",
            "  " + lb,
        ]
        out = self.autocorrelation_outside
        lines.append(
            f"  autocorrelation: bound ±{self.autocorrelation_bound:.3g}, "
            + (f"outside at lags {list(map(int, out[:10]))}" if len(out) else "inside")
        )
        rows = []
        for k, r in self.cross_correlation.items():
            i = int(np.argmax(np.nan_to_num(np.abs(r), nan=-1.0)))
            o = self.cross_outside(k)
            p = self.cross_p_values[k]
            rows.append(
                (
                    k,
                    float(r[i]),
                    int(self.cross_lags[i]),
                    self.cross_bounds[k],
                    len(o),
                    p,
                    "untested (no data)" if not math.isfinite(p) else "yes" if p >= self.alpha else "NO",
                )
            )
        if rows:
            lines.append(
                text_table(
                    ["signal", "max corr", "at lag", "bound", "lags outside", "p-value", "independent"], rows, digits=3
                )
            )
        return "\n".join(lines)

    def plot(self, axes: Any = None) -> Any:
        """Autocorrelation and cross-correlations with their 99% bands (MATLAB ``resid`` style).

        Parameters
        ----------
        axes : sequence of Axes, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_residuals

        return plot_residuals(self, axes=axes)


#: A one-step residual whose RMS is below this share of the output's RMS is rounding error: the
#: model reproduces the data exactly (noise-free data) and the tests pass.
ROUND_OFF_SHARE = 1e-9


def _at_round_off(e: np.ndarray, y: np.ndarray) -> bool:
    scale = float(np.sqrt(np.mean(y * y))) if y.size else 0.0
    return scale > 0 and float(np.sqrt(np.mean(e * e))) <= ROUND_OFF_SHARE * scale


def residuals(model: ArxModel, data: IOData, max_lag: int = 25, alpha: float = 0.01) -> ResidualAnalysis:
    """Residual analysis: is the one-step residual white and independent of the inputs?

    Parameters
    ----------
    model : ArxModel
    data : IOData
        Preferably validation data. Cross-correlations are computed with every input and every
        extra signal of ``data``.
    max_lag : int
        Largest lag L (autocorrelation at 0..L, cross-correlation at −L..L).
    alpha : float
        Level of the Ljung–Box test used by ``is_white`` (bounds are always 99%).

    Returns
    -------
    ResidualAnalysis

    Notes
    -----
    A residual correlated with a signal at positive lags means the model does not use all the
    information that signal carries: a missing input, a wrong delay, or a missing effect built
    from it. :func:`arxid.diagnose` ranks such effects.

    For an output-error model the one-step residual is the free-run error (it has no noise model):
    its whiteness is reported but not expected (``whiteness_expected`` is False), and its
    independence of the inputs is the test of the model, as in MATLAB's ``resid``.
    """
    model = check_model(model)
    data = check_data(data)
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or max_lag < 1:
        raise OrderError(f"max_lag must be an integer >= 1, got {max_lag!r}")
    max_lag = int(max_lag)
    _, e, diverged = prediction_error(model, data, 1)
    if diverged:
        raise ArxidError("the one-step prediction is not finite on these data; check the data for outliers")
    ok = np.isfinite(e)
    n = int(ok.sum())
    if n <= max_lag + 1:
        raise DataError(f"only {n} residual samples for max_lag={max_lag}; use more data or a smaller max_lag")
    segs = data.segments
    ec = _centered(e)
    lags = np.arange(0, max_lag + 1)
    auto = _correlation(ec, ec, lags, segs)
    cl = np.arange(-max_lag, max_lag + 1)
    auto_full = np.concatenate([auto[:0:-1], auto])  # ρ_ee(k) for k = -L..L
    from scipy import stats

    cross, bounds, pvals = {}, {}, {}
    signals = [(name, data.u[:, i]) for i, name in enumerate(data.input_names)] + list(data.extra.items())
    order = min(max_lag, 10)
    ew = _prewhiten(e, segs, order)
    for name, s in signals:
        s = np.asarray(s, dtype=float)
        sc = _centered(np.where(ok, s, np.nan))
        both = ok & np.isfinite(s)
        if int(both.sum()) <= max_lag + 1 or np.ptp(s[both]) == 0:
            cross[name] = np.full(len(cl), np.nan)
            bounds[name] = pvals[name] = math.nan
            continue
        cross[name] = _correlation(ec, sc, cl, segs)
        ss = _correlation(sc, sc, lags, segs)
        ss_full = np.concatenate([ss[:0:-1], ss])
        v = max(float(np.dot(auto_full, ss_full)), 1.0 / max_lag)  # a (near-)constant signal gives ~0
        bounds[name] = Z99 * math.sqrt(v / n)
        # Independence: cross-correlations of the prewhitened series (Haugh's test).
        sw = _prewhiten(np.where(ok, s, np.nan), segs, order)
        pair = np.isfinite(ew) & np.isfinite(sw)
        nw = int(pair.sum())
        if nw <= 2 * max_lag + 1:
            pvals[name] = math.nan
            continue
        rw = _correlation(_centered(np.where(pair, ew, np.nan)), _centered(np.where(pair, sw, np.nan)), cl, segs)
        stat = float(nw * nw * np.sum(rw**2 / (nw - np.abs(cl))))
        pvals[name] = float(stats.chi2.sf(stat, len(cl)))

    q = float(n * (n + 2) * np.sum(auto[1:] ** 2 / (n - lags[1:])))
    noise_parameters = model.na_ + (model.nc_ + model.nd_ if isinstance(model, PolynomialModel) else 0)
    dof = max(max_lag - noise_parameters, 1)
    p = float(stats.chi2.sf(q, dof))
    if _at_round_off(e[ok], data.y[ok]):
        # Nothing left to explain: the correlations of rounding errors say nothing about the model.
        p, pvals = 1.0, {k: (1.0 if math.isfinite(v) else v) for k, v in pvals.items()}
    expected = not (isinstance(model, PolynomialModel) and model.kind == "OE")
    return ResidualAnalysis(
        e,
        n,
        lags,
        auto,
        Z99 / math.sqrt(n),
        cl,
        cross,
        bounds,
        q,
        p,
        dof,
        pvals,
        alpha,
        model.structure_name(),
        expected,
    )


# ---------------------------------------------------------------------------------------------
# where it fails
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
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


@dataclass(frozen=True, eq=False)
class SignalBins:
    """RMS of the one-step residual binned by the value of one signal.

    Attributes
    ----------
    signal : str
        Signal name (an input at ``t − nk``, the output ``y(t−1)``, its rate ``d<y>`` =
        (y(t−1) − y(t−2)) / ts, or an extra signal at t).
    edges : ndarray of shape (n_bins + 1,)
    centers, rms, mean, counts : ndarray of shape (n_bins,)
        Bin centres, residual RMS, residual mean and sample count per bin.
    ratio : float
        Largest bin RMS over the overall RMS (1 = the error does not depend on this signal).
    p_value : float
        Probability that bins this different arise by chance when the error does not depend on
        the signal: Bonferroni combination of a Kruskal–Wallis test on the squared residual (the
        error size differs) and a one-way ANOVA on the residual (a bias differs between bins).
    """

    signal: str
    edges: np.ndarray
    centers: np.ndarray
    rms: np.ndarray
    mean: np.ndarray
    counts: np.ndarray
    ratio: float
    p_value: float


@dataclass(frozen=True, eq=False)
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


def _bin_signal(name: str, x: np.ndarray, e: np.ndarray, n_bins: int) -> SignalBins | None:
    from scipy import stats

    ok = np.isfinite(x) & np.isfinite(e)
    x, e = x[ok], e[ok]
    if len(x) < 4 * n_bins:
        return None
    values = np.unique(x)
    if len(values) < 2:
        return None
    if len(values) <= n_bins:
        mids = (values[1:] + values[:-1]) / 2
        edges = np.concatenate([[values[0]], mids, [values[-1]]])
        idx = np.searchsorted(values, x)
    else:
        edges = np.unique(np.quantile(x, np.linspace(0, 1, n_bins + 1)))
        idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    nb = len(edges) - 1
    groups = [e[idx == i] for i in range(nb)]
    counts = np.array([len(g) for g in groups])
    rms = np.array([metrics.rms(g) for g in groups])
    mean = np.array([np.mean(g) if len(g) else np.nan for g in groups])
    overall = metrics.rms(e)
    used = [g for g in groups if len(g) >= 2]
    if len(used) < 2 or overall == 0:
        return None
    sq = [g**2 for g in used]
    p_kw = float(stats.kruskal(*sq).pvalue) if np.ptp(np.concatenate(sq)) > 0 else 1.0
    p_an = float(stats.f_oneway(*used).pvalue) if all(np.ptp(g) > 0 for g in used) else 1.0
    p_kw = 1.0 if not math.isfinite(p_kw) else p_kw
    p_an = 1.0 if not math.isfinite(p_an) else p_an
    p = min(1.0, 2 * min(p_kw, p_an))
    centers = (edges[1:] + edges[:-1]) / 2
    return SignalBins(name, edges, centers, rms, mean, counts, float(np.nanmax(rms) / overall), p)


def _segment_p_value(res: np.ndarray, lo: int, hi: int, n_windows: int) -> float:
    """One-sided F test: is the one-step residual variance in [lo, hi) larger than outside it?"""
    from scipy import stats

    inside = res[lo:hi]
    outside = np.concatenate([res[:lo], res[hi:]])
    inside, outside = inside[np.isfinite(inside)], outside[np.isfinite(outside)]
    if inside.size < 2 or outside.size < 2:
        return math.nan
    v_out = metrics.mean_square(outside)
    if v_out == 0:
        return math.nan
    f = metrics.mean_square(inside) / v_out
    return float(min(1.0, stats.f.sf(f, inside.size, outside.size) * n_windows))


def where_it_fails(
    model: ArxModel,
    data: IOData,
    horizon: int | None = None,
    *,
    window: int | None = None,
    n_worst: int = 3,
    n_bins: int = 8,
    alpha: float = 0.01,
) -> FailureAnalysis:
    """Locate a model's error in time and by operating point.

    Parameters
    ----------
    model : ArxModel
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

    Returns
    -------
    FailureAnalysis
        ``worst_segments`` with their time ranges and ``by_signal``: residual RMS binned by each
        input (at t − nk), the output (at t − 1), the output rate and each extra signal, with a
        p-value, most significant first. ``.plot()`` and ``.torequire_pandas()`` give figure and table.
    """
    model = check_model(model)
    data = check_data(data)
    horizon = check_horizon(horizon)
    n = data.n_samples
    window = max(10, n // 50) if window is None else int(window)
    if window < 2 or window > n:
        raise ArxidError(f"window must be between 2 and the number of samples ({n}), got {window}")
    _, err, diverged = prediction_error(model, data, horizon)
    if diverged:
        err = np.where(np.isfinite(err), err, np.nan)
    _, res, _ = prediction_error(model, data, 1)
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
    for _ in range(int(n_worst)):
        if not np.isfinite(r).any():
            break
        i = int(np.nanargmax(r))
        lo, hi = max(0, i - half), min(n, i - half + window)
        rms = metrics.rms(err[lo:hi])
        p = _segment_p_value(res, lo, hi, n_windows=max(1, n // window))
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
    # Operating points.
    signals = []
    for i, name in enumerate(data.input_names):
        x = np.full(n, np.nan)
        k = model.nk_[i]
        for a, b in data.segments:
            if b - a > k:
                x[a + k : b] = data.u[a : b - k, i]
        signals.append((name, x))
    y1 = np.full(n, np.nan)
    dy1 = np.full(n, np.nan)
    for a, b in data.segments:
        y1[a + 1 : b] = data.y[a : b - 1]
        dy1[a + 2 : b] = (data.y[a + 1 : b - 1] - data.y[a : b - 2]) / data.ts
    signals.append((data.output_name, y1))
    signals.append((f"d{data.output_name}", dy1))
    signals += [(k, np.asarray(v, dtype=float)) for k, v in data.extra.items()]
    bins = [b for b in (_bin_signal(name, x, res, n_bins) for name, x in signals) if b is not None]
    bins.sort(key=lambda b: (b.p_value, -b.ratio))
    return FailureAnalysis(
        t, err, res, roll, window, overall, tuple(worst), tuple(bins), horizon, alpha, model.structure_name()
    )
