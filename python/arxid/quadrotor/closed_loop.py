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

__all__ = ["PiLoopPlant", "pi_loop"]


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
    # a PRBS with bits of round(1 / band) samples, started at a random point of its period
    hold = max(1, round(1 / band))
    x = prbs(10, band=band, levels=(-p.reference, p.reference), ts=ts, periods=n_samples // (1023 * hold) + 2)
    r = np.roll(x.values, -int(rng.integers(0, x.period)))[:n_samples]
    e = rng.normal(0.0, p.noise_std, n_samples)
    v = np.zeros(n_samples)
    for t in range(n_samples):
        v[t] = e[t] + (p.noise_pole * v[t - 1] if t else 0.0)
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
