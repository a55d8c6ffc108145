"""``arxid diagnose flight.ulg``: a PX4 flight log as the CLI's data (:func:`flight_log_data`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..data.iodata import IOData

__all__ = ["flight_log_data", "is_flight_log"]


def is_flight_log(path: Path) -> bool:
    """Whether ``path`` names a PX4 ULog file (by its suffix ``.ulg``).

    Parameters
    ----------
    path : Path

    Returns
    -------
    bool
    """
    return path.suffix.lower() == ".ulg"


def flight_log_data(
    path: Path, output: str, inputs: Sequence[str], extra: Sequence[str], ts: float | None, units: dict | None
) -> IOData:
    """The CLI's ``--output``, ``--inputs`` and ``--extra`` (``topic.field`` selectors) read from a ULog.

    Parameters
    ----------
    path : Path
    output : str
    inputs, extra : sequence of str
    ts : float or None
        Grid step (None: the output topic's rate).
    units : dict or None
        ``--units`` overrides, by signal name.

    Returns
    -------
    IOData
    """
    data = IOData.from_ulog(path, output=output, inputs=list(inputs), extra=list(extra), ts=ts)
    if not units:
        return data
    unit = {**{data.output_name: data.output_unit}, **dict(zip(data.input_names, data.input_units, strict=True))}
    unit.update(data.extra_units)
    unit.update(units)
    return IOData(
        data.y,
        data.u,
        data.ts,
        output_name=data.output_name,
        input_names=data.input_names,
        output_unit=unit[data.output_name],
        input_units=tuple(unit[n] for n in data.input_names),
        extra=data.extra,
        extra_units={n: unit.get(n, "") for n in data.extra},
    )
