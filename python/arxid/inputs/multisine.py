"""Periodic multisines with crest-factor-minimising phases (MATLAB ``idinput(..., 'sine')``, with
Van der Ouderaa's iterative clipping for the phases instead of random ones)."""

from __future__ import annotations

import numpy as np

from ..exceptions import DataError
from .excitation import Excitation, check_periods, check_ts, crest_factor

__all__ = ["multisine", "schroeder_phases"]


def schroeder_phases(n_lines: int) -> np.ndarray:
    """Schroeder's phases ``-pi k (k - 1) / K`` for ``K`` equal-amplitude lines (k = 1..K).

    Parameters
    ----------
    n_lines : int

    Returns
    -------
    ndarray of shape (n_lines,)
        [rad].
    """
    k = np.arange(1, n_lines + 1, dtype=float)
    return -np.pi * k * (k - 1) / n_lines


def _signal(period: int, lines: np.ndarray, amplitudes: np.ndarray, phases: np.ndarray) -> np.ndarray:
    spec = np.zeros(period // 2 + 1, dtype=complex)
    spec[lines] = amplitudes * np.exp(1j * phases) * period / 2
    return np.fft.irfft(spec, period)


def _clipped_phases(period, lines, amplitudes, phases, iterations):
    """Van der Ouderaa, Schoukens & Renneboog (1988): clip the peaks, keep the phases the clipped
    signal has on the lines, restore the amplitudes; the clip level tightens while it helps."""
    best = phases
    best_cf = crest_factor(_signal(period, lines, amplitudes, phases))
    level = 0.9
    for _ in range(iterations):
        x = _signal(period, lines, amplitudes, phases)
        peak = np.max(np.abs(x))
        spec = np.fft.rfft(np.clip(x, -level * peak, level * peak))
        phases = np.angle(spec[lines])
        cf = crest_factor(_signal(period, lines, amplitudes, phases))
        if cf < best_cf - 1e-9:
            best, best_cf = phases, cf
        else:
            level = min(0.99, level + 0.5 * (1 - level))
    return best


def multisine(
    period: int,
    lines,
    *,
    amplitudes=None,
    rms: float = 1.0,
    periods: int = 1,
    ts: float = 1.0,
    iterations: int = 300,
) -> Excitation:
    """A periodic sum of sines on chosen frequency lines, phased for a low crest factor.

    Line ``k`` is the frequency ``k / (period * ts)`` Hz; a whole number of periods of every sine
    fits in one period of the signal, so there is no leakage. The phases start from Schroeder's and
    are improved by iterative clipping; the result is never worse than Schroeder's phases (for 20
    equal lines: crest factor about 1.5, against about 1.7).

    Parameters
    ----------
    period : int
        Samples in one period, >= 4.
    lines : int or sequence of int
        The excited lines, each in 1 .. period/2 - 1; an int ``K`` means lines 1..K.
    amplitudes : sequence of float, optional
        Relative amplitude of each line (default all equal).
    rms : float
        RMS value of the signal (the amplitudes are scaled to it).
    periods : int
        Number of whole periods.
    ts : float
        Sampling time [s].
    iterations : int
        Clipping iterations (0 keeps Schroeder's phases).

    Returns
    -------
    Excitation

    Raises
    ------
    DataError
        On lines outside the band, repeated lines, or a bad ``period``/``rms``/``periods``/``ts``.

    Notes
    -----
    **Spectrum.** All the power is on the chosen lines, in proportion to the squared amplitudes, and
    exactly zero on every other line of the period's DFT (up to rounding). The crest factor
    max|x| / rms(x) measures how well the signal uses an actuator's range: a lower crest factor puts
    more power into the plant for the same peak.

    Examples
    --------
    >>> from arxid.inputs import multisine
    >>> x = multisine(512, 20, ts=0.002)
    >>> x.crest_factor < 1.6
    True
    """
    if isinstance(period, bool) or not isinstance(period, (int, np.integer)) or period < 4:
        raise DataError(f"period must be a whole number of samples >= 4, got {period!r}")
    line_list = list(range(1, int(lines) + 1)) if np.ndim(lines) == 0 else [int(k) for k in lines]
    arr = np.asarray(line_list, dtype=int)
    if arr.size == 0 or arr.min() < 1 or arr.max() > (period - 1) // 2 or len(set(line_list)) != arr.size:
        raise DataError(
            f"lines must be distinct whole numbers from 1 to {(period - 1) // 2} (below Nyquist for a "
            f"period of {period} samples), got {line_list!r:.80}"
        )
    amp = np.ones(arr.size) if amplitudes is None else np.asarray(amplitudes, dtype=float)
    if amp.shape != arr.shape or not np.all(np.isfinite(amp)) or np.any(amp < 0) or not np.any(amp > 0):
        raise DataError(f"amplitudes must be {arr.size} non-negative finite values, not all zero")
    if not np.isfinite(rms) or rms <= 0:
        raise DataError(f"rms must be a positive value, got {rms!r}")
    ts, periods = check_ts(ts), check_periods(periods)
    phases = _clipped_phases(int(period), arr, amp, schroeder_phases(arr.size), int(iterations))
    one = _signal(int(period), arr, amp, phases)
    one *= rms / np.sqrt(np.mean(one**2))
    f = arr / (period * ts)
    return Excitation(
        values=np.tile(one, periods),
        ts=ts,
        kind="multisine",
        period=int(period),
        description=f"Multisine on {arr.size} line(s) from {f.min():g} Hz to {f.max():g} Hz, RMS {rms:g}.",
    )
