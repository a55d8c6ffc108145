"""Maximum-length pseudo-random binary sequences (MATLAB ``idinput(..., 'prbs', band, levels)``)."""

from __future__ import annotations

import numpy as np

from ..exceptions import DataError
from .excitation import Excitation, check_periods, check_ts

__all__ = ["prbs"]

# Feedback taps of a maximum-length linear feedback shift register of each order: the recurrence
# s[t] = XOR of s[t - k] over the taps k has period 2**order - 1 (its characteristic polynomial is
# primitive). Verified in tests/test_inputs.py up to order 18 by counting the period.
_TAPS: dict[int, tuple[int, ...]] = {
    2: (2, 1),
    3: (3, 2),
    4: (4, 3),
    5: (5, 3),
    6: (6, 5),
    7: (7, 6),
    8: (8, 6, 5, 4),
    9: (9, 5),
    10: (10, 7),
    11: (11, 9),
    12: (12, 11, 10, 4),
    13: (13, 12, 11, 8),
    14: (14, 13, 12, 2),
    15: (15, 14),
    16: (16, 15, 13, 4),
    17: (17, 14),
    18: (18, 11),
    19: (19, 18, 17, 14),
    20: (20, 17),
}


def _bits(order: int) -> np.ndarray:
    """One period (2**order - 1 bits, 0 or 1) of the maximum-length sequence, from the all-ones state."""
    taps = _TAPS[order]
    n = 2**order - 1
    s = np.ones(n + order, dtype=np.uint8)
    # s[t] depends on s[t - k] for k >= min(taps): fill blocks of that length at once
    step = min(taps)
    t = order
    while t < n + order:
        stop = min(t + step, n + order)
        acc = np.zeros(stop - t, dtype=np.uint8)
        for k in taps:
            acc ^= s[t - k : stop - k]
        s[t:stop] = acc
        t = stop
    return s[order:]


def prbs(
    order: int,
    *,
    band: float = 1.0,
    levels: tuple[float, float] = (-1.0, 1.0),
    periods: int = 1,
    ts: float = 1.0,
) -> Excitation:
    """A maximum-length pseudo-random binary sequence (PRBS).

    A shift register of ``order`` bits gives a sequence of period ``2**order - 1`` bits. Each bit is
    held for ``clock = round(1 / band)`` samples, so the period is ``clock * (2**order - 1)``
    samples.

    Parameters
    ----------
    order : int
        Shift-register length, 2 to 20.
    band : float
        Upper edge of the pass band as a fraction of the Nyquist frequency, in (0, 1] (MATLAB's
        ``[0 B]``): 1 switches every sample (white up to Nyquist); 0.25 holds each bit 4 samples
        and puts most of the power below a quarter of Nyquist.
    levels : (float, float)
        The two values, low and high.
    periods : int
        Number of whole periods.
    ts : float
        Sampling time [s].

    Returns
    -------
    Excitation

    Raises
    ------
    DataError
        On an order outside 2..20, a band outside (0, 1], equal levels or a bad ``periods``/``ts``.

    Notes
    -----
    **Spectrum.** With ``band = 1`` and levels ±a, the autocorrelation over one period of
    N = 2^order − 1 samples takes two values only: a² at lag 0 and −a²/N at every other lag, so the
    spectrum is flat (white) at every line k/(N·ts) Hz except the mean. With a clock of c samples
    the spectrum is that of white noise through a c-sample hold: power ∝ sinc²(f·c·ts), with its
    first zero at 1/(c·ts) Hz. Apply whole periods: over a whole period the sequence has
    2^(order−1) high and 2^(order−1) − 1 low bits.

    Examples
    --------
    >>> from arxid.inputs import prbs
    >>> x = prbs(4, levels=(0.0, 1.0))
    >>> x.period, int(x.values.sum())
    (15, 8)
    """
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order not in _TAPS:
        raise DataError(f"order must be a whole number from 2 to 20 (period 2**order - 1 bits), got {order!r}")
    band = float(band)
    if not 0 < band <= 1:
        raise DataError(f"band must be a fraction of the Nyquist frequency in (0, 1], got {band!r}")
    lo, hi = (float(v) for v in levels)
    if not (np.isfinite(lo) and np.isfinite(hi)) or lo == hi:
        raise DataError(f"levels must be two different finite values (low, high), got {levels!r}")
    ts, periods = check_ts(ts), check_periods(periods)
    clock = max(1, round(1.0 / band))
    one = np.where(_bits(int(order)) == 1, hi, lo).repeat(clock)
    return Excitation(
        values=np.tile(one, periods),
        ts=ts,
        kind="prbs",
        period=int(one.shape[0]),
        description=(
            f"Maximum-length PRBS of order {order} ({2**order - 1} bits of {clock} sample(s) each, "
            f"levels {lo:g} and {hi:g}), flat up to about {band * 0.5 / ts:g} Hz."
        ),
    )
