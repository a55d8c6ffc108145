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

import numpy as np

from .._base import metrics
from .._base.formatting import finite_or_none
from .._base.records import record
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


@record
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
        A fitted model (its ``discrete_poles()``).
    ts : float
        Sampling time in seconds.
    n_samples : int
        Record length, for the integrator limit.

    Returns
    -------
    float
    """
    p = np.asarray(model.discrete_poles(), dtype=complex)
    p = p[np.abs(p) > 1e-12]
    if p.size == 0:
        return math.nan
    f = np.abs(np.log(p)) / (2.0 * math.pi * ts)
    f = f[f > 1.0 / (n_samples * ts)]
    return float(f.min()) if f.size else math.nan


def _sin_pi(q: np.ndarray, n: int) -> np.ndarray:
    """sin(π q / n) for integers 0 <= q < 2n, with the argument reduced to [0, π/2] first (exact
    reduction in integers: near π the direct form loses the small result's digits)."""
    neg = q >= n
    p = np.where(neg, q - n, q)
    p = np.minimum(p, n - p)
    s = np.sin(p * (math.pi / n))
    return np.where(neg, -s, s)


def _largest_prime_factor(n: int) -> int:
    """The largest prime factor of ``n`` >= 1 (1 for 1), by trial division (√n steps at most)."""
    largest, d = 1, 2
    while d * d <= n:
        while n % d == 0:
            largest, n = d, n // d
        d += 1 if d == 2 else 2
    return max(largest, n)


def fast_length(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= ``n`` (scipy's ``next_fast_len(n, real=True)``, without importing
    scipy.fft: a fifth of a second of a short diagnosis)."""
    best = 1 << max(n - 1, 0).bit_length()  # the power of two
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            p = p35 << max(0, (n - 1) // p35).bit_length()  # the smallest p35 · 2^a >= n
            best = min(best, p)
            p35 *= 3
        p5 *= 5
    return best


#: A length-n DFT whose prime factors are all at most this is fast (numpy's pocketfft: within ~2x
#: a power of two at 2M samples); a larger factor makes it a Bluestein transform (~10x).
_FAST_PRIME = 500


def _low_power(e: np.ndarray, k: int) -> float:
    """Σ |X_j|² over the DFT bins -k <= j <= k of ``e`` (length n, 2k + 1 < n), X its length-n DFT.

    A length-n DFT is slow when n has a large prime factor (a Bluestein transform, ~10x a smooth
    length). The sum equals Σ_m r(m) D(m) over the lags -n < m < n, with r the linear
    autocorrelation of ``e`` (from one zero-padded transform of a smooth length >= 2n - 1) and D the
    Dirichlet kernel sin(π(2k+1)m/n) / sin(πm/n); exact in exact arithmetic, so the bins and the
    resolution are those of the length-n DFT. When n is a fast length the DFT is taken.
    """
    n = len(e)
    if _largest_prime_factor(n) <= _FAST_PRIME:
        spec = np.abs(np.fft.rfft(e)[: k + 1]) ** 2
        return float(spec[0] + 2.0 * np.sum(spec[1:]))
    size = fast_length(2 * n - 1)
    spec = np.fft.rfft(e, size)
    r = np.fft.irfft(spec.real**2 + spec.imag**2, size)[:n]
    del spec
    total = (2 * k + 1) * float(r[0])
    chunk = 1 << 18
    for lo in range(1, n, chunk):
        m = np.arange(lo, min(lo + chunk, n), dtype=np.int64)
        kernel = _sin_pi(((2 * k + 1) * m) % (2 * n), n) / _sin_pi(m, n)
        total += 2.0 * float(np.einsum("i,i->", r[lo : lo + len(m)], kernel))
    return total


def _finite_runs(x: np.ndarray, segments):
    """The finite run of each experiment (first to last finite sample); a missing sample inside a
    run counts as 0. Runs with fewer than 2 finite samples are skipped."""
    for lo, hi in segments:
        e = x[lo:hi]
        ok = np.isfinite(e)
        if ok.sum() < 2:
            continue
        first, last = int(np.argmax(ok)), len(e) - int(np.argmax(ok[::-1]))
        yield np.where(ok[first:last], e[first:last], 0.0)


def _low_share(error: np.ndarray, segments, ts: float, split: float) -> float:
    """Share of Σ e² in the DFT bins at or below ``split`` Hz, over the experiments (Parseval).

    The one-sided periodogram of each finite run (weight 2 strictly between 0 and Nyquist, 1 at
    both) sums to n Σ e²; its bins at or below ``split`` sum to Σ |X_j|² over |j| <= k, k the last
    such bin (all bins when that reaches Nyquist).
    """
    low = total = 0.0
    for e in _finite_runs(error, segments):
        n = len(e)
        # einsum, not dot: a multithreaded BLAS dot leaves threads spinning on the cores others need
        energy = n * float(np.einsum("i,i->", e, e))
        n_low = int(np.count_nonzero(np.fft.rfftfreq(n, ts) <= split))
        total += energy
        if n_low >= n // 2 + 1:
            low += energy
        elif n_low > 0:
            low += _low_power(e, n_low - 1)
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
    return Disturbance(_low_share(e, validation.segments, ts, split), split, basis, bool(white), metrics.rms(e))
