"""Residual tests (MATLAB ``resid``): is a model's one-step residual white and independent of every
input and logged signal?

:func:`residuals` returns a :class:`ResidualAnalysis`: autocorrelation and cross-correlations with
99% bounds, the Ljung–Box test of whiteness, Haugh's test of independence on prewhitened series, and
a low-frequency test per signal on block means (a slow drift that follows a signal, such as a
draining battery, is what prewhitening removes, so the prewhitened test cannot see it). A residual
correlated with a signal tells *that* the model misses something; :func:`arxid.diagnose` tells
*which effect*.
"""

from __future__ import annotations

import math
from dataclasses import field
from typing import Any

import numpy as np

from .._base.formatting import finite_or_none, require_pandas, text_table
from .._base.probabilities import chi2_sf, t_sf
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from ..models.arguments import check_data, check_model
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel
from ..models.state_space import StateSpaceModel
from .comparison import prediction_error
from .correlation import ar_filter, ar_innovations, centered, signal_whitening, zeroed_correlation
from .state_space import PerOutput, in_model_order, state_space_label, state_space_prediction

__all__ = ["residuals", "ResidualAnalysis", "low_frequency_test"]

#: Two-sided 99% point of the standard normal distribution.
Z99 = 2.5758293035489004


def _block_means(x: np.ndarray, segments, block: int) -> np.ndarray:
    """Means of ``block`` consecutive samples inside each experiment (NaN for a block with fewer
    than half its samples finite); a last partial block of an experiment is dropped."""
    out = []
    for lo, hi in segments:
        m = (hi - lo) // block
        if m == 0:
            continue
        b = x[lo : lo + m * block].reshape(m, block)
        ok = np.isfinite(b)
        count = ok.sum(axis=1)
        total = np.where(ok, b, 0.0).sum(axis=1)
        out.append(np.where(count >= max(block // 2, 1), total / np.maximum(count, 1), np.nan))
    return np.concatenate(out) if out else np.zeros(0)


def _autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample autocorrelation of a centred series at lags 0..max_lag."""
    n = len(x)
    if n * (max_lag + 1) <= 1 << 16:  # short: the direct sums
        full = np.correlate(x, x, mode="full")[n - 1 : n + max_lag]
    else:  # by FFT, n log n (the lags reach half the series in the low-frequency test)
        size = 1 << int(2 * n - 1).bit_length()
        f = np.fft.rfft(x, size)
        full = np.fft.irfft(f * np.conj(f), size)[: max_lag + 1]
        if len(full) < max_lag + 1:
            full = np.concatenate([full, np.zeros(max_lag + 1 - len(full))])
    return full / full[0] if full[0] > 0 else np.zeros(max_lag + 1)


#: Fewest block means the low-frequency test needs.
MIN_BLOCKS = 16


def low_frequency_test(e: np.ndarray, s: np.ndarray, segments, block: int) -> float:
    """p-value of the low-frequency dependence of ``e`` on ``s`` (NaN when there are too few blocks).

    Both series become means over blocks of ``block`` samples (a low-pass filter and decimation:
    what changes within a block is averaged out), and the block means of the residual are regressed
    on those of the signal. The slope's t statistic uses a long-run variance that allows for the
    colour of both series: Bartlett weights over half the blocks (b = 1/2) of the products of the
    autocorrelations of the signal and of the regression's remainder; its p-value is read from a
    Student t with ν = 3 / (2b) = 3 degrees of freedom, the fixed-b approximation of Kiefer and
    Vogelsang (2005), which keeps the level near nominal for slowly drifting residuals and signals
    (a t with M − 2 degrees of freedom would flag an unrelated drift far more often than ``alpha``).

    Parameters
    ----------
    e : ndarray
        The residual (NaN where it does not exist).
    s : ndarray
        The signal, same length.
    segments : sequence of (int, int)
        The experiments' sample ranges; blocks stay inside one.
    block : int
        Samples per block.

    Returns
    -------
    float
    """
    return _low_frequency_of_blocks(
        _block_means(e, segments, block), _block_means(np.asarray(s, dtype=float), segments, block)
    )


def _low_frequency_of_blocks(eb: np.ndarray, sb: np.ndarray) -> float:
    """:func:`low_frequency_test` from the block means of the residual and of the signal."""
    ok = np.isfinite(eb) & np.isfinite(sb)
    eb, sb = eb[ok], sb[ok]
    m = len(eb)
    if m < MIN_BLOCKS:
        return math.nan
    ec, sc = eb - eb.mean(), sb - sb.mean()
    sxx = float(np.dot(sc, sc))
    if sxx <= 1e-300 * max(float(np.dot(sb, sb)), 1e-300) or not np.any(ec):
        return math.nan if sxx <= 0 else 1.0
    beta = float(np.dot(ec, sc)) / sxx
    rest = ec - beta * sc
    bandwidth = m // 2
    weights = 1.0 - np.arange(1, bandwidth + 1) / (bandwidth + 1)
    v = 1.0 + 2.0 * float(np.sum(weights * _autocorrelation(rest, bandwidth)[1:] * _autocorrelation(sc, bandwidth)[1:]))
    v = max(v, 1.0 / bandwidth)
    noise = float(np.dot(rest, rest)) / m
    if noise <= 0:
        return 0.0
    t = beta * math.sqrt(sxx) / math.sqrt(noise * v)
    return float(2.0 * t_sf(abs(t), 1.5 * m / (bandwidth + 1)))


@record(eq=False)
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
    low_frequency_p_values : dict of str to float
        Low-frequency test of dependence per signal (:func:`low_frequency_test`): the residual's
        means over blocks of ``low_frequency_block`` samples against the signal's. It sees a slow
        drift that follows a signal (a battery that drains, a temperature), which the prewhitened
        test discounts: prewhitening turns a slow signal into its tiny sample-to-sample changes.
        NaN when the record has too few blocks.
    low_frequency_block : int
        Samples per block of the low-frequency test (= the largest lag L: it sees what is slower
        than the lag window of the correlation tests).
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
    low_frequency_p_values: dict = field(default_factory=dict)
    low_frequency_block: int = 0

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

    @property
    def independent_low_frequency(self) -> dict[str, bool]:
        """Per signal: True when the low-frequency test does not reject at ``alpha`` (untested left out)."""
        return {k: bool(p >= self.alpha) for k, p in self.low_frequency_p_values.items() if math.isfinite(p)}

    def slow_only(self, name: str) -> bool:
        """True when only the low-frequency test sees ``name``: the residual drifts with it slowly,
        and the prewhitened test does not reject.

        Parameters
        ----------
        name : str
            An input or extra signal.

        Returns
        -------
        bool
        """
        return self.independent.get(name, False) and not self.independent_low_frequency.get(name, True)

    def to_dict(self) -> dict:
        """JSON-ready summary of the tests: Ljung–Box, autocorrelation and per-signal cross-correlation.

        Returns
        -------
        dict
            ``n_samples``, ``max_lag``, ``ljung_box`` (statistic, dof, p-value, white),
            ``autocorrelation`` (bound, lags outside) and ``cross_correlation`` per signal (largest
            value and its lag, bound, lags outside, p-value, independent, and the low-frequency
            test's ``p_value_low_frequency`` and ``independent_low_frequency``); NaN becomes None.
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
                "p_value_low_frequency": finite_or_none(float(self.low_frequency_p_values.get(k, math.nan))),
                "independent_low_frequency": self.independent_low_frequency.get(k),
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
            "low_frequency_block": int(self.low_frequency_block),
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
                    self.low_frequency_p_values.get(k, math.nan),
                    self.verdict(k),
                )
            )
        if rows:
            head = ["signal", "max corr", "at lag", "bound", "lags outside", "p-value", "low-freq. p", "independent"]
            lines.append(text_table(head, rows, digits=3))
            lines.append(
                f"  p-value: prewhitened series (Haugh); low-freq. p: means over {self.low_frequency_block} samples "
                "(sees a slow drift that prewhitening removes)"
            )
        return "\n".join(lines)

    def verdict(self, name: str) -> str:
        """The table's verdict for ``name``: ``yes``, ``NO``, ``NO (slowly)`` (only the low-frequency
        test rejects) or ``untested (no data)``.

        Parameters
        ----------
        name : str
            An input or extra signal.

        Returns
        -------
        str
        """
        if name not in self.independent:
            return "untested (no data)"
        if not self.independent[name]:
            return "NO"
        return "NO (slowly)" if self.slow_only(name) else "yes"

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


def _signal_tests(
    data: IOData,
    name: str,
    s: np.ndarray,
    source: np.ndarray,
    e: np.ndarray,
    ecz: np.ndarray,
    e_blocks: np.ndarray,
    ew: np.ndarray,
    auto_full: np.ndarray,
    max_lag: int,
) -> tuple[np.ndarray, float, float, float]:
    """Cross-correlation with the residual ``e`` (``ecz`` centred, 0 where missing; ``e_blocks`` its
    means over blocks of ``max_lag`` samples), its 99% bound, Haugh's p-value
    (against the prewhitened residual ``ew``) and the low-frequency p-value of one signal ``s`` (``source``: the
    data's array it comes from)."""
    segs = data.segments
    ok = np.isfinite(e)
    cl = np.arange(-max_lag, max_lag + 1)
    n = int(ok.sum())
    used = np.where(ok, s, np.nan)  # the signal where the residual exists
    both = np.isfinite(used)
    if int(np.count_nonzero(both)) <= max_lag + 1:
        return np.full(len(cl), np.nan), math.nan, math.nan, math.nan
    top, bottom = float(np.fmax.reduce(used)), float(np.fmin.reduce(used))  # skip NaN, no copy
    if not math.isfinite(top - bottom):  # ±inf: the range of the finite samples
        top, bottom = float(np.max(used[both])), float(np.min(used[both]))
    if top == bottom:
        return np.full(len(cl), np.nan), math.nan, math.nan, math.nan
    sc = used - used[both].mean()  # centered(used), NaN stays NaN
    slow = _low_frequency_of_blocks(e_blocks, _block_means(used, segs, max_lag))  # = low_frequency_test(e, used, ...)
    cross = zeroed_correlation(ecz, np.where(both, sc, 0.0), cl, segs)
    # The signal's filter and autocorrelation depend on the data and the samples used only:
    # fitted once for the residual tests of every model on these data.
    whitening = signal_whitening(data, name, source, sc, min(max_lag, 10), np.arange(0, max_lag + 1))
    ss = whitening.autocorrelation
    v = max(float(np.dot(auto_full, np.concatenate([ss[:0:-1], ss]))), 1.0 / max_lag)  # (near-)constant: ~0
    bound = Z99 * math.sqrt(v / n)
    # Independence: cross-correlations of the prewhitened series (Haugh's test).
    sw = ar_innovations(sc, segs, whitening.filter)
    pair = np.isfinite(ew) & np.isfinite(sw)
    nw = int(pair.sum())
    if nw <= 2 * max_lag + 1:
        return cross, bound, math.nan, slow
    # centered(ew) and centered(sw) over the pairs, 0 elsewhere
    mw, ms = ew[pair].mean(), sw[pair].mean()
    rw = zeroed_correlation(np.where(pair, ew - mw, 0.0), np.where(pair, sw - ms, 0.0), cl, segs)
    stat = float(nw * nw * np.sum(rw**2 / (nw - np.abs(cl))))
    return cross, bound, float(chi2_sf(stat, len(cl))), slow


def residuals(model: ArxModel | StateSpaceModel, data: IOData, max_lag: int = 25, alpha: float = 0.01) -> Any:
    """Residual analysis: is the one-step residual white and independent of the inputs?

    Parameters
    ----------
    model : ArxModel, PolynomialModel or StateSpaceModel
    data : IOData
        Preferably validation data. Cross-correlations are computed with every input and every
        extra signal of ``data``.
    max_lag : int
        Largest lag L (autocorrelation at 0..L, cross-correlation at −L..L).
    alpha : float
        Level of the Ljung–Box test used by ``is_white`` (bounds are always 99%).

    Returns
    -------
    ResidualAnalysis or PerOutput of ResidualAnalysis
        One analysis per output (by name) for a state-space model of several outputs.

    Notes
    -----
    A residual correlated with a signal at positive lags means the model does not use all the
    information that signal carries: a missing input, a wrong delay, or a missing effect built
    from it. :func:`arxid.diagnose` ranks such effects.

    For an output-error model the one-step residual is the free-run error (it has no noise model):
    its whiteness is reported but not expected (``whiteness_expected`` is False), and its
    independence of the inputs is the test of the model, as in MATLAB's ``resid``.

    Each signal has two tests of independence: the prewhitened cross-correlations at lags −L..L
    (``cross_p_values``), which see a dependence within L samples, and the low-frequency test on
    means over L samples (``low_frequency_p_values``), which sees a slow drift that follows the
    signal. ``independent`` is the first test's verdict; :meth:`ResidualAnalysis.verdict` combines
    both.

    For a state-space model, the residual of each output is its one-step prediction error by the
    innovation form from an initial state fitted to ``data``, tested against the inputs and extra
    signals as above; the Ljung–Box degrees of freedom lose the model's order. Whiteness is not
    expected when the model has no Kalman gain (K = 0: an output-error model).
    """
    if not isinstance(model, StateSpaceModel):
        model = check_model(model)
    data = check_data(data)
    if isinstance(max_lag, bool) or not isinstance(max_lag, (int, np.integer)) or max_lag < 1:
        raise OrderError(f"max_lag must be an integer >= 1, got {max_lag!r}")
    max_lag = int(max_lag)
    if isinstance(model, StateSpaceModel):
        return _state_space_residuals(model, data, max_lag, alpha)
    _, e, diverged = prediction_error(model, data, 1)
    if diverged:
        raise ArxidError("the one-step prediction is not finite on these data; check the data for outliers")
    noise_parameters = model.na_ + (model.nc_ + model.nd_ if isinstance(model, PolynomialModel) else 0)
    expected = not (isinstance(model, PolynomialModel) and model.kind == "OE")
    return _residual_tests(e, data, max_lag, alpha, noise_parameters, model.structure_name(), expected)


def _state_space_residuals(model: StateSpaceModel, data: IOData, max_lag: int, alpha: float) -> Any:
    """The residual tests of each output of a state-space model (see :func:`residuals`)."""
    ordered = in_model_order(model, data, "the data to test the residuals on")
    pred = state_space_prediction(model, ordered, 1, "estimate")
    if not np.isfinite(pred).any():
        raise ArxidError("the one-step prediction is not finite on these data; check the data for outliers")
    expected = bool(np.any(model.k))
    results = {}
    for name in data.output_names:
        one = data.output(name) if data.n_outputs > 1 else data
        with np.errstate(all="ignore"):
            e = one.y - pred[:, model.output_names.index(name)]
        results[name] = _residual_tests(
            e, one, max_lag, alpha, model.order, f"{state_space_label(model)}, output {name}", expected
        )
    return results[data.output_names[0]] if data.n_outputs == 1 else PerOutput(results)


def _residual_tests(
    e: np.ndarray, data: IOData, max_lag: int, alpha: float, noise_parameters: int, name: str, expected: bool
) -> ResidualAnalysis:
    """The tests of :func:`residuals` on the one-step residual ``e`` of single-output ``data``."""
    ok = np.isfinite(e)
    n = int(ok.sum())
    if n <= max_lag + 1:
        raise DataError(f"only {n} residual samples for max_lag={max_lag}; use more data or a smaller max_lag")
    segs = data.segments
    ec = centered(e)
    ecz = np.where(ok, ec, 0.0)
    lags = np.arange(0, max_lag + 1)
    auto = zeroed_correlation(ecz, ecz, lags, segs)
    cl = np.arange(-max_lag, max_lag + 1)
    auto_full = np.concatenate([auto[:0:-1], auto])  # ρ_ee(k) for k = -L..L
    cross, bounds, pvals, slow = {}, {}, {}, {}
    signals = [(name, data.u[:, i], data.u) for i, name in enumerate(data.input_names)]
    signals += [(name, s, s) for name, s in data.extra.items()]
    order = min(max_lag, 10)
    ew = ar_innovations(ec, segs, ar_filter(ec, segs, order))
    e_blocks = _block_means(e, segs, max_lag)  # the residual's side of every low-frequency test
    for name, s, source in signals:
        cross[name], bounds[name], pvals[name], slow[name] = _signal_tests(
            data, name, np.asarray(s, dtype=float), source, e, ecz, e_blocks, ew, auto_full, max_lag
        )

    q = float(n * (n + 2) * np.sum(auto[1:] ** 2 / (n - lags[1:])))
    dof = max(max_lag - noise_parameters, 1)
    p = float(chi2_sf(q, dof))
    if _at_round_off(e[ok], data.y[ok]):
        # Nothing left to explain: the correlations of rounding errors say nothing about the model.
        p, pvals = 1.0, {k: (1.0 if math.isfinite(v) else v) for k, v in pvals.items()}
        slow = {k: (1.0 if math.isfinite(v) else v) for k, v in slow.items()}
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
        name,
        expected,
        slow,
        max_lag,
    )
