"""Which logged signals describe one axis of a multirotor: :func:`axis_preset` and :func:`log_preset`.

A rate loop on one axis (roll, pitch or yaw) has the same signals in every firmware, under other
names:

=============  ============================  ====================  ===================================
signal         Betaflight/INAV blackbox      ArduCopter DataFlash  PX4 ULog
=============  ============================  ====================  ===================================
output         ``gyroADC[i]`` (deg/s)        ``RATE.R`` (deg/s)    ``vehicle_angular_velocity.xyz[i]``
input          ``pidsum[i]`` (P+I+D+F)       ``RATE.ROut``         ``vehicle_torque_setpoint.xyz[i]``
reference      ``setpoint[i]`` (deg/s)       ``RATE.RDes``         ``vehicle_rates_setpoint.roll``
extra          ``vbatLatest``, throttle,     ``BAT.Volt``,         ``battery_status.voltage_v``,
               ``motor[0..3]``               ``RATE.AOut``,        thrust, ``actuator_motors``
                                             ``RCOU.C1..C4``
=============  ============================  ====================  ===================================

The input is what the controller commands (the closed loop's plant input), the reference what the
pilot asked for; with the reference, closed-loop methods (instrumental variables, the r→y/r→u
frequency response) avoid the bias of the feedback.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

from ..exceptions import DataError

__all__ = ["AxisPreset", "AXES", "LOG_KINDS", "axis_preset", "log_kind", "log_preset"]

AXES = ("roll", "pitch", "yaw")
LOG_KINDS = ("blackbox", "dataflash", "ulog")
_BLACKBOX_START = b"H Product:Blackbox flight data recorder"
_SUFFIXES = {".bbl": "blackbox", ".bfl": "blackbox", ".txt": "blackbox", ".bin": "dataflash", ".ulg": "ulog"}


@dataclass(frozen=True)
class AxisPreset:
    """The selectors of one axis in one kind of log.

    Attributes
    ----------
    kind : str
        ``"blackbox"``, ``"dataflash"`` or ``"ulog"``.
    axis : str
        ``"roll"``, ``"pitch"`` or ``"yaw"``.
    output : str
        The measured body rate.
    inputs : tuple of str
        The rate controller's output (the plant's input).
    reference : str
        The rate setpoint.
    extra : tuple of str
        Battery voltage, throttle and motor outputs, those the log holds.
    """

    kind: str
    axis: str
    output: str
    inputs: tuple[str, ...]
    reference: str
    extra: tuple[str, ...]

    def read_arguments(self) -> dict:
        """Keyword arguments of ``IOData.from_blackbox`` / ``from_dataflash`` / ``from_ulog``
        (the reference first among the extra signals).

        Returns
        -------
        dict
        """
        return {"output": self.output, "inputs": list(self.inputs), "extra": [self.reference, *self.extra]}


def _candidates(kind: str, axis: str) -> tuple[list[str], list[str], list[str], list[str]]:
    """Output, input, reference and extra selectors to try, most preferred first."""
    i = AXES.index(axis)
    if kind == "blackbox":
        return (
            [f"gyroADC[{i}]"],
            [f"pidsum[{i}]"],
            [f"setpoint[{i}]"],
            ["vbatLatest", "setpoint[3]", "rcCommand[3]"] + [f"motor[{k}]" for k in range(8)],
        )
    if kind == "dataflash":
        a = "RPY"[i]
        return (
            [f"RATE.{a}"],
            [f"RATE.{a}Out"],
            [f"RATE.{a}Des"],
            ["BAT.Volt", "RATE.AOut"] + [f"RCOU.C{k}" for k in range(1, 9)],
        )
    return (
        [f"vehicle_angular_velocity.xyz[{i}]"],
        [f"vehicle_torque_setpoint.xyz[{i}]", f"actuator_controls_0.control[{i}]"],
        [f"vehicle_rates_setpoint.{axis}"],
        ["battery_status.voltage_v", "vehicle_thrust_setpoint.xyz[2]", "actuator_controls_0.control[3]"]
        + [f"actuator_motors.control[{k}]" for k in range(8)],
    )


def _pid_terms(selector: str) -> list[str]:
    i = selector[len("pidsum[") : -1]
    return [f"{t}[{i}]" for t in ("axisP", "axisI", "axisD", "axisF")]


def axis_preset(kind: str, axis: str, available: Collection[str], source: str = "the log") -> AxisPreset:
    """The signals of one axis among those a log holds.

    Parameters
    ----------
    kind : {"blackbox", "dataflash", "ulog"}
    axis : {"roll", "pitch", "yaw"}
    available : collection of str
        The selectors the log holds (blackbox fields ``gyroADC[0]``; DataFlash ``RATE.R``;
        ULog ``topic.field``).
    source : str
        The file, for error messages.

    Returns
    -------
    AxisPreset

    Raises
    ------
    DataError
        An unknown kind or axis, or a log without the axis's rate, controller output or setpoint
        (the message says which is missing and what the log holds instead).

    Examples
    --------
    >>> p = axis_preset("dataflash", "roll", {"RATE.R", "RATE.RDes", "RATE.ROut", "BAT.Volt"})
    >>> p.output, p.inputs, p.reference, p.extra
    ('RATE.R', ('RATE.ROut',), 'RATE.RDes', ('BAT.Volt',))
    """
    if kind not in LOG_KINDS:
        raise DataError(f"unknown log kind {kind!r}; choose one of {list(LOG_KINDS)}")
    if axis not in AXES:
        raise DataError(f"unknown axis {axis!r}; choose one of {list(AXES)}")
    have = set(available)
    outputs, inputs, references, extras = _candidates(kind, axis)

    def present(selector: str) -> bool:
        if selector.startswith("pidsum["):
            return any(t in have for t in _pid_terms(selector))
        return selector in have

    chosen = {}
    for role, options in (("rate (output)", outputs), ("controller output (input)", inputs), ("setpoint", references)):
        found = [s for s in options if present(s)]
        if not found:
            raise DataError(_missing(kind, axis, role, options, have, source))
        chosen[role] = found[0]
    return AxisPreset(
        kind,
        axis,
        chosen["rate (output)"],
        (chosen["controller output (input)"],),
        chosen["setpoint"],
        tuple(s for s in extras if present(s)),
    )


def _missing(kind: str, axis: str, role: str, options: list[str], have: set[str], source: str) -> str:
    wanted = " or ".join(repr(s) for s in options)
    message = f"{source} holds no {axis} {role}: it logs no {wanted}"
    if kind == "dataflash":
        messages = sorted({s.split(".")[0] for s in have})
        if "RATE" not in messages:
            message += (
                "; ArduCopter logs its rate loop in RATE (R, RDes, ROut). This log has no RATE message"
                + (" but PIDR/PIDP/PIDY (an ArduPlane log?)" if "PIDR" in messages else "")
                + f"; it logs {messages}. Choose the signals with IOData.from_dataflash(output=..., inputs=...)"
            )
    elif kind == "blackbox":
        message += "; the log's fields_disabled_mask may have turned these fields off in the firmware"
    return message


def log_kind(path) -> str:
    """The kind of flight log a file is, by its suffix.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    str
        ``"blackbox"`` (``.bbl``, ``.bfl``, and ``.txt`` when it starts as a blackbox log does),
        ``"dataflash"`` (``.bin``) or ``"ulog"`` (``.ulg``).

    Raises
    ------
    DataError
        Another suffix, or a ``.txt`` file that is not a blackbox log.

    Examples
    --------
    >>> log_kind("LOG00037.BFL"), log_kind("00000042.BIN")
    ('blackbox', 'dataflash')
    """
    suffix = Path(path).suffix.lower()
    if suffix == ".txt" and Path(path).is_file():  # a blackbox log, or a text export such as a CSV
        with Path(path).open("rb") as handle:
            if not handle.read(len(_BLACKBOX_START)) == _BLACKBOX_START:
                raise DataError(
                    f"{Path(path).name} is a text file, not a blackbox log; read a CSV with IOData.from_csv"
                )
    if suffix not in _SUFFIXES:
        raise DataError(
            f"{Path(path).name} is not a flight log arxid knows by its suffix "
            "(.bbl/.bfl/.txt Betaflight/INAV, .bin ArduPilot, .ulg PX4)"
        )
    return _SUFFIXES[suffix]


def log_preset(path, axis: str, *, log: int = 1) -> AxisPreset:
    """The signals of one axis in a flight log file (the selectors it holds are read from it).

    Parameters
    ----------
    path : str or Path
        A blackbox, DataFlash or ULog file (by suffix, see :func:`log_kind`).
    axis : {"roll", "pitch", "yaw"}
    log : int
        Which log of a blackbox file, from 1.

    Returns
    -------
    AxisPreset

    Raises
    ------
    DataError
        The file cannot be read, or holds no signal for the axis (the message says what is
        missing).
    """
    kind = log_kind(path)
    name = Path(path).name
    if kind == "blackbox":
        from .blackbox import blackbox_header

        available: set[str] = set(blackbox_header(path, log).fields)
    elif kind == "dataflash":
        from .dataflash import dataflash_formats

        available = {f"{m}.{f}" for m, fields in dataflash_formats(path).items() for f in fields}
    else:
        available = _ulog_fields(path)
    return axis_preset(kind, axis, available, source=name)


def _ulog_fields(path) -> set[str]:
    from .._base.optional import require

    pyulog = require("pyulog", "reading PX4 flight logs")
    try:
        ulog = pyulog.ULog(str(path))
    except Exception as exc:  # pyulog raises its own and struct errors on a damaged file
        raise DataError(f"{Path(path).name} is not a readable ULog file ({exc})") from None
    out: set[str] = set()
    for d in ulog.data_list:
        prefix = d.name if d.multi_id == 0 else f"{d.name}:{d.multi_id}"
        out.update(f"{prefix}.{f}" for f in d.data if not f.startswith("timestamp"))
    return out
