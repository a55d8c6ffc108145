"""The step response of a rate loop from a flight log, by regularised deconvolution of the gyro by
the setpoint: PIDtoolbox's ``PTstepcalc.m`` (Brian White, v0.55), without a model.

What ``PTstepcalc`` does, and this module repeats (its parameters are the defaults here):

* segments of 2 s + 1 sample (``SP(i : i + 2000·lograte)``), starting every ``round(L / k)``
  samples, k = 10 for logs up to 20 s, 7 up to 60 s and 3 beyond (90 %, 86 % or 67 % overlap); a
  segment is used only when it ends before the last start (``segment_vector + L <
  segment_vector(end)``), and when max |setpoint| ≥ 20 deg/s;
* each segment times a (symmetric) Hann window, 100 zeros on both sides, Fourier transforms divided
  by their length, impulse = real(ifft(G·conj(H) / (H·conj(H) + 10⁻⁴))), step = its cumulative sum;
* optionally ("Y correction", off in PIDtoolbox's window): the step multiplied by 2 − m, m its mean
  over 200–500 ms (the first-order correction ``resp·(1 − m + 1)``, not a division by m);
* kept when its 200–500 ms part lies strictly inside (0.5, 3); its first 500 ms returned; the
  curve shown is the mean of the kept segments.

PIDtoolbox's optional lowess smoothing of the gyro (off by default) is not repeated: smooth the
gyro first if wanted. Here the segments stay inside one experiment and a segment holding a NaN is
dropped; on one gap-free experiment the result is PTstepcalc's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._base.formatting import json_safe
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError

__all__ = ["step_by_deconvolution", "DeconvolvedStep"]


@dataclass(frozen=True, eq=False)
class DeconvolvedStep:
    """Step response of a rate loop estimated from setpoint and gyro (:func:`step_by_deconvolution`).

    Attributes
    ----------
    time : ndarray of shape (n_t,)
        Seconds from the step, 0 to ``duration``.
    response : ndarray of shape (n_t,)
        Mean step response of the kept segments (1 = the setpoint reached).
    segment_responses : ndarray of shape (n_kept, n_t)
        Each kept segment's step response.
    n_segments : int
        Segments laid out over the log (gap-free, inside one experiment).
    n_excited : int
        Of those, segments whose setpoint reaches ``min_setpoint``.
    n_kept : int
        Of those, segments whose 200–500 ms part lies inside (0.5, 3).
    segment_seconds, min_setpoint : float
    y_correction : bool
    reference_name, output_name : str
    """

    time: np.ndarray
    response: np.ndarray
    segment_responses: np.ndarray
    n_segments: int
    n_excited: int
    n_kept: int
    segment_seconds: float
    min_setpoint: float
    y_correction: bool
    reference_name: str = "setpoint"
    output_name: str = "gyro"

    @property
    def peak(self) -> float:
        """Largest value of the mean response (1.1 = 10 % overshoot)."""
        return float(np.max(self.response))

    @property
    def peak_time(self) -> float:
        """Time of :attr:`peak`, seconds."""
        return float(self.time[int(np.argmax(self.response))])

    @property
    def half_rise_time(self) -> float:
        """First time the mean response reaches 0.5, seconds (PIDtoolbox's "latency"); NaN if never."""
        above = np.flatnonzero(self.response >= 0.5)
        return float(self.time[above[0]]) if above.size else math.nan

    def __str__(self) -> str:
        return (
            f"step response of {self.output_name} to {self.reference_name} by deconvolution "
            f"({self.n_kept} of {self.n_excited} excited {self.segment_seconds:g} s segments kept, "
            f"{self.n_segments} laid out)\n"
            f"  reaches 0.5 at {1000 * self.half_rise_time:.1f} ms, peak {self.peak:.3f} at "
            f"{1000 * self.peak_time:.1f} ms, {self.response[-1]:.3f} at {1000 * self.time[-1]:.0f} ms"
        )

    def to_dict(self) -> dict:
        """JSON-ready: ``time_s``, ``response``, the counts, ``peak``, ``peak_time_s``, ``half_rise_time_s``.

        Returns
        -------
        dict
        """
        return json_safe(
            {
                "time_s": self.time,
                "response": self.response,
                "n_segments": self.n_segments,
                "n_excited": self.n_excited,
                "n_kept": self.n_kept,
                "peak": self.peak,
                "peak_time_s": self.peak_time,
                "half_rise_time_s": self.half_rise_time,
                "segment_seconds": self.segment_seconds,
                "min_setpoint": self.min_setpoint,
                "y_correction": self.y_correction,
            }
        )


def _signals(setpoint: Any, gyro: Any, ts: Any, reference: str | None) -> tuple[np.ndarray, np.ndarray, float, list]:
    """Setpoint, gyro, ts and the experiments' ranges from an IOData or from arrays."""
    if isinstance(setpoint, IOData):
        if gyro is not None or ts is not None:
            raise DataError("with an IOData, give the setpoint's name as reference=..., not gyro or ts arrays")
        if reference is None:
            raise DataError(
                "name the setpoint signal: step_by_deconvolution(data, reference='setpoint[0]'); the output is the gyro"
            )
        data = setpoint
        return np.asarray(data.signal(reference), float), data.y, data.ts, data.segments
    if gyro is None or ts is None:
        raise DataError("give setpoint and gyro arrays and ts (seconds), or an IOData with reference=...")
    sp, gy = np.asarray(setpoint, dtype=float), np.asarray(gyro, dtype=float)
    if sp.ndim != 1 or sp.shape != gy.shape:
        raise DataError(f"setpoint and gyro must be 1-D of the same length, got shapes {sp.shape} and {gy.shape}")
    if not (isinstance(ts, (int, float)) and math.isfinite(ts) and ts > 0):
        raise DataError(f"ts must be a positive sampling time in seconds, got {ts!r}")
    return sp, gy, float(ts), [(0, sp.size)]


def segment_starts(n_total: int, segments: list[tuple[int, int]], length: int) -> np.ndarray:
    """First samples of PTstepcalc's segments of ``length + 1`` samples in each experiment.

    Parameters
    ----------
    n_total : int
        Samples in the whole log (sets the overlap: step ``round(length / k)``, k = 10, 7 or 3 for
        logs up to 20 s, 60 s, longer, counting ``length`` as 2 s).
    segments : list of (start, stop)
        The experiments.
    length : int
        Samples per segment, minus one.

    Returns
    -------
    ndarray of int
    """
    seconds = 2.0 * n_total / length
    step = max(round(length / (10 if seconds <= 20 else 7 if seconds <= 60 else 3)), 1)
    out = []
    for a, b in segments:
        starts = np.arange(0, b - a, step)
        out.append(a + starts[starts + length < starts[-1]])
    return np.concatenate(out).astype(int)


def deconvolve(sp: np.ndarray, gy: np.ndarray, regularisation: float, padding: int) -> np.ndarray:
    """Step responses of the rows of ``gy`` to those of ``sp`` (Hann, zero padding, Wiener-type
    regularisation, cumulative sum), PTstepcalc's formula.

    Parameters
    ----------
    sp, gy : ndarray of shape (k, n)
    regularisation : float
        Added to |H|² (PTstepcalc: 1e-4, with the transforms divided by their length).
    padding : int
        Zeros on each side (PTstepcalc: 100).

    Returns
    -------
    ndarray of shape (k, n + 2·padding)
    """
    from scipy.signal.windows import hann

    w = hann(sp.shape[1], sym=True)
    pad = ((0, 0), (padding, padding))
    g = np.fft.fft(np.pad(gy * w, pad), axis=1)
    h = np.fft.fft(np.pad(sp * w, pad), axis=1)
    g, h = g / g.shape[1], h / h.shape[1]
    impulse = np.real(np.fft.ifft(g * np.conj(h) / (h * np.conj(h) + regularisation), axis=1))
    return np.cumsum(impulse, axis=1)


def step_by_deconvolution(
    setpoint: Any,
    gyro: Any = None,
    ts: float | None = None,
    *,
    reference: str | None = None,
    min_setpoint: float = 20.0,
    segment_seconds: float = 2.0,
    duration: float = 0.5,
    y_correction: bool = False,
    regularisation: float = 1e-4,
    padding: int = 100,
) -> DeconvolvedStep:
    """Step response of a rate loop from setpoint and gyro by regularised deconvolution (PIDtoolbox).

    Parameters
    ----------
    setpoint : IOData or array_like of shape (n_samples,)
        An IOData whose output is the gyro (with ``reference`` naming the setpoint), or the
        setpoint samples [deg/s].
    gyro : array_like of shape (n_samples,), optional
        Gyro samples [deg/s] (with a setpoint array).
    ts : float, optional
        Sampling time in seconds (with arrays).
    reference : str, optional
        With an IOData: the setpoint signal's name (an input or an extra signal).
    min_setpoint : float
        A segment is used only when max |setpoint| reaches this (PIDtoolbox: 20 deg/s).
    segment_seconds : float
        Segment length (PIDtoolbox: 2 s).
    duration : float
        Length of the returned response, seconds (PIDtoolbox: 0.5).
    y_correction : bool
        Multiply each step by 2 − m, m its mean over 200–500 ms (PIDtoolbox's "Y correction",
        off by default there).
    regularisation : float
        Added to |H|² in the deconvolution (PIDtoolbox: 1e-4).
    padding : int
        Zeros on each side of a segment (PIDtoolbox: 100).

    Returns
    -------
    DeconvolvedStep
        ``time``, the mean ``response``, ``segment_responses`` and the counts of segments laid
        out, excited and kept.

    Raises
    ------
    DataError
        When the log is too short for a segment, never reaches ``min_setpoint``, or every excited
        segment fails the quality check (a loop that does not follow the setpoint).

    Notes
    -----
    With windowed segments' transforms G (gyro) and H (setpoint), each divided by its length,
    impulse = real(ifft(G·H* / (|H|² + λ))) and the step is its cumulative sum: a Wiener-type
    deconvolution that tolerates frequencies the setpoint does not excite. The module docstring
    lists PTstepcalc's rules that are repeated here.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> ts = 0.001
    >>> sp = np.repeat(rng.uniform(-300, 300, 200), 100)  # 20 s of 0.1 s setpoint steps
    >>> a = np.exp(-ts / 0.02)
    >>> gyro = lfilter([0, 1 - a], [1, -a], sp)  # a first-order loop, 20 ms time constant
    >>> step = arxid.step_by_deconvolution(sp, gyro, ts)
    >>> round(step.half_rise_time, 3), round(float(step.response[-1]), 2)
    (0.014, 1.01)
    """
    sp, gy, ts_, segments = _signals(setpoint, gyro, ts, reference)
    length = int(round(segment_seconds / ts_))
    n_t = int(round(duration / ts_)) + 1
    if length < 4 or n_t > length:
        raise ArxidError(
            f"segment_seconds ({segment_seconds} s) must hold several samples and be longer than "
            f"duration ({duration} s)"
        )
    starts = segment_starts(sp.size, segments, length)
    idx = starts[:, None] + np.arange(length + 1)
    idx = idx[np.isfinite(sp[idx]).all(axis=1) & np.isfinite(gy[idx]).all(axis=1)]
    if idx.shape[0] == 0:
        raise DataError(
            f"no gap-free {segment_seconds:g} s segment fits in the log (segments overlap and must end before the "
            f"last one starts: give at least {3 * segment_seconds:g} s of data)"
        )
    excited = np.max(np.abs(sp[idx]), axis=1) >= min_setpoint
    if not excited.any():
        raise DataError(
            f"the setpoint never reaches {min_setpoint:g} in a {segment_seconds:g} s segment; fly sharper stick moves "
            "or lower min_setpoint (in the setpoint's unit, PIDtoolbox uses 20 deg/s)"
        )
    steps = deconvolve(sp[idx[excited]], gy[idx[excited]], regularisation, padding)
    t_ms = np.arange(steps.shape[1]) * ts_ * 1000.0
    steady = (t_ms > 200.0 + 1e-9) & (t_ms < 500.0 - 1e-9)
    if y_correction:
        steps = steps * (2.0 - steps[:, steady].mean(axis=1, keepdims=True))
    ok = (steps[:, steady].min(axis=1) > 0.5) & (steps[:, steady].max(axis=1) < 3.0)
    if not ok.any():
        raise DataError(
            f"all {int(excited.sum())} excited segments failed PIDtoolbox's check (the 200–500 ms part inside "
            "(0.5, 3)): the gyro does not follow the setpoint; check the signals' names and units"
        )
    kept = steps[ok, :n_t]
    names = (reference or "setpoint", setpoint.output_name if isinstance(setpoint, IOData) else "gyro")
    return DeconvolvedStep(
        time=np.arange(n_t) * ts_,
        response=kept.mean(axis=0),
        segment_responses=kept,
        n_segments=int(idx.shape[0]),
        n_excited=int(excited.sum()),
        n_kept=int(ok.sum()),
        segment_seconds=float(segment_seconds),
        min_setpoint=float(min_setpoint),
        y_correction=bool(y_correction),
        reference_name=names[0],
        output_name=names[1],
    )
