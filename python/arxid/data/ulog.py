"""PX4 flight logs (ULog) onto one time grid: :func:`read_ulog`, behind :meth:`IOData.from_ulog`.

A ULog holds each topic at its own rate, with bursts and dropouts. The reader puts the chosen
fields on one grid of step ``ts``:

* the **inputs** (actuator and torque commands) and any field of a ``*setpoint*`` or ``actuator*``
  topic are held between samples (zero-order hold, as the autopilot applies them);
* the **output** and the other **measurements** are interpolated linearly between samples;
* a grid point farther than ``max_gap`` from the topic's samples (a dropout longer than a few
  samples) is a missing sample (NaN), never interpolated or held across.

The grid is :func:`arxid.data.resample.resample`'s, the same for every kind of log. The grid runs
where every chosen topic has samples. Times (microseconds since boot) are chosen for what each
signal is:

* a **measurement** is stamped with its topic's ``timestamp_sample`` (when the sensor took it)
  where it has one, else its ``timestamp``;
* a **command** (every held signal above) is stamped with its ``timestamp``, when the controller
  published it. The ``timestamp_sample`` of ``actuator_controls_*`` is that of the gyro sample the
  controller answered, about 0.4 ms earlier on a PX4 multicopter: stamping the command with it would
  move every command before its issue and hide that part of the loop's delay from the model.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._base.optional import require
from ..exceptions import DataError
from .resample import resample

__all__ = ["UlogSignals", "read_ulog", "px4_unit"]

#: Units of PX4 fields that are not spelled in their names (PX4 uORB message definitions).
_UNITS = {
    "vehicle_angular_velocity.xyz": "rad/s",
    "vehicle_angular_acceleration.xyz": "rad/s^2",
    "vehicle_rates_setpoint.roll": "rad/s",
    "vehicle_rates_setpoint.pitch": "rad/s",
    "vehicle_rates_setpoint.yaw": "rad/s",
    "vehicle_attitude_setpoint.roll_body": "rad",
    "vehicle_attitude_setpoint.pitch_body": "rad",
    "vehicle_attitude_setpoint.yaw_body": "rad",
    "actuator_controls_0.control": "1",
    "vehicle_torque_setpoint.xyz": "1",
    "vehicle_thrust_setpoint.xyz": "1",
    "actuator_motors.control": "1",
    "actuator_outputs.output": "us",
    "sensor_combined.gyro_rad": "rad/s",
    "sensor_combined.accelerometer_m_s2": "m/s^2",
    "vehicle_attitude.q": "1",
}
# Unit suffixes of PX4 field names (``voltage_v``, ``current_a``, ``gyro_rad``, ...), longest first.
_SUFFIXES = (
    ("_m_s2", "m/s^2"),
    ("_rad_s", "rad/s"),
    ("_m_s", "m/s"),
    ("_mah", "mAh"),
    ("_rad", "rad"),
    ("_deg", "deg"),
    ("_hz", "Hz"),
    ("_pa", "Pa"),
    ("_v", "V"),
    ("_a", "A"),
    ("_m", "m"),
    ("_s", "s"),
    ("_c", "degC"),
)


def px4_unit(topic: str, field: str) -> str:
    """Unit of a PX4 field, from its topic's message definition or its name's suffix ('' if unknown).

    Parameters
    ----------
    topic, field : str
        E.g. ``"battery_status"``, ``"voltage_v"``.

    Returns
    -------
    str

    Examples
    --------
    >>> px4_unit("battery_status", "voltage_v"), px4_unit("vehicle_angular_velocity", "xyz[0]")
    ('V', 'rad/s')
    """
    base = re.sub(r"\[\d+\]$", "", field)
    if f"{topic}.{base}" in _UNITS:
        return _UNITS[f"{topic}.{base}"]
    for suffix, unit in _SUFFIXES:
        if base.endswith(suffix):
            return unit
    return ""


@dataclass(frozen=True)
class _Selector:
    text: str
    topic: str
    instance: int
    field: str

    @classmethod
    def parse(cls, text: str) -> _Selector:
        m = re.fullmatch(r"([A-Za-z0-9_]+)(?::(\d+))?\.(.+)", text)
        if not m:
            raise DataError(
                f"{text!r} does not name a ULog field; write topic.field, e.g. 'vehicle_angular_velocity.xyz[0]' "
                "(topic:1.field for a second instance)"
            )
        return cls(text, m.group(1), int(m.group(2) or 0), m.group(3))

    @property
    def name(self) -> str:
        """The signal name: the selector with characters an effect cannot hold replaced by ``_``."""
        return re.sub(r"\W+", "_", self.text).strip("_")


@dataclass(frozen=True)
class UlogSignals:
    """Fields of a ULog on one grid (what :meth:`IOData.from_ulog` builds its IOData from).

    Attributes
    ----------
    time : ndarray of shape (n,)
        Seconds since boot.
    values : dict of str to ndarray
        Each field on the grid, NaN in dropouts, by signal name.
    units : dict of str to str
    held : dict of str to bool
        Zero-order hold (True) or linear interpolation (False), per signal.
    ts : float
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    units: dict[str, str]
    held: dict[str, bool]
    ts: float


def _topic_samples(ulog, sel: _Selector, path: Path, command: bool) -> tuple[np.ndarray, np.ndarray]:
    """Times [s] and values of one field: a command at its issue (``timestamp``), a measurement at
    its sample (``timestamp_sample`` where the topic has one)."""
    found = [d for d in ulog.data_list if d.name == sel.topic and d.multi_id == sel.instance]
    if not found:
        topics = sorted({d.name for d in ulog.data_list})
        raise DataError(f"{path.name} has no topic {sel.topic!r} (instance {sel.instance}); it logs {topics}")
    data = found[0].data
    if sel.field not in data:
        fields = [k for k in data if not k.startswith("timestamp")]
        raise DataError(f"topic {sel.topic!r} of {path.name} has no field {sel.field!r}; its fields are {fields}")
    t_us = data["timestamp_sample"] if "timestamp_sample" in data and not command else data["timestamp"]
    t = np.asarray(t_us, dtype=np.float64) * 1e-6
    v = np.asarray(data[sel.field], dtype=np.float64)
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def read_ulog(
    path,
    fields: Sequence[str],
    *,
    hold: Sequence[str] = (),
    ts: float | None = None,
    max_gap: float | None = None,
) -> UlogSignals:
    """Read ULog fields onto one time grid.

    Parameters
    ----------
    path : str or Path
        A ``.ulg`` file.
    fields : sequence of str
        ``topic.field`` selectors (``topic:1.field`` for instance 1); the first one sets the
        default grid step.
    hold : sequence of str
        Selectors held between samples (zero-order hold) besides setpoint and actuator topics.
    ts : float, optional
        Grid step [s] (default: the median sample interval of the first field's topic).
    max_gap : float, optional
        Longest interval between samples bridged [s] (default: 3 times each topic's median
        interval, or 3 grid steps if longer); a grid point inside a longer dropout is NaN.

    Returns
    -------
    UlogSignals

    Raises
    ------
    DataError
        On a missing file, topic or field, or no time where all topics were logged.
    MissingDependencyError
        Without pyulog (``pip install 'arxid[px4]'``).
    """
    pyulog = require("pyulog", "reading PX4 flight logs")
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no ULog file at {path}")
    selectors = [_Selector.parse(f) for f in fields]
    repeated = sorted({f for f in fields if list(fields).count(f) > 1})
    if repeated:
        raise DataError(f"each field may be chosen once; repeated: {repeated}")
    try:
        with path.open("rb") as handle:  # our handle: pyulog leaves its own open on a bad header
            if handle.read(7) != b"ULog\x01\x12\x35":
                raise ValueError("it does not start with the ULog header")
            handle.seek(0)
            ulog = pyulog.ULog(handle, sorted({s.topic for s in selectors}))
    except Exception as exc:  # pyulog raises its own and struct errors on a damaged file
        raise DataError(f"{path.name} is not a readable ULog file ({exc})") from None
    held_names = {
        s.text for s in selectors if s.text in set(hold) or "setpoint" in s.topic or s.topic.startswith("actuator")
    }
    samples = {s.text: _topic_samples(ulog, s, path, s.text in held_names) for s in selectors}
    for s in selectors:
        if samples[s.text][0].shape[0] < 2:
            raise DataError(f"{s.text} has fewer than 2 samples in {path.name}")
    grid = resample(samples, hold=held_names, ts=ts, max_gap=max_gap, source=path.name)
    values = {s.name: grid.values[s.text] for s in selectors}
    units = {s.name: px4_unit(s.topic, s.field) for s in selectors}
    held = {s.name: grid.held[s.text] for s in selectors}
    return UlogSignals(grid.time, values, units, held, grid.ts)
