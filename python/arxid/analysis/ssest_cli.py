"""``arxid ssest``: a state-space model of several inputs and outputs by subspace identification,
each output's validation fit and checks, the cross-coupling, and optionally the HTML report."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from .cli_data import UsageError, data_args, load

__all__ = ["add_ssest_command", "cmd_ssest", "EXAMPLE"]

EXAMPLE = (
    "example:\n  arxid ssest rates.csv --output p,q,r --inputs m1,m2,m3,m4 --ts 0.002 --detrend --stable --horizon 10\n"
    "  arxid ssest rates.csv --output p,q,r --inputs m1,m2,m3,m4 --ts 0.002 --order 6 -o rates.html --json\n"
    "  arxid ssest rates.csv --output p,q,r --inputs m1,m2,m3,m4 --extra vbat --ts 0.002 --detrend --diagnose"
)

#: The subspace methods (arxid.models.subspace.METHODS), named here so that building the parser
#: imports no numerics.
_METHODS = ("n4sid", "moesp", "cva")


def add_ssest_command(sub: Any, kw: dict[str, Any], common: Any) -> None:
    """The ``ssest`` sub-command and its options.

    Parameters
    ----------
    sub : argparse sub-parsers
    kw : dict
        The parser's formatter and help line.
    common : callable
        Adds ``--json`` and ``--no-progress``.
    """
    p = sub.add_parser(
        "ssest",
        epilog=EXAMPLE,
        description="Estimate a state-space model of all the outputs at once (subspace identification), then "
        "check each output on validation data: fit, residual tests, where it fails; and the cross-coupling.",
        **kw,
    )
    data_args(p)
    p.add_argument("--order", type=int, metavar="N", help="number of states (default: the singular value criterion)")
    p.add_argument("--method", choices=_METHODS, default="n4sid", help="subspace weighting (default %(default)s)")
    p.add_argument("--stable", action="store_true", help="reflect unstable poles inside the unit circle")
    p.add_argument(
        "--detrend",
        action="store_true",
        help="remove each signal's mean from the estimation and the validation data (an offset otherwise needs "
        "an integrating state)",
    )
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument(
        "--initial",
        choices=["estimate", "zero"],
        default="estimate",
        help="initial state of each validation record: fitted to it, or zero (default %(default)s)",
    )
    p.add_argument(
        "--diagnose",
        action="store_true",
        help="also search each output for a missing physical effect (candidate terms such as u1*vbat, judged on "
        "the validation data)",
    )
    p.add_argument("-o", metavar="REPORT.html", default=None, help="also write the HTML report to this file")
    p.add_argument("--title", help="report title")
    common(p)
    p.set_defaults(func=cmd_ssest)


def cmd_ssest(args: argparse.Namespace) -> int:
    """Run ``arxid ssest``; returns the exit code."""
    from .._base.formatting import json_safe
    from .state_space import analyse_state_space

    if args.order is not None and args.order < 1:
        raise UsageError(f"--order must be a number of states >= 1, got {args.order}")
    t0 = time.perf_counter()
    est, val = load(args, several_outputs=True)
    if args.detrend:
        est, val = est.detrend(), val.detrend()
    a = analyse_state_space(
        est,
        val,
        order=args.order,
        method=args.method,
        stable=args.stable,
        horizon=args.horizon,
        initial=args.initial,
        diagnose=args.diagnose,
    )
    out: dict[str, Any] = a.to_dict()
    if args.o:
        from .report.state_space import render_state_space_html

        source = Path(args.data).name + (f" + {Path(args.validation).name}" if args.validation else "")
        path = Path(args.o)
        path.write_text(render_state_space_html(a, title=args.title, source=source), encoding="utf-8")
        out["report"] = str(path)
    out["seconds"] = time.perf_counter() - t0
    if args.json:
        import json

        sys.stdout.write(json.dumps(json_safe(out), allow_nan=False, indent=2) + "\n")
        return 0
    print("\n".join(a.summary_lines()))
    if args.o:
        print(f"\nreport written to {args.o}")
    return 0
