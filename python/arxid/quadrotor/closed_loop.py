"""A rate axis flown under a PI controller: closed-loop data with known answers.

:func:`pi_loop` simulates the discrete plant

.. math:: y(t) = \\frac{b_1 q^{-1} + b_2 q^{-2}}{1 + a_1 q^{-1} + a_2 q^{-2}} u(t) + v(t), \\qquad
   v(t) = \\frac{1}{1 - c\\,q^{-1}} e(t)

(coloured output noise: gusts and vibration) with ``u = K_p (r - y) + K_i ts Σ (r - y)`` in closed
loop, or with the same kind of excitation applied straight to the plant in open loop. The reference
``r`` is a PRBS (:func:`arxid.inputs.prbs`) and is logged, as a flight controller logs its setpoint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.iodata import IOData
from ..exceptions import DataError
from ..inputs import prbs

__all__ = ["PiLoopPlant", "pi_loop", "RateLoopPlant", "pid_rate_loop"]


@dataclass(frozen=True)
class PiLoopPlant:
    """True parameters of :func:`pi_loop`.

    Parameters
    ----------
    a : (float, float)
        Denominator ``1 + a1 q^-1 + a2 q^-2``.
    b : (float, float)
        Numerator ``b1 q^-1 + b2 q^-2`` (one sample of delay: ``nk = 1``).
    noise_pole : float
        Pole ``c`` of the output noise filter ``1 / (1 - c q^-1)``.
    noise_std : float
        Standard deviation of the white noise ``e`` that drives it.
    kp, ki : float
        PI gains (``ki`` per second).
    reference : float
        Amplitude of the PRBS reference (closed loop) or input (open loop).
    """

    a: tuple[float, float] = (-1.5, 0.7)
    b: tuple[float, float] = (0.10, 0.05)
    noise_pole: float = 0.95
    noise_std: float = 0.1
    kp: float = 0.8
    ki: float = 5.0
    reference: float = 1.0

    @property
    def gain(self) -> float:
        """Static gain of the plant ``B(1) / A(1)``."""
        return float(sum(self.b) / (1.0 + sum(self.a)))

    @property
    def poles(self) -> np.ndarray:
        """Poles of the plant (roots of ``z^2 + a1 z + a2``)."""
        return np.roots([1.0, *self.a])


def pi_loop(
    seed: int = 0,
    n_samples: int = 4000,
    *,
    ts: float = 0.01,
    closed: bool = True,
    plant: PiLoopPlant | None = None,
    band: float = 0.1,
) -> IOData:
    """Simulate the plant of :class:`PiLoopPlant` under a PI controller (or in open loop).

    Parameters
    ----------
    seed : int
        Seeds the reference's start and the noise.
    n_samples : int
        Length, >= 200.
    ts : float
        Sampling time [s].
    closed : bool
        True: ``u`` is the PI controller's command on the measured output, ``r`` its setpoint.
        False: ``u = r`` is applied straight to the plant (open loop; the noise is the same).
    plant : PiLoopPlant, optional
        True parameters (default :class:`PiLoopPlant()`).
    band : float
        Bandwidth of the PRBS reference as a fraction of the Nyquist frequency: each bit is held
        for ``round(1 / band)`` samples (default 0.1, bits of 10 samples; 0.5 excites the plant up to
        half the Nyquist frequency, where its zero shows).

    Returns
    -------
    IOData
        Output ``y`` [rad/s], input ``u`` [1], extra signal ``r`` (the logged reference, [rad/s]
        in closed loop, the applied command in open loop).

    Examples
    --------
    >>> from arxid.datasets import pi_loop
    >>> d = pi_loop(seed=1, n_samples=500)
    >>> d.input_names, sorted(d.extra)
    (('u',), ['r'])
    """
    if n_samples < 200:
        raise DataError(f"n_samples must be at least 200, got {n_samples}")
    p = plant or PiLoopPlant()
    rng = np.random.default_rng(seed)
    r, v = _reference_and_noise(rng, n_samples, band, p.reference, p.noise_pole, p.noise_std)
    (a1, a2), (b1, b2) = p.a, p.b
    y, u, clean = np.zeros(n_samples), np.zeros(n_samples), np.zeros(n_samples)
    integral = 0.0
    for t in range(n_samples):
        c1 = clean[t - 1] if t >= 1 else 0.0
        c2 = clean[t - 2] if t >= 2 else 0.0
        u1 = u[t - 1] if t >= 1 else 0.0
        u2 = u[t - 2] if t >= 2 else 0.0
        clean[t] = -a1 * c1 - a2 * c2 + b1 * u1 + b2 * u2
        y[t] = clean[t] + v[t]
        if closed:
            err = r[t] - y[t]
            integral += err * ts
            u[t] = p.kp * err + p.ki * integral
        else:
            u[t] = r[t]
    return IOData(
        y,
        u,
        ts,
        output_name="y",
        input_names=("u",),
        output_unit="rad/s",
        input_units=("1",),
        extra={"r": r},
        extra_units={"r": "rad/s" if closed else "1"},
    )


@dataclass(frozen=True)
class RateLoopPlant:
    """True parameters of :func:`pid_rate_loop`: a rate axis behind a motor lag and a delay.

    The plant from the command ``u`` to the rate ``y`` is

    .. math:: y(t) = \\frac{b (1 - m) q^{-(d + 1)}}{(1 - a q^{-1})(1 - m q^{-1})} u(t) + v(t),
       \\qquad v(t) = \\frac{1}{1 - c q^{-1}} e(t)

    (``nk = d + 1``, ``nb = 1``, ``na = 2``): a first-order motor of pole ``m`` after ``d`` samples of
    transport delay, then a damped rate of pole ``a``.

    Parameters
    ----------
    rate_pole, rate_gain : float
        ``a`` and ``b`` of the rate dynamics.
    motor_pole : float
        ``m``, the motor lag's pole.
    delay : int
        ``d``, samples of delay before the motor (2 to 4 in the flight controllers of small drones).
    noise_pole, noise_std : float
        ``c`` and the standard deviation of ``e``.
    kp, ki, kd : float
        PID gains (``ki`` per second, ``kd`` in seconds).
    derivative_pole : float
        Pole of the first-order filter on the derivative term.
    reference : float
        Amplitude of the PRBS rate setpoint.
    """

    rate_pole: float = 0.9
    rate_gain: float = 0.2
    motor_pole: float = 0.6
    delay: int = 2
    noise_pole: float = 0.9
    noise_std: float = 0.05
    kp: float = 0.6
    ki: float = 2.0
    kd: float = 0.002
    derivative_pole: float = 0.5
    reference: float = 1.0

    @property
    def gain(self) -> float:
        """Static gain of the plant ``b / (1 - a)``."""
        return float(self.rate_gain / (1.0 - self.rate_pole))

    @property
    def poles(self) -> np.ndarray:
        """Poles of the plant (the rate's and the motor's)."""
        return np.array([self.rate_pole, self.motor_pole])

    @property
    def nk(self) -> int:
        """Delay of the plant in samples (the transport delay and one for the motor)."""
        return self.delay + 1


def pid_rate_loop(
    seed: int = 0,
    n_samples: int = 20000,
    *,
    ts: float = 0.002,
    plant: RateLoopPlant | None = None,
    band: float = 0.3,
    battery_sag: float = 0.0,
) -> IOData:
    """Simulate the rate axis of :class:`RateLoopPlant` under a PID controller with a filtered derivative.

    Parameters
    ----------
    seed : int
        Seeds the reference's start and the noise.
    n_samples : int
        Length, >= 200.
    ts : float
        Sampling time [s].
    plant : RateLoopPlant, optional
        True parameters (default :class:`RateLoopPlant()`).
    band : float
        Bandwidth of the PRBS setpoint as a fraction of the Nyquist frequency.
    battery_sag : float
        Volts the battery loses over the record (0: none). The motors' torque is the command times
        ``vbat / 15 V`` (a motor driven at battery voltage), which the controller's integral
        partly hides; the voltage is logged as ``vbat``.

    Returns
    -------
    IOData
        Output ``rate`` [rad/s], input ``command`` [1] (the PID sum), extra signals ``rate_sp`` (the
        logged setpoint [rad/s]), ``pid_d`` (the controller's derivative term [1]) and, with a
        battery sag, ``vbat`` [V].

    Examples
    --------
    >>> from arxid.datasets import pid_rate_loop
    >>> d = pid_rate_loop(seed=1, n_samples=500)
    >>> d.input_names, sorted(d.extra)
    (('command',), ['pid_d', 'rate_sp'])
    """
    if n_samples < 200:
        raise DataError(f"n_samples must be at least 200, got {n_samples}")
    p = plant or RateLoopPlant()
    rng = np.random.default_rng(seed)
    r, v = _reference_and_noise(rng, n_samples, band, p.reference, p.noise_pole, p.noise_std)
    k = np.arange(n_samples)
    vbat = 16.8 - battery_sag * k / n_samples + 0.1 * battery_sag * np.sin(k / 700.0)
    y, u, d_term = _fly_pid(r, v, p, ts, vbat / 15.0 if battery_sag else np.ones(n_samples))
    extra, units = {"rate_sp": r, "pid_d": d_term}, {"rate_sp": "rad/s", "pid_d": "1"}
    if battery_sag:
        extra["vbat"], units["vbat"] = vbat, "V"
    return IOData(
        y,
        u,
        ts,
        output_name="rate",
        input_names=("command",),
        output_unit="rad/s",
        input_units=("1",),
        extra=extra,
        extra_units=units,
    )


def _reference_and_noise(
    rng: np.random.Generator, n: int, band: float, amplitude: float, pole: float, std: float
) -> tuple[np.ndarray, np.ndarray]:
    """A PRBS reference of ±``amplitude`` with bits of ``round(1 / band)`` samples, started at a random
    point of its period, and the coloured output noise ``e / (1 - pole q^-1)``, e of ``std``."""
    hold = max(1, round(1 / band))
    x = prbs(10, band=band, levels=(-amplitude, amplitude), periods=n // (1023 * hold) + 2)
    r = np.roll(x.values, -int(rng.integers(0, x.period)))[:n]
    e = rng.normal(0.0, std, n)
    v = np.zeros(n)
    for t in range(n):
        v[t] = e[t] + (pole * v[t - 1] if t else 0.0)
    return r, v


def _fly_pid(
    r: np.ndarray, v: np.ndarray, p: RateLoopPlant, ts: float, authority: np.ndarray
) -> tuple[np.ndarray, ...]:
    """The loop sample by sample: the plant's state, the measured rate, the PID command (whose
    torque is scaled by ``authority``, the battery's share of its nominal voltage)."""
    n = r.shape[0]
    y, u, d_term = np.zeros(n), np.zeros(n), np.zeros(n)
    rate = torque = integral = derivative = last_error = 0.0
    for t in range(n):
        command = u[t - p.delay] * authority[t - p.delay] if t >= p.delay else 0.0
        rate = p.rate_pole * rate + p.rate_gain * torque  # the torque of the last sample
        torque = p.motor_pole * torque + (1.0 - p.motor_pole) * command
        y[t] = rate + v[t]
        error = r[t] - y[t]
        integral += error * ts
        derivative = p.derivative_pole * derivative + (1.0 - p.derivative_pole) * (error - last_error) / ts
        last_error = error
        d_term[t] = p.kd * derivative
        u[t] = p.kp * error + p.ki * integral + d_term[t]
    return y, u, d_term
