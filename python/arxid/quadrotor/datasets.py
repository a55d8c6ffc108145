"""Simulated data sets with known answers: a quadrotor flight and a thrust stand.

Both simulators are deterministic for a seed and expose their true parameters
(:class:`QuadrotorParameters`), so every identification in :mod:`arxid.quadrotor` can be checked
against the truth. They produce the embedded default data of ``arxid demo``: arxid ships no
third-party data.

The flight simulator
--------------------
:func:`quadrotor_flight` flies a plus frame, motor 1 front, 2 right, 3 back, 4 left (as in a published
quadrotor study, Sarıoğlu & Kural).
Rotational dynamics (eqs. 13-17)::

    Ixx p' = k l (w4^2 - w2^2) + (Iyy - Izz) q r - Ir q W
    Iyy q' = k l (w3^2 - w1^2) + (Izz - Ixx) p r + Ir p W
    Izz r' = b (-w1^2 + w2^2 - w3^2 + w4^2) + (Ixx - Iyy) p q,   W = -w1 + w2 - w3 + w4

with Euler-angle kinematics, integrated by semi-implicit Euler at ``ts``. The logged attitude is a
complementary filter's estimate (gyro integrated, pulled towards the accelerometer tilt with
``estimator_time_constant``), delayed with the gyro by ``delay_samples - 1`` samples; the
controller flies on these logged values. Motors follow ``w' = a0 vbat d - a1 w - a2 w^2``,
integrated exactly over each sample. A PID attitude controller (on the delayed measurements) and an
altitude loop tracking eq. 15 of the battery-aware thrust study (Staub & Franchi, ICRA 2015) compute
thrust and torques, allocate them to squared speeds with the nominal parameters and turn those into
duty assuming ``nominal_voltage`` (no battery compensation). The battery's open-circuit voltage falls
linearly with charge drawn; the terminal voltage sags by ``R * I`` with ``I`` from the propellers'
mechanical power.
"""

from __future__ import annotations

import numpy as np

from ..data.iodata import IOData
from ..exceptions import DataError
from .closed_loop import PiLoopPlant, RateLoopPlant, pi_loop, pid_rate_loop
from .flight_sim import DEFAULT_EFFECTS, QuadrotorParameters, quadrotor_flight
from .flight_sim import MAX_SAMPLES as MAX_SAMPLES
from .stand_sim import PWM_FULL_SCALE as PWM_FULL_SCALE
from .stand_sim import thrust_stand, thrust_stand_static

__all__ = [
    "QuadrotorParameters",
    "DEFAULT_EFFECTS",
    "quadrotor_flight",
    "PiLoopPlant",
    "pi_loop",
    "RateLoopPlant",
    "pid_rate_loop",
    "quadrotor_axis",
    "thrust_stand",
    "thrust_stand_static",
]


def quadrotor_axis(
    data: IOData, axis: str = "roll", frame: str = "plus", extra=("vbat", "thrust", "roll", "pitch", "yaw")
) -> IOData:
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
    from .mixer import Mixer

    if axis not in ("roll", "pitch", "yaw"):
        raise DataError(f"axis must be 'roll', 'pitch' or 'yaw', got {axis!r}")
    angle = data.signal(axis)
    keep = {}
    for name in extra:
        if name != axis:
            keep[name] = data.signal(name)
    src = IOData(
        angle,
        np.column_stack([data.signal(f"w{i}") for i in range(1, 5)]),
        data.ts,
        output_name=axis,
        input_names=("w1", "w2", "w3", "w4"),
        output_unit="rad",
        input_units=("rad/s",) * 4,
        extra=keep,
        extra_units={k: data.unit(k) for k in keep},
        experiment_starts=data.experiment_starts,
    )
    mixed = Mixer(frame).apply(src, channels=(f"{axis}_torque",))
    ex = {k: v for k, v in mixed.extra.items() if k not in ("w1", "w2", "w3", "w4")}
    return mixed.with_signals(extra=ex)
