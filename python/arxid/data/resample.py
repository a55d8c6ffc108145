"""Logged signals onto one uniform time grid: :func:`resample`, for every flight log and CSV.

A flight controller logs each signal when it has it: the gyro at the loop rate with jitter, the
battery a few times a second, a message lost now and then. Identification needs one sampling
time, so :func:`resample` puts every signal on one grid of step ``ts``:

* **commands** (the inputs, setpoints, actuator outputs) are **held** between samples (a
  zero-order hold, as the controller applies them);
* **measurements** (the output and the other logged signals) are **interpolated linearly**;
* a grid point inside a **dropout** (two samples farther apart than ``max_gap``) is missing
  (NaN): never held or interpolated across, so no fit ever sees made-up samples.

The grid starts where the last signal starts and stops where the first one stops, so every
signal is defined on it.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass

import numpy as np

from ..exceptions import DataError

__all__ = ["Resampled", "on_grid", "resample"]


@dataclass(frozen=True)
class Resampled:
    """Signals on one uniform grid (what :func:`resample` returns).

    Attributes
    ----------
    time : ndarray of shape (n,)
        The grid [s], in the time base of the samples.
    values : dict of str to ndarray of shape (n,)
        Each signal on the grid, NaN inside dropouts, in the order given.
    held : dict of str to bool
        Zero-order hold (True) or linear interpolation (False), per signal.
    ts : float
        The grid step [s].
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    held: dict[str, bool]
    ts: float


def on_grid(t: np.ndarray, v: np.ndarray, grid: np.ndarray, hold: bool, max_gap: float) -> np.ndarray:
    """One signal sampled at times ``t`` (increasing), on ``grid``.

    Parameters
    ----------
    t, v : ndarray of shape (m,)
        Sample times [s] (non-decreasing) and values.
    grid : ndarray of shape (n,)
        Times wanted [s].
    hold : bool
        Hold the last sample (zero-order hold) instead of interpolating linearly.
    max_gap : float
        Longest interval between two samples that is bridged [s]; a grid time inside a longer
        one, or outside ``[t[0], t[-1]]``, is NaN.

    Returns
    -------
    ndarray of shape (n,)

    Examples
    --------
    >>> import numpy as np
    >>> t, v = np.array([0.0, 1.0, 2.0, 5.0]), np.array([0.0, 10.0, 20.0, 50.0])
    >>> on_grid(t, v, np.arange(6.0), hold=False, max_gap=1.5)
    array([ 0., 10., 20., nan, nan, 50.])
    >>> on_grid(t, v, np.array([0.5, 1.5]), hold=True, max_gap=1.5)
    array([ 0., 10.])
    """
    # A grid time within a millionth of a step of a sample is that sample's time (the grid's
    # start + k * step differs from logged times by rounding): hold it, not the one before.
    tol = 1e-6 * float(grid[1] - grid[0]) if grid.shape[0] > 1 else 0.0
    after = np.searchsorted(t, grid + tol, side="right")  # first sample after each grid time
    before = np.clip(after - 1, 0, len(t) - 1)
    nxt = np.clip(after, 0, len(t) - 1)
    out = v[before].astype(np.float64, copy=True) if hold else np.interp(grid, t, v)
    # inside a dropout (next sample more than max_gap after the last): unknown, neither held nor bridged
    out[(t[nxt] - t[before] > max_gap) & (grid > t[before] + tol)] = np.nan
    out[(grid < t[0] - tol) | (grid > t[-1] + tol)] = np.nan
    return out


def _median_step(t: np.ndarray) -> float:
    steps = np.diff(t)
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else float("nan")


def resample(
    samples: Mapping[str, tuple[np.ndarray, np.ndarray]],
    *,
    hold: Collection[str] = (),
    ts: float | None = None,
    max_gap: float | None = None,
    source: str = "the log",
) -> Resampled:
    """Put signals logged at their own (jittered, multi-rate) times onto one uniform grid.

    Parameters
    ----------
    samples : mapping of str to (t, v)
        Each signal's sample times [s] and values, by name; the first one sets the default step.
        Times need not be sorted (they are, stably); repeated times keep the last value for a
        held signal.
    hold : collection of str
        Names of the commands, held between samples (zero-order hold); the others are
        interpolated linearly.
    ts : float, optional
        Grid step [s] (default: the median sample interval of the first signal).
    max_gap : float, optional
        Longest interval between two samples that is bridged [s] (default: 3 times the signal's
        own median interval, or 3 grid steps if longer); a grid time inside a longer dropout is
        NaN.
    source : str
        The file, for error messages.

    Returns
    -------
    Resampled

    Raises
    ------
    DataError
        A signal with fewer than 2 finite time stamps, a ``ts`` or ``max_gap`` that is not a
        positive number, or signals that were never logged at the same time.

    Examples
    --------
    A gyro logged every 1 ms with jitter and a battery voltage every 100 ms, on a 1 ms grid:

    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> t_gyro = np.arange(2000) * 1e-3 + rng.uniform(-2e-4, 2e-4, 2000)
    >>> t_vbat = np.arange(20) * 0.1
    >>> r = resample({"gyro": (t_gyro, np.sin(t_gyro)), "vbat": (t_vbat, 16.0 - t_vbat)}, ts=1e-3)
    >>> round(r.ts, 6), r.values["gyro"].shape == r.values["vbat"].shape
    (0.001, True)
    """
    if not samples:
        raise DataError("choose at least one signal to resample")
    series: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, (t, v) in samples.items():
        t = np.asarray(t, dtype=np.float64)
        v = np.asarray(v, dtype=np.float64)
        keep = np.isfinite(t)
        t, v = t[keep], v[keep]
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
        if t.shape[0] < 2 or t[-1] <= t[0]:
            raise DataError(f"{name} has fewer than 2 samples at distinct times in {source}")
        series[name] = (t, v)
    steps = {name: _median_step(t) for name, (t, _) in series.items()}
    first = next(iter(series))
    step = float(ts) if ts is not None else steps[first]
    if not np.isfinite(step) or step <= 0:
        raise DataError(f"ts must be a positive number of seconds, got {ts!r}")
    if max_gap is not None and not (np.isfinite(max_gap) and max_gap > 0):
        raise DataError(f"max_gap must be a positive number of seconds, got {max_gap!r}")
    start = max(t[0] for t, _ in series.values())
    stop = min(t[-1] for t, _ in series.values())
    if stop - start < step:
        raise DataError(f"the chosen signals of {source} were never logged at the same time; choose others")
    grid = start + step * np.arange(int(np.floor((stop - start) / step)) + 1)
    held_names = set(hold)
    values, held = {}, {}
    for name, (t, v) in series.items():
        gap = float(max_gap) if max_gap is not None else 3.0 * max(steps[name], step)
        values[name] = on_grid(t, v, grid, name in held_names, gap)
        held[name] = name in held_names
    return Resampled(grid, values, held, step)
