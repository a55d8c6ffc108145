"""ArduPilot DataFlash logs (``.bin``): :func:`read_dataflash`, behind :meth:`IOData.from_dataflash`.

The Rust core decodes the log with the ``ardupilot-binlog`` crate (MIT/Apache). Fields are chosen
as ``MESSAGE.Field``, the names ArduPilot writes (``RATE.R``, ``RATE.RDes``, ``RATE.ROut``,
``BAT.Volt``, ``RCOU.C1``), in ArduPilot's units (the log's ``UNIT``/``FMTU`` messages name them:
``RATE.R`` in deg/s, ``BAT.Volt`` in V). Times are each message's ``TimeUS``.

Messages come at their own rates (``RATE`` at the loop's log rate, ``BAT`` at 10 Hz): the signals
go onto one grid with :func:`arxid.data.resample.resample`. Commands (the inputs, desired values
``*Des*``, controller outputs ``*Out``, ``RCOU``/``RCIN``) are held, measurements interpolated,
long gaps NaN. A message with several instances (two batteries) is read for one ``instance``.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._base import _core
from ..exceptions import ArxidWarning, DataError
from .blackbox import signal_name
from .resample import resample

__all__ = ["DataflashSignals", "dataflash_formats", "read_dataflash"]

_HELD_MESSAGES = ("RCOU", "RCIN", "RCI2")


def _is_command(message: str, field: str) -> bool:
    return message in _HELD_MESSAGES or "Des" in field or field.endswith("Out") or field == "Tar"


@dataclass(frozen=True)
class DataflashSignals:
    """Fields of a DataFlash log on one grid (what :meth:`IOData.from_dataflash` builds on).

    Attributes
    ----------
    time : ndarray of shape (n,)
        Seconds since boot.
    values : dict of str to ndarray
        Each field on the grid (NaN in gaps), by signal name (``RATE_R``), in the order asked.
    units : dict of str to str
    held : dict of str to bool
    ts : float
    messages : int
        Messages decoded in the file (all types).
    bytes_lost : int
        Bytes of the file in no decoded message (damaged or cut short).
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    units: dict[str, str]
    held: dict[str, bool]
    ts: float
    messages: int
    bytes_lost: int


def _check_path(path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no DataFlash log file at {path}")
    return path


def _parse(selector: str) -> tuple[str, str]:
    m = re.fullmatch(r"([A-Z0-9_]+)\.(\w+)", str(selector))
    if not m:
        raise DataError(
            f"{selector!r} does not name a DataFlash field; write MESSAGE.Field as ArduPilot logs it, e.g. 'RATE.R'"
        )
    return m[1], m[2]


def dataflash_formats(path, logged: bool = True) -> dict[str, tuple[str, ...]]:
    """The message types a DataFlash log holds, with their fields.

    Parameters
    ----------
    path : str or Path
    logged : bool
        Only the types with at least one message (ArduPilot defines many it never logs); False:
        every type the log's ``FMT`` messages define.

    Returns
    -------
    dict of str to tuple of str
        Field names by message name (``{"RATE": ("TimeUS", "RDes", "R", "ROut", ...), ...}``).

    Raises
    ------
    DataError
        The file is missing or not a DataFlash log.
    """
    path = _check_path(path)
    formats = _core.dataflash_read(path, [])[4]
    return {name: tuple(fields) for name, fields, count in formats if count or not logged}


def read_dataflash(
    path,
    fields: Sequence[str],
    *,
    instance: int | None = None,
    hold: Sequence[str] = (),
    ts: float | None = None,
    max_gap: float | None = None,
) -> DataflashSignals:
    """Read DataFlash fields onto one time grid.

    Parameters
    ----------
    path : str or Path
        A ``.bin`` file.
    fields : sequence of str
        ``MESSAGE.Field`` selectors; the first one's message sets the default grid step.
    instance : int, optional
        Instance of messages that have several (``BAT`` of the second battery: 1); default the
        lowest one logged.
    hold : sequence of str
        Selectors held between samples besides the commands.
    ts : float, optional
        Grid step [s] (default: the median interval of the first field's message).
    max_gap : float, optional
        Longest interval between samples bridged [s] (default: 3 times each message's interval).

    Returns
    -------
    DataflashSignals

    Raises
    ------
    DataError
        The file is missing or not a DataFlash log, a message or field is not in it, a message
        has no sample (or none of ``instance``), or the messages never overlap in time.

    Warns
    -----
    ArxidWarning
        When part of the file cannot be decoded (damaged or cut short): how many bytes.
    """
    path = _check_path(path)
    fields = list(fields)
    repeated = sorted({f for f in fields if fields.count(f) > 1})
    if repeated:
        raise DataError(f"each field may be chosen once; repeated: {repeated}")
    pairs = [_parse(f) for f in fields]
    messages, lost, n_messages, n_bytes, _ = _core.dataflash_read(path, pairs)
    by_name = dict(messages)
    if lost:
        warnings.warn(
            f"{path.name}: {lost} of {n_bytes} bytes ({100 * lost / max(n_bytes, 1):.2g} %) could not be decoded "
            f"(damaged or cut short); the {n_messages} messages around them were read",
            ArxidWarning,
            stacklevel=3,
        )
    samples, units = {}, {}
    for f, (message, field) in zip(fields, pairs, strict=True):
        time_us, inst, columns, msg_units = by_name[message]
        names = [b for a, b in pairs if a == message]
        v = columns[names.index(field)]
        keep = np.ones(time_us.shape[0], dtype=bool)
        if inst is not None and inst.size:
            chosen = int(np.nanmin(inst)) if instance is None else int(instance)
            keep = inst == chosen
            if not keep.any():
                raise DataError(
                    f"{path.name} logs {message} for instance(s) {sorted({int(i) for i in np.unique(inst)})}, "
                    f"not {chosen}"
                )
        if not keep.any():
            raise DataError(f"{path.name} defines {message} but logs no {message} message")
        samples[f] = (time_us[keep] * 1e-6, v[keep])
        units[f] = msg_units[names.index(field)]
    held_names = {f for f, (m, fl) in zip(fields, pairs, strict=True) if f in set(hold) or _is_command(m, fl)}
    grid = resample(samples, hold=held_names, ts=ts, max_gap=max_gap, source=path.name)
    return DataflashSignals(
        grid.time,
        {signal_name(f): grid.values[f] for f in fields},
        {signal_name(f): units[f] for f in fields},
        {signal_name(f): grid.held[f] for f in fields},
        grid.ts,
        n_messages,
        lost,
    )
