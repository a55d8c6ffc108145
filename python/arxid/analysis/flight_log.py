"""``arxid diagnose flight.bbl --axis roll``: a flight log as the CLI's data (:func:`flight_log_data`).

PX4 ULog (``.ulg``), Betaflight/INAV blackbox (``.bbl``, ``.bfl``, ``.txt``) and ArduPilot DataFlash
(``.bin``) are read by their own readers with the signals named as the firmware writes them; with
an axis the preset of :mod:`arxid.data.presets` names them (gyro as output, the controller's output
as input, the setpoint as reference, battery, throttle and motors as extra signals).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..data.iodata import IOData
from ..exceptions import DataError

# The readers and presets (data.blackbox, data.presets) load in the functions that use them: the
# command line asks is_flight_log of every file, and a CSV file needs neither.

__all__ = ["flight_log_data", "is_flight_log", "axis_signals"]

_FLIGHT_LOG_SUFFIXES = (".ulg", ".bbl", ".bfl", ".bin", ".txt")


def is_flight_log(path: Path) -> bool:
    """Whether ``path`` names a flight log (a ULog, blackbox or DataFlash file; a ``.txt`` file only
    when it starts as a blackbox log).

    Parameters
    ----------
    path : Path

    Returns
    -------
    bool
    """
    if path.suffix.lower() not in _FLIGHT_LOG_SUFFIXES:
        return False
    from ..data.presets import log_kind

    try:
        log_kind(path)
    except DataError:  # a .txt export such as a CSV file
        return False
    return True


def axis_signals(path: Path, axis: str, log: int = 1) -> tuple[str, list[str], list[str], str]:
    """The output, inputs, extra signals and reference of one axis of a flight log, as selectors,
    and the reference's signal name.

    Parameters
    ----------
    path : Path
    axis : {"roll", "pitch", "yaw"}
    log : int
        Which log of a blackbox file, from 1.

    Returns
    -------
    output : str
    inputs, extra : list of str
        The extra signals hold the reference first.
    reference : str
        The reference's signal name in the data (``setpoint_0``, ``RATE_RDes``, ...).

    Raises
    ------
    DataError
        When the log holds no signal for the axis (the message says what is missing).
    """
    from ..data.blackbox import signal_name
    from ..data.presets import log_preset

    preset = log_preset(path, axis, log=log)
    args = preset.read_arguments()
    return args["output"], args["inputs"], args["extra"], signal_name(preset.reference)


def flight_log_data(
    path: Path,
    output: str | Sequence[str],
    inputs: Sequence[str],
    extra: Sequence[str],
    ts: float | None,
    units: dict | None,
    log: int = 1,
) -> IOData:
    """The CLI's ``--output``, ``--inputs`` and ``--extra`` (the firmware's selectors) read from a log.

    Parameters
    ----------
    path : Path
    output : str or sequence of str
        One output selector, or several.
    inputs, extra : sequence of str
    ts : float or None
        Grid step (None: the log's own rate).
    units : dict or None
        ``--units`` overrides, by signal name.
    log : int
        Which log of a blackbox file, from 1.

    Returns
    -------
    IOData
    """
    from ..data.presets import log_kind

    kw: dict[str, Any] = {"output": output, "inputs": list(inputs), "extra": list(extra), "ts": ts}
    kind = log_kind(path)
    if kind == "blackbox":
        data = IOData.from_blackbox(path, log=log, **kw)
    elif kind == "dataflash":
        data = IOData.from_dataflash(path, **kw)
    else:
        data = IOData.from_ulog(path, **kw)
    if not units:
        return data
    unit = dict(zip(data.output_names, data.output_units, strict=True))
    unit.update(zip(data.input_names, data.input_units, strict=True))
    unit.update(data.extra_units)
    unit.update(units)
    return data.with_samples(
        output_unit=[unit[n] for n in data.output_names],
        input_units=tuple(unit[n] for n in data.input_names),
        extra_units={n: unit.get(n, "") for n in data.extra},
    )
