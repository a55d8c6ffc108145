"""Welch cross-spectral matrices over the gap-free runs of the data (the H1 estimate's spectra).

:func:`spectra` averages Hann-windowed, 50 %-overlapping segments laid out in each gap-free run of
each experiment (:func:`finite_runs`), so no segment holds a NaN or crosses an experiment's start;
on one run it equals ``scipy.signal.csd`` with ``noverlap = nperseg // 2``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "spectra",
    "hann_window",
    "finite_runs",
    "default_segment_length",
    "HANN_OVERLAP_CORRELATION",
    "effective_averages",
]

# Welch (1967): for a Hann window with 50 % overlap, neighbouring segments' spectra correlate with
# c = 0.167, so K averages have the variance of K / (1 + 2 c²) independent ones.
HANN_OVERLAP_CORRELATION = 0.167


def effective_averages(n_segments: int) -> float:
    """Independent averages equivalent to ``n_segments`` 50 %-overlapping Hann segments (Welch 1967).

    Parameters
    ----------
    n_segments : int

    Returns
    -------
    float
    """
    return n_segments / (1.0 + 2.0 * HANN_OVERLAP_CORRELATION**2)


def finite_runs(mask: np.ndarray, segments: list[tuple[int, int]], length: int) -> list[tuple[int, int]]:
    """Half-open ranges of at least ``length`` samples, inside one experiment, where ``mask`` holds."""
    out = []
    for a, b in segments:
        m = np.concatenate([[False], mask[a:b], [False]])
        edges = np.flatnonzero(np.diff(m.astype(np.int8)))
        out += [(a + s, a + e) for s, e in zip(edges[::2], edges[1::2]) if e - s >= length]
    return out


#: Welch segments whose spectra are computed together (bounds the memory of a long record's spectra).
_CHUNK = 64


def spectra(signals: np.ndarray, runs: list[tuple[int, int]], ts: float, segment_length: int):
    """Welch cross-spectral matrix of ``signals`` over ``runs``, averaged by segment count.

    Parameters
    ----------
    signals : ndarray of shape (q, n_samples)
    runs : list of (start, stop)
        Gap-free ranges, each at least ``segment_length`` long.
    ts : float
        Sampling time [s].
    segment_length : int
        Samples per Hann segment (50 % overlap, mean removed per segment).

    Returns
    -------
    frequency : ndarray of shape (n_f,)
        Hz.
    s : ndarray of complex, shape (n_f, q, q)
        ``s[f, i, j]`` = E[conj(X_i) X_j] (``scipy.signal.csd(x_i, x_j)``), one-sided density.
    n_segments : int
        Segments averaged.
    """
    if segment_length % 2:
        return _spectra_by_csd(signals, runs, ts, segment_length)
    q = signals.shape[0]
    step = segment_length // 2
    window = hann_window(segment_length)
    n_f = segment_length // 2 + 1
    total = np.zeros((q, q, n_f), dtype=complex)
    count = 0
    for a, b in runs:
        k = 1 + (b - a - segment_length) // step
        # Each signal's segments are transformed once and every cross-spectrum formed from those
        # transforms (as scipy.signal.csd with a Hann window, 50 % overlap and each segment's mean
        # removed), in chunks of at most _CHUNK segments: the transforms of a long record at once
        # would hold several copies of it.
        for first in range(0, k, _CHUNK):
            kc = min(_CHUNK, k - first)
            lo = a + first * step
            frames = np.lib.stride_tricks.sliding_window_view(
                signals[:, lo : lo + (kc - 1) * step + segment_length], segment_length, axis=-1
            )[:, ::step]
            frames = frames - frames.mean(axis=-1, keepdims=True)
            x = np.fft.rfft(frames * window, axis=-1)
            for i in range(q):
                for j in range(i, q):
                    total[i, j] += np.sum(np.conj(x[i]) * x[j], axis=0)
        count += k
    for i in range(q):
        for j in range(i):
            total[i, j] = np.conj(total[j, i])
    # One-sided density: every bin but 0 and Nyquist doubled, scaled by fs Σ w².
    total /= (1.0 / ts) * float(np.sum(window**2)) * count
    total[..., 1 : n_f - 1] *= 2.0
    freq = np.fft.rfftfreq(segment_length, ts)
    return freq, np.moveaxis(total, -1, 0), count


def hann_window(n: int) -> np.ndarray:
    """``scipy.signal.get_window("hann", n)``, the periodic Hann window of ``n`` samples, computed as
    scipy does (0.5 + 0.5 cos over ``n + 1`` points from -π to π, the last dropped) without importing
    scipy.signal, which would take most of a short analysis's time."""
    if n <= 1:
        return np.ones(n)
    fac = np.linspace(-np.pi, np.pi, n + 1)
    w = np.zeros(n + 1)
    w += 0.5 * np.cos(0 * fac)
    w += 0.5 * np.cos(fac)
    return w[:n]


def _spectra_by_csd(signals: np.ndarray, runs: list[tuple[int, int]], ts: float, segment_length: int):
    """:func:`spectra` from ``scipy.signal.csd`` per chunk of segments (an odd segment length, whose
    segments advance by more than half a segment)."""
    from scipy.signal import csd

    total, count, freq = None, 0, None
    step = segment_length // 2
    for a, b in runs:
        k = 1 + (b - a - segment_length) // step
        for first in range(0, k, _CHUNK):
            kc = min(_CHUNK, k - first)
            lo = a + first * step
            x = signals[:, lo : lo + (kc - 1) * step + segment_length]
            freq, s = csd(x[:, None, :], x[None, :, :], fs=1.0 / ts, nperseg=segment_length, noverlap=step, axis=-1)
            total = s * kc if total is None else total + s * kc
        count += k
    assert total is not None and freq is not None
    return freq, np.moveaxis(total / count, -1, 0), count


def default_segment_length(n: int) -> int:
    """A power of two near n/16 (about 30 averages), between 32 and 4096 samples."""
    return int(2 ** np.clip(round(math.log2(max(n, 2) / 16)), 5, 12))
