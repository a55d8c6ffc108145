"""The flight-log constructors of :class:`~arxid.IOData`: :meth:`~FlightLogReaders.from_blackbox`
(Betaflight/INAV) and :meth:`~FlightLogReaders.from_dataflash` (ArduPilot), each reading a log
onto one time grid with :func:`arxid.data.resample.resample`. :class:`~arxid.IOData` inherits them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TypeVar

from ..exceptions import DataError
from .outputs import GridBuilt, output_list

__all__ = ["FlightLogReaders", "selector_lists"]

_T = TypeVar("_T", bound="FlightLogReaders")


def selector_lists(inputs, extra) -> tuple[list[str], list[str]]:
    """Inputs and extra signals as lists (a single string is one name); at least one input.

    Parameters
    ----------
    inputs, extra : str or sequence of str

    Returns
    -------
    (list of str, list of str)

    Raises
    ------
    DataError
        No input.
    """
    inputs = [inputs] if isinstance(inputs, str) else list(inputs)
    extra = [extra] if isinstance(extra, str) else list(extra)
    if not inputs:
        raise DataError("name at least one input field")
    return inputs, extra


class FlightLogReaders(GridBuilt):
    """Constructors of :class:`~arxid.IOData` from flight logs (the class inherits them)."""

    @classmethod
    def from_blackbox(
        cls: type[_T],
        path,
        *,
        output: str | Sequence[str],
        inputs: Sequence[str],
        extra: Sequence[str] = (),
        log: int = 1,
        ts: float | None = None,
        max_gap: float | None = None,
    ) -> _T:
        """Read a Betaflight or INAV blackbox log (``.bbl``, ``.bfl``, ``.txt``) onto one time grid.

        Fields are named as the firmware writes them, in its units (see
        :mod:`arxid.data.blackbox`): gyro and setpoints in deg/s, ``vbatLatest`` in V, motors in
        the header's ``motorOutput`` range; ``pidsum[i]`` is the PID output of axis ``i`` (P + I +
        D + feedforward). Commands (setpoints, PID terms, motors and the inputs) are held between
        frames, measurements interpolated, gaps longer than ``max_gap`` are NaN. Signal names are
        the selectors with brackets replaced by ``_`` (``gyroADC_0``).

        Parameters
        ----------
        path : str or Path
        output : str or sequence of str
            E.g. ``"gyroADC[0]"`` (roll rate), or several (``["gyroADC[0]", "gyroADC[1]", "gyroADC[2]"]``).
        inputs : sequence of str
            E.g. ``["pidsum[0]"]`` or ``["axisP[0]", "axisI[0]", "axisD[0]"]``.
        extra : sequence of str
            Signals kept for diagnostics (``"setpoint[0]"``, ``"vbatLatest"``, ``"motor[0]"``).
        log : int
            Which log of the file (one per arming), from 1.
        ts : float, optional
            Grid step [s]; default the median frame interval.
        max_gap : float, optional
            Longest interval between frames bridged [s]; default 3 frame intervals.

        Returns
        -------
        IOData

        Raises
        ------
        DataError
            A missing or unreadable file, no such log or field (the message names the file).
        """
        from .blackbox import read_blackbox

        inputs, extra = selector_lists(inputs, extra)
        outputs = output_list(output)
        sig = read_blackbox(path, [*outputs, *inputs, *extra], log=log, hold=inputs, ts=ts, max_gap=max_gap)
        return cls._from_grid(sig.values, sig.units, sig.ts, len(inputs), len(outputs))

    @classmethod
    def from_dataflash(
        cls: type[_T],
        path,
        *,
        output: str | Sequence[str],
        inputs: Sequence[str],
        extra: Sequence[str] = (),
        instance: int | None = None,
        ts: float | None = None,
        max_gap: float | None = None,
    ) -> _T:
        """Read an ArduPilot DataFlash log (``.bin``) onto one time grid.

        Fields are ``MESSAGE.Field`` as ArduPilot logs them, in its units (see
        :mod:`arxid.data.dataflash`). Commands (the inputs, ``*Des*``, ``*Out``, ``RCOU``) are
        held between samples, measurements interpolated, gaps longer than ``max_gap`` are NaN.
        Signal names are the selectors with ``.`` replaced by ``_`` (``RATE_R``).

        Parameters
        ----------
        path : str or Path
        output : str or sequence of str
            E.g. ``"RATE.R"`` (ArduCopter's roll rate, deg/s), or several.
        inputs : sequence of str
            E.g. ``["RATE.ROut"]`` (the roll rate controller's output).
        extra : sequence of str
            Signals kept for diagnostics (``"RATE.RDes"``, ``"BAT.Volt"``).
        instance : int, optional
            Instance of messages logged for several units (batteries); default the lowest.
        ts : float, optional
            Grid step [s]; default the output message's median interval.
        max_gap : float, optional
            Longest interval between samples bridged [s]; default 3 times each message's.

        Returns
        -------
        IOData

        Raises
        ------
        DataError
            A missing or unreadable file, no such message or field (the message names the file).
        """
        from .dataflash import read_dataflash

        inputs, extra = selector_lists(inputs, extra)
        outputs = output_list(output)
        sig = read_dataflash(path, [*outputs, *inputs, *extra], instance=instance, hold=inputs, ts=ts, max_gap=max_gap)
        return cls._from_grid(sig.values, sig.units, sig.ts, len(inputs), len(outputs))
