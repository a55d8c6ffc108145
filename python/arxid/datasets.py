"""Simulated data sets with known answers: a quadrotor flight and a thrust stand.

Both simulators are deterministic for a seed and expose their true parameters
(:class:`QuadrotorParameters`), so every identification in :mod:`arxid.quadrotor` can be checked
against the truth. They produce the embedded default data of ``arxid demo``: arxid ships no
third-party data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .data import IOData
from .exceptions import DataError

__all__ = ["QuadrotorParameters", "DEFAULT_EFFECTS", "quadrotor_flight", "quadrotor_axis",
           "thrust_stand", "thrust_stand_static"]

#: Hidden effects of :func:`quadrotor_flight` and their defaults.
DEFAULT_EFFECTS = {"battery_sag": True, "motor_mismatch": False, "gyroscopic": True, "delay": True,
                   "noise": True, "turbulence": True}

_G = 9.81
PWM_FULL_SCALE = 65535.0


@dataclass(frozen=True)
class QuadrotorParameters:
    """True parameters of the simulated quadrotor (Crazyflie 2.1 sized, plus frame of seed 004).

    Attributes
    ----------
    mass : float
        [kg].
    arm : float
        Distance from the centre to each motor [m].
    inertia : tuple of 3 float
        ``Ixx, Iyy, Izz`` [kg m^2].
    rotor_inertia : float
        Inertia of one rotor with propeller [kg m^2] (gyroscopic term ``Ir * Omega x e_z * w``).
    thrust_coefficient : float
        ``k`` in ``f = k w^2`` [N s^2/rad^2].
    drag_coefficient : float
        ``b`` in the reaction torque ``b w^2`` [N m s^2/rad^2].
    motor : tuple of 3 float
        ``a0, a1, a2`` of ``dw/dt = a0 V - a1 w - a2 w^2`` (w in rad/s, V in volt).
    mismatch : tuple of 4 float
        Relative deviation of each motor's ``a0`` and thrust coefficient when the
        ``motor_mismatch`` effect is on.
    battery_full, battery_empty : float
        Open-circuit voltage with a full and an empty battery [V] (linear in charge drawn).
    capacity_mah : float
        Battery capacity. Scaled down from a real 250 mAh so that a 20 s log spans the voltage
        range of a several-minute flight.
    internal_resistance : float
        [ohm]; the voltage sags by ``R * I`` under load.
    efficiency : float
        Mechanical / electrical power of the propulsion; sets the load current.
    avionics_current : float
        [A].
    nominal_voltage : float
        Voltage the controller assumes when it turns thrust requests into duty (it does not
        compensate the battery), and the constant battery voltage when ``battery_sag`` is off [V].
    delay_samples : int
        Samples from a motor-speed change to its first effect on the logged attitude (seed 004
        found ``nk = 8`` at 2 ms): one sample of sampling plus ``delay_samples - 1`` of sensor lag.
    gyro_noise : float
        Gyro white noise [rad/s] (a BMI088 after the Crazyflie's 80 Hz filter).
    tilt_noise : float
        Noise of the accelerometer's tilt angle [rad] that the attitude estimate leans on.
    estimator_time_constant : float
        Complementary-filter time constant [s]: the attitude estimate integrates the gyro and
        follows the accelerometer tilt only this slowly, so its error is slow, not white.
    speed_noise, vbat_noise, accel_noise : float
        Noise of the logged motor speeds [rad/s], battery voltage [V] and ``az`` [m/s^2].
    turbulence : float
        RMS of the gust torque on each axis [N m] (``turbulence`` effect).
    turbulence_time_constant : float
        Correlation time of the gust torque [s] (first-order low-pass white noise).
    pilot_amplitude : tuple of 3 float
        RMS of the roll, pitch and yaw references [rad].
    pilot_band : tuple of 2 float
        Frequency band of the roll and pitch reference sines [Hz] (yaw: 0.05-0.5 Hz).
    pilot_sines : int
        Number of sines in the roll and pitch references.
    """

    mass: float = 0.027
    arm: float = 0.046
    inertia: tuple = (1.66e-5, 1.67e-5, 2.93e-5)
    rotor_inertia: float = 3.0e-9
    thrust_coefficient: float = 2.08e-8
    drag_coefficient: float = 1.1e-10
    motor: tuple = (2.0e4, 20.0, 1.6e-3)
    mismatch: tuple = (0.04, -0.03, 0.02, -0.05)
    battery_full: float = 4.15
    battery_empty: float = 3.45
    capacity_mah: float = 20.0
    internal_resistance: float = 0.15
    efficiency: float = 0.5
    avionics_current: float = 0.2
    nominal_voltage: float = 3.8
    delay_samples: int = 8
    gyro_noise: float = 2.5e-3
    tilt_noise: float = 5e-3
    estimator_time_constant: float = 1.0
    speed_noise: float = 1.0
    vbat_noise: float = 5e-3
    accel_noise: float = 0.05
    turbulence: float = 1.5e-5
    turbulence_time_constant: float = 0.01
    pilot_amplitude: tuple = (0.10, 0.10, 0.05)
    pilot_band: tuple = (1.0, 6.0)
    pilot_sines: int = 8

    @property
    def roll_gain(self) -> float:
        """``c`` of seed 003's ``roll'' = c (w4^2 - w2^2)``: ``k * arm / Ixx``."""
        return self.thrust_coefficient * self.arm / self.inertia[0]

    @property
    def pitch_gain(self) -> float:
        """``k * arm / Iyy``."""
        return self.thrust_coefficient * self.arm / self.inertia[1]

    @property
    def yaw_gain(self) -> float:
        """``b / Izz``."""
        return self.drag_coefficient / self.inertia[2]


def _effects(effects) -> dict:
    out = dict(DEFAULT_EFFECTS)
    if effects is not None:
        unknown = set(effects) - set(out)
        if unknown:
            raise DataError(f"unknown effects {sorted(unknown)}; the simulator knows {sorted(out)}")
        out.update({k: bool(v) for k, v in effects.items()})
    return out


def _sum_of_sines(rng, t, amplitude, f_lo, f_hi, n=5):
    """Pilot-like excitation: n sines log-spaced over [f_lo, f_hi] (each jittered by up to 10 %)
    with random phases, amplitudes falling as 1/f^2 as in seed 001 eq. 15 (equal acceleration
    content), normalised to ``amplitude`` RMS. Log spacing keeps every seed's log equally rich in
    the fast content that makes the delay identifiable."""
    f = np.geomspace(f_lo, f_hi, n) * np.exp(rng.uniform(-0.1, 0.1, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    a = 1.0 / f**2
    w = 2 * np.pi * f
    x = (a * np.sin(np.outer(t, w) + ph)).sum(axis=1)
    xd = (a * w * np.cos(np.outer(t, w) + ph)).sum(axis=1)
    s = amplitude / np.sqrt(0.5 * (a**2).sum())
    return s * x, s * xd


def _eq15(t):
    """Seed 001 eq. 15: the vertical reference z(t) and its first two derivatives."""
    w = 2 * np.pi * np.array([0.3, 0.2, 0.1, 0.5, 0.6])
    a = 0.3 * np.array([1.0, 0.95, 0.9, 0.8, 0.7]) / w**2
    ph = np.pi * np.array([1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6])
    arg = np.outer(t, w) + ph
    return (a * np.sin(arg)).sum(1), (a * w * np.cos(arg)).sum(1), -(a * w**2 * np.sin(arg)).sum(1)


#: Largest simulated record (samples): 10^4 s at 2 ms, about a gigabyte of state; more is refused
#: before anything is allocated.
MAX_SAMPLES = 5_000_000


def _check_timing(duration, ts):
    if not (ts > 0 and math.isfinite(ts)):
        raise DataError(f"ts must be a positive number of seconds, got {ts!r}")
    if not math.isfinite(duration):
        raise DataError(f"duration must be a finite number of seconds, got {duration!r}")
    n = int(round(duration / ts))
    if n < 100:
        raise DataError(f"duration {duration} s at ts {ts} s gives {n} samples; ask for at least 100")
    if n > MAX_SAMPLES:
        raise DataError(f"duration {duration:g} s at ts {ts} s gives {n} samples; ask for at most {MAX_SAMPLES} "
                        f"({MAX_SAMPLES * ts:g} s)")
    return n


def _rng(seed):
    """``numpy.random.default_rng(seed)`` with a DataError for a seed it cannot take."""
    try:
        return np.random.default_rng(seed)
    except (ValueError, TypeError):
        raise DataError(f"seed must be a non-negative integer, got {seed!r}") from None


def quadrotor_flight(seed: int = 0, duration: float = 20.0, ts: float = 0.002, effects=None,
                     output: str = "roll", parameters: QuadrotorParameters | None = None) -> IOData:
    """Simulate a closed-loop quadrotor flight with pilot-like excitation.

    Parameters
    ----------
    seed : int
        Seeds excitation and noise; the same seed gives the same log, bit for bit.
    duration : float
        [s].
    ts : float
        Sampling and integration step [s] (2 ms as in seeds 003 and 004).
    effects : dict of str to bool, optional
        Hidden effects to switch (missing keys keep their defaults):

        ``battery_sag`` (default on)
            Battery voltage drops with charge drawn and sags with load current; off: constant
            ``nominal_voltage``.
        ``motor_mismatch`` (default off)
            Each motor's ``a0`` and thrust coefficient deviate by ``parameters.mismatch``.
        ``gyroscopic`` (default on)
            The ``Omega x I Omega`` and rotor terms of seed 004 eqs. 13-17.
        ``delay`` (default on)
            The logged attitude and rates lag the motors: ``nk = delay_samples`` (8) instead of 1.
        ``noise`` (default on)
            Sensor noise: gyro noise (logged in ``p, q, r`` and integrated by the attitude
            estimate), accelerometer tilt noise (low-passed by the estimate), motor-speed,
            battery-voltage and accelerometer noise. Off: the logged attitude is the true one.
        ``turbulence`` (default on)
            A broadband gust torque on every axis (``parameters.turbulence`` RMS, correlation
            time ``turbulence_time_constant``), about 0.25 degrees of hover jitter.
    output : str
        Which logged signal becomes the output (``"roll"``, ``"pitch"``, ``"yaw"``, ``"az"``, ...).
    parameters : QuadrotorParameters, optional
        True parameters (default :class:`QuadrotorParameters()`).

    Returns
    -------
    IOData
        Inputs: PWM duty ``d1..d4``. Output: ``output``. Extra signals: ``roll, pitch, yaw``
        [rad] (logged, delayed), ``p, q, r`` [rad/s] (gyro, delayed), ``w1..w4`` [rad/s] (motor
        speeds), ``vbat`` [V], ``thrust`` [N] (true total thrust), ``az`` [m/s^2]
        (accelerometer, body z specific force), ``z`` [m], ``tau_x, tau_y, tau_z`` [N m] (true
        body torques), ``roll_ref, pitch_ref, yaw_ref`` [rad], ``current`` [A].

    Notes
    -----
    Plus frame, motor 1 front, 2 right, 3 back, 4 left (seed 004). Rotational dynamics (eqs. 13-17)::

        Ixx p' = k l (w4^2 - w2^2) + (Iyy - Izz) q r - Ir q W
        Iyy q' = k l (w3^2 - w1^2) + (Izz - Ixx) p r + Ir p W
        Izz r' = b (-w1^2 + w2^2 - w3^2 + w4^2) + (Ixx - Iyy) p q,   W = -w1 + w2 - w3 + w4

    with Euler-angle kinematics, integrated by semi-implicit Euler at ``ts``. The logged attitude
    is a complementary filter's estimate (gyro integrated, pulled towards the accelerometer tilt
    with ``estimator_time_constant``), delayed with the gyro by ``delay_samples - 1`` samples; the
    controller flies on these logged values. Motors follow
    ``w' = a0 vbat d - a1 w - a2 w^2``, integrated exactly over each sample. A PID attitude
    controller (on the delayed measurements) and an altitude loop tracking seed 001's eq. 15
    compute thrust and torques, allocate them to squared speeds with the nominal parameters and
    turn those into duty assuming ``nominal_voltage`` (no battery compensation). The battery's
    open-circuit voltage falls linearly with charge drawn; the terminal voltage sags by
    ``R * I`` with ``I`` from the propellers' mechanical power.

    Examples
    --------
    >>> from arxid.datasets import quadrotor_flight
    >>> d = quadrotor_flight(seed=1, duration=2.0)
    >>> d.n_samples, d.input_names
    (1000, ('d1', 'd2', 'd3', 'd4'))
    """
    eff = _effects(effects)
    par = parameters or QuadrotorParameters()
    n = _check_timing(duration, ts)
    rng = _rng(seed)
    t = np.arange(n) * ts

    # references: roll/pitch/yaw sums of sines, altitude from seed 001 eq. 15
    (a_r, a_p, a_y), (lo, hi) = par.pilot_amplitude, par.pilot_band
    phr, phrd = _sum_of_sines(rng, t, a_r, lo, hi, par.pilot_sines)
    thr, thrd = _sum_of_sines(rng, t, a_p, lo, hi, par.pilot_sines)
    psr, psrd = _sum_of_sines(rng, t, a_y, 0.05, 0.5)
    zr, zrd, zrdd = _eq15(t)

    # noise, drawn up front so the loop stays lean and the log is the same with noise off
    # (the draw order is fixed: switching an effect never changes the other random signals)
    ns = 1.0 if eff["noise"] else 0.0
    raw = {k: rng.standard_normal((n, 3) if k in ("tilt", "gyro") else ((n, 4) if k == "w" else n))
           for k in ("tilt", "gyro", "w", "vbat", "az")}
    turb = rng.standard_normal((n, 3))
    gyro_noise = ns * par.gyro_noise * raw["gyro"]
    # attitude estimate: a complementary filter integrates the gyro and pulls towards the
    # accelerometer's tilt with time constant estimator_time_constant; its error is the gyro noise
    # integrated and the tilt noise low-passed (the linearised filter, exact for noise off)
    beta = math.exp(-ts / par.estimator_time_constant)
    from scipy.signal import lfilter

    att_err = lfilter([1.0], [1.0, -beta], ts * gyro_noise + (1 - beta) * ns * par.tilt_noise * raw["tilt"], axis=0)
    # turbulence torque: first-order low-pass white noise of RMS par.turbulence [N m]
    alpha = math.exp(-ts / par.turbulence_time_constant)
    turb_f = lfilter([math.sqrt(1 - alpha * alpha)], [1.0, -alpha], turb, axis=0)
    turb_f *= par.turbulence if eff["turbulence"] else 0.0

    ixx, iyy, izz = par.inertia
    ir = par.rotor_inertia if eff["gyroscopic"] else 0.0
    gyro = 1.0 if eff["gyroscopic"] else 0.0
    kt, kq, arm, mass = par.thrust_coefficient, par.drag_coefficient, par.arm, par.mass
    a0, a1, a2 = par.motor
    mis = np.asarray(par.mismatch, float) if eff["motor_mismatch"] else np.zeros(4)
    a0_i = a0 * (1 + mis)
    kt_i = kt * (1 + mis * 0.5)
    dm = max(par.delay_samples - 1, 0) if eff["delay"] else 0
    vnom = par.nominal_voltage
    cap = par.capacity_mah * 3.6  # coulomb
    sag = eff["battery_sag"]

    # gains (acceleration commands): PID on roll/pitch, PD on yaw, PID on altitude
    kp, kd, ki = 36.0, 12.0, 5.0
    kpy, kdy = 9.0, 6.0
    kpz, kdz, kiz = 9.0, 6.0, 3.0

    ang = np.zeros((n, 3))
    rate = np.zeros((n, 3))
    W = np.zeros((n, 4))
    D = np.zeros((n, 4))
    vb_log = np.zeros(n)
    T_log = np.zeros(n)
    tau_log = np.zeros((n, 3))
    z_log = np.zeros(n)
    cur_log = np.zeros(n)

    phi = th = psi = 0.0
    p = q = r = 0.0
    z = zd = 0.0
    iphi = ith = iz = 0.0
    w_hover = math.sqrt(mass * _G / (4 * kt))
    w = np.full(4, w_hover)
    drawn = 0.0
    current = 0.0
    nang = att_err
    nrate = gyro_noise
    sin, cos, tan, sqrt, exp = math.sin, math.cos, math.tan, math.sqrt, math.exp
    wl = [w_hover] * 4
    for k in range(n):
        ang[k] = (phi, th, psi)
        rate[k] = (p, q, r)
        # delayed, noisy measurements for the controller (the same values are logged)
        j = k - dm if k >= dm else 0
        phm = ang[j, 0] + nang[k, 0]
        thm = ang[j, 1] + nang[k, 1]
        psm = ang[j, 2] + nang[k, 2]
        pm = rate[j, 0] + nrate[k, 0]
        qm = rate[j, 1] + nrate[k, 1]
        rm = rate[j, 2] + nrate[k, 2]
        eph = phr[k] - phm
        eth = thr[k] - thm
        iphi += eph * ts
        ith += eth * ts
        tx = ixx * (kp * eph + kd * (phrd[k] - pm) + ki * iphi)
        ty = iyy * (kp * eth + kd * (thrd[k] - qm) + ki * ith)
        tz = izz * (kpy * (psr[k] - psm) + kdy * (psrd[k] - rm))
        ez = zr[k] - z
        iz += ez * ts
        tcmd = mass * (_G + kpz * ez + kdz * (zrd[k] - zd) + kiz * iz + zrdd[k]) / max(cos(phm) * cos(thm), 0.5)
        # allocation with nominal parameters (plus frame), then duty at the nominal voltage
        s4 = tcmd / (4 * kt)
        rr = tx / (2 * kt * arm)
        pp = ty / (2 * kt * arm)
        yy = tz / (4 * kq)
        wsq = (s4 - pp - yy, s4 - rr + yy, s4 + pp - yy, s4 + rr + yy)
        duty = []
        for ws in wsq:
            wd = sqrt(ws) if ws > 0 else 0.0
            dd = (a1 * wd + a2 * wd * wd) / (a0 * vnom)
            duty.append(1.0 if dd > 1 else (0.0 if dd < 0 else dd))
        # battery: open-circuit voltage from charge drawn, sag from last sample's current
        if sag:
            vb = par.battery_full - (par.battery_full - par.battery_empty) * min(drawn / cap, 1.0) \
                - par.internal_resistance * current
        else:
            vb = vnom
        # forces from the present speeds
        w1, w2, w3, w4 = wl
        f1, f2, f3, f4 = kt_i[0] * w1 * w1, kt_i[1] * w2 * w2, kt_i[2] * w3 * w3, kt_i[3] * w4 * w4
        thrust = f1 + f2 + f3 + f4
        bx = arm * (f4 - f2) + turb_f[k, 0]
        by = arm * (f3 - f1) + turb_f[k, 1]
        bz = kq * (-w1 * w1 + w2 * w2 - w3 * w3 + w4 * w4) + turb_f[k, 2]
        W[k] = wl
        D[k] = duty
        vb_log[k] = vb
        T_log[k] = thrust
        tau_log[k] = (bx, by, bz)
        z_log[k] = z
        cur_log[k] = current
        # motors: exact step of the Riccati equation with the voltage held
        new = []
        for i in range(4):
            v = vb * duty[i]
            root = sqrt(a1 * a1 + 4 * a0_i[i] * a2 * v)
            rp = (root - a1) / (2 * a2)
            rmn = (-a1 - root) / (2 * a2)
            wi = wl[i]
            rho = (wi - rp) / (wi - rmn) * exp(-root * ts)
            new.append((rp - rho * rmn) / (1 - rho))
        # rigid body (seed 004 eqs. 13-17), semi-implicit Euler
        om = -w1 + w2 - w3 + w4
        pd_ = (bx + gyro * (iyy - izz) * q * r - ir * q * om) / ixx
        qd_ = (by + gyro * (izz - ixx) * p * r + ir * p * om) / iyy
        rd_ = (bz + gyro * (ixx - iyy) * p * q) / izz
        p += ts * pd_
        q += ts * qd_
        r += ts * rd_
        sph, cph, cth = sin(phi), cos(phi), cos(th)
        phi += ts * (p + tan(th) * (sph * q + cph * r))
        th += ts * (cph * q - sph * r)
        psi += ts * ((sph * q + cph * r) / cth)
        zd += ts * (thrust * cph * cth / mass - _G)
        z += ts * zd
        # load current: propellers' mechanical power / efficiency / voltage
        pmech = kq * (w1 ** 3 + w2 ** 3 + w3 ** 3 + w4 ** 3)
        current = pmech / (par.efficiency * vb) + par.avionics_current
        drawn += current * ts
        wl = new

    idx = np.maximum(np.arange(n) - dm, 0)
    ang_m = ang[idx] + att_err
    rate_m = rate[idx] + gyro_noise
    sig_out = {
        "roll": ang_m[:, 0], "pitch": ang_m[:, 1], "yaw": ang_m[:, 2],
        "p": rate_m[:, 0], "q": rate_m[:, 1], "r": rate_m[:, 2],
        **{f"w{i + 1}": W[:, i] + ns * par.speed_noise * raw["w"][:, i] for i in range(4)},
        "vbat": vb_log + ns * par.vbat_noise * raw["vbat"], "thrust": T_log,
        "az": T_log / mass + ns * par.accel_noise * raw["az"],
        "z": z_log, "tau_x": tau_log[:, 0], "tau_y": tau_log[:, 1], "tau_z": tau_log[:, 2],
        "roll_ref": phr, "pitch_ref": thr, "yaw_ref": psr, "current": cur_log,
    }
    units = {"roll": "rad", "pitch": "rad", "yaw": "rad", "p": "rad/s", "q": "rad/s", "r": "rad/s",
             **{f"w{i + 1}": "rad/s" for i in range(4)}, "vbat": "V", "thrust": "N", "az": "m/s^2",
             "z": "m", "tau_x": "N m", "tau_y": "N m", "tau_z": "N m", "roll_ref": "rad",
             "pitch_ref": "rad", "yaw_ref": "rad", "current": "A"}
    if output not in sig_out:
        raise DataError(f"unknown output {output!r}; choose from {sorted(sig_out)}")
    y = sig_out.pop(output)
    return IOData(y, D, ts, output_name=output, input_names=("d1", "d2", "d3", "d4"),
                  output_unit=units[output], input_units=("1",) * 4, extra=sig_out,
                  extra_units={k: units[k] for k in sig_out})


def quadrotor_axis(data: IOData, axis: str = "roll", frame: str = "plus",
                   extra=("vbat", "thrust", "roll", "pitch", "yaw")) -> IOData:
    """Identification data set of one axis: logged angle against its mixer pseudo-torque.

    Parameters
    ----------
    data : IOData
        A flight log with ``w1..w4`` and the angle (e.g. from :func:`quadrotor_flight`).
    axis : {"roll", "pitch", "yaw"}
    frame : {"plus", "x"}
        Mixer frame (the simulator flies a plus frame).
    extra : sequence of str
        Signals kept as extra signals (those that are not the output).

    Returns
    -------
    IOData
        Output the angle [rad], input ``<axis>_torque`` [(rad/s)^2] (e.g. ``w4^2 - w2^2``).
    """
    from .quadrotor.mixer import Mixer

    if axis not in ("roll", "pitch", "yaw"):
        raise DataError(f"axis must be 'roll', 'pitch' or 'yaw', got {axis!r}")
    angle = data.signal(axis)
    keep = {}
    for name in extra:
        if name != axis:
            keep[name] = data.signal(name)
    src = IOData(angle, np.column_stack([data.signal(f"w{i}") for i in range(1, 5)]), data.ts,
                 output_name=axis, input_names=("w1", "w2", "w3", "w4"), output_unit="rad",
                 input_units=("rad/s",) * 4, extra=keep,
                 extra_units={k: data.unit(k) for k in keep}, experiment_starts=data.experiment_starts)
    mixed = Mixer(frame).apply(src, channels=(f"{axis}_torque",))
    ex = {k: v for k, v in mixed.extra.items() if k not in ("w1", "w2", "w3", "w4")}
    return mixed.with_signals(extra=ex)


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
            out[k:k + hold] = rng.uniform(0.15, 1.0) * 65535
            k += hold
        return out
    if profile == "sines":  # seed 001 eq. 15 shape on the command, around 55 % throttle
        f = np.array([0.3, 0.2, 0.1, 0.5, 0.6]) * 4
        a = np.array([1.0, 0.95, 0.9, 0.8, 0.7])
        ph = np.pi * np.array([1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6]) + rng.uniform(0, 0.3, 5)
        x = (a * np.sin(2 * np.pi * np.outer(t, f) + ph)).sum(1)
        return np.clip(0.55 + 0.38 * x / np.abs(x).max(), 0.1, 1.0) * 65535
    raise DataError(f"unknown profile {profile!r}; use 'ramp', 'steps' or 'sines'")


def thrust_stand(seed: int = 0, duration: float = 60.0, ts: float = 0.01, profile: str = "sines",
                 supply: float | None = None, effects=None,
                 parameters: QuadrotorParameters | None = None) -> IOData:
    """Simulate the whole quadrotor on a load cell, all four motors on one PWM command.

    Parameters
    ----------
    seed : int
    duration : float
        [s].
    ts : float
        [s].
    profile : {"sines", "ramp", "steps"}
        PWM command: a sum of five sines (seed 001 eq. 15 shape), a slow ramp up and back down
        (like the Bitcraze Crazyflie stand log) or random throttle steps (motor dynamics).
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
    eff = _effects(effects)
    par = parameters or QuadrotorParameters()
    n = _check_timing(duration, ts)
    rng = _rng(seed)
    t = np.arange(n) * ts
    pwm = _stand_pwm(profile, t, rng)
    duty = pwm / PWM_FULL_SCALE
    a0, a1, a2 = par.motor
    mis = np.asarray(par.mismatch, float) if eff["motor_mismatch"] else np.zeros(4)
    a0_i = a0 * (1 + mis)
    kt_i = par.thrust_coefficient * (1 + 0.5 * mis)
    cap = par.capacity_mah * 3.6
    W = np.zeros((n, 4))
    vb_log = np.zeros(n)
    cur_log = np.zeros(n)
    w = np.zeros(4)
    drawn = current = 0.0
    for k in range(n):
        if supply is None:
            vb = par.battery_full - (par.battery_full - par.battery_empty) * min(drawn / cap, 1.0) \
                - par.internal_resistance * current
        else:
            vb = float(supply)
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
    ns = 1.0 if eff["noise"] else 0.0
    thrust = (kt_i * W**2).sum(1) + ns * 0.002 * rng.standard_normal(n)
    torque1 = par.drag_coefficient * W[:, 0] ** 2 + ns * 2e-6 * rng.standard_normal(n)
    wm = W + ns * 5.0 * rng.standard_normal((n, 4))
    extra = {"duty": duty, "vbat": vb_log + ns * 5e-3 * rng.standard_normal(n),
             **{f"w{i + 1}": wm[:, i] for i in range(4)},
             **{f"rpm{i + 1}": wm[:, i] * 60 / (2 * np.pi) for i in range(4)},
             "torque1": torque1, "current": cur_log}
    units = {"duty": "1", "vbat": "V", **{f"w{i + 1}": "rad/s" for i in range(4)},
             **{f"rpm{i + 1}": "rpm" for i in range(4)}, "torque1": "N m", "current": "A"}
    return IOData(thrust, pwm, ts, output_name="thrust", input_names=("pwm",), output_unit="N",
                  input_units=("1",), extra=extra, extra_units=units)


def thrust_stand_static(seed: int = 0, pwm_levels=None, supply_levels=(3.5, 3.7, 3.9, 4.1),
                        thrust_noise: float = 0.002, parameters: QuadrotorParameters | None = None) -> IOData:
    """Static thrust-stand table: settled thrust and torque per (PWM, supply voltage) point.

    Parameters
    ----------
    seed : int
    pwm_levels : array_like, optional
        PWM commands (0..65535); default 12 levels from 15 % to 100 %.
    supply_levels : sequence of float
        Bench-supply voltages [V], standing in for battery charge levels (seed 000).
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
    rng = _rng(seed)
    pwm_levels = np.linspace(0.15, 1.0, 12) * PWM_FULL_SCALE if pwm_levels is None else np.asarray(pwm_levels, float)
    from .quadrotor.motor import MotorModel

    motor = MotorModel(*par.motor)
    pw, vb = np.meshgrid(pwm_levels, np.asarray(supply_levels, float))
    pw, vb = pw.ravel(), vb.ravel()
    duty = pw / PWM_FULL_SCALE
    w = motor.steady_speed(duty * vb)
    thrust = 4 * par.thrust_coefficient * w**2 + thrust_noise * rng.uniform(-1, 1, w.size)
    torque = par.drag_coefficient * w**2 + thrust_noise * 0.005 * rng.uniform(-1, 1, w.size)
    return IOData(thrust, pw, 1.0, output_name="thrust", input_names=("pwm",), output_unit="N",
                  extra={"duty": duty, "vbat": vb, "w": w, "torque1": torque},
                  extra_units={"vbat": "V", "w": "rad/s", "torque1": "N m"})
