"""The ``arxid`` command: fit, sweep, diagnose, report and demo from a shell.

Readable tables by default; ``--json`` prints one JSON object on stdout (NaN becomes null) for
scripts. Progress bars go to stderr. Exit code 0 on success, 2 with a one-line message on bad
arguments or data, 1 on an unexpected internal error.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._base.launch import EXIT_INTERRUPTED, end_startup, leave_to_exit
from .._base.limits import MAX_ORDER
from ..exceptions import ArxidError, DataError
from .cli_data import UsageError, data_args, load, load_data, names, parse_units, reference_name

if TYPE_CHECKING:
    from .pipeline import Analysis

# The commands import what they run when they run: ``arxid --help`` and a small analysis do not
# pay for the modules of the others.

__all__ = ["main", "load_data", "parse_range"]

EXIT_OK, EXIT_INTERNAL, EXIT_USAGE = 0, 1, 2


class _Version(argparse.Action):
    """``--version``: the version is read from the installed metadata when asked (its import costs
    more than the rest of ``arxid --help``)."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS, **kwargs: Any):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help="show the version and exit")

    def __call__(self, parser: argparse.ArgumentParser, namespace: Any, values: Any, option_string: Any = None):
        from .._base.version import __version__

        print(f"arxid {__version__}")  # on stdout, as argparse's own version action
        parser.exit()


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage block: scripts read stderr
        raise UsageError(f"{self.prog}: {message} (see {self.prog} --help)")


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


def _parse_orders(text: str) -> tuple[int, int, int]:
    parts = names(text)
    try:
        vals = tuple(int(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 3 or min(vals) < 0:
        raise UsageError(f"--orders {text!r} must be three non-negative integers NA,NB,NK, e.g. 2,1,8")
    na, nb, nk = vals
    return na, nb, nk


def _range_text(r: Sequence[int]) -> str:
    return f"{min(r)}:{max(r)}"


_GRID_HELP = {"na": "poles", "nb": "input coefficients", "nk": "input delays in samples"}


def _order_args(p: argparse.ArgumentParser) -> None:
    from ..selection.search import DEFAULT_GRID

    p.add_argument("--orders", metavar="NA,NB,NK", help="one fixed structure, e.g. 2,1,8 (instead of a sweep)")
    for k, what in _GRID_HELP.items():
        p.add_argument(
            f"--{k}",
            metavar="RANGE",
            default=None,
            help=f"{k} grid ({what}), e.g. 1:4 (inclusive) or 1,2,5 (default {_range_text(DEFAULT_GRID[k])})",
        )


def _grow_args(p: argparse.ArgumentParser) -> None:
    from ..selection.growth import DEFAULT_GROWTH_SECONDS

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


def _model_arg(p: argparse.ArgumentParser) -> None:
    from ..models.spec import MODEL_FORMS

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


def _grid(args) -> dict | None:
    """The sweep grid from --na/--nb/--nk (each defaulting to DEFAULT_GRID), or None with --orders."""
    from ..selection.search import DEFAULT_GRID

    given = {k: getattr(args, k, None) for k in ("na", "nb", "nk")}
    if getattr(args, "orders", None):
        if any(v is not None for v in given.values()):
            raise UsageError("give either --orders NA,NB,NK or the grid --na/--nb/--nk, not both")
        return None
    return {k: parse_range(v, k) if v is not None else list(DEFAULT_GRID[k]) for k, v in given.items()}


def _progress(args) -> bool:
    return not args.no_progress and sys.stderr.isatty()


def _print_json(obj) -> None:
    import json

    from .._base.formatting import json_safe

    sys.stdout.write(json.dumps(json_safe(obj), allow_nan=False, indent=2) + "\n")


# ---------------------------------------------------------------------------------------- commands
def cmd_fit(args) -> int:
    import numpy as np

    from .._base.formatting import text_table
    from ..models.arx_model import arx
    from .verdicts import negative_fit_note

    est, val = load(args, need_validation=False)
    orders = _parse_orders(args.orders) if args.orders else None
    if orders is None:
        raise UsageError("fit needs the structure: --orders NA,NB,NK (find one with 'arxid sweep')")
    effects = names(args.effects)
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
    from .._base.formatting import format_value
    from ..selection.search import sweep
    from .pipeline import choose
    from .verdicts import negative_fit_note

    est, val = load(args)
    grid = _grid(args)
    if grid is None:
        o = _parse_orders(args.orders)
        grid = {"na": [o[0]], "nb": [o[1]], "nk": [o[2]]}
    given = {k: v for k, v in grid.items() if getattr(args, k, None) is not None or args.orders}
    t0 = time.perf_counter()
    # arxid.sweep's own rule and budget: the default grid grows, a given grid with --grow
    kw = dict(progress=_progress(args), expect=args.expect, horizon=args.horizon, auto_extend=args.grow)
    res = sweep(est, validation=val, growth_seconds=args.max_seconds, **kw, **given)
    res = res if res.growth is not None else res.extend(max_rounds=0, max_seconds=args.max_seconds)
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
    from ..models.spec import parse_model_spec
    from .pipeline import analyse

    orders = _parse_orders(args.orders) if args.orders else None
    spec = getattr(args, "model", None)
    if spec is not None:
        if orders is not None or any(getattr(args, k, None) is not None for k in ("na", "nb", "nk")):
            raise UsageError("give either --model or --orders / --na --nb --nk, not both")
        parse_model_spec(spec)  # a typed error with the correct form, before the data are read
    est, val = load(args)
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
        reference=reference_name(args.reference),
    )


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
    from .report.html import render_html

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
    import numpy as np

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


#: Each command's line in ``arxid --help``.
_COMMANDS = {
    "fit": "fit one ARX structure (optionally with effects)",
    "sweep": "fit and validate every (na, nb, nk) of a grid",
    "diagnose": "rank the missing physical effect and climb the error ladder",
    "report": "write a self-contained HTML report",
    "ssest": "fit a state-space model of several outputs and check each output",
    "demo": "the hidden battery effect of a simulated quadrotor, end to end",
    "bench": "time the grid search on this machine, on your data or a synthetic record",
    "fleet": "diagnose a fleet of logs where they are, on a Dask cluster",
}


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``arxid`` parser with every command's options, or with those of ``command`` alone (the
    others listed by name and help line when ``command`` names none): the options of a command import
    what they describe."""
    root = _Parser(
        prog="arxid",
        description="ARX system identification that finds the missing physical effect.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n  arxid demo\n  arxid sweep data.csv --output y --inputs u --ts 0.01\n"
        "  arxid diagnose data.csv --output y --inputs u --extra vbat --ts 0.01 --json\n"
        "run 'arxid COMMAND --help' for each command's options.",
    )
    root.add_argument("--version", action=_Version)
    sub = root.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    add = {"fit": _add_fit, "sweep": _add_sweep, "diagnose": _add_diagnose, "report": _add_report}
    add.update(ssest=_add_ssest, demo=_add_demo, bench=_add_bench, fleet=_add_fleet)
    for name, help_line in _COMMANDS.items():
        kw: dict[str, Any] = {"formatter_class": argparse.RawDescriptionHelpFormatter, "help": help_line}
        if command is None or name == command:
            add[name](sub, kw)
        elif command not in _COMMANDS:  # a command named: the others' parsers are never read
            sub.add_parser(name, **kw)
    return root


def _add_fit(sub: Any, kw: dict[str, Any]) -> None:
    description = "Fit one ARX model by QR and report its errors."
    p = sub.add_parser("fit", epilog=_EXAMPLES["fit"], description=description, **kw)
    data_args(p, split_default=False)
    p.add_argument("--orders", metavar="NA,NB,NK", required=True, help="structure, e.g. 2,1,8")
    p.add_argument("--effects", metavar="E[,F]", default="", help="effect terms, e.g. 'u1*vbat,const'")
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--save", metavar="MODEL.json", help="write the fitted model as JSON")
    _common(p)
    p.set_defaults(func=cmd_fit)


def _add_sweep(sub: Any, kw: dict[str, Any]) -> None:
    p = sub.add_parser(
        "sweep",
        epilog=_EXAMPLES["sweep"],
        description="Exhaustive order sweep, ranked by validation error; step sanity checks. The default grid "
        "grows while the best structure sits on its edge, as arxid.sweep(data) does in Python.",
        **kw,
    )
    data_args(p)
    _order_args(p)
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--expect", choices=["stable", "integrating", "double-integrating"], help="step sanity expectation")
    p.add_argument("--top", type=int, default=20, metavar="N", help="rows to print (default %(default)s)")
    p.add_argument("--all", action="store_true", help="print every structure (instead of --top)")
    _grow_args(p)
    _common(p)
    p.set_defaults(func=cmd_sweep)


def _add_ssest(sub: Any, kw: dict[str, Any]) -> None:
    from .ssest_cli import add_ssest_command

    add_ssest_command(sub, kw, _common)


def _add_bench(sub: Any, kw: dict[str, Any]) -> None:
    from .benchmark import add_bench_command

    add_bench_command(sub, kw, load=load, grid=_grid)


def _add_fleet(sub: Any, kw: dict[str, Any]) -> None:
    from .fleet_cli import add_fleet_command

    fleet: dict[str, Any] = dict(load_data=load_data, names=names, units=parse_units, orders=_parse_orders)
    fleet.update(grid=_grid, grow_args=_grow_args, order_args=_order_args, initial_arg=_initial_arg, common=_common)
    fleet.update(print_json=_print_json)
    add_fleet_command(sub, kw, {**fleet, "usage_error": UsageError})


def _initial_arg(p: Any) -> None:
    p.add_argument(
        "--initial",
        choices=["zero", "estimate"],
        default="zero",
        help="initial conditions of the validation free runs: 'zero' starts from the measured outputs, 'estimate' "
        "fits them first, for a validation record that starts mid-transient (default %(default)s)",
    )


def _add_diagnose(sub: Any, kw: dict[str, Any]) -> None:
    p = sub.add_parser(
        "diagnose",
        epilog=_EXAMPLES["diagnose"],
        description="Diagnose a model: residual tests, suspects, ladder.",
        **kw,
    )
    data_args(p)
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


def _add_report(sub: Any, kw: dict[str, Any]) -> None:
    p = sub.add_parser(
        "report",
        epilog=_EXAMPLES["report"],
        description="Sweep, choose, diagnose and write one HTML file with every plot embedded.",
        **kw,
    )
    data_args(p)
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


def _add_demo(sub: Any, kw: dict[str, Any]) -> None:
    p = sub.add_parser(
        "demo",
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


def _command_of(argv: Sequence[str]) -> str | None:
    """The command ``argv`` runs (its first word that is not an option), if it names one."""
    word = next((a for a in argv if not a.startswith("-")), None)
    return word if word in _COMMANDS else None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``arxid`` command line; returns the exit code (0 ok, 2 bad arguments or data)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_of(argv) or "")
    try:
        end_startup()  # a Ctrl-C from here on is the KeyboardInterrupt below
        args = parser.parse_args(argv)
        if not getattr(args, "command", None):
            raise UsageError(
                "arxid: choose a command: fit, sweep, diagnose, report, ssest, demo, bench or fleet (see arxid --help)"
            )
        for name in ("horizon", "max_steps", "top"):
            v = getattr(args, name, None)
            if v is not None and v < 1:
                raise UsageError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
        budget = getattr(args, "max_seconds", None)
        if budget is not None and not (math.isfinite(budget) and budget >= 0):
            raise UsageError(f"--max-seconds must be a number of seconds >= 0, got {budget:g}")
        code = int(args.func(args) or EXIT_OK)
        leave_to_exit()
        return code
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
        return EXIT_INTERRUPTED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
