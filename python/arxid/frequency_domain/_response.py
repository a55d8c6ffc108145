"""The result of :func:`arxid.frf`: :class:`FrequencyResponse`, a measured frequency response with
its coherence and confidence band."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._base.formatting import json_safe, require_pandas
from ..data.iodata import IOData

__all__ = ["FrequencyResponse"]

#: Coherence above which an estimate is called reliable in the summary (and in the tests' criterion).
GOOD_COHERENCE = 0.9


@dataclass(frozen=True, eq=False)
class FrequencyResponse:
    """A frequency response estimated from data, without a model (MATLAB's ``idfrd`` from ``spa``).

    Built by :func:`arxid.frf`; not constructed directly.

    Attributes
    ----------
    frequency : ndarray of shape (n_f,)
        Frequencies in Hz (above 0, up to the Nyquist frequency).
    response : ndarray of complex, shape (n_f, n_inputs)
        The estimate Ĥ(f) from each input to the output (output units per input unit).
    coherence : ndarray of shape (n_f,)
        γ² in [0, 1]: the share of the output's power the estimate explains (open loop: the
        (multiple) coherence of the inputs and the output; with a reference, see :func:`arxid.frf`).
    variance : ndarray of shape (n_f, n_inputs)
        E|Ĥ − H|², the estimate's random error (Bendat & Piersol).
    confidence : float
        Probability that the band (:attr:`magnitude_band_db`, :attr:`phase_band_deg`) holds the true
        response at each frequency.
    method : str
        ``"welch"`` or ``"blackman-tukey"``.
    resolution : int
        Welch: the segment length in samples; Blackman–Tukey: the lag window's width M.
    n_averages : float
        Effective number of independent averages behind each estimate.
    reference : tuple of str
        Reference signal(s) of a closed-loop estimate (empty in open loop).
    output_name, output_unit : str
    input_names, input_units : tuple of str
    ts : float
        Sampling time of the data, seconds.
    data : IOData
        The data the estimate came from (for :func:`arxid.tf_from_frequency`).
    """

    frequency: np.ndarray
    response: np.ndarray
    coherence: np.ndarray
    variance: np.ndarray
    confidence: float
    method: str
    resolution: int
    n_averages: float
    reference: tuple[str, ...]
    output_name: str
    output_unit: str
    input_names: tuple[str, ...]
    input_units: tuple[str, ...]
    ts: float
    data: IOData = field(repr=False)

    # ------------------------------------------------------------------ derived curves
    @property
    def magnitude_db(self) -> np.ndarray:
        """20·log10|Ĥ|, shape (n_f, n_inputs)."""
        with np.errstate(divide="ignore"):
            return 20.0 * np.log10(np.abs(self.response))

    @property
    def phase_deg(self) -> np.ndarray:
        """Phase of Ĥ in degrees, wrapped to (−180, 180] (unwrapping a noisy estimate adds turns)."""
        return np.degrees(np.angle(self.response))

    @property
    def relative_error(self) -> np.ndarray:
        """Normalised random error of |Ĥ| (Bendat & Piersol): √((1 − γ²) / (2 n γ²)) for one input.

        Also the standard deviation of the phase in radians. Shape (n_f, n_inputs).
        """
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.sqrt(self.variance / 2.0) / np.abs(self.response)

    @property
    def band_radius(self) -> np.ndarray:
        """Radius r of the confidence disc around Ĥ: the error is complex normal with E|δ|² =
        ``variance``, so P(|δ| > r) = exp(−r² / variance) = 1 − ``confidence``."""
        return np.sqrt(-math.log(1.0 - self.confidence) * self.variance)

    @property
    def magnitude_band_db(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper edge of the gain band in dB, 20·log10(|Ĥ| ∓ r) (−inf where r ≥ |Ĥ|)."""
        mag, r = np.abs(self.response), self.band_radius
        with np.errstate(divide="ignore"):
            return 20.0 * np.log10(np.maximum(mag - r, 0.0)), 20.0 * np.log10(mag + r)

    @property
    def phase_band_deg(self) -> np.ndarray:
        """Half-width of the phase band in degrees, arcsin(r / |Ĥ|) (180 where r ≥ |Ĥ|)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = self.band_radius / np.abs(self.response)
        return np.where(ratio < 1.0, np.degrees(np.arcsin(np.minimum(ratio, 1.0))), 180.0)

    @property
    def n_inputs(self) -> int:
        """Number of inputs (columns of :attr:`response`)."""
        return int(self.response.shape[1])

    # ------------------------------------------------------------------ text
    @property
    def method_text(self) -> str:
        """How it was estimated, in words."""
        if self.method == "welch":
            how = f"Welch H1, {self.resolution}-sample Hann segments, 50 % overlap"
        else:
            how = f"Blackman–Tukey, Hann lag window of width {self.resolution}"
        if self.reference:
            how += f", closed loop through the reference {', '.join(self.reference)}"
        return f"{how}, {self.n_averages:.0f} averages"

    @property
    def summary(self) -> str:
        """Where the estimate is reliable: ``coherence above 0.9 from 0.2 to 40 Hz``."""
        good = self.frequency[self.coherence > GOOD_COHERENCE]
        if good.size == 0:
            return f"coherence below {GOOD_COHERENCE} everywhere: excite the input more or average longer"
        share = good.size / self.frequency.size
        return (
            f"coherence above {GOOD_COHERENCE} from {good[0]:.3g} to {good[-1]:.3g} Hz "
            f"({100 * share:.0f} % of the frequencies)"
        )

    def _input_line(self, i: int) -> str:
        mag, good = self.magnitude_db[:, i], self.coherence > GOOD_COHERENCE
        k = int(np.nanargmax(np.where(good, mag, -np.inf))) if good.any() else int(np.nanargmax(mag))
        lo, hi = self.magnitude_band_db
        width = np.nanmedian((hi[:, i] - lo[:, i])[good]) / 2 if good.any() else math.nan
        out, inp = self.output_unit, self.input_units[i]
        unit = f" [{out}/{inp}]" if out and inp else f" [{out} per input unit]" if out else ""
        return (
            f"  from {self.input_names[i]}{unit}: {mag[0]:.3g} dB at {self.frequency[0]:.3g} Hz, "
            f"peak {mag[k]:.3g} dB at {self.frequency[k]:.3g} Hz; band ±{width:.2g} dB "
            f"({100 * self.confidence:g} %, median where coherent)"
        )

    def __str__(self) -> str:
        lines = [
            f"frequency response of {self.output_name} ({self.method_text})",
            f"  {self.frequency[0]:.3g} to {self.frequency[-1]:.3g} Hz, {self.frequency.size} frequencies; "
            + self.summary,
        ]
        return "\n".join(lines + [self._input_line(i) for i in range(self.n_inputs)])

    # ------------------------------------------------------------------ export
    def to_dict(self) -> dict:
        """JSON-ready: the settings and, per input, the curves (NaN and ±inf become None).

        Returns
        -------
        dict
            ``method``, ``resolution``, ``n_averages``, ``confidence``, ``reference``, ``output``,
            ``summary``, ``frequency_hz``, ``coherence`` and ``inputs``: for each input name,
            ``magnitude_db``, ``phase_deg``, ``magnitude_low_db``, ``magnitude_high_db``,
            ``phase_halfwidth_deg``, ``relative_error``.
        """
        lo, hi = self.magnitude_band_db
        per_input = {
            name: {
                "magnitude_db": self.magnitude_db[:, i],
                "phase_deg": self.phase_deg[:, i],
                "magnitude_low_db": lo[:, i],
                "magnitude_high_db": hi[:, i],
                "phase_halfwidth_deg": self.phase_band_deg[:, i],
                "relative_error": self.relative_error[:, i],
            }
            for i, name in enumerate(self.input_names)
        }
        out = {
            "method": self.method,
            "resolution": self.resolution,
            "n_averages": self.n_averages,
            "confidence": self.confidence,
            "reference": list(self.reference),
            "output": self.output_name,
            "summary": self.summary,
            "frequency_hz": self.frequency,
            "coherence": self.coherence,
            "inputs": per_input,
        }
        return json_safe(out)

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    def plot(self, model: Any = None, input: int = 0) -> Any:
        """Bode figure (:func:`arxid.plots.plot_bode`): the estimate with its band and coherence, and
        a fitted model's response, the frequencies where it leaves the band shaded red.

        Parameters
        ----------
        model : fitted arxid model, optional
            ``arx``, ``oe``, ``tfest``, :func:`arxid.tf_from_frequency`, ...
        input : int
            Which input.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.bode import plot_bode
        from ._model_response import model_response

        g = None if model is None else model_response(model, self.frequency, input)
        name = "model" if model is None else model.structure_name()
        return plot_bode(self, g, input=input, model_name=name)

    def to_pandas(self) -> Any:
        """One row per frequency: ``coherence``, and per input ``magnitude_db``, ``phase_deg`` and
        the band (columns suffixed ``[input]`` when there are several inputs).

        Returns
        -------
        pandas.DataFrame
            Indexed by ``frequency_hz``.
        """
        pd = require_pandas()
        lo, hi = self.magnitude_band_db
        cols: dict[str, np.ndarray] = {"coherence": self.coherence}
        for i, name in enumerate(self.input_names):
            tag = f"[{name}]" if self.n_inputs > 1 else ""
            cols[f"magnitude_db{tag}"] = self.magnitude_db[:, i]
            cols[f"phase_deg{tag}"] = self.phase_deg[:, i]
            cols[f"magnitude_low_db{tag}"] = lo[:, i]
            cols[f"magnitude_high_db{tag}"] = hi[:, i]
            cols[f"phase_halfwidth_deg{tag}"] = self.phase_band_deg[:, i]
        return pd.DataFrame(cols, index=pd.Index(self.frequency, name="frequency_hz"))
