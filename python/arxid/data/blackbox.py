"""Betaflight and INAV blackbox logs (``.bbl``, ``.bfl``, ``.txt``): :func:`read_blackbox`, behind
:meth:`IOData.from_blackbox`.

The Rust core decodes the log with the ``blackbox-log`` crate (MIT/Apache). Fields are named as the
firmware writes them (``gyroADC[0]``, ``setpoint[0]``, ``axisP[0]``, ``motor[2]``, ``vbatLatest``),
in the firmware's units: gyro and setpoints in deg/s, battery voltage in V, current in A,
acceleration in g, motor outputs in the range of the header's ``motorOutput`` (DShot 158..2047
say). ``pidsum[i]`` is the PID controller's output on axis ``i``, the sum of the P, I, D and
feedforward terms (``axisP[i] + axisI[i] + axisD[i] + axisF[i]``, the terms the log holds).

A file holds one log per arming; ``log`` picks one (from 1). The frames come at the log rate with
jitter, and frames the firmware could not write or the decoder could not read leave gaps: the
signals go onto one grid with :func:`arxid.data.resample.resample` (commands held, measurements
interpolated, long gaps NaN).
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
from .resample import resample

__all__ = ["BlackboxSignals", "blackbox_header", "read_blackbox", "signal_name"]

#: Fields of commands, held between frames (zero-order hold); the rest are interpolated.
_COMMANDS = ("setpoint", "rcCommand", "axisP", "axisI", "axisD", "axisF", "pidsum", "motor")
_PID_TERMS = ("axisP", "axisI", "axisD", "axisF")


def signal_name(selector: str) -> str:
    """The signal name of a field: brackets and other characters an effect cannot hold become ``_``.

    Parameters
    ----------
    selector : str

    Returns
    -------
    str

    Examples
    --------
    >>> signal_name("gyroADC[0]"), signal_name("RATE.ROut")
    ('gyroADC_0', 'RATE_ROut')
    """
    return re.sub(r"\W+", "_", selector).strip("_")


@dataclass(frozen=True)
class BlackboxHeader:
    """The header of one log: what it holds, without decoding a frame.

    Attributes
    ----------
    n_logs : int
        Logs in the file.
    headers : dict of str to str
        The ``H name:value`` lines (firmware, PID gains, rates, filters).
    fields : tuple of str
        Fields of the main frames, as the firmware names them.
    """

    n_logs: int
    headers: dict[str, str]
    fields: tuple[str, ...]

    @property
    def motor_range(self) -> tuple[float, float] | None:
        """The motor output range of the header's ``motorOutput`` (e.g. ``(158, 2047)``)."""
        text = self.headers.get("motorOutput", "")
        parts = [p for p in text.split(",") if p.strip()]
        try:
            return (float(parts[0]), float(parts[1])) if len(parts) >= 2 else None
        except ValueError:
            return None


def blackbox_header(path, log: int = 1) -> BlackboxHeader:
    """The header of log ``log`` of a blackbox file (its fields, firmware and settings).

    Parameters
    ----------
    path : str or Path
    log : int
        Which log of the file, from 1.

    Returns
    -------
    BlackboxHeader

    Raises
    ------
    DataError
        The file is missing, not a blackbox log, has no log ``log``, or its header is unusable.
    """
    path = _check_path(path)
    n_logs, headers, fields = _core.blackbox_fields(path, _log_number(log))
    return BlackboxHeader(n_logs, dict(headers), tuple(fields))


@dataclass(frozen=True)
class BlackboxSignals:
    """Fields of one blackbox log on one grid (what :meth:`IOData.from_blackbox` builds on).

    Attributes
    ----------
    time : ndarray of shape (n,)
        Seconds since power-on.
    values : dict of str to ndarray
        Each field on the grid (NaN in gaps), by signal name (``gyroADC_0``), in the order asked.
    units : dict of str to str
    held : dict of str to bool
    ts : float
    header : BlackboxHeader
    frames : int
        Main frames decoded.
    frames_lost : int
        Frames missing between them (counted from the jumps of the frame times).
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    units: dict[str, str]
    held: dict[str, bool]
    ts: float
    header: BlackboxHeader
    frames: int
    frames_lost: int


def _check_path(path) -> Path:
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no blackbox log file at {path}")
    return path


def _log_number(log) -> int:
    if isinstance(log, bool) or not isinstance(log, (int, np.integer)) or log < 1:
        raise DataError(f"log must be the number of a log in the file, counted from 1; got {log!r}")
    return int(log)


def _unit(field: str, rust_unit: str, header: BlackboxHeader) -> str:
    if rust_unit:
        return rust_unit
    base, _, index = field.partition("[")
    if base == "setpoint" and index != "3]":
        return "deg/s"
    if base == "motor" and header.motor_range:
        lo, hi = header.motor_range
        return f"{lo:g}..{hi:g}"
    return ""


def _frames_lost(time_us: np.ndarray) -> int:
    """Frames missing, from the jumps of the frame times (the log's usual step; the decoder's
    loop iteration numbers skip between P frames, so they cannot count frames)."""
    steps = np.diff(time_us)
    steps = steps[steps > 0]
    if steps.size == 0:
        return 0
    usual = float(np.median(steps))
    jumps = steps[steps > 1.5 * usual]
    return int(np.sum(np.round(jumps / usual) - 1))


def read_blackbox(
    path,
    fields: Sequence[str],
    *,
    log: int = 1,
    hold: Sequence[str] = (),
    ts: float | None = None,
    max_gap: float | None = None,
) -> BlackboxSignals:
    """Read fields of a Betaflight/INAV blackbox log onto one time grid.

    Parameters
    ----------
    path : str or Path
        A ``.bbl``, ``.bfl`` or ``.txt`` blackbox file.
    fields : sequence of str
        Main-frame fields as the firmware names them (``gyroADC[0]``), or ``pidsum[i]``.
    log : int
        Which log of the file (one per arming), from 1.
    hold : sequence of str
        Fields held between frames besides the commands (setpoints, PID terms, motors).
    ts : float, optional
        Grid step [s] (default: the median frame interval).
    max_gap : float, optional
        Longest interval between frames bridged [s] (default: 3 frame intervals).

    Returns
    -------
    BlackboxSignals

    Raises
    ------
    DataError
        The file is missing, not a blackbox log, has no log ``log`` or no such field, or no frame
        of it can be read.

    Warns
    -----
    ArxidWarning
        When frames are lost (the count) or the log is cut short.
    """
    path = _check_path(path)
    log = _log_number(log)
    fields = list(fields)
    repeated = sorted({f for f in fields if fields.count(f) > 1})
    if repeated:
        raise DataError(f"each field may be chosen once; repeated: {repeated}")
    header = blackbox_header(path, log)
    wanted: list[str] = []
    for f in fields:
        m = re.fullmatch(r"pidsum\[(\d)\]", f)
        if m:
            terms = [f"{t}[{m[1]}]" for t in _PID_TERMS if f"{t}[{m[1]}]" in header.fields]
            if not terms:
                raise DataError(f"{path.name} log {log} holds no PID term of axis {m[1]} (axisP[{m[1]}] ...)")
            wanted += [t for t in terms if t not in wanted]
        elif f not in wanted:
            wanted.append(f)
    _, _, _, time_us, _, columns, units, complete = _core.blackbox_read(path, log, wanted)
    raw = dict(zip(wanted, columns, strict=True))
    raw_units = dict(zip(wanted, units, strict=True))
    t = time_us * 1e-6
    samples: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    unit: dict[str, str] = {}
    for f in fields:
        m = re.fullmatch(r"pidsum\[(\d)\]", f)
        if m:
            parts = [raw[f"{x}[{m[1]}]"] for x in _PID_TERMS if f"{x}[{m[1]}]" in raw]
            samples[f] = (t, np.sum(parts, axis=0))
            unit[f] = ""
        else:
            samples[f] = (t, raw[f])
            unit[f] = _unit(f, raw_units[f], header)
    lost = _frames_lost(time_us)
    if lost or not complete:
        what = []
        if lost:
            what.append(f"{lost} frame(s) are missing between the {len(t)} read (gaps, NaN where long)")
        if not complete:
            what.append("the log ends without its end-of-log mark (cut short)")
        warnings.warn(f"{path.name} log {log}: " + "; ".join(what), ArxidWarning, stacklevel=3)
    held_names = {f for f in fields if f in set(hold) or f.split("[")[0] in _COMMANDS}
    grid = resample(samples, hold=held_names, ts=ts, max_gap=max_gap, source=f"{path.name} log {log}")
    return BlackboxSignals(
        grid.time,
        {signal_name(f): grid.values[f] for f in fields},
        {signal_name(f): unit[f] for f in fields},
        {signal_name(f): grid.held[f] for f in fields},
        grid.ts,
        header,
        len(t),
        lost,
    )
