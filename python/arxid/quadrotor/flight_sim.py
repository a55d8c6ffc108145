"""The quadrotor flight simulator behind :func:`arxid.datasets.quadrotor_flight`.

The aircraft, controller, sensors and battery it simulates are described in :mod:`arxid.datasets`
("The flight simulator"). :class:`QuadrotorParameters` (the truth), the effect switches, the record
length checks and the battery model are shared with the thrust stand (:mod:`arxid.quadrotor.stand_sim`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = ["QuadrotorParameters", "DEFAULT_EFFECTS", "quadrotor_flight"]

#: Hidden effects of :func:`quadrotor_flight` and their defaults.
DEFAULT_EFFECTS = {
    "battery_sag": True,
    "motor_mismatch": False,
    "gyroscopic": True,
    "delay": True,
    "noise": True,
    "turbulence": True,
}

_G = 9.81


@dataclass(frozen=True)
class QuadrotorParameters:
    """True parameters of the simulated quadrotor (Crazyflie 2.1 sized, plus frame of Sarıoğlu & Kural).

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
        Samples from a motor-speed change to its first effect on the logged attitude (Sarıoğlu & Kural
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
        """``c`` of ``roll'' = c (w4^2 - w2^2)``: ``k * arm / Ixx``.

        The rotational model of a published grey-box study of a Crazyflie's motor and rotational
        dynamics.
        """
        return self.thrust_coefficient * self.arm / self.inertia[0]

    @property
    def pitch_gain(self) -> float:
        """``k * arm / Iyy``."""
        return self.thrust_coefficient * self.arm / self.inertia[1]

    @property
    def yaw_gain(self) -> float:
        """``b / Izz``."""
        return self.drag_coefficient / self.inertia[2]


def effect_switches(effects) -> dict:
    """:data:`DEFAULT_EFFECTS` with the switches of ``effects`` (a mapping, or None) applied."""
    out = dict(DEFAULT_EFFECTS)
    if effects is not None:
        unknown = set(effects) - set(out)
        if unknown:
            raise DataError(f"unknown effects {sorted(unknown)}; the simulator knows {sorted(out)}")
        out.update({k: bool(v) for k, v in effects.items()})
    return out


def _sum_of_sines(rng, t, amplitude, f_lo, f_hi, n=5):
    """Pilot-like excitation: n sines log-spaced over [f_lo, f_hi] (each jittered by up to 10 %)
    with random phases, amplitudes falling as 1/f^2 as in eq. 15 of the battery-aware thrust study
    (Staub & Franchi, ICRA 2015; equal acceleration content), normalised to ``amplitude`` RMS. Log
    spacing keeps every random seed's log equally rich in the fast content that makes the delay
    identifiable."""
    f = np.geomspace(f_lo, f_hi, n) * np.exp(rng.uniform(-0.1, 0.1, n))
    ph = rng.uniform(0, 2 * np.pi, n)
    a = 1.0 / f**2
    w = 2 * np.pi * f
    x = (a * np.sin(np.outer(t, w) + ph)).sum(axis=1)
    xd = (a * w * np.cos(np.outer(t, w) + ph)).sum(axis=1)
    s = amplitude / np.sqrt(0.5 * (a**2).sum())
    return s * x, s * xd


def _eq15(t):
    """Staub & Franchi eq. 15: the vertical reference z(t) and its first two derivatives."""
    w = 2 * np.pi * np.array([0.3, 0.2, 0.1, 0.5, 0.6])
    a = 0.3 * np.array([1.0, 0.95, 0.9, 0.8, 0.7]) / w**2
    ph = np.pi * np.array([1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 6])
    arg = np.outer(t, w) + ph
    return (a * np.sin(arg)).sum(1), (a * w * np.cos(arg)).sum(1), -(a * w**2 * np.sin(arg)).sum(1)


#: Largest simulated record (samples): 10^4 s at 2 ms, about a gigabyte of state; more is refused
#: before anything is allocated.
MAX_SAMPLES = 5_000_000


def sample_count(duration, ts):
    """Samples of a record of ``duration`` at ``ts`` (both checked; 100 to :data:`MAX_SAMPLES`)."""
    if not (ts > 0 and math.isfinite(ts)):
        raise DataError(f"ts must be a positive number of seconds, got {ts!r}")
    if not math.isfinite(duration):
        raise DataError(f"duration must be a finite number of seconds, got {duration!r}")
    n = int(round(duration / ts))
    if n < 100:
        raise DataError(f"duration {duration} s at ts {ts} s gives {n} samples; ask for at least 100")
    if n > MAX_SAMPLES:
        raise DataError(
            f"duration {duration:g} s at ts {ts} s gives {n} samples; ask for at most {MAX_SAMPLES} "
            f"({MAX_SAMPLES * ts:g} s)"
        )
    return n


def seeded_rng(seed):
    """``numpy.random.default_rng(seed)`` with a DataError for a seed it cannot take."""
    try:
        return np.random.default_rng(seed)
    except (ValueError, TypeError):
        raise DataError(f"seed must be a non-negative integer, got {seed!r}") from None


# Signals of quadrotor_flight and their units (any of them can be the output).
_FLIGHT_UNITS = {
    "roll": "rad",
    "pitch": "rad",
    "yaw": "rad",
    "p": "rad/s",
    "q": "rad/s",
    "r": "rad/s",
    **{f"w{i + 1}": "rad/s" for i in range(4)},
    "vbat": "V",
    "thrust": "N",
    "az": "m/s^2",
    "z": "m",
    "tau_x": "N m",
    "tau_y": "N m",
    "tau_z": "N m",
    "roll_ref": "rad",
    "pitch_ref": "rad",
    "yaw_ref": "rad",
    "current": "A",
}


def quadrotor_flight(
    seed: int = 0,
    duration: float = 20.0,
    ts: float = 0.002,
    effects: Mapping[str, bool] | None = None,
    output: str = "roll",
    parameters: QuadrotorParameters | None = None,
    roll_reference=None,
) -> IOData:
    """Simulate a closed-loop quadrotor flight with pilot-like excitation.

    Parameters
    ----------
    seed : int
        Seeds excitation and noise; the same seed gives the same log, bit for bit.
    duration : float
        [s].
    ts : float
        Sampling and integration step [s] (2 ms as in the grey-box Crazyflie study and in
        Sarıoğlu & Kural's ARX study).
    effects : dict of str to bool, optional
        Hidden effects to switch (missing keys keep their defaults):

        ``battery_sag`` (default on)
            Battery voltage drops with charge drawn and sags with load current; off: constant
            ``nominal_voltage``.
        ``motor_mismatch`` (default off)
            Each motor's ``a0`` and thrust coefficient deviate by ``parameters.mismatch``.
        ``gyroscopic`` (default on)
            The ``Omega x I Omega`` and rotor terms of Sarıoğlu & Kural eqs. 13-17.
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
    roll_reference : array_like of shape (>= n_samples,), optional
        A designed roll setpoint [rad] (for instance an :mod:`arxid.inputs` PRBS or multisine)
        flown instead of the pilot's roll; its first ``duration / ts`` samples are used, with no
        rate feed-forward (the setpoint may step). It is logged as ``roll_ref``.

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
    The simulated aircraft, controller, sensors and battery are described in the docstring of
    :mod:`arxid.datasets` ("The flight simulator").

    Examples
    --------
    >>> from arxid.datasets import quadrotor_flight
    >>> d = quadrotor_flight(seed=1, duration=2.0)
    >>> d.n_samples, d.input_names
    (1000, ('d1', 'd2', 'd3', 'd4'))
    """
    eff = effect_switches(effects)
    par = parameters or QuadrotorParameters()
    n = sample_count(duration, ts)
    if output not in _FLIGHT_UNITS:
        raise DataError(f"unknown output {output!r}; choose from {sorted(_FLIGHT_UNITS)}")
    rng = seeded_rng(seed)
    # the draw order is fixed (references, then noise): switching an effect never changes the
    # other random signals
    ref = _pilot_references(rng, np.arange(n) * ts, par)
    if roll_reference is not None:
        ref = _designed_roll(ref, roll_reference, n)
    noise = _sensor_noise(rng, n, ts, par, eff)
    air = _Airframe.of(par, eff)
    log = _fly(ref, noise, air, par, ts)
    return _flight_data(log, ref, noise, air, par, output, ts)


@dataclass(frozen=True)
class _References:
    """Pilot references of a simulated flight (arrays of shape (n,)): angles [rad] and rates
    [rad/s], altitude [m] with its first two derivatives."""

    roll: np.ndarray
    roll_rate: np.ndarray
    pitch: np.ndarray
    pitch_rate: np.ndarray
    yaw: np.ndarray
    yaw_rate: np.ndarray
    z: np.ndarray
    z_rate: np.ndarray
    z_acc: np.ndarray


def _pilot_references(rng: np.random.Generator, t: np.ndarray, par: QuadrotorParameters) -> _References:
    """Roll, pitch and yaw references as sums of sines (drawn from ``rng`` in that order), altitude
    from Staub & Franchi's eq. 15."""
    (a_r, a_p, a_y), (lo, hi) = par.pilot_amplitude, par.pilot_band
    phr, phrd = _sum_of_sines(rng, t, a_r, lo, hi, par.pilot_sines)
    thr, thrd = _sum_of_sines(rng, t, a_p, lo, hi, par.pilot_sines)
    psr, psrd = _sum_of_sines(rng, t, a_y, 0.05, 0.5)
    zr, zrd, zrdd = _eq15(t)
    return _References(phr, phrd, thr, thrd, psr, psrd, zr, zrd, zrdd)


def _designed_roll(ref: _References, roll_reference, n: int) -> _References:
    """``ref`` with the roll setpoint replaced by a designed one (no rate feed-forward)."""
    r = np.asarray(roll_reference, dtype=float).reshape(-1)
    if r.shape[0] < n or not np.all(np.isfinite(r[:n])):
        raise DataError(
            f"roll_reference must hold at least {n} finite samples (duration / ts), got {r.shape[0]}; "
            "design a longer input or fly a shorter duration"
        )
    return replace(ref, roll=r[:n].copy(), roll_rate=np.zeros(n))


@dataclass(frozen=True)
class _Noise:
    """Random signals of a simulated flight, drawn up front so that the loop stays lean and the
    log is the same with noise off (``scale`` 0: every sensor noise is zero)."""

    scale: float
    raw: dict[str, np.ndarray]  # unit normal draws: tilt, gyro (n, 3), w (n, 4), vbat, az (n,)
    gyro: np.ndarray  # gyro noise (n, 3) [rad/s]
    attitude: np.ndarray  # error of the attitude estimate (n, 3) [rad]
    turbulence: np.ndarray  # gust torque (n, 3) [N m]


def _sensor_noise(rng: np.random.Generator, n: int, ts: float, par: QuadrotorParameters, eff: dict) -> _Noise:
    """Sensor noise and turbulence of ``n`` samples.

    The attitude estimate is a complementary filter: it integrates the gyro and pulls towards the
    accelerometer's tilt with time constant ``estimator_time_constant``, so its error is the gyro
    noise integrated plus the tilt noise low-passed (the linearised filter, exact for noise off).
    The turbulence torque is first-order low-passed white noise of RMS ``par.turbulence``.
    """
    from scipy.signal import lfilter

    ns = 1.0 if eff["noise"] else 0.0
    raw = {
        k: rng.standard_normal((n, 3) if k in ("tilt", "gyro") else ((n, 4) if k == "w" else n))
        for k in ("tilt", "gyro", "w", "vbat", "az")
    }
    turb = rng.standard_normal((n, 3))
    gyro_noise = ns * par.gyro_noise * raw["gyro"]
    beta = math.exp(-ts / par.estimator_time_constant)
    att_err = lfilter([1.0], [1.0, -beta], ts * gyro_noise + (1 - beta) * ns * par.tilt_noise * raw["tilt"], axis=0)
    alpha = math.exp(-ts / par.turbulence_time_constant)
    turb_f = lfilter([math.sqrt(1 - alpha * alpha)], [1.0, -alpha], turb, axis=0)
    turb_f *= par.turbulence if eff["turbulence"] else 0.0
    return _Noise(ns, raw, gyro_noise, att_err, turb_f)


@dataclass(frozen=True)
class _Airframe:
    """Constants of the flight loop: the true parameters with the effects switched in or out."""

    ixx: float
    iyy: float
    izz: float
    ir: float  # rotor inertia (0 without the gyroscopic effect)
    gyro: float  # 1 with the gyroscopic effect, else 0
    kt: float
    kq: float
    arm: float
    mass: float
    a0: float
    a1: float
    a2: float
    a0_i: tuple[float, ...]  # a0 of each motor (motor mismatch)
    kt_i: tuple[float, ...]  # thrust coefficient of each motor
    dm: int  # samples by which the logged attitude and rates lag the true ones
    vnom: float
    cap: float  # battery capacity [C]
    sag: bool

    @classmethod
    def of(cls, par: QuadrotorParameters, eff: dict) -> _Airframe:
        """The constants of ``par`` under the effects ``eff``."""
        mis = np.asarray(par.mismatch, float) if eff["motor_mismatch"] else np.zeros(4)
        a0, a1, a2 = par.motor
        ixx, iyy, izz = par.inertia
        return cls(
            ixx=ixx,
            iyy=iyy,
            izz=izz,
            ir=par.rotor_inertia if eff["gyroscopic"] else 0.0,
            gyro=1.0 if eff["gyroscopic"] else 0.0,
            kt=par.thrust_coefficient,
            kq=par.drag_coefficient,
            arm=par.arm,
            mass=par.mass,
            a0=a0,
            a1=a1,
            a2=a2,
            a0_i=tuple((a0 * (1 + mis)).tolist()),
            kt_i=tuple((par.thrust_coefficient * (1 + mis * 0.5)).tolist()),
            dm=max(par.delay_samples - 1, 0) if eff["delay"] else 0,
            vnom=par.nominal_voltage,
            cap=par.capacity_mah * 3.6,
            sag=eff["battery_sag"],
        )


class _FlightLog:
    """Per-sample records of :func:`_fly` (true attitude and rates, speeds, duty, battery, forces).

    The loop appends rows of Python floats to lists and :meth:`arrays` stacks them once at the end:
    writing a numpy row per sample, and the numpy scalars it hands back, cost several times the
    arithmetic itself. Python floats are the same IEEE doubles, so the log is bit for bit the same."""

    def __init__(self) -> None:
        self.ang: list[tuple[float, float, float]] = []
        self.rate: list[tuple[float, float, float]] = []
        self.w: list[list[float]] = []
        self.duty: list[list[float]] = []
        self.vbat: list[float] = []
        self.thrust: list[float] = []
        self.torque: list[tuple[float, float, float]] = []
        self.z: list[float] = []
        self.current: list[float] = []

    def measured(self, k: int, noise: _NoiseRows, dm: int) -> tuple[float, float, float, float, float, float]:
        """Delayed, noisy attitude and rates at sample ``k`` as the controller sees (and logs) them."""
        j = k - dm if k >= dm else 0
        (a0, a1, a2), (r0, r1, r2) = self.ang[j], self.rate[j]
        (na0, na1, na2), (nr0, nr1, nr2) = noise.attitude[k], noise.gyro[k]
        return a0 + na0, a1 + na1, a2 + na2, r0 + nr0, r1 + nr1, r2 + nr2

    def arrays(self) -> _FlightArrays:
        """The records as arrays of shape (n,) or (n, k)."""
        return _FlightArrays(**{name: np.array(rows, dtype=float) for name, rows in vars(self).items()})


@dataclass(frozen=True)
class _FlightArrays:
    """The records of :class:`_FlightLog` as arrays."""

    ang: np.ndarray
    rate: np.ndarray
    w: np.ndarray
    duty: np.ndarray
    vbat: np.ndarray
    thrust: np.ndarray
    torque: np.ndarray
    z: np.ndarray
    current: np.ndarray


class _NoiseRows:
    """The noise the loop reads, as lists of Python-float rows (see :class:`_FlightLog`)."""

    def __init__(self, noise: _Noise) -> None:
        self.attitude = noise.attitude.tolist()
        self.gyro = noise.gyro.tolist()
        self.turbulence = noise.turbulence.tolist()


class _Controller:
    """PID on roll and pitch, PD on yaw, PID on altitude (acceleration commands), flying on the
    delayed measurements, allocating with the nominal parameters and turning squared speeds into
    duty at the nominal voltage (no battery compensation)."""

    kp, kd, ki = 36.0, 12.0, 5.0
    kpy, kdy = 9.0, 6.0
    kpz, kdz, kiz = 9.0, 6.0, 3.0

    def __init__(self, ref: _References, air: _Airframe, ts: float):
        # lists of Python floats: see _FlightLog
        self.ref = SimpleNamespace(**{name: values.tolist() for name, values in vars(ref).items()})
        self.air, self.ts = air, ts
        self.iphi = self.ith = self.iz = 0.0

    def duty(self, k: int, meas: tuple, z: float, zd: float) -> list[float]:
        """Duty of the four motors at sample ``k`` (integrators advance by one sample)."""
        ref, air, ts = self.ref, self.air, self.ts
        kp, kd, ki = self.kp, self.kd, self.ki
        phm, thm, psm, pm, qm, rm = meas
        eph = ref.roll[k] - phm
        eth = ref.pitch[k] - thm
        self.iphi += eph * ts
        self.ith += eth * ts
        tx = air.ixx * (kp * eph + kd * (ref.roll_rate[k] - pm) + ki * self.iphi)
        ty = air.iyy * (kp * eth + kd * (ref.pitch_rate[k] - qm) + ki * self.ith)
        tz = air.izz * (self.kpy * (ref.yaw[k] - psm) + self.kdy * (ref.yaw_rate[k] - rm))
        ez = ref.z[k] - z
        self.iz += ez * ts
        acc = _G + self.kpz * ez + self.kdz * (ref.z_rate[k] - zd) + self.kiz * self.iz + ref.z_acc[k]
        tcmd = air.mass * acc / max(math.cos(phm) * math.cos(thm), 0.5)
        return _allocate(air, tx, ty, tz, tcmd)


def _allocate(air: _Airframe, tx: float, ty: float, tz: float, tcmd: float) -> list[float]:
    """Plus-frame allocation of torques and thrust to squared speeds, then duty at ``vnom`` in [0, 1]."""
    kt, arm, a1, a2 = air.kt, air.arm, air.a1, air.a2
    s4 = tcmd / (4 * kt)
    rr = tx / (2 * kt * arm)
    pp = ty / (2 * kt * arm)
    yy = tz / (4 * air.kq)
    duty = []
    for ws in (s4 - pp - yy, s4 - rr + yy, s4 + pp - yy, s4 + rr + yy):
        wd = math.sqrt(ws) if ws > 0 else 0.0
        dd = (a1 * wd + a2 * wd * wd) / (air.a0 * air.vnom)
        duty.append(1.0 if dd > 1 else (0.0 if dd < 0 else dd))
    return duty


def battery_voltage(par: QuadrotorParameters, drawn: float, current: float, cap: float) -> float:
    """Terminal voltage: open-circuit voltage from the charge ``drawn`` of capacity ``cap`` [C], sag
    from the last ``current``."""
    full, empty = par.battery_full, par.battery_empty
    return full - (full - empty) * min(drawn / cap, 1.0) - par.internal_resistance * current


def _forces(air: _Airframe, wl: list, gust: list[float]) -> tuple[float, tuple[float, float, float]]:
    """Total thrust and body torques (with the gust torque) from the present motor speeds."""
    w1, w2, w3, w4 = wl
    kt_i, arm = air.kt_i, air.arm
    f1, f2, f3, f4 = kt_i[0] * w1 * w1, kt_i[1] * w2 * w2, kt_i[2] * w3 * w3, kt_i[3] * w4 * w4
    bx = arm * (f4 - f2) + gust[0]
    by = arm * (f3 - f1) + gust[1]
    bz = air.kq * (-w1 * w1 + w2 * w2 - w3 * w3 + w4 * w4) + gust[2]
    return f1 + f2 + f3 + f4, (bx, by, bz)


def _motor_speeds(air: _Airframe, wl: list, duty: list[float], vb: float, ts: float) -> list:
    """Speeds one sample on: exact step of each motor's Riccati equation with the voltage held."""
    a1, a2, a0_i = air.a1, air.a2, air.a0_i
    new = []
    for i in range(4):
        v = vb * duty[i]
        root = math.sqrt(a1 * a1 + 4 * a0_i[i] * a2 * v)
        rp = (root - a1) / (2 * a2)
        rmn = (-a1 - root) / (2 * a2)
        wi = wl[i]
        rho = (wi - rp) / (wi - rmn) * math.exp(-root * ts)
        new.append((rp - rho * rmn) / (1 - rho))
    return new


class _RigidBody:
    """Attitude, body rates and altitude, advanced by semi-implicit Euler (Sarıoğlu & Kural eqs. 13-17 with
    Euler-angle kinematics)."""

    def __init__(self) -> None:
        self.phi = self.th = self.psi = 0.0
        self.p = self.q = self.r = 0.0
        self.z = self.zd = 0.0

    def step(self, air: _Airframe, torque: tuple, om: float, thrust: float, ts: float) -> None:
        """Advance one sample under body ``torque``, rotor speed sum ``om`` and total ``thrust``."""
        bx, by, bz = torque
        ixx, iyy, izz, gyro, ir = air.ixx, air.iyy, air.izz, air.gyro, air.ir
        p, q, r, phi, th = self.p, self.q, self.r, self.phi, self.th
        pd_ = (bx + gyro * (iyy - izz) * q * r - ir * q * om) / ixx
        qd_ = (by + gyro * (izz - ixx) * p * r + ir * p * om) / iyy
        rd_ = (bz + gyro * (ixx - iyy) * p * q) / izz
        p += ts * pd_
        q += ts * qd_
        r += ts * rd_
        sph, cph, cth = math.sin(phi), math.cos(phi), math.cos(th)
        self.phi = phi + ts * (p + math.tan(th) * (sph * q + cph * r))
        self.th = th + ts * (cph * q - sph * r)
        self.psi += ts * ((sph * q + cph * r) / cth)
        self.zd += ts * (thrust * cph * cth / air.mass - _G)
        self.z += ts * self.zd
        self.p, self.q, self.r = p, q, r


def _fly(ref: _References, noise: _Noise, air: _Airframe, par: QuadrotorParameters, ts: float) -> _FlightArrays:
    """The closed loop, sample by sample: measure, control, battery, forces, log, motors, body."""
    n = ref.roll.shape[0]
    log = _FlightLog()
    rows = _NoiseRows(noise)
    body = _RigidBody()
    ctl = _Controller(ref, air, ts)
    wl = [math.sqrt(air.mass * _G / (4 * air.kt))] * 4  # hover
    drawn = current = 0.0
    for k in range(n):
        log.ang.append((body.phi, body.th, body.psi))
        log.rate.append((body.p, body.q, body.r))
        duty = ctl.duty(k, log.measured(k, rows, air.dm), body.z, body.zd)
        vb = battery_voltage(par, drawn, current, air.cap) if air.sag else air.vnom
        thrust, torque = _forces(air, wl, rows.turbulence[k])
        log.w.append(wl)
        log.duty.append(duty)
        log.vbat.append(vb)
        log.thrust.append(thrust)
        log.torque.append(torque)
        log.z.append(body.z)
        log.current.append(current)
        new = _motor_speeds(air, wl, duty, vb, ts)
        w1, w2, w3, w4 = wl
        body.step(air, torque, -w1 + w2 - w3 + w4, thrust, ts)
        # load current: propellers' mechanical power / efficiency / voltage
        pmech = air.kq * (w1**3 + w2**3 + w3**3 + w4**3)
        current = pmech / (par.efficiency * vb) + par.avionics_current
        drawn += current * ts
        wl = new
    return log.arrays()


def _flight_data(
    log: _FlightArrays,
    ref: _References,
    noise: _Noise,
    air: _Airframe,
    par: QuadrotorParameters,
    output: str,
    ts: float,
) -> IOData:
    """The logged signals (delayed, with sensor noise) as :class:`IOData` with ``output`` as output."""
    n = log.ang.shape[0]
    ns, raw = noise.scale, noise.raw
    idx = np.maximum(np.arange(n) - air.dm, 0)
    ang_m = log.ang[idx] + noise.attitude
    rate_m = log.rate[idx] + noise.gyro
    signals = {
        "roll": ang_m[:, 0],
        "pitch": ang_m[:, 1],
        "yaw": ang_m[:, 2],
        "p": rate_m[:, 0],
        "q": rate_m[:, 1],
        "r": rate_m[:, 2],
        **{f"w{i + 1}": log.w[:, i] + ns * par.speed_noise * raw["w"][:, i] for i in range(4)},
        "vbat": log.vbat + ns * par.vbat_noise * raw["vbat"],
        "thrust": log.thrust,
        "az": log.thrust / air.mass + ns * par.accel_noise * raw["az"],
        "z": log.z,
        "tau_x": log.torque[:, 0],
        "tau_y": log.torque[:, 1],
        "tau_z": log.torque[:, 2],
        "roll_ref": ref.roll,
        "pitch_ref": ref.pitch,
        "yaw_ref": ref.yaw,
        "current": log.current,
    }
    y = signals.pop(output)
    return IOData(
        y,
        log.duty,
        ts,
        output_name=output,
        input_names=("d1", "d2", "d3", "d4"),
        output_unit=_FLIGHT_UNITS[output],
        input_units=("1",) * 4,
        extra=signals,
        extra_units={k: _FLIGHT_UNITS[k] for k in signals},
    )
