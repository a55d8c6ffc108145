"""``arxid bench``: how fast the grid search runs on this machine, on the user's data or on a
synthetic record, against MATLAB's ``arxstruc`` method in vectorised numpy run on the same data
(:mod:`arxid.selection.baseline`) and against the machine's multiply-add throughput."""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from ..exceptions import DataError
from ..selection import baseline
from ..selection.search import DEFAULT_GRID, sweep
from .pipeline import analyse

__all__ = ["SweepBenchmark", "benchmark_sweep", "synthetic_records", "add_bench_command"]

#: Samples of each synthetic record when neither DATA nor ``--samples`` is given.
DEFAULT_SAMPLES = 100_000
#: Structures the numpy reference solves (and simulates) before its time is extrapolated.
DEFAULT_BASELINE_STRUCTURES = 400
_MIN_SAMPLES = 200
#: Multiply-adds the FMA throughput is measured on, at least.
_FMA_PROBE = 1e9


def synthetic_records(n_samples: int, n_inputs: int = 1, seed: int = 0) -> tuple[IOData, IOData]:
    """Estimation and validation records of a stable second-order plant driven by white inputs.

    Input ``i`` acts through ``(0.5 q^-1 + 0.25 q^-2) q^-i / A(q)``, ``A = 1 - 1.5 q^-1 + 0.7 q^-2``,
    plus output noise of standard deviation about 0.05 filtered by ``1/A``.

    Parameters
    ----------
    n_samples : int
        Samples of each record.
    n_inputs : int
        Number of inputs.
    seed : int
        Seed of the estimation record (the validation record uses ``seed + 1``).

    Returns
    -------
    (IOData, IOData)
        Estimation and validation records, sampled at 0.01 s.

    Examples
    --------
    >>> est, val = synthetic_records(1000, n_inputs=2)
    >>> est.n_samples, est.n_inputs
    (1000, 2)
    """
    from scipy.signal import lfilter  # here: the command line starts without scipy.signal

    out = []
    a = [1.0, -1.5, 0.7]
    for s in (seed, seed + 1):
        rng = np.random.default_rng(s)
        u = rng.standard_normal((n_samples, n_inputs))
        y = lfilter([1.0], a, 0.05 * rng.standard_normal(n_samples))
        for i in range(n_inputs):
            y += lfilter(np.r_[np.zeros(i + 1), 0.5, 0.25], a, u[:, i])
        out.append(IOData(y, u if n_inputs > 1 else u[:, 0], ts=0.01))
    return out[0], out[1]


@dataclass(frozen=True)
class SweepBenchmark:
    """Speed of one sweep on one machine, measured by :func:`benchmark_sweep`.

    Attributes
    ----------
    data : str
        Where the records came from (a file name, or ``"synthetic"``).
    samples_estimation, samples_validation, n_inputs : int
        Size of the records.
    grid : dict
        The grid swept (na, nb, nk; nb and nk shared by every input).
    structures, simulated : int
        Structures ranked, and those simulated in free run on the validation record.
    sweep_seconds : float
        Median wall time of ``arxid.sweep`` over ``repeat`` runs.
    structures_per_second, samples_per_second : float
        ``structures`` and ``samples_estimation + samples_validation`` over ``sweep_seconds``.
    numpy_seconds : float
        Wall time of the numpy reference (``arxstruc`` by Gram matrices and Cholesky solves, lfilter
        free runs of the same structures), extrapolated from ``numpy_structures_timed`` structures.
    ratio_to_numpy : float
        ``numpy_seconds / sweep_seconds``.
    agreement : float
        Largest relative difference between the two one-step validation errors on the timed structures.
    multiply_adds : float
        Multiply-adds of the free runs (coefficients and error of each simulated structure per sample).
    fma_bound_seconds : float
        Time of those multiply-adds at the machine's FMA throughput on all cores (``threads``).
    multiply_adds_per_second : float
        That throughput.
    analyse_seconds : float or None
        Wall time of ``arxid.analyse`` on the same records and grid (when asked).
    """

    data: str
    samples_estimation: int
    samples_validation: int
    n_inputs: int
    grid: dict
    structures: int
    simulated: int
    repeat: int
    threads: int
    sweep_seconds: float
    structures_per_second: float
    samples_per_second: float
    numpy_seconds: float
    numpy_structures_timed: int
    numpy_extrapolated: bool
    ratio_to_numpy: float
    agreement: float
    multiply_adds: float
    fma_bound_seconds: float
    multiply_adds_per_second: float
    analyse_seconds: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The measurements as a JSON-ready dict (the keys are the attribute names).

        Returns
        -------
        dict
        """
        return asdict(self)

    def lines(self) -> list[str]:
        """The measurements in plain sentences, one per line.

        Returns
        -------
        list of str
        """
        n_all = self.samples_estimation + self.samples_validation
        extra = f", extrapolated from {self.numpy_structures_timed:,}" if self.numpy_extrapolated else ""
        out = [
            f"data: {self.data}, {self.samples_estimation:,} estimation + {self.samples_validation:,} validation "
            f"samples, {self.n_inputs} input(s); {self.threads} threads",
            "grid: "
            + ", ".join(f"{k} {_range(v)}" for k, v in self.grid.items())
            + f": {self.structures:,} structures, {self.simulated:,} simulated in free run",
            f"arxid sweep: {self.sweep_seconds:.4g} s (median of {self.repeat}): "
            f"{self.structures_per_second:,.0f} structures/s, {self.samples_per_second:,.0f} samples/s "
            f"({n_all:,} samples)",
            f"numpy arxstruc (Gram + Cholesky, lfilter free runs) on the same data: {self.numpy_seconds:.4g} s"
            f"{extra}: arxid is {self.ratio_to_numpy:.1f}x faster; one-step errors agree to {self.agreement:.1e}",
            f"machine's limit: {self.multiply_adds / 1e9:.3g} G multiply-adds of the free runs at "
            f"{self.multiply_adds_per_second / 1e9:.3g} G/s (FMA, all cores) take {self.fma_bound_seconds:.3g} s; "
            f"the whole sweep takes {self.sweep_seconds / self.fma_bound_seconds:.1f}x that",
        ]
        if self.analyse_seconds is not None:
            out.append(
                f"arxid analyse (sweep, choice, diagnosis, ladder): {self.analyse_seconds:.4g} s, "
                f"{self.analyse_seconds / self.sweep_seconds:.1f}x the sweep"
            )
        return out

    def __str__(self) -> str:
        return "\n".join(self.lines())


def _range(v: Sequence[int]) -> str:
    v = list(v)
    return f"{v[0]}..{v[-1]}" if v == list(range(v[0], v[-1] + 1)) and len(v) > 1 else ",".join(map(str, v))


def _median_seconds(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times), out


def _numpy_reference(est: IOData, val: IOData, grid: baseline.ArxGrid, res: Any, limit: int, seed: int) -> tuple:
    """Seconds of the numpy reference on every structure of ``res`` (extrapolated from at most
    ``limit`` ranked and ``limit`` simulated ones), structures timed, and the agreement."""
    rng = np.random.default_rng(seed)
    n = len(res)
    ue, uv = est.u.reshape(est.n_samples, -1), val.u.reshape(val.n_samples, -1)
    t = time.perf_counter()
    g, gv = grid.gram(est.y, ue), grid.gram(val.y, uv)
    t_gram = time.perf_counter() - t

    def pick(idx: np.ndarray) -> np.ndarray:
        return idx if len(idx) <= limit else np.sort(rng.choice(idx, limit, replace=False))

    def structures(idx: np.ndarray) -> list:
        return [(int(res.na[i]), tuple(map(int, res.nb[i])), tuple(map(int, res.nk[i]))) for i in idx]

    ranked = pick(np.arange(n))
    sample = structures(ranked)
    t = time.perf_counter()
    _, losses = baseline.arxstruc(g, gv, grid, sample)
    t_rank = time.perf_counter() - t
    ours = np.asarray(res.rms_val_one_step)[ranked] ** 2
    ref = losses / (val.n_samples - grid.lag)
    agreement = float(np.nanmax(np.abs(ours - ref) / ref)) if len(ref) else 0.0
    sim_all = np.flatnonzero(np.asarray(res.stage) == 2) if len(res.stage) else np.arange(n)
    sim = pick(sim_all)
    sim_structures = structures(sim)
    thetas, _ = baseline.arxstruc(g, gv, grid, sim_structures)
    t = time.perf_counter()
    for theta, s in zip(thetas, sim_structures):
        baseline.free_run_rms(theta, s, val.y, uv, grid.lag)
    t_sim = time.perf_counter() - t
    seconds = t_gram + t_rank * n / max(len(ranked), 1) + t_sim * len(sim_all) / max(len(sim), 1)
    timed = max(len(ranked), len(sim))
    return seconds, timed, len(ranked) < n or len(sim) < len(sim_all), agreement, sim_all


def benchmark_sweep(
    est: IOData,
    val: IOData,
    grid: Mapping[str, Sequence[int]] | None = None,
    *,
    repeat: int = 3,
    with_analyse: bool = False,
    baseline_structures: int = DEFAULT_BASELINE_STRUCTURES,
    data_name: str = "synthetic",
) -> SweepBenchmark:
    """Time ``arxid.sweep`` on two records against the numpy reference and the machine's FMA limit.

    The sweep validates every structure on ``val`` in free run (the best 1,000 after a one-step
    ranking when the grid is larger), with no integrator test and no free run on ``est``: the work
    the numpy reference does too (:mod:`arxid.selection.baseline`).

    Parameters
    ----------
    est, val : IOData
        Estimation and validation records (complete: no missing samples).
    grid : mapping with keys na, nb, nk, optional
        The grid (nb and nk shared by every input); missing keys take :data:`arxid.DEFAULT_GRID`.
    repeat : int
        Sweeps timed (the median is reported).
    with_analyse : bool
        Also time ``arxid.analyse`` once on the same records and grid.
    baseline_structures : int
        Structures the numpy reference solves, and simulates, before its time is extrapolated.
    data_name : str
        Where the records came from, for the report.

    Returns
    -------
    SweepBenchmark

    Raises
    ------
    DataError
        When a record has missing samples or is too short for the grid, or ``repeat`` or
        ``baseline_structures`` is below 1.

    Examples
    --------
    >>> est, val = synthetic_records(2000)
    >>> b = benchmark_sweep(est, val, {"na": [1, 2], "nb": [1, 2], "nk": [0, 1]}, repeat=1)
    >>> b.structures, b.structures_per_second == b.structures / b.sweep_seconds
    (8, True)
    """
    if repeat < 1 or baseline_structures < 1:
        raise DataError("repeat and baseline_structures must be at least 1")
    g = {k: [int(v) for v in (grid or {}).get(k, DEFAULT_GRID[k])] for k in ("na", "nb", "nk")}
    m = est.n_inputs
    env = baseline.ArxGrid(
        na_max=max(g["na"]),
        span=max(g["nk"]) + max(g["nb"]),
        lag=max(max(g["na"]), max(g["nk"]) + max(g["nb"]) - 1, 1),
        n_inputs=m,
    )
    for d in (est, val):
        if not (np.isfinite(d.y).all() and np.isfinite(d.u).all()):
            raise DataError("arxid bench needs complete records: this one has missing samples (fill or cut them first)")
        if d.n_samples - env.lag <= 2 * (env.na_max + m * env.span + 1):
            raise DataError(
                f"a record of {d.n_samples} samples is too short for the grid (largest lag {env.lag}); "
                "give a longer record or a smaller grid"
            )

    def run() -> Any:
        return sweep(
            est, g["na"], g["nb"], g["nk"], validation=val, progress=False, expect="stable", simulate_estimation=False
        )

    run()  # thread pool and imports outside the timing
    t_sweep, res = _median_seconds(run, repeat)
    t_np, timed, extrapolated, agreement, simulated = _numpy_reference(est, val, env, res, baseline_structures, 0)
    n_sim = val.n_samples - env.lag
    coeffs = np.asarray(res.na)[simulated] + np.asarray(res.nb).reshape(len(res), -1)[simulated].sum(axis=1) + 1
    madds = float(coeffs.sum()) * n_sim
    # The throughput on enough work to hide the thread pool's start (about 0.1 s on one core).
    probe = max(madds, _FMA_PROBE)
    t_probe, _ = _median_seconds(lambda: _core.fma_limit(int(probe // 8)), 3)
    throughput = probe / t_probe
    t_analyse = None
    if with_analyse:
        t_analyse, _ = _median_seconds(lambda: analyse(est, val, grid=g, progress=False), 1)
    return SweepBenchmark(
        data=data_name,
        samples_estimation=est.n_samples,
        samples_validation=val.n_samples,
        n_inputs=m,
        grid=g,
        structures=len(res),
        simulated=len(simulated),
        repeat=repeat,
        threads=os.cpu_count() or 1,
        sweep_seconds=t_sweep,
        structures_per_second=len(res) / t_sweep,
        samples_per_second=(est.n_samples + val.n_samples) / t_sweep,
        numpy_seconds=t_np,
        numpy_structures_timed=timed,
        numpy_extrapolated=extrapolated,
        ratio_to_numpy=t_np / t_sweep,
        agreement=agreement,
        multiply_adds=madds,
        fma_bound_seconds=madds / throughput,
        multiply_adds_per_second=throughput,
        analyse_seconds=t_analyse,
    )


# ------------------------------------------------------------------------------------ command line
_EXAMPLE = (
    "examples:\n"
    "  arxid bench                                  # synthetic records of 100,000 samples each\n"
    "  arxid bench --samples 1000000 --synthetic-inputs 3 --json\n"
    "  arxid bench flight.csv --output roll --inputs roll_torque --ts 0.002 --analyse"
)


def add_bench_command(sub: Any, kw: dict[str, Any], load: Callable, grid: Callable) -> None:
    """Add ``arxid bench`` to the command line's subparsers.

    Parameters
    ----------
    sub : argparse subparsers
        Where the command goes.
    kw : dict
        Keyword arguments of the subparser (its help line, the help formatter).
    load : callable
        ``load(args) -> (est, val)``: the command line's reader of DATA (split or ``--validation``).
    grid : callable
        ``grid(args) -> dict``: the command line's reader of ``--na``, ``--nb``, ``--nk``.
    """
    p = sub.add_parser(
        "bench",
        epilog=_EXAMPLE,
        description="Time arxid's sweep (and optionally the whole analysis) against MATLAB's arxstruc method in "
        "vectorised numpy on the same data, and against the machine's multiply-add throughput.",
        **kw,
    )
    p.add_argument("data", metavar="DATA", nargs="?", help="CSV file with a header row, or .npz archive (optional)")
    p.add_argument("--output", metavar="COL", help="output column of DATA")
    p.add_argument("--inputs", metavar="A[,B]", help="input column(s) of DATA, comma separated")
    t = p.add_mutually_exclusive_group()
    t.add_argument("--ts", type=float, metavar="S", help="sampling time of DATA in seconds")
    t.add_argument("--time", metavar="COL", help="time column of DATA (uniformly sampled, seconds)")
    v = p.add_mutually_exclusive_group()
    v.add_argument("--validation", metavar="VAL.csv", help="separate validation file with the same columns")
    v.add_argument("--split", type=float, metavar="F", help="estimation fraction of DATA (default 0.7)")
    p.add_argument(
        "--samples",
        type=int,
        metavar="N",
        help=f"without DATA: synthetic estimation and validation records of N samples each (default {DEFAULT_SAMPLES})",
    )
    p.add_argument("--synthetic-inputs", type=int, default=1, metavar="M", help="inputs of the synthetic records")
    for k in ("na", "nb", "nk"):
        p.add_argument(f"--{k}", metavar="RANGE", help=f"{k} grid, e.g. 1:4 (default: arxid's default grid)")
    p.add_argument("--repeat", type=int, default=3, metavar="R", help="sweeps timed, median (default %(default)s)")
    p.add_argument("--analyse", action="store_true", help="also time the whole analysis (arxid analyse) once")
    p.add_argument(
        "--baseline-structures",
        type=int,
        default=DEFAULT_BASELINE_STRUCTURES,
        metavar="N",
        help="structures the numpy reference runs before its time is extrapolated (default %(default)s)",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout instead of sentences")
    p.add_argument("--no-progress", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(func=lambda args: _cmd_bench(args, load, grid), extra="", units="")


def _cmd_bench(args: Any, load: Callable, grid: Callable) -> int:
    for name in ("repeat", "baseline_structures", "synthetic_inputs"):
        if getattr(args, name) < 1:
            raise DataError(f"--{name.replace('_', '-')} must be at least 1, got {getattr(args, name)}")
    if args.data is None:
        given = [f"--{n}" for n in ("output", "inputs", "validation", "split", "ts", "time") if getattr(args, n)]
        if given:
            raise DataError(f"{', '.join(given)} describe DATA: give the data file too, or leave them out")
        n = DEFAULT_SAMPLES if args.samples is None else args.samples
        if n < _MIN_SAMPLES:
            raise DataError(f"--samples {n} is too few: give at least {_MIN_SAMPLES} samples per record")
        est, val = synthetic_records(n, args.synthetic_inputs)
        name = "synthetic second-order plant (seeds 0 and 1)"
    else:
        if args.samples is not None:
            raise DataError("--samples sizes a synthetic record: give either DATA or --samples, not both")
        if not args.output or not args.inputs:
            raise DataError("DATA needs --output COL and --inputs A[,B] (the columns to identify)")
        est, val = load(args)
        name = os.path.basename(args.data)
    b = benchmark_sweep(
        est,
        val,
        grid(args),
        repeat=args.repeat,
        with_analyse=args.analyse,
        baseline_structures=args.baseline_structures,
        data_name=name,
    )
    if args.json:
        sys.stdout.write(json.dumps(b.to_dict(), indent=2) + "\n")
    else:
        print(b)
    return 0
