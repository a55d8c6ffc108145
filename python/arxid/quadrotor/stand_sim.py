"""The thrust-stand simulators behind :func:`arxid.datasets.thrust_stand` (the whole quadrotor on a
load cell, all four motors on one PWM command) and :func:`arxid.datasets.thrust_stand_static` (the
settled table per PWM and supply voltage). They fly no controller: the motors, the battery and the
true parameters are those of the flight simulator (:mod:`arxid.quadrotor.flight_sim`).
"""

from __future__ import annotations

import numpy as np

from ..data.iodata import IOData
from ..exceptions import DataError
from .flight_sim import QuadrotorParameters, battery_voltage, effect_switches, sample_count, seeded_rng

__all__ = ["thrust_stand", "thrust_stand_static"]

#: Full-scale PWM command (16 bit): duty = pwm / PWM_FULL_SCALE.
PWM_FULL_SCALE = 65535.0


def _stand_pwm(profile, t, rng):
    T = t[-1] if t[-1] > 0 else 1.0
    if profile == "ramp":  # up and back down, like the Bitcraze stand log
        x = 1 - np.abs(2 * t / T - 1)
        return np.round(x * 65000 / 500) * 500
    if profile == "steps":  # random throttle steps every 0.3-1 s (motor dynamics)
        out = np.empty_like(t)
        k = 0
        while k < t.size:
            hold = int(rng.uniform(0.3, 1.0) / (t[1] - t[0])) + 1
            out[k : k + hold] = rng.uniform(0.15, 1.0) * 65535
            k += hold
        return out
    if profile == "sines":  # eq. 15 shape (Staub & Franchi) on the command, around 55 % throttle
        f = np.array([0.3, 0.2, 0.1, 0.5, 0.6]) * 4
        a = np.array([1.0, 0.95, 0.9, 0.8, 0.7])
        ph = np.pi * np.array([1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6]) + rng.uniform(0, 0.3, 5)
        x = (a * np.sin(2 * np.pi * np.outer(t, f) + ph)).sum(1)
        return np.clip(0.55 + 0.38 * x / np.abs(x).max(), 0.1, 1.0) * 65535
    raise DataError(f"unknown profile {profile!r}; use 'ramp', 'steps' or 'sines'")


def thrust_stand(
    seed: int = 0,
    duration: float = 60.0,
    ts: float = 0.01,
    profile: str = "sines",
    supply: float | None = None,
    effects=None,
    parameters: QuadrotorParameters | None = None,
) -> IOData:
    """Simulate the whole quadrotor on a load cell, all four motors on one PWM command.

    Parameters
    ----------
    seed : int
    duration : float
        [s].
    ts : float
        [s].
    profile : {"sines", "ramp", "steps"}
        PWM command: a sum of five sines (the shape of eq. 15 of the battery-aware thrust study,
        Staub & Franchi, ICRA 2015), a slow ramp up and back down (like the Bitcraze Crazyflie stand
        log) or random throttle steps (motor dynamics).
    supply : float, optional
        Constant supply voltage (bench supply); default: the draining, sagging battery.
    effects : dict, optional
        ``motor_mismatch`` and ``noise`` as in :func:`quadrotor_flight`.
    parameters : QuadrotorParameters, optional

    Returns
    -------
    IOData
        Output ``thrust`` [N] (load cell); input ``pwm`` (0..65535); extra ``duty``, ``vbat`` [V],
        ``w1..w4`` [rad/s], ``rpm1..rpm4``, ``torque1`` [N m] (reaction torque of motor 1),
        ``current`` [A].
    """
    eff = effect_switches(effects)
    par = parameters or QuadrotorParameters()
    n = sample_count(duration, ts)
    rng = seeded_rng(seed)
    pwm = _stand_pwm(profile, np.arange(n) * ts, rng)
    duty = pwm / PWM_FULL_SCALE
    mis = np.asarray(par.mismatch, float) if eff["motor_mismatch"] else np.zeros(4)
    w, vbat, current = _stand_run(par, duty, par.motor[0] * (1 + mis), supply, ts)
    return _stand_data(rng, pwm, duty, w, vbat, current, par.thrust_coefficient * (1 + 0.5 * mis), par, eff, ts)


def _stand_run(
    par: QuadrotorParameters, duty: np.ndarray, a0_i: np.ndarray, supply: float | None, ts: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Motor speeds (n, 4), supply voltage and current (n,) of the four motors on one duty signal,
    from the battery (``supply`` None) or a constant supply."""
    n = duty.shape[0]
    _, a1, a2 = par.motor
    cap = par.capacity_mah * 3.6
    W = np.zeros((n, 4))
    vb_log = np.zeros(n)
    cur_log = np.zeros(n)
    w = np.zeros(4)
    drawn = current = 0.0
    for k in range(n):
        vb = battery_voltage(par, drawn, current, cap) if supply is None else float(supply)
        W[k] = w
        vb_log[k] = vb
        cur_log[k] = current
        v = vb * duty[k]
        root = np.sqrt(a1 * a1 + 4 * a0_i * a2 * v)
        rp = (root - a1) / (2 * a2)
        rmn = (-a1 - root) / (2 * a2)
        rho = (w - rp) / (w - rmn) * np.exp(-root * ts)
        w = (rp - rho * rmn) / (1 - rho)
        current = par.drag_coefficient * float((W[k] ** 3).sum()) / (par.efficiency * vb) + par.avionics_current
        drawn += current * ts
    return W, vb_log, cur_log


def _stand_data(
    rng: np.random.Generator,
    pwm: np.ndarray,
    duty: np.ndarray,
    W: np.ndarray,
    vbat: np.ndarray,
    current: np.ndarray,
    kt_i: np.ndarray,
    par: QuadrotorParameters,
    eff: dict,
    ts: float,
) -> IOData:
    """The stand's log: load cell thrust and torque, speeds and voltage with their sensor noise."""
    n = W.shape[0]
    ns = 1.0 if eff["noise"] else 0.0
    thrust = (kt_i * W**2).sum(1) + ns * 0.002 * rng.standard_normal(n)
    torque1 = par.drag_coefficient * W[:, 0] ** 2 + ns * 2e-6 * rng.standard_normal(n)
    wm = W + ns * 5.0 * rng.standard_normal((n, 4))
    extra = {
        "duty": duty,
        "vbat": vbat + ns * 5e-3 * rng.standard_normal(n),
        **{f"w{i + 1}": wm[:, i] for i in range(4)},
        **{f"rpm{i + 1}": wm[:, i] * 60 / (2 * np.pi) for i in range(4)},
        "torque1": torque1,
        "current": current,
    }
    units = {
        "duty": "1",
        "vbat": "V",
        **{f"w{i + 1}": "rad/s" for i in range(4)},
        **{f"rpm{i + 1}": "rpm" for i in range(4)},
        "torque1": "N m",
        "current": "A",
    }
    return IOData(
        thrust,
        pwm,
        ts,
        output_name="thrust",
        input_names=("pwm",),
        output_unit="N",
        input_units=("1",),
        extra=extra,
        extra_units=units,
    )


def thrust_stand_static(
    seed: int = 0,
    pwm_levels=None,
    supply_levels=(3.5, 3.7, 3.9, 4.1),
    thrust_noise: float = 0.002,
    parameters: QuadrotorParameters | None = None,
) -> IOData:
    """Static thrust-stand table: settled thrust and torque per (PWM, supply voltage) point.

    Parameters
    ----------
    seed : int
    pwm_levels : array_like, optional
        PWM commands (0..65535); default 12 levels from 15 % to 100 %.
    supply_levels : sequence of float
        Bench-supply voltages [V], standing in for battery charge levels (as in the
        set-membership quadrocopter study "Robust Identification of Quadrocopter Model for Control
        Purposes").
    thrust_noise : float
        Standard deviation of the load-cell noise [N] (uniform noise of that half-width, so the
        error is bounded as set-membership assumes).
    parameters : QuadrotorParameters, optional

    Returns
    -------
    IOData
        One sample per operating point (``ts = 1``): output ``thrust`` [N] (all four motors),
        input ``pwm``; extra ``duty``, ``vbat`` [V], ``w`` [rad/s] (settled speed of each motor),
        ``torque1`` [N m] (reaction torque of one motor).
    """
    par = parameters or QuadrotorParameters()
    rng = seeded_rng(seed)
    pwm_levels = np.linspace(0.15, 1.0, 12) * PWM_FULL_SCALE if pwm_levels is None else np.asarray(pwm_levels, float)
    from .motor import MotorModel

    motor = MotorModel(*par.motor)
    pw, vb = np.meshgrid(pwm_levels, np.asarray(supply_levels, float))
    pw, vb = pw.ravel(), vb.ravel()
    duty = pw / PWM_FULL_SCALE
    w = motor.steady_speed(duty * vb)
    thrust = 4 * par.thrust_coefficient * w**2 + thrust_noise * rng.uniform(-1, 1, w.size)
    torque = par.drag_coefficient * w**2 + thrust_noise * 0.005 * rng.uniform(-1, 1, w.size)
    return IOData(
        thrust,
        pw,
        1.0,
        output_name="thrust",
        input_names=("pwm",),
        output_unit="N",
        extra={"duty": duty, "vbat": vb, "w": w, "torque1": torque},
        extra_units={"vbat": "V", "w": "rad/s", "torque1": "N m"},
    )
