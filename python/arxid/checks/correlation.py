"""Correlations and prewhitening for the residual tests (:mod:`arxid.checks.residual_analysis`).

Lagged correlations inside each experiment, an AR prewhitening filter (order by AIC), and a small
memo of what depends on a logged signal and not on the model: the residual tests of several models
on the same data prewhiten each signal over the same samples, so its AR filter and its
autocorrelation are fitted once per record (keyed on the data, the signal and the samples used; a
few coefficients each, never a copy of the signal).

Examples
--------
>>> import numpy as np
>>> x = np.random.default_rng(0).standard_normal(1000)
>>> r = correlation(centered(x), centered(x), np.arange(3), [(0, 1000)])
>>> float(r[0])
1.0
"""

from __future__ import annotations

import hashlib
import math
import weakref
from collections.abc import Sequence

import numpy as np

from .._base import _core
from .._base.digital_filter import lfilter
from .._base.nested import nested_from_factor
from ..data.iodata import IOData
from ..models.lagged import ar_factor

__all__ = [
    "centered",
    "correlation",
    "zeroed_correlation",
    "ar_filter",
    "ar_innovations",
    "SignalWhitening",
    "signal_whitening",
]


def centered(x: np.ndarray) -> np.ndarray:
    """``x`` minus the mean of its finite samples (a copy; NaN stays NaN).

    Parameters
    ----------
    x : array_like of shape (n_samples,)

    Returns
    -------
    ndarray of shape (n_samples,)
    """
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    if ok.all():  # the same mean as over x[ok], without the copy
        return x - x.mean()
    if not ok.any():
        return x.copy()
    return x - x[ok].mean()  # NaN and ±inf stay what they are


#: Lags up to which a correlation is summed lag by lag rather than by FFT.
_DIRECT_LAGS = 128
#: A record longer than four times this has its consecutive lags summed by the core (:func:`_blocked`).
_CORRELATION_BLOCK = 8192


def correlation(a: np.ndarray, b: np.ndarray, lags: np.ndarray, segments: Sequence[tuple[int, int]]) -> np.ndarray:
    """corr(a(t), b(t − k)) for each lag k, over pairs inside one experiment where both exist.

    Normalised by √(Σa² Σb²) over the valid samples of each, as MATLAB ``resid`` and ``xcorr``
    with the biased estimator do.

    Parameters
    ----------
    a, b : ndarray of shape (n_samples,)
        Centred series (NaN where missing).
    lags : ndarray of int
    segments : sequence of (int, int)
        The experiments' sample ranges.

    Returns
    -------
    ndarray of shape (len(lags),)
    """
    av = np.where(np.isfinite(a), a, 0.0)
    bv = av if b is a else np.where(np.isfinite(b), b, 0.0)
    return zeroed_correlation(av, bv, lags, segments)


def zeroed_correlation(
    av: np.ndarray, bv: np.ndarray, lags: np.ndarray, segments: Sequence[tuple[int, int]]
) -> np.ndarray:
    """:func:`correlation` of series given with 0 where they are missing (no NaN), as it computes it.

    Parameters
    ----------
    av, bv : ndarray of shape (n_samples,)
        Centred series, 0 where missing.
    lags : ndarray of int
    segments : sequence of (int, int)

    Returns
    -------
    ndarray of shape (len(lags),)
    """
    saa = float(np.sum(av * av))
    den = math.sqrt(saa * (saa if bv is av else float(np.sum(bv * bv))))
    out = np.zeros(len(lags))
    if den == 0:
        return out
    lags = np.asarray(lags)
    for lo, hi in segments:
        n = hi - lo
        # Many lags of a long record: every lag at once by FFT (n log n). A few dozen lags (the
        # residual tests' usual 2 x 25 + 1) cost less as one dot product each (n per lag), without
        # the FFT's padding to twice the length; on a long record, block by block.
        if n * len(lags) > 1 << 18 and len(lags) > _DIRECT_LAGS:
            size = 1 << int(2 * n - 1).bit_length()
            c = np.fft.irfft(np.fft.rfft(av[lo:hi], size) * np.conj(np.fft.rfft(bv[lo:hi], size)), size)
            inside = np.abs(lags) < n
            out[inside] += c[lags[inside] % size]
        elif n > 4 * _CORRELATION_BLOCK and np.array_equal(lags, np.arange(lags[0], lags[0] + len(lags))):
            out += _blocked(av[lo:hi], bv[lo:hi], int(lags[0]), int(lags[-1]))
        else:
            for i, k in enumerate(lags):
                if abs(k) >= n:
                    continue
                if k >= 0:
                    out[i] += float(np.dot(av[lo + k : hi], bv[lo : hi - k]))
                else:
                    out[i] += float(np.dot(av[lo : hi + k], bv[lo - k : hi]))
    return out / den


def _blocked(a: np.ndarray, b: np.ndarray, first: int, last: int) -> np.ndarray:
    """Σ_t a(t) b(t − k) for k = first..last (consecutive), ``b`` zero beyond its ends: by the Rust
    core, each block of samples summed against every lag while it is in cache, on every core."""
    a, b = (np.ascontiguousarray(v, dtype=float) for v in (a, b))
    return np.asarray(_core.lagged_products(a, b, first, last))


def ar_filter(x: np.ndarray, segments: Sequence[tuple[int, int]], max_order: int) -> np.ndarray:
    """Coefficients a of the AR model ``x(t) = a₁ x(t−1) + … + a_p x(t−p) + e(t)`` of a centred series,
    order p by AIC (0..max_order; empty for p = 0 or too few samples).

    Lags stay inside one experiment and skip missing samples.

    Parameters
    ----------
    x : ndarray of shape (n_samples,)
    segments : sequence of (int, int)
    max_order : int

    Returns
    -------
    ndarray of shape (p,)
    """
    r, m = ar_factor(x, segments, max_order)
    if m <= 2 * max_order + 2:
        return np.zeros(0)
    best_aic, best = math.log(max(float(np.sum(r[:, -1] ** 2)) / m, 1e-300)), np.zeros(0)
    rss_all, coefs = nested_from_factor(r)  # every order from one factor
    for p in range(1, max_order + 1):
        a, rss = coefs[p], float(rss_all[p]) / m
        aic = math.log(max(rss, 1e-300)) + 2.0 * p / m
        if aic < best_aic:
            best_aic, best = aic, np.asarray(a)
    return best


def ar_innovations(x: np.ndarray, segments: Sequence[tuple[int, int]], a: np.ndarray) -> np.ndarray:
    """``x(t) − a₁ x(t−1) − … − a_p x(t−p)`` inside each experiment, NaN where the lags do not exist
    (``x`` itself when ``a`` is empty).

    Parameters
    ----------
    x : ndarray of shape (n_samples,)
        A centred series.
    segments : sequence of (int, int)
    a : ndarray of shape (p,)
        From :func:`ar_filter`.

    Returns
    -------
    ndarray of shape (n_samples,)
    """
    p = len(a)
    if p == 0:
        return x
    out = np.full(len(x), np.nan)
    fir = np.concatenate([[1.0], -np.asarray(a)])  # x(t) - a1 x(t-1) - ... - ap x(t-p)
    for lo, hi in segments:
        if hi - lo > p:
            out[lo + p : hi] = lfilter(fir, [1.0], x[lo:hi])[p:]
    return out


class SignalWhitening:
    """What the residual tests need of one logged signal on the samples where the residual exists.

    Attributes
    ----------
    filter : ndarray
        The signal's AR prewhitening coefficients (:func:`ar_filter`).
    autocorrelation : ndarray
        Its normalised autocorrelation at lags 0..L.
    """

    def __init__(self, source: np.ndarray, filter: np.ndarray, autocorrelation: np.ndarray):
        self._source = source  # the data's own array (no copy): a replaced signal is not matched
        self.filter, self.autocorrelation = filter, autocorrelation


#: Per IOData (weakly held: an entry goes with its data): (signal, samples used, order, lags) → SignalWhitening.
_MEMO: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Most signal filters kept per IOData (the oldest go first).
_MAX_SIGNALS = 64


def signal_whitening(
    data: IOData, name: str, source: np.ndarray, sc: np.ndarray, order: int, lags: np.ndarray
) -> SignalWhitening:
    """The AR filter and autocorrelation of the centred signal ``sc``, memoised per data.

    Parameters
    ----------
    data : IOData
        The data the signal belongs to.
    name : str
        The signal's name.
    source : ndarray
        The data's array of the signal (its identity is checked on a hit).
    sc : ndarray of shape (n_samples,)
        The signal on the samples used (NaN elsewhere), centred: the key holds which samples.
    order : int
        Largest AR order.
    lags : ndarray of int
        Lags 0..L of the autocorrelation.

    Returns
    -------
    SignalWhitening
    """
    used = hashlib.blake2b(np.packbits(np.isfinite(sc)).tobytes(), digest_size=16).digest()
    key = (name, used, int(order), tuple(int(k) for k in lags))
    memo = _MEMO.setdefault(data, {})
    hit = memo.get(key)
    if hit is not None and hit._source is source:
        return hit
    out = SignalWhitening(source, ar_filter(sc, data.segments, order), correlation(sc, sc, lags, data.segments))
    memo[key] = out
    while len(memo) > _MAX_SIGNALS:  # bounded: a long series of structures keeps only the latest
        memo.pop(next(iter(memo)))
    return out
