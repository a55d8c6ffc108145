"""Frequency sweeps (chirps), linear or logarithmic."""

from __future__ import annotations

import numpy as np

from ..exceptions import DataError
from .excitation import Excitation, check_ts

__all__ = ["chirp"]


def chirp(
    n_samples: int,
    f0: float,
    f1: float,
    *,
    ts: float,
    method: str = "linear",
    amplitude: float = 1.0,
) -> Excitation:
    """A sine whose frequency sweeps from ``f0`` to ``f1`` Hz over the signal.

    Parameters
    ----------
    n_samples : int
        Length, >= 2.
    f0, f1 : float
        Start and end frequencies [Hz], > 0 and below Nyquist ``0.5 / ts``.
    ts : float
        Sampling time [s].
    method : {"linear", "log"}
        Linear: the frequency grows at a constant rate, ``f(t) = f0 + (f1 - f0) t / T``. Log: it
        grows by a constant factor per second, ``f(t) = f0 (f1 / f0)^(t / T)``, so every decade
        gets the same time.
    amplitude : float
        Peak value.

    Returns
    -------
    Excitation

    Raises
    ------
    DataError
        On frequencies outside (0, Nyquist), an unknown method or a bad length.

    Notes
    -----
    **Spectrum.** The power spreads over the swept band ``[f0, f1]``: evenly per hertz for a linear
    chirp, evenly per decade (falling as 1/f per hertz) for a log chirp. The phase is
    ``2π(f0 t + (f1 − f0) t² / 2T)`` (linear) or ``2π f0 T (r^(t/T) − 1) / ln r`` with
    ``r = f1/f0`` (log), ``T`` the duration.

    Examples
    --------
    >>> from arxid.inputs import chirp
    >>> x = chirp(1000, 1.0, 50.0, ts=0.002, method="log")
    >>> round(x.crest_factor, 1)
    1.4
    """
    ts = check_ts(ts)
    if isinstance(n_samples, bool) or not isinstance(n_samples, (int, np.integer)) or n_samples < 2:
        raise DataError(f"n_samples must be a whole number >= 2, got {n_samples!r}")
    nyquist = 0.5 / ts
    if not (0 < f0 < nyquist and 0 < f1 < nyquist):
        raise DataError(f"f0 and f1 must lie between 0 and the Nyquist frequency {nyquist:g} Hz, got {f0!r}, {f1!r}")
    t = np.arange(n_samples) * ts
    duration = n_samples * ts
    if method == "linear":
        phase: np.ndarray = 2 * np.pi * (f0 * t + (f1 - f0) * t**2 / (2 * duration))
    elif method == "log":
        if f0 == f1:
            phase = 2 * np.pi * f0 * t
        else:
            r = f1 / f0
            phase = 2 * np.pi * f0 * duration * (r ** (t / duration) - 1) / np.log(r)
    else:
        raise DataError(f"method must be 'linear' or 'log', got {method!r}")
    return Excitation(
        values=float(amplitude) * np.sin(phase),
        ts=ts,
        kind="chirp",
        period=int(n_samples),
        description=f"{method.capitalize()} chirp from {f0:g} Hz to {f1:g} Hz, peak {amplitude:g}.",
    )
