"""``arxid fleet``: the analysis of a fleet of logs on a Dask cluster from the command line.

``arxid fleet LOG [LOG ...] --output y --inputs u [--extra vbat] [--ts S] (--orders NA,NB,NK | --na ...)
[--scheduler ADDRESS | --workers N]``: every log (files, or quoted glob patterns such as
``'flights/*.csv'``) is read by the workers with the options of ``arxid diagnose``; the last
``1 - split`` of each log validates. Without ``--scheduler`` a local cluster of ``--workers``
processes is started for the run. It prints what :func:`arxid.analyse` with ``client=`` returns
(:class:`~arxid.analysis.fleet_analysis.FleetAnalysis`): the model, the suspects, the missing effect,
the logs it shows in and the ladder; ``--json`` its :meth:`~FleetAnalysis.to_dict`.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import glob
import logging
import re
from collections.abc import Iterator, Sequence
from typing import Any

from ..exceptions import ArxidError
from .fleet_analysis import FleetAnalysis, analyse_fleet
from .pipeline import DEFAULT_SPLIT

__all__ = ["add_fleet_command", "expand_logs"]

_EXAMPLE = (
    "example:\n  arxid fleet 'flights/*.csv' --output roll --inputs roll_torque --extra vbat --ts 0.002 "
    "--orders 2,1,8\n  arxid fleet a.npz b.npz c.npz --output y --inputs u --orders 2,2,1 "
    "--scheduler tcp://10.0.0.5:8786 --json"
)


def expand_logs(patterns: Sequence[str]) -> list[str]:
    """The log files named by ``patterns``: each a file, or a glob pattern (sorted matches).

    Parameters
    ----------
    patterns : sequence of str

    Returns
    -------
    list of str

    Raises
    ------
    ArxidError
        For a pattern that matches no file.
    """
    paths: list[str] = []
    for p in patterns:
        if glob.has_magic(p):
            found = sorted(glob.glob(p))
            if not found:
                raise ArxidError(f"no log file matches {p!r}; check the pattern (quote it so the shell keeps it)")
            paths += found
        else:
            paths.append(p)
    return paths


@contextlib.contextmanager
def _client(scheduler: str | None, workers: int) -> Iterator[Any]:
    """A Dask client of the scheduler at ``scheduler``, or of a local cluster started for the run."""
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:
        raise ArxidError("the fleet analysis needs Dask, which is not installed: pip install 'arxid[dask]'") from None
    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    if workers < 1:
        raise ArxidError(f"--workers must be at least 1, got {workers}")
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=":0", silence_logs=logging.ERROR)
    with cluster, Client(cluster) as client:
        yield client


def _run(args: argparse.Namespace, helpers: dict[str, Any]) -> int:
    split = DEFAULT_SPLIT if args.split is None else args.split
    if not 0 < split < 1:
        raise helpers["usage_error"](f"--split {split} must be a fraction between 0 and 1, e.g. {DEFAULT_SPLIT}")
    names = helpers["names"]
    read = functools.partial(
        helpers["load_data"],
        output=args.output,
        inputs=names(args.inputs),
        extra=names(args.extra),
        ts=args.ts,
        time_col=args.time,
        units=helpers["units"](args.units),
    )
    orders = helpers["orders"](args.orders) if args.orders else None
    grid = helpers["grid"](args)
    if all(getattr(args, k) is None for k in ("na", "nb", "nk")):
        grid = None  # the default grid, grown as by 'arxid diagnose' unless --no-grow
    kw: dict[str, Any] = dict(orders=orders, grid=grid, horizon=args.horizon, expect=args.expect)
    kw.update(max_steps=args.max_steps, initial=args.initial, grow=args.grow, max_seconds=args.max_seconds)
    if args.candidates:  # commas inside parentheses belong to a threshold: dz(u1,0.2)
        kw["candidates"] = [c.strip() for c in re.split(r",(?![^()]*\))", args.candidates) if c.strip()]
    logs = expand_logs(args.logs)
    with _client(args.scheduler, args.workers) as client:
        a: FleetAnalysis = analyse_fleet(logs, client, split=split, read=read, **kw)
    if args.json:
        helpers["print_json"](a.to_dict())
    else:
        n = len(a.diagnosis.suspects)
        print("\n".join(a.summary_lines(n_suspects=n if args.all else 12)))
    return 0


def add_fleet_command(sub: Any, kw: dict[str, Any], helpers: dict[str, Any]) -> None:
    """Add ``arxid fleet`` to the command line's subparsers.

    Parameters
    ----------
    sub : argparse subparsers
    kw : dict
        Keyword arguments of the subparser (its help line, the help formatter).
    helpers : dict of str to callable
        The command line's own readers: ``load_data`` (a file as IOData), ``names`` (a comma list),
        ``units`` (``--units``), ``orders`` (``--orders``), ``grid`` (``--na/--nb/--nk``),
        ``order_args`` and ``initial_arg`` (their options), ``common`` (``--json``...),
        ``print_json`` and ``usage_error`` (the error class of bad arguments).
    """
    p = sub.add_parser(
        "fleet",
        epilog=_EXAMPLE,
        description="Sweep or fit, diagnose and climb the error ladder over many logs on a Dask cluster, and say "
        "which logs the missing effect shows in (the same answer as on the logs merged in one process).",
        **kw,
    )
    p.add_argument("logs", metavar="LOG", nargs="+", help="log files (CSV, .npz, .ulg), or quoted glob patterns")
    p.add_argument("--output", required=True, metavar="COL", help="output column")
    p.add_argument("--inputs", required=True, metavar="A[,B]", help="input column(s), comma separated")
    p.add_argument("--extra", metavar="C[,D]", default="", help="logged signals kept for diagnostics (e.g. vbat)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--ts", type=float, metavar="S", help="sampling time in seconds")
    g.add_argument("--time", metavar="COL", help="time column (uniformly sampled, seconds)")
    p.add_argument("--units", metavar="NAME=UNIT,...", default="", help="units of the signals, e.g. vbat=V")
    p.add_argument(
        "--split", type=float, metavar="F", help=f"estimation fraction of each log (default {DEFAULT_SPLIT})"
    )
    helpers["order_args"](p)
    helpers["grow_args"](p)
    p.add_argument(
        "--candidates",
        metavar="E[,F]",
        default="",
        help="candidates, e.g. 'u1*vbat,dz(u1,0.2),na+1' (default: auto)",
    )
    p.add_argument("--horizon", type=int, metavar="K", help="validation prediction horizon (default: free run)")
    p.add_argument("--max-steps", type=int, default=3, metavar="N", help="largest number of ladder steps (default 3)")
    p.add_argument("--expect", choices=["stable", "integrating", "double-integrating"], help="step sanity expectation")
    p.add_argument("--all", action="store_true", help="print every suspect (default: the best 12)")
    c = p.add_mutually_exclusive_group()
    c.add_argument("--scheduler", metavar="ADDRESS", help="address of a running Dask scheduler, e.g. tcp://host:8786")
    c.add_argument("--workers", type=int, default=2, metavar="N", help="local worker processes (default %(default)s)")
    helpers["initial_arg"](p)
    helpers["common"](p)
    p.set_defaults(func=functools.partial(_run, helpers=helpers))
