"""Where the model fails in frequency: the data's own frequency response against the model's.

:func:`frequency_check` estimates the frequency response from the measured data without a model
(Welch-averaged cross-spectra, the H1 estimator ``S_yu / S_uu``, with the coherence), draws it beside
the model's frequency response with the model's confidence band from the parameter covariance, and
names the frequency bands where the two disagree beyond both uncertainties.

How a band is decided (so what is drawn is what is tested):

* The model's free-run error e = y − ŷ on the data is put through the same Welch windows: its H1
  estimate from the inputs, M(f) = S_eu / S_uu, is the data's estimate minus the model's, and the
  window's smoothing (leakage) cancels between the two. For one input M = H1(y) − H1(ŷ).
* Its variance is that of an H1 estimate, (1 − γ²_e) S_ee [S_uu⁻¹]_ii / n (Bendat & Piersol, with n
  the effective number of averages of a 50 %-overlapping Hann window, Welch 1967), plus the model's
  own variance E|δG|² from the covariance (:func:`arxid.uncertainty.frequency_response`).
* |M|² / σ² is exponential under "the model is right" (a complex normal error), so the p-value of a
  frequency is exp(−|M|²/σ²). A band starts at a frequency whose p-value is below α / (number of
  frequencies) (Bonferroni: no band on a correct model, at family-wise level α) and extends over
  the neighbouring frequencies with p-value below α.

The bands drawn around the curves are at the same level 1 − α (default 99 %).

Examples
--------
>>> import numpy as np, arxid
>>> rng = np.random.default_rng(0)
>>> u = rng.standard_normal(8000)
>>> y = np.zeros(8000)
>>> for t in range(1, 8000):
...     y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + 0.05 * rng.standard_normal()
>>> data = arxid.IOData(y, u, ts=0.01)
>>> arxid.frequency_check(arxid.arx(data, 1, 1, 1), data).summary
'the model matches the data within the uncertainty from 0.2 to 50 Hz (slower changes, such as a drift,
are not resolved by 512-sample segments)'
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._base.formatting import finite_or_none
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError
from ..frequency_domain._spectra import default_segment_length, effective_averages, finite_runs, spectra
from ..models.arguments import check_data, check_model
from ..models.arx_model import ArxModel
from .bands import frequency_response, normal_quantile

__all__ = ["frequency_check", "FrequencyCheck", "FrequencyBand", "spectra"]

# Neighbouring Welch frequencies of a Hann window overlap over about 4 bins: bands closer than that
# are one band.
_MERGE_GAP = 4
# Bands named in the one-line summary (the widest); the rest are counted.
_SUMMARY_BANDS = 3


@record
class FrequencyBand:
    """A range of frequencies where the model and the data disagree beyond the uncertainty.

    Attributes
    ----------
    input : str
        The input whose transfer function disagrees.
    low, high : float
        Edges in Hz (the first and last frequency of the band).
    worst : float
        Frequency of the smallest p-value in the band, Hz.
    p_value : float
        That smallest p-value.
    """

    input: str
    low: float
    high: float
    worst: float
    p_value: float

    @property
    def text(self) -> str:
        """``between 12 and 40 Hz`` (``at 25 Hz`` for a single frequency)."""
        if math.isclose(self.low, self.high):
            return f"at {self.low:.3g} Hz"
        return f"between {self.low:.3g} and {self.high:.3g} Hz"

    def to_dict(self) -> dict:
        """``input``, ``low_hz``, ``high_hz``, ``worst_hz``, ``p_value``.

        Returns
        -------
        dict
        """
        return {
            "input": self.input,
            "low_hz": self.low,
            "high_hz": self.high,
            "worst_hz": self.worst,
            "p_value": finite_or_none(float(self.p_value)),
        }


@record(eq=False)
class FrequencyCheck:
    """The data's frequency response against the model's, and where they disagree.

    Attributes
    ----------
    model_name : str
    output_name, output_unit : str
    input_names, input_units : tuple of str
    frequency : ndarray of shape (n_f,)
        Hz, from the first Welch frequency above 0 to the Nyquist frequency.
    data_response, model_response : ndarray of complex, shape (n_f, n_inputs)
        H1 estimate from the data, and the model's B/A (linear part).
    data_sd, model_sd : ndarray of shape (n_f, n_inputs)
        √E|δ|² of each.
    coherence : ndarray of shape (n_f,)
        (Multiple) coherence between the inputs and the measured output.
    miss, miss_sd : ndarray, shape (n_f, n_inputs)
        H1 estimate from the inputs to the model's error (complex) and its standard deviation
        under "the model is right" (data and model variance together).
    p_value : ndarray of shape (n_f, n_inputs)
        exp(−|miss|² / miss_sd²).
    bands : tuple of FrequencyBand
        Where the model misses the data.
    residual_spectrum, noise_spectrum : ndarray of shape (n_f,)
        Power spectral density of the model's error, and of the part of the output no linear
        model of the inputs can explain, (1 − γ²) S_yy (unit²/Hz).
    segment_length : int
        Welch segment length in samples.
    n_averages : float
        Effective number of averages.
    alpha : float
        Significance level (bands drawn at 1 − alpha).
    """

    model_name: str
    output_name: str
    output_unit: str
    input_names: tuple[str, ...]
    input_units: tuple[str, ...]
    frequency: np.ndarray
    data_response: np.ndarray
    data_sd: np.ndarray
    model_response: np.ndarray
    model_sd: np.ndarray
    coherence: np.ndarray
    miss: np.ndarray
    miss_sd: np.ndarray
    p_value: np.ndarray
    bands: tuple[FrequencyBand, ...]
    residual_spectrum: np.ndarray
    noise_spectrum: np.ndarray
    segment_length: int
    n_averages: float
    alpha: float = 0.01

    @property
    def level(self) -> float:
        """Confidence level of the drawn bands, 1 − alpha."""
        return 1.0 - self.alpha

    @property
    def summary(self) -> str:
        """One sentence: ``the model misses the data between 12 and 40 Hz`` (or that it matches)."""
        f = self.frequency
        if not self.bands:
            return (
                f"the model matches the data within the uncertainty from {f[0]:.2g} to {f[-1]:.3g} Hz "
                f"(slower changes, such as a drift, are not resolved by {self.segment_length}-sample segments)"
            )
        several = len(self.input_names) > 1
        widest = sorted(self.bands, key=lambda b: b.low - b.high)[:_SUMMARY_BANDS]
        parts = [b.text + (f" (from {b.input})" if several else "") for b in sorted(widest, key=lambda b: b.low)]
        rest = len(self.bands) - len(widest)
        if rest:
            parts.append(f"{rest} narrower band{'s' if rest > 1 else ''}")
        return "the model misses the data " + _and(parts)

    def __str__(self) -> str:
        return (
            f"frequency check of {self.model_name}: {self.summary}\n"
            f"  (Welch H1 estimate, {self.segment_length}-sample Hann segments, {self.n_averages:.0f} "
            f"averages, {100 * self.level:g} % level)"
        )

    def to_dict(self) -> dict:
        """JSON-ready: ``summary``, ``bands``, ``segment_length``, ``n_averages``, ``alpha`` (not the curves).

        Returns
        -------
        dict
        """
        return {
            "summary": self.summary,
            "bands": [b.to_dict() for b in self.bands],
            "frequency_range_hz": [float(self.frequency[0]), float(self.frequency[-1])],
            "segment_length": self.segment_length,
            "n_averages": float(self.n_averages),
            "alpha": self.alpha,
        }

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None

        Returns
        -------
        str
        """
        import json

        return json.dumps(self.to_dict(), indent=indent)

    def plot(self, input: int = 0) -> Any:
        """Magnitude, phase, coherence and error spectrum, the disagreeing bands shaded.

        Parameters
        ----------
        input : int
            Which input's transfer function.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.frequency import plot_frequency_check

        return plot_frequency_check(self, input)


def _and(parts: list[str]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def _h1(s_uu: np.ndarray, s_ux: np.ndarray, s_xx: np.ndarray, n_avg: float) -> tuple[np.ndarray, ...]:
    """H1 estimate of x from the inputs, its standard deviation, and the multiple coherence."""
    h = np.linalg.solve(s_uu, s_ux[..., None])[..., 0]
    coh = np.clip(np.real(np.sum(np.conj(s_ux) * h, axis=1)) / np.maximum(s_xx, 1e-300), 0.0, 1.0)
    inv_diag = np.real(np.diagonal(np.linalg.inv(s_uu), axis1=1, axis2=2))
    var = (1.0 - coh)[:, None] * s_xx[:, None] * inv_diag / n_avg
    return h, np.sqrt(np.maximum(var, 0.0)), coh


def _bands(p: np.ndarray, f: np.ndarray, alpha: float, name: str) -> list[FrequencyBand]:
    """Bands seeded at Bonferroni-significant frequencies, extended over neighbours below ``alpha``,
    and merged across gaps of at most ``_MERGE_GAP`` frequencies (a Hann window's main lobe)."""
    seed = p < alpha / len(p)
    weak = p < alpha
    spans: list[list[int]] = []
    for i in np.flatnonzero(seed):
        if spans and i <= spans[-1][1]:
            continue
        lo, hi = int(i), int(i)
        while lo > 0 and weak[lo - 1]:
            lo -= 1
        while hi + 1 < len(p) and weak[hi + 1]:
            hi += 1
        if spans and lo - spans[-1][1] <= _MERGE_GAP:
            spans[-1][1] = hi
        else:
            spans.append([lo, hi])
    out = []
    for lo, hi in spans:
        worst = lo + int(np.argmin(p[lo : hi + 1]))
        out.append(FrequencyBand(name, float(f[lo]), float(f[hi]), float(f[worst]), float(p[worst])))
    return out


def frequency_check(
    model: ArxModel,
    data: IOData,
    *,
    segment_length: int | None = None,
    alpha: float = 0.01,
) -> FrequencyCheck:
    """Compare the model's frequency response with a model-free estimate from ``data``.

    Parameters
    ----------
    model : ArxModel
        A fitted model (its linear part from each input is compared; effect terms enter through
        its free-run error).
    data : IOData
        Measured data, best the validation data.
    segment_length : int, optional
        Welch segment length in samples (default: a power of two near n/16, 32 to 4096).
    alpha : float
        Significance level of the disagreement test; the bands are drawn at 1 − alpha.

    Returns
    -------
    FrequencyCheck
        ``summary`` says in one sentence where the model misses the data; ``plot()`` draws it.

    Raises
    ------
    DataError
        When no gap-free stretch of the data is as long as one segment.
    """
    model, data = check_model(model), check_data(data)
    normal_quantile(1.0 - alpha)  # checks alpha
    with np.errstate(all="ignore"):
        e = data.y - model.predict(data, None)
    x = np.vstack([data.u.T, data.y, e])
    nseg = int(segment_length) if segment_length is not None else default_segment_length(int(np.isfinite(e).sum()))
    runs = finite_runs(np.isfinite(x).all(axis=0), data.segments, nseg)
    if not runs:
        raise DataError(
            f"the frequency check needs a gap-free stretch of at least {nseg} samples where the model's "
            "free run is finite; give longer data or a smaller segment_length"
        )
    freq, s, count = spectra(x, runs, data.ts, nseg)
    keep = freq > 0
    freq, s = freq[keep], s[keep]
    n_avg = effective_averages(count)
    m = data.n_inputs
    s_uu = s[:, :m, :m]
    h_y, sd_y, coh_y = _h1(s_uu, s[:, :m, m], np.real(s[:, m, m]), n_avg)
    miss, sd_e, coh_e = _h1(s_uu, s[:, :m, m + 1], np.real(s[:, m + 1, m + 1]), n_avg)
    g = np.empty_like(h_y)
    sd_g = np.empty(g.shape)
    for i in range(m):
        g[:, i], sd_g[:, i] = frequency_response(model, freq, i)
    miss_sd = np.sqrt(sd_e**2 + sd_g**2)
    with np.errstate(all="ignore"):
        p = np.exp(-(np.abs(miss) ** 2) / np.maximum(miss_sd**2, 1e-300))
    bands = [b for i in range(m) for b in _bands(p[:, i], freq, alpha, data.input_names[i])]
    return FrequencyCheck(
        model.structure_name(),
        data.output_name,
        data.output_unit,
        tuple(data.input_names),
        tuple(data.input_units),
        freq,
        h_y,
        sd_y,
        g,
        sd_g,
        coh_y,
        miss,
        miss_sd,
        p,
        tuple(sorted(bands, key=lambda b: b.low)),
        np.real(s[:, m + 1, m + 1]),
        (1.0 - coh_y) * np.real(s[:, m, m]),
        nseg,
        float(n_avg),
        alpha,
    )
