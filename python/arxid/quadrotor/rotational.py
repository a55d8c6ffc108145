"""Rotational grey box ``roll'' = c (w4^2 - w2^2)`` with a delay.

The rotational model (eqs. 24-26) of a published grey-box study of a Crazyflie quadrotor's motor
and rotational dynamics.

Each attitude axis, seen through the input mixer, is a double integrator with a gain ``c``
(``k l / Ixx`` for roll) and a pure delay. The sampled model is

    y[t] - 2 y[t-1] + y[t-2] = c ts^2 u[t - delay]

(ARX(2, 1, delay) with ``A = (1 - q^-1)^2`` known), where ``delay`` counts samples from an input
change to its first effect on the logged angle (Sarıoğlu & Kural found 8 at 2 ms).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._base import metrics
from ..data.iodata import IOData
from ..exceptions import DataError, IdentifiabilityError

__all__ = ["RotationalModel", "RotationalFit", "identify_rotational"]


def _windows(y, u, delay, window, ts):
    """Cut one experiment into windows of ``window`` samples and return, per window, the angle
    and the double-integrated delayed input ``s`` (zero at the window start), both (n_win, window).

    Inside a window ``y[k+j] = y[k] + j * (rate * ts) + c * s[j]``: linear in the initial angle,
    the initial rate and ``c``."""
    n = y.shape[0]
    first = delay  # u[t - delay] must exist from the window's second sample on
    n_win = (n - first) // window
    if n_win < 1:
        return np.empty((0, window)), np.empty((0, window)), np.empty(0, dtype=int)
    starts = first + window * np.arange(n_win)
    idx = starts[:, None] + np.arange(window)[None, :]
    g = u[idx - delay] * ts * ts
    g[:, 0] = 0.0  # the window's first sample does not feel its own input
    return y[idx], np.cumsum(np.cumsum(g, axis=1), axis=1), idx


def _const(window, ts):
    """Double-integrated unit acceleration inside a window (zero at its start)."""
    j = np.arange(window, dtype=float)
    return ts * ts * j * (j + 1) / 2


def _project(x, window):
    """Remove from each row its least-squares fit by a + b j (the unknown initial angle and rate)."""
    j = np.arange(window, dtype=float)
    basis = np.column_stack([np.ones(window), j])
    q, _ = np.linalg.qr(basis)
    return x - (x @ q) @ q.T


@dataclass(frozen=True)
class RotationalModel:
    """Double integrator with gain and delay: ``y'' (t) = gain * u(t - delay * ts)``.

    Parameters
    ----------
    gain : float
        ``c`` [rad/s^2 per input unit] (roll: ``k l / Ixx``).
    delay : int
        Input-to-output delay in samples (ARX ``nk``).
    ts : float
        Sampling time [s].
    offset : float
        Constant angular acceleration [rad/s^2] (a trim torque, e.g. from mismatched motors).
    """

    gain: float
    delay: int
    ts: float
    offset: float = 0.0

    @property
    def b(self) -> float:
        """ARX numerator coefficient ``c ts^2`` (Sarıoğlu & Kural eq. 29 reports 4.222e-8)."""
        return self.gain * self.ts**2

    def predict(self, data: IOData, window: int = 100) -> np.ndarray:
        """Response over windows, each from its own least-squares initial angle and rate.

        MATLAB ``compare`` with estimated initial conditions. The double integrator drifts in free
        run, so whole-record simulation is meaningless on closed-loop data.

        Parameters
        ----------
        data : IOData
            Output the angle, first input the pseudo-torque.
        window : int
            Window length in samples.

        Returns
        -------
        ndarray of shape (n_samples,)
            The predicted angle, NaN at samples no window covers.
        """
        out = np.full(data.n_samples, np.nan)
        u = data.u[:, 0]
        for a, b in data.segments:
            yw, sw, idx = _windows(data.y[a:b], u[a:b], self.delay, window, self.ts)
            if idx.size:
                resid = _project(yw - self.gain * sw - self.offset * _const(window, self.ts), window)
                out[a + idx] = yw - resid
        return out

    def simulate(self, u, y0: float = 0.0, rate0: float = 0.0) -> np.ndarray:
        """Free-run response to an input (the input before the start taken as zero).

        Parameters
        ----------
        u : array_like of shape (n_samples,)
            Input (pseudo-torque).
        y0 : float
            Initial angle [rad].
        rate0 : float
            Initial rate [rad/s].

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        u = np.asarray(u, dtype=float)
        g = np.zeros(u.size)
        if self.delay < u.size:
            g[self.delay :] = self.gain * self.ts**2 * u[: u.size - self.delay]
        g += self.offset * self.ts**2
        g[0] = 0.0
        inc = rate0 * self.ts + np.cumsum(g)  # y[t] - y[t-1]
        inc[0] = 0.0
        return y0 + np.cumsum(inc)

    def evaluate(self, data: IOData, window: int = 100) -> RotationalScore:
        """RMS and fit percent of :meth:`predict` on ``data``.

        For example pitch data for a roll model: the symmetry check of the grey-box Crazyflie
        study and of Sarıoğlu & Kural's ARX study.

        Parameters
        ----------
        data : IOData
            Output the angle, first input the pseudo-torque.
        window : int
            Window length in samples.

        Returns
        -------
        RotationalScore
            Over the samples that a window covers.
        """
        yhat = self.predict(data, window)
        return RotationalScore(
            rms=metrics.prediction_rms(data.y, yhat),
            fit_percent=metrics.fit_percent(data.y, yhat),
            window=int(window),
            n_samples=int((np.isfinite(yhat) & np.isfinite(data.y)).sum()),
        )

    def __str__(self) -> str:
        off = f" + {self.offset:.4g}" if self.offset else ""
        return (
            f"y'' = {self.gain:.6g} * u(t - {self.delay} samples){off}   "
            f"[ARX(2,1,{self.delay}): b = {self.b:.4g}, A = 1 - 2 z^-1 + z^-2]"
        )


@dataclass(frozen=True)
class RotationalScore:
    """How well a rotational model reproduces the angle over windows of ``window`` samples."""

    rms: float
    fit_percent: float
    window: int
    n_samples: int

    def __str__(self) -> str:
        return (
            f"{self.window}-sample window rms {self.rms:.4g}, fit {self.fit_percent:.2f} % ({self.n_samples} samples)"
        )


@dataclass(frozen=True)
class RotationalFit:
    """Result of :func:`identify_rotational`.

    Attributes
    ----------
    model : RotationalModel
    gain_stderr : float
        Standard error of the gain from the window residuals (white-noise assumption).
    score : RotationalScore
        On the estimation data.
    delays : tuple of int
        Candidate delays.
    losses : tuple of float
        Mean squared window prediction error for each candidate delay.
    """

    model: RotationalModel
    gain_stderr: float
    score: RotationalScore
    delays: tuple
    losses: tuple

    def __str__(self) -> str:
        rows = "\n".join(
            f"    {d:3d}  {loss:.4g}{'  <' if d == self.model.delay else ''}"
            for d, loss in zip(self.delays, self.losses, strict=True)
        )
        return (
            f"rotational model  {self.model}\n"
            f"  gain {self.model.gain:.6g} +- {self.gain_stderr:.2g}, {self.score}\n"
            f"  delay  mean squared error ({self.score.window}-sample windows)\n{rows}"
        )


def identify_rotational(data: IOData, delays=range(0, 16), window: int = 100, offset: bool = False) -> RotationalFit:
    """Identify gain and delay of ``y'' = c u(t - delay)`` by prediction-error minimisation.

    Parameters
    ----------
    data : IOData
        Output the angle [rad], first input the mixer pseudo-torque (e.g.
        :func:`arxid.datasets.quadrotor_axis`).
    delays : iterable of int
        Candidate delays in samples.
    window : int
        Window length in samples. The record is cut into windows; in each, the initial angle and
        rate are free (estimated) and the gain is common. The double integrator drifts in free
        run, so a whole-record simulation error is not usable on closed-loop flight data.
    offset : bool
        Also fit a constant angular acceleration (trim torque). Needed when the motors are not
        identical: the controller then holds a steady torque offset that ``c u`` cannot explain.

    Returns
    -------
    RotationalFit

    Notes
    -----
    Inside a window the model output is linear in the initial angle, the initial rate and ``c``,
    so the output-error minimum for each delay is a closed-form least-squares problem (the two
    initial-state columns are projected out). The delay is the candidate with the smallest
    error. This is the grey-box study's PEM (output error with estimated initial states, as MATLAB
    ``pem`` does for a grey box) without an iterative search, and it is not biased by white angle noise
    the way one-step (equation-error) regression on second differences is.
    """
    if data.n_inputs < 1:
        raise DataError("the data need the pseudo-torque as an input")
    delays = tuple(int(d) for d in delays)
    if not delays or min(delays) < 0:
        raise DataError(f"delays must be non-negative sample counts, got {delays}")
    if window < 3:
        raise DataError(f"window must be at least 3 samples, got {window}")
    u = data.u[:, 0]
    if np.nanstd(u) == 0:
        raise IdentifiabilityError(
            "the pseudo-torque is constant; the gain cannot be identified", regressors=(data.input_names[0],)
        )
    losses, fits = [], []
    for d in delays:
        loss, fit = _fit_delay(data, d, window, offset)
        losses.append(loss)
        fits.append(fit)
    best = int(np.argmin(losses))
    model = RotationalModel(gain=fits[best][0], delay=delays[best], ts=data.ts, offset=fits[best][2])
    return RotationalFit(
        model=model, gain_stderr=fits[best][1], score=model.evaluate(data, window), delays=delays, losses=tuple(losses)
    )


def _fit_delay(data: IOData, delay: int, window: int, offset: bool) -> tuple[float, tuple[float, float, float]]:
    """Mean squared window prediction error of the best gain for one delay, and that gain with its
    standard error and the offset (0 without ``offset``)."""
    u = data.u[:, 0]
    ys, ss = [], []
    for a, b in data.segments:
        yw, sw, _ = _windows(data.y[a:b], u[a:b], delay, window, data.ts)
        ys.append(yw)
        ss.append(sw)
    yw, sw = np.concatenate(ys), np.concatenate(ss)
    ok = np.all(np.isfinite(yw), axis=1) & np.all(np.isfinite(sw), axis=1)
    if ok.sum() < 2:
        raise DataError(
            f"fewer than 2 complete windows of {window} samples for delay {delay}; log longer or use a shorter window"
        )
    py = _project(yw[ok], window).ravel()
    cols = [_project(sw[ok], window).ravel()]
    if offset:
        cols.append(np.tile(_project(_const(window, data.ts)[None, :], window)[0], int(ok.sum())))
    phi = np.column_stack(cols)
    q, r = np.linalg.qr(phi)
    theta = np.linalg.solve(r, q.T @ py)
    e = py - phi @ theta
    dof = max(e.size - 2 * ok.sum() - phi.shape[1], 1)
    rinv = np.linalg.inv(r)
    se = np.sqrt(e @ e / dof * (rinv @ rinv.T)[0, 0])
    return metrics.mean_square(e), (float(theta[0]), float(se), float(theta[1]) if offset else 0.0)
