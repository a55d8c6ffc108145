"""Seeded simulated plants shared by several test files (one definition each)."""

from __future__ import annotations

import math

import numpy as np

import arxid


def position_servo(seed: int = 0, n: int = 2000, ts: float = 0.01, delay: int = 8) -> arxid.IOData:
    """A DC motor with viscous and Coulomb friction driving an inertia, position measured, the
    command reaching the motor ``delay`` samples late (bus and driver latency): an integrating plant.

    Simulated with 10 Euler substeps per sample; the angle is measured with 1e-4 rad of noise.
    """
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.standard_normal(n // 20 + 1), 20)[:n]
    inertia, viscous, gain, coulomb = 0.01, 0.05, 1.0, 0.1
    speed = angle = 0.0
    y = np.zeros(n)
    h = ts / 10
    for t in range(n):
        torque = gain * (u[t - delay] if t >= delay else 0.0)
        for _ in range(10):
            speed += h * (torque - viscous * speed - coulomb * math.tanh(speed / 0.01)) / inertia
            angle += h * speed
        y[t] = angle + 1e-4 * rng.standard_normal()
    return arxid.IOData(y, u, ts, output_name="angle", input_names=["voltage"])
