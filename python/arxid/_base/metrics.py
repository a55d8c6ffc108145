"""The one definition of every error measure and model-order criterion arxid reports.

Every module (model, sweep, validation, diagnosis, ladder, quadrotor tools, report, CLI) calls these
functions; nothing else in the package computes an RMS, a fit percent, a divergence verdict or an
information criterion.

Definitions (MATLAB's System Identification Toolbox where it has one):

* ``rms(e)`` — √(mean e²) over the finite samples of ``e`` (NaN marks a missing sample).
* ``fit_percent(y, ŷ)`` — NRMSE fit, 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖), over the samples where both exist
  (MATLAB ``compare`` / ``goodnessOfFit`` with ``'NRMSE'``); −inf when the prediction diverged.
* divergence — a prediction has diverged when any value is infinite or larger in magnitude than
  ``DIVERGENCE_FACTOR`` times the largest measured |y|. The Rust core owns the rule (its free-run
  lanes stop there) and exposes it, so the sweep and the Python layer always agree.
* ``fpe``, ``aic``, ``aicc``, ``naic``, ``bic`` — from the loss V = RSS / N of the one-step residual on N
  rows with p parameters: FPE = V (1 + p/N) / (1 − p/N); AIC = N log V + 2p + N (log 2π + 1);
  AICc = AIC + 2p (p + 1) / (N − p − 1); nAIC = log V + 2p / N; BIC = N log V + p log N + N (log 2π + 1).
* ``selstruc`` — MATLAB ``selstruc(V, c)``'s modified loss V (1 + c d / N) of a loss V (``arxstruc``:
  the one-step loss on the validation data), d parameters and N estimation rows; c = 2 is its
  ``'aic'``, c = log N its ``'mdl'``, c = 0 the plain loss.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ArxidError
from . import _core
from .probabilities import standard_normal_quantile

__all__ = [
    "normal_quantile",
    "DIVERGENCE_FACTOR",
    "divergence_limit",
    "diverged",
    "mean_square",
    "rms",
    "rms_of_groups",
    "prediction_rms",
    "fit_percent",
    "fit_percent_part",
    "fit_percent_of_parts",
    "fit_percent_from_norms",
    "rolling_rms",
    "fpe",
    "aic",
    "aicc",
    "naic",
    "bic",
    "selstruc",
]

#: A prediction beyond this many times the largest measured |y| has diverged (owned by the Rust core).
DIVERGENCE_FACTOR: float = float(_core.DIVERGENCE_FACTOR)

#: Samples of the measured output that bound the divergence limit from below (see :func:`diverged`).
_HEAD = 4096

if TYPE_CHECKING:  # numpy.typing parses its docstrings on import
    from numpy.typing import ArrayLike as _ArrayLike
_Float = float | np.ndarray


def divergence_limit(y: _ArrayLike) -> float:
    """Magnitude beyond which a prediction of the measured output ``y`` counts as diverged."""
    return float(_core.divergence_limit(np.ascontiguousarray(y, dtype=float)))


def diverged(y: _ArrayLike, pred: _ArrayLike) -> bool:
    """True when ``pred`` reaches inf or leaves ±:func:`divergence_limit` of ``y`` (NaN is missing data)."""
    p = _flat(pred)
    if not p.size:
        return False
    top = _core.peak_magnitude(p)  # the largest |pred| over the samples that have one (±inf wins)
    if math.isnan(top):  # no sample has a prediction
        return False
    # A few of y's samples bound the limit from below: a pass over all of y only when pred nears it.
    head = finite_peak(np.asarray(y, dtype=float).reshape(-1)[:_HEAD])
    if top <= DIVERGENCE_FACTOR * max(head, sys.float_info.min):
        return False
    return math.isinf(top) or top > divergence_limit(y)


def mean_square(e: _ArrayLike) -> float:
    """Mean of e² over the finite samples (NaN when there are none)."""
    total, n = _core.finite_squares(_flat(e))  # one pass: no mask, copy or array of squares
    return total / n if n else math.nan


def _flat(x: _ArrayLike) -> np.ndarray:
    """``x`` as one contiguous, aligned row of floats for the core (a view when it already is one)."""
    return np.require(np.asarray(x, dtype=float).reshape(-1), requirements=["C", "A"])


def rms(e: _ArrayLike) -> float:
    """Root mean square of ``e`` over its finite samples (NaN when there are none)."""
    return math.sqrt(mean_square(e))


def rms_of_groups(e: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """:func:`rms` of each group of consecutive samples of a finite ``e`` (``counts[i]`` samples in
    group i; NaN for an empty group), from one array of squares.

    Parameters
    ----------
    e : ndarray of shape (n,)
        Finite samples, group by group.
    counts : ndarray of int of shape (n_groups,)
        Samples per group, summing to n.

    Returns
    -------
    ndarray of shape (n_groups,)

    Examples
    --------
    >>> rms_of_groups(np.array([3.0, 4.0, 1.0]), np.array([2, 0, 1])).tolist()
    [3.5355339059327378, nan, 1.0]
    """
    squares = e * e
    ends = np.cumsum(counts)
    return np.array(
        [math.sqrt(float(np.mean(squares[b - c : b]))) if c else math.nan for b, c in zip(ends, counts, strict=True)]
    )


def prediction_rms(y: _ArrayLike, pred: _ArrayLike) -> float:
    """RMS of ``y − pred`` where both exist; ``inf`` when the prediction diverged."""
    if diverged(y, pred):
        return math.inf
    yf, pf = _flat(y), _flat(pred)
    if yf.shape != pf.shape:  # broadcasting, as numpy's difference would
        with np.errstate(invalid="ignore", over="ignore"):
            return rms(np.asarray(y, dtype=float) - np.asarray(pred, dtype=float))
    total, n = _core.finite_squares_of_difference(yf, pf)  # one pass, no array of differences
    return math.sqrt(total / n) if n else math.nan


def fit_percent_from_norms(error_norm: _Float, centred_norm: _Float) -> _Float:
    """100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) from the two norms (element-wise for arrays; NaN when ‖y − ȳ‖ = 0)."""
    with np.errstate(all="ignore"):
        d = np.asarray(centred_norm, dtype=float)
        out = np.where(d > 0, 100.0 * (1.0 - np.asarray(error_norm, dtype=float) / np.where(d > 0, d, 1.0)), np.nan)
    return float(out) if out.ndim == 0 else out


def fit_percent(y: _ArrayLike, pred: _ArrayLike) -> float:
    """NRMSE fit in percent over the samples where ``y`` and ``pred`` both exist.

    ``-inf`` when the prediction diverged, NaN when no sample has both or ``y`` is constant there.
    """
    return fit_percent_of_parts([fit_percent_part(y, pred)])


def fit_percent_part(y: _ArrayLike, pred: _ArrayLike) -> np.ndarray:
    """What one part of the data (one worker's logs) contributes to :func:`fit_percent`.

    Parameters
    ----------
    y, pred : array_like of shape (n_samples,)
        Measured output and its prediction.

    Returns
    -------
    ndarray of shape (8,)
        Samples with both, largest finite |y|, largest finite |pred|, whether pred is infinite
        somewhere, largest |y| where both exist, and the scaled squared error, mean and squared
        deviation from the mean there (combine parts with :func:`fit_percent_of_parts`).
    """
    yf, pf = _flat(y), _flat(pred)
    if yf.shape != pf.shape:  # broadcasting, as numpy's difference would
        yb, pb = np.broadcast_arrays(np.asarray(y, dtype=float), np.asarray(pred, dtype=float))
        yf, pf = _flat(yb), _flat(pb)
    # One pass finds the samples where both exist, the peaks and the sum of y there; a second the
    # two sums of squares (the Rust core: no mask, no copy of the samples used).
    n, peak_y, peak_pred, infinite, big, total = _core.fit_pass(yf, pf)
    head = [n, peak_y, peak_pred, infinite]
    if n == 0:
        return np.array(head + [0.0, 0.0, 0.0, 0.0], dtype=float)
    mean = total / n
    # The ratio of norms does not depend on the unit: scaled to max |y| = 1, outputs near 1e154
    # or 1e-200 neither overflow nor underflow the sums of squares.
    sse, spread = _core.fit_squares(yf, pf, mean, _unit_scale(big))
    return np.array(head + [big, sse, mean, spread], dtype=float)


def finite_peak(x: _ArrayLike) -> float:
    """Largest |x| over the finite samples of ``x`` (0 when there are none), in one pass."""
    return _core.finite_peak(_flat(x))


def _unit_scale(big: float) -> float:
    return 1.0 / big if big > 0 and math.isfinite(1.0 / big) else 1.0


def fit_percent_of_parts(parts: Sequence[np.ndarray]) -> float:
    """:func:`fit_percent` over all the samples of several parts (:func:`fit_percent_part`).

    Parameters
    ----------
    parts : sequence of ndarray of shape (8,)

    Returns
    -------
    float
        The fit of the parts' samples taken together; for one part, :func:`fit_percent` of it.
    """
    a = np.asarray(parts, dtype=float).reshape(-1, 8)
    n, peak_y, peak_pred, infinite, big, sse, mean, m2 = a.T
    if infinite.any() or peak_pred.max() > divergence_limit(np.array([peak_y.max()])):
        return -math.inf
    if n.sum() == 0:
        return math.nan
    # Each part was scaled by its own largest |y|; bring them to the largest of all.
    ratio = np.array([_unit_scale(big.max()) / _unit_scale(b) for b in big]) ** 2
    with np.errstate(over="ignore", invalid="ignore"):
        total_sse = float(np.dot(sse, ratio))
        total_m2 = float(pooled_moments(np.column_stack([n, mean * _unit_scale(big.max()), m2 * ratio]))[2])
    return float(fit_percent_from_norms(math.sqrt(total_sse), math.sqrt(total_m2)))


def pooled_moments(parts: _ArrayLike) -> np.ndarray:
    """Count, mean and squared deviation from the mean of several parts' samples taken together.

    Parameters
    ----------
    parts : array_like of shape (k, ..., 3)
        ``(n, mean, m2)`` of each of ``k`` parts (:func:`centred_moments`), for one quantity or for
        many side by side.

    Returns
    -------
    ndarray of shape (..., 3)
        ``(n, mean, m2)`` of all the samples, by Chan's pooling (each part's mean differs from the
        whole's, which adds ``n_i (mean_i - mean)²``); parts without samples are ignored, and a
        quantity without any sample is ``(0, nan, nan)``.
    """
    a = np.asarray(parts, dtype=float)
    n_i = a[..., 0]
    used = n_i > 0
    n = n_i.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(used, n_i * a[..., 1], 0.0).sum(axis=0) / n
        spread = np.where(used, a[..., 2] + n_i * (a[..., 1] - mean) ** 2, 0.0).sum(axis=0)
    return np.stack([n, mean, np.where(n > 0, spread, np.nan)], axis=-1)


def scored_moments(y: np.ndarray, segments: Sequence[tuple[int, int]], lag: int) -> tuple[int, float, float]:
    """:func:`centred_moments` of the output samples a sweep scores: from ``lag`` into each experiment.

    Parameters
    ----------
    y : ndarray
        The measured output.
    segments : sequence of (start, stop)
        The experiments (:attr:`arxid.IOData.segments`).
    lag : int
        The sweep's first lag.

    Returns
    -------
    tuple
        ``(n, mean, m2)``; parts of a fleet combine with :func:`pooled_moments`.
    """
    return centred_moments([y[a + lag : b] for a, b in segments if b > a + lag])


def centred_moments(parts: Sequence[np.ndarray]) -> tuple[int, float, float]:
    """Count, mean and squared deviation from the mean (``‖y − ȳ‖²``) of the finite samples of
    ``parts`` taken together.

    Parameters
    ----------
    parts : sequence of ndarray
        Pieces of a signal (views; they are not copied when every sample is finite).

    Returns
    -------
    tuple
        ``(n, mean, m2)``; ``(0, nan, nan)`` without a finite sample.
    """
    if parts and all(np.isfinite(p).all() for p in parts):
        # Σy² − nȳ² on views (no copy of the data), unless cancellation would cost accuracy.
        n = sum(len(p) for p in parts)
        total = sum(float(p.sum()) for p in parts)
        # einsum, not dot: a multithreaded BLAS call here leaves its threads spinning on the cores
        # the next sweep's Rust threads need.
        sq = sum(float(np.einsum("i,i->", p, p)) for p in parts)
        centred = sq - total * total / n if n else 0.0
        if n and centred > 1e-6 * sq:
            return n, total / n, centred
    y = np.concatenate(parts) if parts else np.zeros(0)
    y = y[np.isfinite(y)]
    if not y.size:
        return 0, math.nan, math.nan
    mean = float(y.mean())
    return int(y.size), mean, float(np.dot(y - mean, y - mean))


def rolling_rms(e: _ArrayLike, window: int) -> np.ndarray:
    """Centred rolling RMS of ``e`` over ``window`` samples, ignoring NaN; NaN where fewer than half
    the window's samples exist."""
    x = np.asarray(e, dtype=float)
    ok = np.isfinite(x)
    w = max(int(window), 1)
    n = len(x)
    if w > n:  # the window outgrows the record: numpy's "same" convolution (short, rare)
        ker = np.ones(w)
        s = np.convolve(np.where(ok, x * x, 0.0), ker, mode="same")
        c = np.convolve(ok.astype(float), ker, mode="same")
    else:  # sums over [i - w//2, i + (w-1)//2] by cumulative sums: linear in n
        cs = np.concatenate([[0.0], np.cumsum(np.where(ok, x * x, 0.0))])
        cc = np.concatenate([[0], np.cumsum(ok)])
        s, c = np.empty(n), np.empty(n)
        back, ahead = w // 2, (w - 1) // 2 + 1
        a, b = back, max(back, n - ahead + 1)  # the windows inside the record: slices
        s[a:b] = cs[a + ahead : b + ahead] - cs[a - back : b - back]
        c[a:b] = cc[a + ahead : b + ahead] - cc[a - back : b - back]
        for part in (np.arange(0, min(a, n)), np.arange(b, n)):  # the windows cut by an end
            lo, hi = np.clip(part - back, 0, n), np.clip(part + ahead, 0, n)
            s[part], c[part] = cs[hi] - cs[lo], cc[hi] - cc[lo]
        np.maximum(s, 0.0, out=s)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.sqrt(s / c)
    out[c < max(1, w // 2)] = np.nan
    return out


def _loss(rss: _Float, n: int) -> np.ndarray:
    return np.asarray(rss, dtype=float) / n


def _scalar(x: np.ndarray) -> _Float:
    return float(x) if np.ndim(x) == 0 else x


def fpe(rss: _Float, n: int, p: _Float) -> _Float:
    """Akaike's final prediction error V (N + p) / (N − p) (MATLAB ``fpe``); inf when p ≥ N."""
    with np.errstate(all="ignore"):
        p = np.asarray(p, dtype=float)
        return _scalar(np.where(p < n, _loss(rss, n) * (n + p) / (n - p), np.inf))


def _log_loss(rss: _Float, n: int) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.log(_loss(rss, n))


def aic(rss: _Float, n: int, p: _Float) -> _Float:
    """AIC as MATLAB's ``aic`` computes it: N log V + 2p + N (log 2π + 1) (−inf for a perfect fit)."""
    p = np.asarray(p, dtype=float)
    return _scalar(n * _log_loss(rss, n) + 2 * p + n * (math.log(2 * math.pi) + 1))


def aicc(rss: _Float, n: int, p: _Float) -> _Float:
    """Small-sample corrected AIC (MATLAB ``aic(..., 'AICc')``): AIC + 2p (p + 1) / (N − p − 1)."""
    p = np.asarray(p, dtype=float)
    with np.errstate(all="ignore"):
        corr = np.where(n - p - 1 > 0, 2 * p * (p + 1) / (n - p - 1), np.inf)
    return _scalar(np.asarray(aic(rss, n, p)) + corr)


def naic(rss: _Float, n: int, p: _Float) -> _Float:
    """Normalised AIC (MATLAB ``aic(..., 'nAIC')``): log V + 2p / N."""
    p = np.asarray(p, dtype=float)
    return _scalar(_log_loss(rss, n) + 2 * p / n)


def bic(rss: _Float, n: int, p: _Float) -> _Float:
    """BIC as MATLAB's ``aic(..., 'BIC')``: N log V + p log N + N (log 2π + 1)."""
    p = np.asarray(p, dtype=float)
    return _scalar(n * _log_loss(rss, n) + p * math.log(n) + n * (math.log(2 * math.pi) + 1))


def selstruc(loss: _Float, n: int, p: _Float, c: float) -> _Float:
    """MATLAB ``selstruc``'s criterion V (1 + c p / N): c = 2 is ``'aic'``, c = log N ``'mdl'``."""
    p = np.asarray(p, dtype=float)
    return _scalar(np.asarray(loss, dtype=float) * (1 + c * p / n))


def parameter_covariance(inv_gram: np.ndarray, rss: float, n_rows: int) -> np.ndarray:
    """Covariance of least-squares parameters, rss · (ΦᵀΦ)⁻¹ / (N − p).

    The same as the noise variance times (ΦᵀΦ)⁻¹, in an order that stays in range for outputs near
    the limits of floating point (beyond them an entry is inf or NaN).

    Parameters
    ----------
    inv_gram : ndarray of shape (p, p)
        (ΦᵀΦ)⁻¹.
    rss : float
        Residual sum of squares.
    n_rows : int
        Regression rows N.

    Returns
    -------
    ndarray of shape (p, p)
    """
    inv_gram = np.asarray(inv_gram, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        return (inv_gram * rss) / max(n_rows - inv_gram.shape[0], 1)


def normal_quantile(level: float) -> float:
    """Two-sided point of the standard normal distribution: 2.576 for ``level`` 0.99.

    Parameters
    ----------
    level : float
        Confidence level in (0, 1).

    Returns
    -------
    float
    """
    if not 0.0 < level < 1.0:
        raise ArxidError(f"level must be a confidence level between 0 and 1, e.g. 0.99, got {level!r}")
    return standard_normal_quantile(0.5 + level / 2.0)
