"""What remains when nothing explains it: the low-frequency share of a model's validation error.

When the diagnosis finds no significant effect but the residuals are not white, something the
model does not see may still drive the output: an unlogged disturbance (a gust, a load, a drift).
:func:`remaining_disturbance` says how slow it is: the share of the validation error's mean square
(at the diagnosis' horizon) below the model's slowest mode, from the error's discrete Fourier
transform, so the shares of all frequencies add up to the whole error, offset included.

A disturbance is reported (:attr:`Disturbance.found`) when the residual is not white and most of
the validation error is below that frequency: slower than anything the plant itself does. (The
one-step residual cannot tell on its own: a high-order ARX model's noise part absorbs a slow
disturbance into its one-step prediction, so only the free run shows it.) A coloured residual with
a mostly fast error left is not called a disturbance: one stray lag of the whiteness test, or a
small slow bias beside a larger fast error, is not one.

Examples
--------
>>> import numpy as np, arxid
>>> from arxid.diagnosis.disturbance import remaining_disturbance
>>> rng = np.random.default_rng(0)
>>> u = rng.standard_normal(4000)
>>> drift = np.cumsum(rng.standard_normal(4000)) * 0.02
>>> y = np.zeros(4000)
>>> for t in range(1, 4000):
...     y[t] = 0.5 * y[t - 1] + u[t - 1]
>>> data = arxid.IOData(y + drift, u, ts=0.01)
>>> m = arxid.arx(data, 1, 1, 1)
>>> d = remaining_disturbance(m, data, data.y - m.predict(data), white=False)
>>> d.found, d.low_frequency_share > 0.5
(True, True)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._base.formatting import finite_or_none
from ..data.iodata import IOData
from ..models.arx_model import ArxModel

__all__ = [
    "Disturbance",
    "remaining_disturbance",
    "slowest_mode_hz",
    "LOW_FREQUENCY_MAJORITY",
    "SLOWEST_MODE",
]

#: Share of the error below the split above which the disturbance is called low-frequency.
LOW_FREQUENCY_MAJORITY = 0.5
#: The usual split: the natural frequency of the model's slowest pole.
SLOWEST_MODE = "the model's slowest mode"


@dataclass(frozen=True)
class Disturbance:
    """The validation error a model leaves, split at its slowest mode.

    Attributes
    ----------
    low_frequency_share : float
        Share of the error's mean square below ``split_hz`` (0..1; the mean, an offset, counts as
        low-frequency).
    split_hz : float
        The split frequency in Hz.
    split_basis : str
        Where the split comes from: ``"the model's slowest mode"`` or, for a model without a finite
        mode (no poles, or only integrators), ``"a tenth of the Nyquist frequency"``.
    white : bool
        Whether the model's one-step residual passed the whiteness test (a white residual leaves
        nothing to explain, and no disturbance is reported).
    rms : float
        RMS of the error.
    """

    low_frequency_share: float
    split_hz: float
    split_basis: str
    white: bool
    rms: float

    @property
    def low_frequency(self) -> bool:
        """True when most of the error (``LOW_FREQUENCY_MAJORITY``) is below the split."""
        return self.low_frequency_share >= LOW_FREQUENCY_MAJORITY

    @property
    def found(self) -> bool:
        """True when a disturbance slower than the plant dominates what remains: the residual is not
        white and most of the validation error lies below the split (:attr:`low_frequency`)."""
        return bool(not self.white and self.low_frequency)

    @property
    def sentence(self) -> str:
        """The plain statement for a diagnosis with no significant suspect (``""`` for a white residual).

        Returns
        -------
        str
            e.g. ``"an unlogged disturbance remains: low-frequency, 87 % of the error (below 1.6 Hz,
            slower than the model's slowest mode); no logged signal and no candidate effect explains it"``.
        """
        if not self.found:
            return ""
        basis = "slower than the model's slowest mode" if self.split_basis == SLOWEST_MODE else self.split_basis
        below = f"below {self.split_hz:.3g} Hz, {basis}"
        return (
            f"an unlogged disturbance remains: low-frequency, {100 * self.low_frequency_share:.0f} % of the error "
            f"({below}); no logged signal and no candidate effect explains it"
        )

    def to_dict(self) -> dict:
        """``low_frequency_share``, ``split_hz``, ``split_basis``, ``white``, ``rms``, ``found`` and
        ``sentence``.

        Returns
        -------
        dict
            NaN becomes None.
        """
        return {
            "low_frequency_share": finite_or_none(float(self.low_frequency_share)),
            "split_hz": finite_or_none(float(self.split_hz)),
            "split_basis": self.split_basis,
            "white": bool(self.white),
            "rms": finite_or_none(float(self.rms)),
            "found": self.found,
            "sentence": self.sentence,
        }


def slowest_mode_hz(model: ArxModel, ts: float, n_samples: int) -> float:
    """Natural frequency in Hz of the model's slowest pole, |ln p| / (2π ts); NaN when it has none.

    Poles at 0 (pure delays) have no finite frequency, and a pole slower than one cycle per record
    acts as an integrator there; neither counts.

    Parameters
    ----------
    model : ArxModel
        A fitted model (its ``poles()``).
    ts : float
        Sampling time in seconds.
    n_samples : int
        Record length, for the integrator limit.

    Returns
    -------
    float
    """
    p = np.asarray(model.poles(), dtype=complex)
    p = p[np.abs(p) > 1e-12]
    if p.size == 0:
        return math.nan
    f = np.abs(np.log(p)) / (2.0 * math.pi * ts)
    f = f[f > 1.0 / (n_samples * ts)]
    return float(f.min()) if f.size else math.nan


def _periodograms(x: np.ndarray, segments, ts: float):
    """(|DFT|², frequency in Hz, bin weight) of the finite run of each experiment; a missing sample
    inside a run counts as 0. The weight is 2 for the bins strictly between 0 and Nyquist (a one-sided
    spectrum), 1 for those two."""
    for lo, hi in segments:
        e = x[lo:hi]
        ok = np.isfinite(e)
        if ok.sum() < 2:
            continue
        first, last = int(np.argmax(ok)), len(e) - int(np.argmax(ok[::-1]))
        e = np.where(ok[first:last], e[first:last], 0.0)
        weight = np.ones(len(e) // 2 + 1)
        weight[1 : (len(e) + 1) // 2] = 2.0
        yield np.abs(np.fft.rfft(e)) ** 2, np.fft.rfftfreq(len(e), ts), weight


def _low_share(error: np.ndarray, segments, ts: float, split: float) -> float:
    """Share of Σ e² in the DFT bins at or below ``split`` Hz, over the experiments (Parseval)."""
    low = total = 0.0
    for spec, f, weight in _periodograms(error, segments, ts):
        low += float(np.sum((spec * weight)[f <= split]))
        total += float(np.sum(spec * weight))
    return low / total if total > 0 else math.nan


def remaining_disturbance(model: ArxModel, validation: IOData, error: np.ndarray, white: bool) -> Disturbance:
    """The low-frequency share of a model's validation error.

    Parameters
    ----------
    model : ArxModel
        The fitted model (its poles set the split).
    validation : IOData
        The data the error was measured on.
    error : ndarray
        Measured − predicted output at the diagnosis' horizon (NaN where there is no prediction).
    white : bool
        Whether the one-step residual passed the whiteness test.

    Returns
    -------
    Disturbance
    """
    ts = float(validation.ts)
    split = slowest_mode_hz(model, ts, validation.n_samples)
    basis = SLOWEST_MODE
    if not math.isfinite(split):
        split, basis = 0.1 / (2.0 * ts), "a tenth of the Nyquist frequency"
    e = np.asarray(error, dtype=float)
    finite = e[np.isfinite(e)]
    rms = float(np.sqrt(np.mean(finite**2))) if finite.size else math.nan
    return Disturbance(_low_share(e, validation.segments, ts, split), split, basis, bool(white), rms)
