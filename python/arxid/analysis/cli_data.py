"""The data a command of the ``arxid`` CLI names: its arguments (:func:`data_args`), the file read
into :class:`~arxid.IOData` (:func:`load_data`: CSV, ``.npz`` or a flight log, with ``--axis`` a
flight log's preset), and the split into estimation and validation records (:func:`load`)."""

from __future__ import annotations

import argparse
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..exceptions import DataError

# The readers and the pipeline's defaults are imported where used: ``arxid --help`` needs none of them.

__all__ = ["UsageError", "data_args", "load", "load_data", "names", "parse_units", "reference_name"]


class UsageError(Exception):
    """A bad command line or bad data: reported in one line, exit code 2."""


def names(text: str | None) -> list[str]:
    return [s.strip() for s in (text or "").split(",") if s.strip()]


def parse_units(text: str | None) -> dict[str, str]:
    """``"V2=V,V1=V"`` → {"V2": "V", "V1": "V"} (the ``--units`` option)."""
    out: dict[str, str] = {}
    for part in names(text):
        name, sep, unit = part.partition("=")
        if not sep or not name.strip() or not unit.strip():
            raise UsageError(f"--units {text!r}: write NAME=UNIT pairs separated by commas, e.g. V2=V,V1=V")
        out[name.strip()] = unit.strip()
    return out


def load_data(  # noqa: C901
    path: str,
    output: str | Sequence[str],
    inputs: Sequence[str],
    extra: Sequence[str] = (),
    ts: float | None = None,
    time_col: str | None = None,
    units: dict[str, str] | None = None,
    resample: bool = False,
    log: int = 1,
):
    """Read a CSV file (header row) or a ``.npz`` archive (arrays by name) into :class:`~arxid.IOData`.

    Parameters
    ----------
    path : str
        ``.csv`` or ``.npz`` file.
    output : str or sequence of str
        Output column (array) name, or several (a comma-separated string or a list).
    inputs, extra : sequence of str
        Input and extra signal names.
    ts : float, optional
        Sampling time in seconds.
    time_col : str, optional
        Time column (uniformly sampled seconds), instead of ``ts``.
    units : dict of str to str, optional
        Unit of each signal by name (``--units``); overrides units in a CSV header.
    resample : bool
        Put a time column with jitter on a uniform grid (``--resample``, see
        :meth:`~arxid.IOData.from_csv`).
    log : int
        Which log of a blackbox file, from 1.

    In a ``.npz`` the sampling time is ``ts``, a time array named by ``time_col``, or a scalar
    array ``ts`` in the archive.
    """
    import numpy as np

    from ..data.iodata import IOData
    from .flight_log import flight_log_data, is_flight_log
    from .npz_data import read_npz

    p = Path(path)
    if not p.exists():
        raise DataError(f"data file {path!r} does not exist")
    if not p.is_file():
        raise DataError(f"data file {path!r} is not a regular file (a directory, device or pipe)")
    if not inputs:
        raise UsageError("name the input column(s) with --inputs A[,B,...]")
    outputs = names(output) if isinstance(output, str) else list(output or ())
    if not outputs:
        raise UsageError("name the output column with --output COL")
    output = outputs[0] if len(outputs) == 1 else outputs
    wanted = [*outputs, *inputs, *extra] + ([time_col] if time_col else [])
    if is_flight_log(p):  # a PX4 ULog: topic.field selectors, grid from the log (analysis/flight_log.py)
        return flight_log_data(p, output, inputs, extra, ts, units, log)
    if p.suffix.lower() == ".npy":
        raise DataError(
            f"{p.name} holds one unnamed array; save the signals by name with "
            "numpy.savez('log.npz', y=..., u=..., ts=...) or write a CSV file with a header row"
        )
    if p.suffix.lower() == ".npz":
        columns, ts = read_npz(p, wanted, ts, time_col)
        data = IOData._from_columns(
            columns,
            output=output,
            inputs=list(inputs),
            extra=list(extra),
            ts=ts,
            time=time_col,
            units=units,
            source=p.name,
            resample=resample,
        )
    else:
        try:
            if ts is None and time_col is None:
                raise UsageError("give the sampling time with --ts SECONDS or a time column with --time COL")
            grid: dict[str, Any] = dict(ts=ts, time=time_col, units=units, resample=resample)
            data = IOData.from_csv(p, output=output, inputs=list(inputs), extra=list(extra), **grid)
        except UnicodeDecodeError:
            raise DataError(
                f"{p.name} is not a text CSV file (it holds bytes that are not UTF-8); "
                "give a CSV file with a header row or a .npz archive"
            ) from None
    signals = [*zip(data.output_names, data.outputs.T), *zip(data.input_names, data.u.T), *data.extra.items()]
    for name, values in signals:
        if not np.isfinite(values).any():
            raise DataError(f"{p.name}: the column {name!r} holds no numbers (every sample is missing)")
    return data


def data_args(p: argparse.ArgumentParser, validation: bool = True, split_default: bool = True) -> None:
    from .pipeline import DEFAULT_SPLIT

    p.add_argument(
        "data",
        metavar="DATA",
        help="CSV file with a header row, .npz archive, or a flight log: PX4 .ulg (topic.field), "
        "Betaflight/INAV .bbl/.bfl/.txt (gyroADC[0]), ArduPilot .bin (RATE.R)",
    )
    p.add_argument(
        "--output", metavar="COL", help="output column (not with --axis); 'arxid ssest' takes several: p,q,r"
    )
    p.add_argument("--inputs", metavar="A[,B]", help="input column(s), comma separated (not with --axis)")
    p.add_argument(
        "--axis",
        choices=("roll", "pitch", "yaw"),
        help="a flight log's rate loop on this axis: the gyro as output, the controller's output as input, the "
        "setpoint as reference, battery, throttle and motors as extra signals",
    )
    p.add_argument("--log", type=int, default=1, metavar="N", help="which log of a blackbox file (from 1)")
    p.add_argument("--extra", metavar="C[,D]", default="", help="logged signals kept for diagnostics (e.g. vbat)")
    p.add_argument(
        "--reference",
        metavar="C",
        default=None,
        help="the setpoint the controller tracks (closed-loop data: the plant is identified with it as instrument; "
        "default: recognised from the names, e.g. roll_sp, setpoint)",
    )
    g = p.add_mutually_exclusive_group()
    g.add_argument("--ts", type=float, metavar="S", help="sampling time in seconds")
    g.add_argument("--time", metavar="COL", help="time column (uniformly sampled, seconds)")
    jitter = "put a --time column with jitter on a uniform grid (inputs held, other signals interpolated)"
    p.add_argument("--resample", action="store_true", help=jitter)
    p.add_argument(
        "--units",
        metavar="NAME=UNIT,...",
        default="",
        help="units of the signals for tables and plot axes, e.g. V2=V,V1=V (a CSV header 'vbat[V]' gives them too)",
    )
    if validation:
        v = p.add_mutually_exclusive_group()
        v.add_argument("--validation", metavar="VAL.csv", help="separate validation file with the same columns")
        v.add_argument(
            "--split",
            type=float,
            metavar="F",
            default=None,
            help="estimation fraction of DATA when no --validation is given "
            + (f"(default {DEFAULT_SPLIT})" if split_default else "(default: no validation, fit on all of DATA)"),
        )


def axis_preset(args) -> None:
    """With --axis, the flight log's preset fills --output, --inputs, --extra and --reference."""
    from .flight_log import axis_signals, is_flight_log

    if not getattr(args, "axis", None):
        return
    if args.output or args.inputs:
        raise UsageError("give either --axis or --output/--inputs: the axis names the signals of the log")
    path = Path(args.data)
    if not is_flight_log(path):
        raise UsageError(f"--axis reads a flight log (.bbl, .bfl, .txt, .bin, .ulg); {path.name} is not one")
    output, inputs, extra, reference = axis_signals(path, args.axis, args.log)
    args.output, args.inputs = output, ",".join(inputs)
    args.extra = ",".join([*extra, *names(args.extra)])
    args.reference = args.reference or reference


def load(args, need_validation: bool = True, several_outputs: bool = False):
    from .pipeline import DEFAULT_SPLIT

    axis_preset(args)
    if not several_outputs and len(names(args.output)) > 1:
        raise UsageError(
            f"--output {args.output} names {len(names(args.output))} outputs; 'arxid {args.command}' models one: "
            "give one, or fit a state-space model of all of them with 'arxid ssest'"
        )
    inputs, extra = names(args.inputs), names(args.extra)
    reference = getattr(args, "reference", None)
    if reference and reference_name(reference) not in {reference_name(e) for e in extra}:
        extra = [*extra, reference]  # the reference is read with the other logged signals
    units = parse_units(args.units)
    grid: dict[str, Any] = dict(
        ts=args.ts,
        time_col=args.time,
        units=units,
        resample=getattr(args, "resample", False),
        log=getattr(args, "log", 1),
    )
    data = load_data(args.data, args.output, inputs, extra, **grid)
    val = None
    if getattr(args, "validation", None):
        val = load_data(args.validation, args.output, inputs, extra, **grid)
        if abs(val.ts - data.ts) > 1e-9 * data.ts:
            raise UsageError(f"the validation data are sampled at {val.ts:g} s but DATA at {data.ts:g} s")
        return data, val
    split = getattr(args, "split", None)
    if split is None and not need_validation:
        return data, None
    split = DEFAULT_SPLIT if split is None else split
    if not 0 < split < 1:
        raise UsageError(f"--split {split} must be a fraction between 0 and 1, e.g. {DEFAULT_SPLIT}")
    return data.split(split)


def reference_name(name: str | None) -> str | None:
    """The reference as the data name it: a ULog selector's ``.`` and brackets become ``_``."""
    return None if not name else re.sub(r"[.\[\]]+", "_", name).strip("_")
