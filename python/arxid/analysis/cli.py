"""The ``arxid`` command: fit, sweep, diagnose, report and demo from a shell.

Readable tables by default; ``--json`` prints one JSON object on stdout (NaN becomes null) for
scripts. Progress bars go to stderr. Exit code 0 on success, 2 with a one-line message on bad
arguments or data, 1 on an unexpected internal error.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._base.formatting import format_value, json_safe, text_table
from .._base.limits import MAX_ORDER
from .._base.version import __version__
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.arx_model import arx
from ..models.spec import MODEL_FORMS, parse_model_spec
from ..selection.growth import DEFAULT_GROWTH_SECONDS
from ..selection.search import DEFAULT_GRID, sweep
from .benchmark import add_bench_command
from .fleet_cli import add_fleet_command
from .flight_log import axis_signals, flight_log_data, is_flight_log
from .npz_data import read_npz
from .pipeline import DEFAULT_SPLIT, Analysis, analyse, choose
from .report.html import render_html
from .verdicts import negative_fit_note

__all__ = ["main", "load_data", "parse_range"]

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE = 0, 1, 2


class UsageError(Exception):
    """A bad command line or bad data: reported in one line, exit code 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage block: scripts read stderr
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


def _names(text: str | None) -> list[str]:
    return [s.strip() for s in (text or "").split(",") if s.strip()]


def parse_range(text: str, name: str) -> Sequence[int]:
    """``"1:4"`` → range(1, 5) (inclusive), ``"0,2,5"`` → [0, 2, 5], ``"3"`` → [3].

    A single ``LOW:HIGH`` stays a lazy ``range``: its size is judged by the sweep's memory check,
    not by building it here.
    """
    out: list[int] = []
    try:
        parts = [p.strip() for p in text.split(",")]
        for part in parts:
            if ":" in part:
                a, b = part.split(":", 1)
                lo, hi = int(a), int(b)
                if hi < lo:
                    raise UsageError(f"--{name} {text!r}: the range {part} is empty (write LOW:HIGH, inclusive)")
                if lo >= 0 and hi > MAX_ORDER:
                    raise UsageError(f"--{name} {text!r}: {hi} is too large (at most {MAX_ORDER})")
                if len(parts) == 1 and lo >= 0:
                    return range(lo, hi + 1)
                if hi - lo > 10**6:
                    raise UsageError(f"--{name} {text!r}: the range {part} is too long to combine with others")
                out.extend(range(lo, hi + 1))
            elif part:
                out.append(int(part))
    except ValueError:
        raise UsageError(f"--{name} {text!r} is not a range; write e.g. 1:4 (inclusive) or 1,2,5") from None
    if not out or min(out) < 0:
        raise UsageError(f"--{name} {text!r} must list non-negative integers")
    return sorted(set(out))


def parse_units(text: str | None) -> dict[str, str]:
    """``"V2=V,V1=V"`` → {"V2": "V", "V1": "V"} (the ``--units`` option)."""
    out: dict[str, str] = {}
    for part in _names(text):
        name, sep, unit = part.partition("=")
        if not sep or not name.strip() or not unit.strip():
            raise UsageError(f"--units {text!r}: write NAME=UNIT pairs separated by commas, e.g. V2=V,V1=V")
        out[name.strip()] = unit.strip()
    return out


def _parse_orders(text: str) -> tuple[int, int, int]:
    parts = _names(text)
    try:
        vals = tuple(int(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 3 or min(vals) < 0:
        raise UsageError(f"--orders {text!r} must be three non-negative integers NA,NB,NK, e.g. 2,1,8")
    na, nb, nk = vals
    return na, nb, nk


def load_data(  # noqa: C901
    path: str,
    output: str,
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
    output : str
        Output column (array) name.
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
    p = Path(path)
    if not p.exists():
        raise DataError(f"data file {path!r} does not exist")
    if not p.is_file():
        raise DataError(f"data file {path!r} is not a regular file (a directory, device or pipe)")
    if not inputs:
        raise UsageError("name the input column(s) with --inputs A[,B,...]")
    if not output:
        raise UsageError("name the output column with --output COL")
    wanted = [output, *inputs, *extra] + ([time_col] if time_col else [])
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
    for name, values in [(data.output_name, data.y), *zip(data.input_names, data.u.T), *data.extra.items()]:
        if not np.isfinite(values).any():
            raise DataError(f"{p.name}: the column {name!r} holds no numbers (every sample is missing)")
    return data


def _data_args(p: argparse.ArgumentParser, validation: bool = True, split_default: bool = True) -> None:
    p.add_argument(
        "data",
        metavar="DATA",
        help="CSV file with a header row, .npz archive, or a flight log: PX4 .ulg (topic.field), "
        "Betaflight/INAV .bbl/.bfl/.txt (gyroADC[0]), ArduPilot .bin (RATE.R)",
    )
    p.add_argument("--output", metavar="COL", help="output column (not with --axis)")
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


def _range_text(r: Sequence[int]) -> str:
    return f"{min(r)}:{max(r)}"


_GRID_HELP = {"na": "poles", "nb": "input coefficients", "nk": "input delays in samples"}


def _order_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--orders", metavar="NA,NB,NK", help="one fixed structure, e.g. 2,1,8 (instead of a sweep)")
    for k, what in _GRID_HELP.items():
        p.add_argument(
            f"--{k}",
            metavar="RANGE",
            default=None,
            help=f"{k} grid ({what}), e.g. 1:4 (inclusive) or 1,2,5 (default {_range_text(DEFAULT_GRID[k])})",
        )


def _grow_args(p: argparse.ArgumentParser) -> None:
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--grow",
        dest="grow",
        action="store_const",
        const=True,
        default=None,
        help="grow the grid while the chosen structure sits on its edge and growing lowers its validation error, "
        "also a grid given by --na/--nb/--nk (the default grid grows unless --no-grow)",
    )
    g.add_argument("--no-grow", dest="grow", action="store_const", const=False, help="sweep the grid as it is")
    p.add_argument(
        "--max-seconds",
        type=float,
        default=DEFAULT_GROWTH_SECONDS,
        metavar="S",
        help="time budget of the grid search in seconds: no larger grid is started that would pass it "
        "(default %(default)g)",
    )


def _grows(args) -> bool:
    """Grow the grid: asked for, or the default grid (no --na/--nb/--nk and no --no-grow)."""
    if args.grow is not None:
        return bool(args.grow)
    return all(getattr(args, k, None) is None for k in ("na", "nb", "nk"))


def _model_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--model",
        metavar="KIND:ORDERS",
        help="one structure to fit and diagnose instead of a sweep: "
        + ", ".join(form for form, _ in MODEL_FORMS.values())
        + " (e.g. oe:2,2,3)",
    )


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout instead of tables")
    p.add_argument("--no-progress", action="store_true", help="no progress bars on stderr")


def _axis_preset(args) -> None:
    """With --axis, the flight log's preset fills --output, --inputs, --extra and --reference."""
    if not getattr(args, "axis", None):
        return
    if args.output or args.inputs:
        raise UsageError("give either --axis or --output/--inputs: the axis names the signals of the log")
    path = Path(args.data)
    if not is_flight_log(path):
        raise UsageError(f"--axis reads a flight log (.bbl, .bfl, .txt, .bin, .ulg); {path.name} is not one")
    output, inputs, extra, reference = axis_signals(path, args.axis, args.log)
    args.output, args.inputs = output, ",".join(inputs)
    args.extra = ",".join([*extra, *_names(args.extra)])
    args.reference = args.reference or reference


def _load(args, need_validation: bool = True):
    _axis_preset(args)
    inputs, extra = _names(args.inputs), _names(args.extra)
    reference = getattr(args, "reference", None)
    if reference and _reference_name(reference) not in {_reference_name(e) for e in extra}:
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


def _grid(args) -> dict | None:
    """The sweep grid from --na/--nb/--nk (each defaulting to DEFAULT_GRID), or None with --orders."""
    given = {k: getattr(args, k, None) for k in ("na", "nb", "nk")}
    if getattr(args, "orders", None):
        if any(v is not None for v in given.values()):
            raise UsageError("give either --orders NA,NB,NK or the grid --na/--nb/--nk, not both")
        return None
    return {k: parse_range(v, k) if v is not None else list(DEFAULT_GRID[k]) for k, v in given.items()}


def _progress(args) -> bool:
    return not args.no_progress and sys.stderr.isatty()


def _print_json(obj) -> None:
    sys.stdout.write(json.dumps(json_safe(obj), allow_nan=False, indent=2) + "\n")


# ---------------------------------------------------------------------------------------- commands
def cmd_fit(args) -> int:
    est, val = _load(args, need_validation=False)
    orders = _parse_orders(args.orders) if args.orders else None
    if orders is None:
        raise UsageError("fit needs the structure: --orders NA,NB,NK (find one with 'arxid sweep')")
    effects = _names(args.effects)
    model = arx(est, *orders, effects=effects)
    h = args.horizon
    if val is not None and not np.isfinite(model.predict(val, h)).any():
        raise DataError(
            f"the validation data ({val.n_samples} samples) are too short for {model.structure_name()}: no "
            "sample is left to predict after its initial conditions; give longer validation data"
        )
    out = {
        "model": model.to_dict(),
        "structure": model.structure_name(),
        "n_rows": model.n_rows_,
        "fit_est_one_step": model.fit_percent_,
        "rms_pred_est": model.rms(est, 1),
        "horizon": h,
    }
    if val is not None:
        out.update(rms_sim_val=model.rms(val, h), rms_pred_val=model.rms(val, 1), fit_val=model.fit_percent(val, h))
    if args.save:
        model.to_json(args.save)
        out["saved"] = args.save
    if args.json:
        _print_json(out)
        return EXIT_OK
    print(str(model))
    rows = [
        ["one-step fit on estimation [%]", out["fit_est_one_step"]],
        ["one-step RMS on estimation", out["rms_pred_est"]],
    ]
    if val is not None:
        what = "free-run" if h is None else f"{h}-step"
        rows += [
            [f"{what} RMS on validation", out["rms_sim_val"]],
            ["one-step RMS on validation", out["rms_pred_val"]],
            [f"{what} fit on validation [%]", out["fit_val"]],
        ]
    print()
    print(text_table(["measure", "value"], rows))
    if val is not None and negative_fit_note(out["fit_val"]):
        print(f"({negative_fit_note(out['fit_val'])})")
    if args.save:
        print(f"\nmodel saved to {args.save}")
    return EXIT_OK


def cmd_sweep(args) -> int:
    est, val = _load(args)
    grid = _grid(args)
    if grid is None:
        o = _parse_orders(args.orders)
        grid = {"na": [o[0]], "nb": [o[1]], "nk": [o[2]]}
    t0 = time.perf_counter()
    res = sweep(est, validation=val, progress=_progress(args), expect=args.expect, horizon=args.horizon, **grid)
    res = res.extend(max_rounds=None if _grows(args) else 0, max_seconds=args.max_seconds)
    growth = res.growth
    best, choice = choose(res)
    elapsed = time.perf_counter() - t0
    rank = choice.rank or 0  # a sweep's choice always has a rank
    top = len(res) if args.all else args.top
    rows = res.summary(top=max(top, rank + 1))["structures"]
    row = rows[rank]
    out = {
        "n_structures": len(res),
        "seconds": elapsed,
        "grid": {k: list(v) for k, v in grid.items()},
        "grid_growth": None if growth is None else growth.to_dict(),
        "measure": res.measure,
        "horizon": res.horizon,
        "integrating": res.integrating,
        "choice": choice.to_dict(),
        "best": {
            "structure": best.structure_name(),
            "na": best.na_,
            "nb": list(best.nb_),
            "nk": list(best.nk_),
            "rms_val": row["rms_val"],
            "fit_val": row["fit_val"],
            "parameters": best.parameters_,
        },
        "rejected": dict(choice.skipped),
        "table": rows[:top],
    }
    if args.json:
        _print_json(out)
        return EXIT_OK
    print(res.table(top, more_hint="--all prints every one"))
    print(f"\n{len(res)} structures in {elapsed:.2f} s")
    for name, why in choice.skipped[:8]:
        print(f"skipped {name}: {why}")
    if choice.grid_edge:
        print(choice.grid_edge)
    if growth is not None and (growth.grew or growth.stop != "inside"):
        print("\n".join(growth.lines()))
    print(
        f"best sane structure: {best.structure_name()}  (validation RMS {format_value(row['rms_val'])}, "
        f"fit {format_value(row['fit_val'])} %, {res.measure})"
    )
    if negative_fit_note(row["fit_val"]):
        print(f"({negative_fit_note(row['fit_val'])})")
    return EXIT_OK


def _analyse(args) -> Analysis:
    orders = _parse_orders(args.orders) if args.orders else None
    spec = getattr(args, "model", None)
    if spec is not None:
        if orders is not None or any(getattr(args, k, None) is not None for k in ("na", "nb", "nk")):
            raise UsageError("give either --model or --orders / --na --nb --nk, not both")
        parse_model_spec(spec)  # a typed error with the correct form, before the data are read
    est, val = _load(args)
    grid = None if spec is not None or all(getattr(args, k, None) is None for k in ("na", "nb", "nk")) else _grid(args)
    return analyse(
        est,
        val,
        orders=orders,
        grid=grid,
        grow=args.grow,
        max_seconds=args.max_seconds,
        model=spec,
        horizon=args.horizon,
        expect=args.expect,
        max_steps=args.max_steps,
        progress=_progress(args),
        initial=args.initial,
        reference=_reference_name(args.reference),
    )


def _reference_name(name: str | None) -> str | None:
    """The reference as the data name it: a ULog selector's ``.`` and brackets become ``_``."""
    return None if not name else re.sub(r"[.\[\]]+", "_", name).strip("_")


def cmd_diagnose(args) -> int:
    a = _analyse(args)
    if args.json:
        _print_json(a.to_dict())
    else:
        n = len(a.diagnosis.suspects)
        print("\n".join(a.summary_lines(n_suspects=n if args.all else 12)))
        if n > 12 and not args.all:
            print(f"({n - 12} more suspects: --all prints every one)")
    return EXIT_OK


def cmd_report(args) -> int:
    t0 = time.perf_counter()
    a = _analyse(args)
    source = Path(args.data).name + (f" + {Path(args.validation).name}" if args.validation else "")
    path = Path(args.o)
    path.write_text(render_html(a, title=args.title, source=source), encoding="utf-8")
    if args.json:
        _print_json(
            {"report": str(path), "bytes": path.stat().st_size, "seconds": time.perf_counter() - t0, **a.to_dict()}
        )
    else:
        print(f"report written to {path} ({path.stat().st_size / 1e6:.1f} MB, {time.perf_counter() - t0:.1f} s)")
        print("\n".join(a.short_summary()))
        print("(arxid diagnose with the same options prints the whole diagnosis)")
    return EXIT_OK


def cmd_demo(args) -> int:
    from .demo import run_demo

    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise UsageError(f"--duration {args.duration:g} must be a positive number of seconds, e.g. 20")
    if args.write_data is not None:
        return _write_demo_flight(args)

    res = run_demo(
        output=args.o,
        seed=args.seed,
        duration=args.duration,
        progress=_progress(args),
        stream=sys.stderr if args.json else sys.stdout,
    )
    if args.json:
        _print_json(res.to_dict())
    return EXIT_OK


def _write_demo_flight(args) -> int:
    """``arxid demo --write-data FILE.csv``: the simulated flight as a CSV file, no analysis."""
    from .demo import DURATION, demo_flight_columns

    columns = demo_flight_columns(seed=args.seed, duration=args.duration or DURATION)
    header = ",".join(columns)
    try:
        np.savetxt(args.write_data, np.column_stack(list(columns.values())), "%.12g", ",", header=header, comments="")
    except OSError as exc:
        raise UsageError(f"cannot write {args.write_data}: {exc.strerror or exc}") from exc
    n, ts = len(columns["time"]), float(columns["time"][1])
    print(f"flight of seed {args.seed} written to {args.write_data} ({n} samples, --ts {ts:g}; columns {header})")
    return EXIT_OK


_EXAMPLES = {
    "fit": "example:\n  arxid fit flight.csv --output roll --inputs roll_torque --ts 0.002 --orders 2,1,8 --split 0.7\n"
    "  arxid fit flight.csv --output roll --inputs roll_torque --extra vbat --ts 0.002 --orders 2,1,8 "
    "--effects roll_torque*vbat --json",
    "sweep": "example:\n  arxid sweep flight.csv --output roll --inputs roll_torque --ts 0.002 --na 2:4 --nb 1:2 --nk 0:10\n"  # noqa: E501
    "  arxid sweep log.npz --output y --inputs u --validation val.npz --json",
    "diagnose": "example:\n  arxid diagnose flight.csv --output roll --inputs roll_torque --extra vbat --ts 0.002 "
    "--orders 2,1,8 --split 0.7 --json\n"
    "  arxid diagnose log.csv --output y --inputs u --ts 0.01 --model oe:2,2,3",
    "report": "example:\n  arxid report flight.csv --output roll --inputs roll_torque --extra vbat --time t -o report.html",  # noqa: E501
    "demo": "example:\n  arxid demo                       # simulated quadrotor flight, writes arxid-demo-report.html\n"
    "  arxid demo -o /tmp/demo.html --seed 3\n"
    "  arxid demo --seed 1 --write-data est.csv   # the simulated flight only, as CSV",
}


def build_parser() -> argparse.ArgumentParser:
    root = _Parser(
        prog="arxid",
        description="ARX system identification that finds the missing physical effect.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  arxid demo\n  arxid sweep data.csv --output y --inputs u --ts 0.01\n"
        "  arxid diagnose data.csv --output y --inputs u --extra vbat --ts 0.01 --json\n"
        "run 'arxid COMMAND --help' for each command's options.",
    )
    root.add_argument("--version", action="version", version=f"arxid {__version__}")
    sub = root.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    kw: dict[str, Any] = {"formatter_class": argparse.RawDescriptionHelpFormatter}

    p = sub.add_parser(
        "fit",
        help="fit one ARX structure (optionally with effects)",
        epilog=_EXAMPLES["fit"],
        description="Fit one ARX model by QR and report its errors.",
        **kw,
    )
    _data_args(p, split_default=False)
    p.add_argument("--orders", metavar="NA,NB,NK", required=True, help="structure, e.g. 2,1,8")
    p.add_argument("--effects", metavar="E[,F]", default="", help="effect terms, e.g. 'u1*vbat,const'")
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--save", metavar="MODEL.json", help="write the fitted model as JSON")
    _common(p)
    p.set_defaults(func=cmd_fit)

    p = sub.add_parser(
        "sweep",
        help="fit and validate every (na, nb, nk) of a grid",
        epilog=_EXAMPLES["sweep"],
        description="Exhaustive order sweep, ranked by validation error; step sanity checks.",
        **kw,
    )
    _data_args(p)
    _order_args(p)
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--expect", choices=["stable", "integrating", "double-integrating"], help="step sanity expectation")
    p.add_argument("--top", type=int, default=20, metavar="N", help="rows to print (default %(default)s)")
    p.add_argument("--all", action="store_true", help="print every structure (instead of --top)")
    _grow_args(p)
    _common(p)
    p.set_defaults(func=cmd_sweep)
    _add_analysis_commands(sub, kw)
    add_bench_command(sub, kw, load=_load, grid=_grid)
    fleet: dict[str, Any] = dict(load_data=load_data, names=_names, units=parse_units, orders=_parse_orders)
    fleet.update(grid=_grid, order_args=_order_args, initial_arg=_initial_arg, common=_common, print_json=_print_json)
    add_fleet_command(sub, kw, {**fleet, "usage_error": UsageError})
    return root


def _initial_arg(p: Any) -> None:
    p.add_argument(
        "--initial",
        choices=["zero", "estimate"],
        default="zero",
        help="initial conditions of the validation free runs: 'zero' starts from the measured outputs, 'estimate' "
        "fits them first, for a validation record that starts mid-transient (default %(default)s)",
    )


def _add_analysis_commands(sub: Any, kw: dict[str, Any]) -> None:
    """The commands that run the analysis pipeline: diagnose, report, demo."""
    p = sub.add_parser(
        "diagnose",
        help="rank the missing physical effect and climb the error ladder",
        epilog=_EXAMPLES["diagnose"],
        description="Diagnose a model: residual tests, suspects, ladder.",
        **kw,
    )
    _data_args(p)
    _order_args(p)
    _model_arg(p)
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--max-steps", type=int, default=3, metavar="N", help="largest number of ladder steps (default 3)")
    p.add_argument("--expect", choices=["stable", "integrating", "double-integrating"], help="step sanity expectation")
    p.add_argument("--all", action="store_true", help="print every suspect (default: the best 12)")
    _initial_arg(p)
    _grow_args(p)
    _common(p)
    p.set_defaults(func=cmd_diagnose)

    p = sub.add_parser(
        "report",
        help="write a self-contained HTML report",
        epilog=_EXAMPLES["report"],
        description="Sweep, choose, diagnose and write one HTML file with every plot embedded.",
        **kw,
    )
    _data_args(p)
    _order_args(p)
    _model_arg(p)
    p.add_argument("-o", metavar="REPORT.html", default="report.html", help="output file (default %(default)s)")
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--max-steps", type=int, default=3, metavar="N", help="largest number of ladder steps (default 3)")
    p.add_argument("--expect", choices=["stable", "integrating", "double-integrating"], help="step sanity expectation")
    p.add_argument("--title", help="report title")
    _initial_arg(p)
    _grow_args(p)
    _common(p)
    p.set_defaults(func=cmd_report)

    p = sub.add_parser(
        "demo",
        help="the hidden battery effect of a simulated quadrotor, end to end",
        epilog=_EXAMPLES["demo"],
        description="Simulated quadrotor flight with battery sag: sweep, "
        "diagnose, add the missing effect, print the error ladder, write an HTML report.",
        **kw,
    )
    p.add_argument(
        "-o", metavar="REPORT.html", default="arxid-demo-report.html", help="report file (default %(default)s)"
    )
    p.add_argument("--seed", type=int, default=0, help="simulation seed (default %(default)s)")
    p.add_argument("--duration", type=float, default=None, help="flight duration in seconds (default: the demo's)")
    p.add_argument(
        "--write-data",
        metavar="FLIGHT.csv",
        help="write the simulated flight (time, az, collective, collective_true, vbat, z) to a CSV file and stop",
    )
    _common(p)
    p.set_defaults(func=cmd_demo)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``arxid`` command line; returns the exit code (0 ok, 2 bad arguments or data)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if not getattr(args, "command", None):
            raise UsageError(
                "arxid: choose a command: fit, sweep, diagnose, report, demo, bench or fleet (see arxid --help)"
            )
        for name in ("horizon", "max_steps", "top"):
            v = getattr(args, name, None)
            if v is not None and v < 1:
                raise UsageError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
        budget = getattr(args, "max_seconds", None)
        if budget is not None and not (math.isfinite(budget) and budget >= 0):
            raise UsageError(f"--max-seconds must be a number of seconds >= 0, got {budget:g}")
        return int(args.func(args) or EXIT_OK)
    except UsageError as exc:
        print(str(exc).splitlines()[0], file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:  # pragma: no cover - `arxid ... | head`
        return EXIT_OK
    except (ArxidError, OSError, MemoryError) as exc:
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"arxid: error: {msg}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("arxid: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
