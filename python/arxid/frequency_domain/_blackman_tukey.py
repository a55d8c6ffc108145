"""Blackman–Tukey spectra (MATLAB's ``spa``): sample covariances up to lag M, a Hann lag window,
and their Fourier transform at chosen frequencies."""

from __future__ import annotations

import numpy as np

__all__ = ["lag_spectra", "default_lag_width", "hann_lag_window"]


def default_lag_width(n_samples: int) -> int:
    """MATLAB ``spa``'s documented default width of the lag window, M = min(30, N / 10).

    Parameters
    ----------
    n_samples : int

    Returns
    -------
    int
    """
    return int(min(30, n_samples // 10))


def hann_lag_window(width: int) -> np.ndarray:
    """W(τ) = ½ (1 + cos(π τ / M)) for τ = 0 .. M (zero at τ = M), as ``spa``.

    Parameters
    ----------
    width : int
        M.

    Returns
    -------
    ndarray of shape (M + 1,)
    """
    tau = np.arange(width + 1)
    return 0.5 * (1.0 + np.cos(np.pi * tau / width))


def _lagged_products(x: np.ndarray, width: int) -> np.ndarray:
    """``c[i, j, k]`` = Σ_t x_i(t) x_j(t + τ_k) for τ = −M .. M over one run (each signal's mean removed)."""
    x = x - x.mean(axis=1, keepdims=True)
    n = x.shape[1]
    nfft = 1 << int(np.ceil(np.log2(n + width + 1)))
    f = np.fft.rfft(x, nfft, axis=1)
    c = np.fft.irfft(np.conj(f)[:, None, :] * f[None, :, :], nfft, axis=-1)
    return np.concatenate([c[..., nfft - width :], c[..., : width + 1]], axis=-1)


def lag_spectra(
    signals: np.ndarray, runs: list[tuple[int, int]], ts: float, width: int, frequency: np.ndarray
) -> tuple[np.ndarray, float]:
    """Cross-spectral matrix by Blackman–Tukey over the gap-free ``runs``.

    Parameters
    ----------
    signals : ndarray of shape (q, n_samples)
    runs : list of (start, stop)
        Gap-free ranges; each run's mean is removed and no product crosses a run's edge.
    ts : float
        Sampling time, seconds.
    width : int
        Width M of the Hann lag window.
    frequency : ndarray of shape (n_f,)
        Hz.

    Returns
    -------
    s : ndarray of complex, shape (n_f, q, q)
        ``s[f, i, j]`` = Σ_τ W(τ) R_ij(τ) e^{−iωτ ts}, R_ij(τ) = (1/N) Σ_t x_i(t) x_j(t + τ), as a
        one-sided density (the convention of ``scipy.signal.csd``).
    n_averages : float
        N / Σ_τ W(τ)², the equivalent number of independent averages.
    """
    q = signals.shape[0]
    total = np.zeros((q, q, 2 * width + 1))
    n = 0
    for a, b in runs:
        total += _lagged_products(signals[:, a:b], width)
        n += b - a
    half = hann_lag_window(width)
    window = np.concatenate([half[:0:-1], half])
    lags = np.arange(-width, width + 1)
    kernel = np.exp(-2j * np.pi * np.outer(frequency, lags) * ts)
    s = np.einsum("fk,ijk->fij", kernel, total * window / n) * 2.0 * ts
    return s, n / float(np.sum(window**2))
