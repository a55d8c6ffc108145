"""Motor model with battery: simulate, identify, convert PWM.

The model of a published grey-box study of a Crazyflie quadrotor's motor and rotational dynamics
and of Sarıoğlu & Kural's "Modeling and ARX Identification of a Quadrotor MiniUAV" (eqs. 21-23 in
both).

The motor speed obeys ``dw/dt = a0*V - a1*w - a2*w^2`` with armature voltage ``V = vbat*duty``
(eq. 22). ``a1`` is back-EMF and friction, ``a2`` the propeller's aerodynamic load.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._base import metrics
from ..data.iodata import IOData
from ..exceptions import DataError, IdentifiabilityError

__all__ = ["MotorModel", "MotorFit", "identify_motor", "speeds_from_pwm", "fit_percent"]


def fit_percent(measured, simulated) -> float:
    """NRMSE fit in percent, as MATLAB ``compare`` and the grey-box study report it.

    ``100 * (1 - ||y - yhat|| / ||y - mean(y)||)`` over the samples where both exist (NaN marks a
    missing sample): :func:`arxid._metrics.fit_percent`, the definition every arxid report uses.

    Parameters
    ----------
    measured : array_like of shape (n_samples,)
        Measured signal ``y``.
    simulated : array_like of shape (n_samples,)
        Simulated or predicted signal ``yhat``.

    Returns
    -------
    float
        Fit in percent (100: perfect); ``-inf`` when the simulation diverged, NaN when no sample
        has both values or ``y`` is constant there.
    """
    return metrics.fit_percent(measured, simulated)


def _step(w: np.ndarray, v: np.ndarray, a0: float, a1: float, a2: float, ts: float) -> np.ndarray:
    """Exact solution of the Riccati equation over one sample with the voltage held (ZOH).

    dw/dt = -a2 (w - r+)(w - r-) with roots r+- of a2 w^2 + a1 w - a0 v = 0, so
    (w - r+)/(w - r-) decays as exp(-sqrt(a1^2 + 4 a0 a2 v) t). Exact for any ts, so a coarse
    log and a fine simulation agree."""
    if a2 <= 1e-15:  # linear motor: first-order lag
        if a1 <= 1e-15:
            return w + a0 * v * ts
        e = math.exp(-a1 * ts)
        return w * e + (a0 * v / a1) * (1.0 - e)
    root = np.sqrt(np.maximum(a1 * a1 + 4.0 * a0 * a2 * v, 0.0))
    rp = (-a1 + root) / (2.0 * a2)
    rm = (-a1 - root) / (2.0 * a2)
    rho = (w - rp) / (w - rm) * np.exp(-root * ts)
    return (rp - rho * rm) / (1.0 - rho)


def _riccati_run(w0: float, volts: list[float], a0: float, a1: float, a2: float, ts: float) -> np.ndarray:
    """:func:`_step` over a record of one motor, in plain floats (~10x faster than numpy scalars)."""
    out = [w0]
    wk = w0
    c1, c2, sq, ex = a1 * a1, 4.0 * a0 * a2, math.sqrt, math.exp
    for vk in volts:
        root = sq(max(c1 + c2 * vk, 0.0))
        rp = (root - a1) / (2.0 * a2)
        rm = (-a1 - root) / (2.0 * a2)
        rho = (wk - rp) / (wk - rm) * ex(-root * ts)
        wk = (rp - rho * rm) / (1.0 - rho)
        out.append(wk)
    return np.asarray(out)


@dataclass(frozen=True)
class MotorModel:
    """``dw/dt = a0*V - a1*w - a2*w^2``, ``V = vbat*duty`` (Sarıoğlu & Kural eqs. 21-22).

    Parameters
    ----------
    a0 : float
        Voltage gain [rad/s^2/V].
    a1 : float
        Linear damping (back-EMF, friction) [1/s].
    a2 : float
        Quadratic (propeller) load [1/rad].

    Examples
    --------
    >>> import numpy as np
    >>> from arxid.quadrotor import MotorModel
    >>> m = MotorModel(2.0e4, 20.0, 1.6e-3)
    >>> round(float(m.steady_speed(2.0)), 1)   # rad/s at 2 V
    1753.9
    """

    a0: float
    a1: float
    a2: float

    def steady_speed(self, voltage):
        """Equilibrium speed for a constant armature voltage.

        Parameters
        ----------
        voltage : array_like
            Armature voltage ``V = vbat * duty`` [V].

        Returns
        -------
        ndarray, same shape as ``voltage``
            Speed at which ``dw/dt = 0``.
        """
        v = np.asarray(voltage, dtype=float)
        if self.a2 <= 1e-15:
            return self.a0 * v / self.a1
        return (-self.a1 + np.sqrt(self.a1**2 + 4 * self.a0 * self.a2 * np.maximum(v, 0))) / (2 * self.a2)

    def duty_for_speed(self, speed, vbat):
        """Duty that holds ``speed`` in steady state at battery voltage ``vbat``.

        Parameters
        ----------
        speed : array_like
            Motor speed.
        vbat : array_like
            Battery voltage [V] (broadcast against ``speed``).

        Returns
        -------
        ndarray
            Duty, clipped to [0, 1].
        """
        w = np.asarray(speed, dtype=float)
        return np.clip((self.a1 * w + self.a2 * w * w) / (self.a0 * np.asarray(vbat, dtype=float)), 0.0, 1.0)

    def simulate(self, duty, vbat, ts: float, w0=None) -> np.ndarray:
        """Free-run simulation of motor speeds.

        Parameters
        ----------
        duty : array_like of shape (n_samples,) or (n_samples, n_motors)
            PWM duty in [0, 1] (Crazyflie: ``pwm / 65535``), held over each sample.
        vbat : array_like of shape (n_samples,)
            Battery voltage [V].
        ts : float
            Sampling time [s].
        w0 : float or array_like of shape (n_motors,), optional
            Initial speed; default the steady speed of the first sample.

        Returns
        -------
        ndarray, same shape as ``duty``
            Speed at each sample (``w[0] = w0``; ``w[k+1]`` follows from ``V[k]``).
        """
        d = np.asarray(duty, dtype=float)
        vb = np.asarray(vbat, dtype=float)
        if vb.shape[0] != d.shape[0]:
            raise DataError(f"duty has {d.shape[0]} samples but vbat has {vb.shape[0]}")
        volts = d * (vb[:, None] if d.ndim == 2 else vb)
        w = np.empty_like(volts)
        w[0] = self.steady_speed(volts[0]) if w0 is None else w0
        a0, a1, a2 = float(self.a0), float(self.a1), float(self.a2)
        if a2 > 1e-15 and volts.ndim == 1:
            return _riccati_run(float(w[0]), volts[:-1].tolist(), a0, a1, a2, ts)
        if a2 > 1e-15:  # the motors are independent: one plain-float run each
            for i in range(volts.shape[1]):
                w[:, i] = _riccati_run(float(w[0, i]), volts[:-1, i].tolist(), a0, a1, a2, ts)
            return w
        for k in range(volts.shape[0] - 1):
            w[k + 1] = _step(w[k], volts[k], a0, a1, a2, ts)
        return w

    def __str__(self) -> str:
        return f"dw/dt = {self.a0:.6g}*V - {self.a1:.6g}*w - {self.a2:.6g}*w^2"


@dataclass(frozen=True)
class MotorFit:
    """Identified motor model and how well it reproduces the measured speed.

    Attributes
    ----------
    model : MotorModel
        After free-run refinement (or the regression estimate when ``refine=False``).
    regression : MotorModel
        Linear-regression estimate on the discretised equation (the starting point).
    fit_percent : float
        Free-run NRMSE fit of ``model`` on the data, in percent (the grey-box study: 91.73 %).
    rms : float
        Free-run RMS error [speed unit].
    regression_fit_percent : float
        Free-run fit of the regression estimate.
    n_samples : int
    """

    model: MotorModel
    regression: MotorModel
    fit_percent: float
    rms: float
    regression_fit_percent: float
    n_samples: int

    @property
    def a0(self) -> float:
        """``a0`` of :attr:`model`."""
        return self.model.a0

    @property
    def a1(self) -> float:
        """``a1`` of :attr:`model`."""
        return self.model.a1

    @property
    def a2(self) -> float:
        """``a2`` of :attr:`model`."""
        return self.model.a2

    def __str__(self) -> str:
        return (
            f"motor model  {self.model}\n"
            f"  free-run fit {self.fit_percent:.2f} %  (rms {self.rms:.4g}), {self.n_samples} samples\n"
            f"  regression   {self.regression}  (fit {self.regression_fit_percent:.2f} %)"
        )


def _check(duty, vbat, speed):
    d = np.asarray(duty, dtype=float).reshape(-1)
    vb = np.asarray(vbat, dtype=float).reshape(-1)
    w = np.asarray(speed, dtype=float).reshape(-1)
    if not (d.shape == vb.shape == w.shape):
        raise DataError(
            f"duty, vbat and speed must have the same length, got {d.shape[0]}, {vb.shape[0]}, {w.shape[0]}"
        )
    if d.shape[0] < 20:
        raise DataError(f"only {d.shape[0]} samples; the motor model needs at least 20 (a few time constants)")
    for name, a in (("duty", d), ("vbat", vb), ("speed", w)):
        if not np.all(np.isfinite(a)):
            raise DataError(f"{name} holds NaN or inf; remove those samples first")
    if d.min() < 0 or d.max() > 1.0 + 1e-9:
        raise DataError(
            f"duty spans [{d.min():g}, {d.max():g}] but must lie in [0, 1]; "
            "pass duty = pwm / 65535 (or your PWM's full scale)"
        )
    return d, vb, w


def identify_motor(duty, vbat, speed, ts: float, refine: bool = True) -> MotorFit:
    """Identify ``a0, a1, a2`` from PWM duty, battery voltage and measured speed.

    Parameters
    ----------
    duty : array_like of shape (n_samples,)
        PWM duty in [0, 1].
    vbat : array_like of shape (n_samples,)
        Battery voltage [V].
    speed : array_like of shape (n_samples,)
        Measured motor speed (rad/s, or rpm: the parameters then come out in rpm).
    ts : float
        Sampling time [s].
    refine : bool
        Refine the regression estimate by minimising the free-run simulation error with
        ``scipy.optimize.least_squares`` (the grey-box study's PEM).

    Returns
    -------
    MotorFit

    Notes
    -----
    The regression uses the trapezoidal discretisation
    ``(w[k+1] - w[k])/ts = a0*V[k] - a1*(w[k] + w[k+1])/2 - a2*(w[k]^2 + w[k+1]^2)/2``,
    linear in the parameters and accurate to O(ts^2). Differencing amplifies speed noise and the
    regressors contain the noisy speed, so the regression is biased on noisy data; the free-run
    refinement removes that bias, since simulation error does not depend on differentiated data.
    """
    from scipy.optimize import least_squares

    d, vb, w = _check(duty, vbat, speed)
    v = d * vb
    dw = (w[1:] - w[:-1]) / ts
    phi = np.column_stack([v[:-1], -(w[1:] + w[:-1]) / 2, -(w[1:] ** 2 + w[:-1] ** 2) / 2])
    scale = np.abs(phi).max(axis=0)
    if np.any(scale == 0) or np.linalg.matrix_rank(phi / scale) < 3:
        raise IdentifiabilityError(
            "the data do not excite the motor: duty or speed is constant; "
            "log throttle steps or ramps that span the operating range",
            regressors=("V", "w", "w^2"),
        )
    theta = np.linalg.lstsq(phi / scale, dw, rcond=None)[0] / scale
    regression = MotorModel(*(float(t) for t in theta))
    sim0 = regression.simulate(d, vb, ts, w0=w[0])
    fit0 = fit_percent(w, sim0) if np.all(np.isfinite(sim0)) else -np.inf
    model = regression
    if refine:
        x0 = np.maximum(theta, [1e-12, 0.0, 0.0]) / np.abs(theta).clip(1e-12)
        ref = np.abs(theta).clip(1e-12)

        def residual(x):
            sim = MotorModel(*(x * ref)).simulate(d, vb, ts, w0=w[0])
            r = sim - w
            return np.where(np.isfinite(r), r, 1e6)

        sol = least_squares(
            residual,
            x0,
            bounds=([0.0, 0.0, 0.0], [np.inf, np.inf, np.inf]),
            x_scale=1.0,
            xtol=1e-12,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=200,
        )
        model = MotorModel(*(float(t) for t in sol.x * ref))
    sim = model.simulate(d, vb, ts, w0=w[0])
    return MotorFit(
        model=model,
        regression=regression,
        fit_percent=fit_percent(w, sim),
        rms=metrics.prediction_rms(w, sim),
        regression_fit_percent=float(fit0),
        n_samples=int(w.shape[0]),
    )


def speeds_from_pwm(
    data: IOData,
    model: MotorModel,
    duty=("d1", "d2", "d3", "d4"),
    vbat: str = "vbat",
    names=("w1", "w2", "w3", "w4"),
    pwm_full_scale: float = 1.0,
) -> IOData:
    """Add simulated motor speeds to logged flight data that have PWM and battery voltage only.

    Parameters
    ----------
    data : IOData
        Holds the duty (or raw PWM) signals and the battery voltage.
    model : MotorModel
        Identified motor model (Sarıoğlu & Kural used one model for all four motors).
    duty : sequence of str
        Names of the duty or PWM signals, motor order.
    vbat : str
        Name of the battery-voltage signal.
    names : sequence of str
        Names of the new speed signals (extra signals of the result).
    pwm_full_scale : float
        Divide the PWM signals by this to get duty (65535 for Crazyflie raw PWM).

    Returns
    -------
    IOData
        ``data`` with the speeds added as extra signals, ready for :meth:`Mixer.apply`.
    """
    if len(names) != len(duty):
        raise DataError(f"{len(duty)} duty signals but {len(names)} speed names")
    dmat = np.column_stack([data.signal(n) for n in duty]) / float(pwm_full_scale)
    if dmat.min() < 0 or dmat.max() > 1.0 + 1e-9:
        raise DataError(
            f"duty spans [{dmat.min():g}, {dmat.max():g}]; set pwm_full_scale "
            "(65535 for Crazyflie PWM) so that duty lies in [0, 1]"
        )
    w = np.empty_like(dmat)
    for a, b in data.segments:
        w[a:b] = model.simulate(dmat[a:b], data.signal(vbat)[a:b], data.ts)
    extra = {**data.extra, **{n: w[:, i] for i, n in enumerate(names)}}
    return data.with_signals(extra=extra)
