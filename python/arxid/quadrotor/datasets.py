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
    "body_rates",
    "RATE_INPUTS",
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


#: What drives the body rates in :func:`body_rates`.
RATE_INPUTS = ("commands", "torques")


def body_rates(data: IOData, inputs: str = "commands", frame: str = "plus", extra=("vbat",)) -> IOData:
    """Identification data of the three body rates at once: data of several outputs for
    :func:`arxid.ssest`.

    Parameters
    ----------
    data : IOData
        A flight log with ``p, q, r``, the motor commands ``d1..d4`` as inputs and the motor speeds
        ``w1..w4`` (as :func:`quadrotor_flight` logs them).
    inputs : {"commands", "torques"}
        The four motor commands (PWM duty, as flown), or the mixer's three pseudo-torques from the
        logged motor speeds (``roll_torque``, ``pitch_torque``, ``yaw_torque``, in (rad/s)^2).
    frame : {"plus", "x"}
        Mixer frame for ``"torques"`` (the simulator flies a plus frame).
    extra : sequence of str
        Logged signals kept as extra signals.

    Returns
    -------
    IOData
        Outputs ``p, q, r`` [rad/s]; inputs as chosen; the experiments of ``data``.

    Examples
    --------
    >>> from arxid.datasets import body_rates, quadrotor_flight
    >>> rates = body_rates(quadrotor_flight(seed=1, duration=2.0, output="p"))
    >>> rates.output_names, rates.input_names
    (('p', 'q', 'r'), ('d1', 'd2', 'd3', 'd4'))
    """
    from .mixer import CHANNELS, Mixer

    if inputs not in RATE_INPUTS:
        raise DataError(f"inputs must be one of {list(RATE_INPUTS)}, got {inputs!r}")
    rates = np.column_stack([data.signal(name) for name in ("p", "q", "r")])
    if inputs == "commands":
        u, names, units = data.u, data.input_names, data.input_units
    else:
        channels = ("roll_torque", "pitch_torque", "yaw_torque")
        mixed = Mixer(frame)(np.column_stack([data.signal(f"w{i}") for i in range(1, 5)]))
        u = mixed[:, [CHANNELS.index(c) for c in channels]]
        names, units = channels, ("(rad/s)^2",) * 3
    return IOData(
        rates,
        u,
        data.ts,
        output_name=["p", "q", "r"],
        input_names=names,
        output_unit=[data.unit(name) for name in ("p", "q", "r")],
        input_units=units,
        extra={name: data.signal(name) for name in extra},
        extra_units={name: data.unit(name) for name in extra},
        experiment_starts=data.experiment_starts,
    )
