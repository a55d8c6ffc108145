"""Sweeps over fleets of logs, in process or on a Dask cluster.

:func:`arxid.sweep` accepts a list of experiments (:class:`~arxid.IOData` objects or file paths)
and, optionally, ``client=`` (a ``dask.distributed.Client``; ``pip install 'arxid[dask]'``).

Merged (one sweep over every log). Each Dask task reads a share of the logs once, keeps it on its
worker and reduces it to the triangular factor R of the grid's largest regressor (regressors never
straddle two logs); the factors are combined by QR in a tree, and every structure is solved from the
final R on the client. The free-run simulation is spread over the workers too: each share simulates
the structures on its own logs (judged by the divergence limit of the whole fleet) and sends back
their squared-error sums, so no log moves between workers. What travels over the network: the grid,
R factors of ``q × q`` numbers (``q`` = columns of the largest regressor), the parameters and the
scores of each structure; never the logs, when the workers read their own files. The client also
reads the logs once to build the :class:`~arxid.SweepResult` (which refits models and checks step
responses on them).

Per log (``per_experiment=True``): each log is swept separately on a worker; the result is a
:class:`FleetSweep`, one table per log and a summary of how the chosen structure varies.

Point it at a real cluster with ``Client("scheduler-address:8786")``; the workers need arxid
installed and, for file paths, the files at the same paths.

File paths: ``.npz`` files holding ``y`` (N,), ``u`` (N, m) and ``ts``, or ``.csv`` files read
with ``read=dict(output=..., inputs=[...])`` (the arguments of :meth:`IOData.from_csv`); ``read``
may also be a function of the path returning an IOData.
"""

from __future__ import annotations

import math
import operator
import os
import zipfile
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _core
from .data import IOData
from .exceptions import ArxidError, DataError

__all__ = ["FleetSweep", "LogSignals", "load_experiment", "read_log", "merge_logs", "split_experiment", "DaskEngine"]


def load_experiment(source: Any, read: Any = None) -> IOData:
    """One log as IOData.

    Parameters
    ----------
    source : IOData, str or path-like
        The log, or a ``.npz`` / ``.csv`` file.
    read : dict or callable, optional
        For CSV files the keyword arguments of :meth:`IOData.from_csv`; or a function of the path.

    Returns
    -------
    IOData

    Raises
    ------
    DataError
        For a file that cannot be read this way.
    """
    if isinstance(source, IOData):
        return source
    if callable(read):
        data = read(source)
        if not isinstance(data, IOData):
            raise DataError(f"read({source!r}) returned {type(data).__name__}, not an IOData")
        return data
    path = os.fspath(source)
    if path.endswith(".npz"):
        with np.load(path) as z:
            return IOData(z["y"], z["u"], ts=float(z["ts"]))
    if path.endswith(".csv") and isinstance(read, dict):
        return IOData.from_csv(path, **read)
    raise DataError(
        f"cannot read {path!r}: give .npz files (y, u, ts), .csv files with read=dict(output=..., inputs=[...]), "
        f"or read=<function of the path returning an IOData>"
    )


def read_log(source: Any, read: Any, name: str) -> IOData:
    """One log as IOData, with any failure to read it reported as a DataError naming the log.

    Parameters
    ----------
    source : IOData, str or path-like
    read : dict or callable or None
        As in :func:`load_experiment`.
    name : str
        The log's name in messages (:func:`log_name`).

    Returns
    -------
    IOData

    Raises
    ------
    DataError
        Naming the log, for a missing, unreadable or malformed file.
    """
    try:
        return load_experiment(source, read)
    except ArxidError as exc:
        raise DataError(f"cannot read log {name!r}: {exc}") from exc
    except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(
            f"cannot read log {name!r}: {exc}; give an IOData or the path of a readable .npz (y, u, ts) or .csv file"
        ) from exc


@dataclass(frozen=True)
class LogSignals:
    """What every log of a fleet must share to be fitted together: the sampling time in seconds and
    the names of the output, inputs and extra signals (as :meth:`IOData.merge` requires)."""

    ts: float
    output_name: str
    input_names: tuple
    output_unit: str
    input_units: tuple
    extra: tuple

    @classmethod
    def of(cls, data: IOData) -> LogSignals:
        """The signals of one log.

        Parameters
        ----------
        data : IOData

        Returns
        -------
        LogSignals
        """
        return cls(
            data.ts, data.output_name, data.input_names, data.output_unit, data.input_units, tuple(sorted(data.extra))
        )


def check_alike(signals: Sequence[LogSignals], names: Sequence[str]) -> None:
    """Refuse a fleet whose logs differ in sampling time or signal names, naming the odd log.

    Parameters
    ----------
    signals : sequence of LogSignals
        One per log.
    names : sequence of str
        The logs' names, in the same order.

    Raises
    ------
    DataError
    """
    first, ref = signals[0], names[0]
    for sig, name in zip(signals[1:], names[1:], strict=True):
        if not math.isclose(sig.ts, first.ts, rel_tol=1e-9):
            raise DataError(
                f"log {name!r} is sampled at ts={sig.ts:g} s but log {ref!r} at ts={first.ts:g} s; "
                "resample the logs to one sampling time"
            )
        for what, a, b in (
            ("output", first.output_name, sig.output_name),
            ("inputs", list(first.input_names), list(sig.input_names)),
            ("extra signals", list(first.extra), list(sig.extra)),
        ):
            if a != b:
                raise DataError(
                    f"log {name!r} has {what} {b!r} but log {ref!r} has {a!r}; every log needs the same "
                    "signals (rename the columns, or read every log with the same read=)"
                )


def load_logs(sources: Sequence[Any], read: Any = None) -> list[IOData]:
    """Every log read and checked to share its sampling time and signals with the first.

    Parameters
    ----------
    sources : sequence of IOData or paths
    read : dict or callable, optional
        As in :func:`load_experiment`.

    Returns
    -------
    list of IOData

    Raises
    ------
    DataError
        For an empty list, or naming the log that cannot be read or does not match the first.
    """
    if not len(sources):
        raise DataError("the list of logs is empty; give at least one IOData or file path")
    names = [log_name(s, i) for i, s in enumerate(sources)]
    logs = [read_log(s, read, n) for s, n in zip(sources, names, strict=True)]
    check_alike([LogSignals.of(d) for d in logs], names)
    return logs


def merge_logs(sources: Sequence[Any], read: Any = None) -> IOData:
    """The logs as one IOData with one experiment per log (regressors never straddle two logs).

    Parameters
    ----------
    sources : sequence of IOData or paths
    read : dict or callable, optional
        As in :func:`load_experiment`.

    Returns
    -------
    IOData
    """
    return IOData.merge(load_logs(sources, read))


def reduce_tree(client: Any, futures: list, combine: Callable) -> Any:
    """Futures combined pairwise on the cluster, level by level, down to one; its result.

    Parameters
    ----------
    client : dask.distributed.Client
    futures : list of futures
        At least one.
    combine : callable
        Of two results, returning one of the same kind.

    Returns
    -------
    Any
        The combination of all.
    """
    while len(futures) > 1:
        futures = [
            client.submit(combine, futures[i], futures[i + 1]) if i + 1 < len(futures) else futures[i]
            for i in range(0, len(futures), 2)
        ]
    return futures[0].result()


def split_experiment(data: IOData, validation: Any) -> tuple[IOData, IOData | None]:
    """A log's estimation and validation parts (the last ``validation`` fraction validates).

    Parameters
    ----------
    data : IOData
    validation : float or None
        Fraction of each log held out for validation.

    Returns
    -------
    tuple of (IOData, IOData or None)
    """
    if validation is None:
        return data, None
    return data.split(1 - float(validation))


def merged_part(sources: Sequence[Any], read: Any, validation: Any, which: str) -> IOData:
    """The estimation (``"est"``) or validation (``"val"``) parts of the logs as one IOData.

    Parameters
    ----------
    sources : sequence
        The logs.
    read : dict or callable or None
        As in :func:`load_experiment`.
    validation : float or None
        Fraction of each log held out.
    which : {"est", "val"}

    Returns
    -------
    IOData
        One experiment per log.
    """
    loaded = [split_experiment(load_experiment(s, read), validation) for s in sources]
    parts = [est if which == "est" else val for est, val in loaded]
    return IOData.merge([p for p in parts if p is not None])


def _aligned(a: np.ndarray, dtype: Any) -> np.ndarray:
    """A C-contiguous, aligned copy when needed (arrays deserialised on a worker may be neither)."""
    return np.require(a, dtype=dtype, requirements=["C", "A"])


def _arrays(d: IOData) -> tuple[np.ndarray, np.ndarray, list[int]]:
    return _aligned(d.y, np.float64), _aligned(d.u, np.float64), list(d.experiment_starts)


def load_split(sources: Sequence[Any], read: Any, validation: Any) -> tuple:
    """A worker's logs, read and split into their merged estimation and validation parts.

    Parameters
    ----------
    sources : sequence
        The logs this task reads.
    read : dict or callable or None
        As in :func:`load_experiment`.
    validation : float or None
        Fraction of each log held out.

    Returns
    -------
    tuple
        ``(estimation part, validation part or None)``.
    """
    split = [split_experiment(load_experiment(s, read), validation) for s in sources]
    est = IOData.merge([e for e, _ in split])
    val = None if validation is None else IOData.merge([v for _, v in split if v is not None])
    return est, val


def with_factors(parts: tuple, layout: np.ndarray) -> tuple:
    """The parts of :func:`load_split` with their factors (:func:`partial_factors`) appended.

    Parameters
    ----------
    parts : tuple
        ``(estimation part, validation part or None)``.
    layout : ndarray of shape (S, 1 + 2m)
        The grid.

    Returns
    -------
    tuple
        ``(estimation part, validation part or None, factors)``.
    """
    return parts[0], parts[1], partial_factors(parts, layout)


def _peak(d: IOData | None) -> float:
    y = np.abs(d.y[np.isfinite(d.y)]) if d is not None else np.zeros(0)
    return float(y.max()) if y.size else 0.0


def partial_factors(parts: tuple, layout: np.ndarray) -> tuple:
    """The factors of a worker's estimation and validation parts, and their largest |y|.

    Parameters
    ----------
    parts : tuple
        The estimation and validation parts.
    layout : ndarray of shape (S, 1 + 2m)
        The grid.

    Returns
    -------
    tuple
        ``(R_est, n_est, R_val, n_val, peak_est, peak_val)`` (R_val None without validation).
    """
    est, val = parts[0], parts[1]
    layout = _aligned(layout, np.int64)
    r_est, n_est = _core.grid_factor(*_arrays(est), layout, [])
    r_val, n_val = _core.grid_factor(*_arrays(val), layout, []) if val is not None else (None, 0)
    return r_est, n_est, r_val, n_val, _peak(est), _peak(val)


def stack_factors(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
    """The triangular factor of two stacked factors (the R of ``[a; b]``; None stands for no rows).

    Parameters
    ----------
    a, b : ndarray of shape (q, q) or None

    Returns
    -------
    ndarray of shape (q, q) or None
    """
    if a is None or b is None:
        return a if b is None else b
    return np.asarray(np.linalg.qr(np.vstack([a, b]), mode="r"))


def combine_factors(a: tuple, b: tuple) -> tuple:
    """Two partials combined by QR of their stacked factors (one node of the reduction tree).

    Parameters
    ----------
    a, b : tuple
        ``(R_est, n_est, R_val, n_val, peak_est, peak_val)`` each.

    Returns
    -------
    tuple
        The same for the rows of both.
    """
    return (
        stack_factors(a[0], b[0]),
        a[1] + b[1],
        stack_factors(a[2], b[2]),
        a[3] + b[3],
        max(a[4], b[4]),
        max(a[5], b[5]),
    )


def simulate_parts(parts: tuple, which: str, layout: np.ndarray, theta: np.ndarray, args: dict) -> tuple:
    """Every structure simulated on a worker's logs, judged by the whole fleet's divergence limit.

    Parameters
    ----------
    parts : tuple
        From :func:`with_factors`.
    which : {"est", "val"}
        The parts to simulate on.
    layout : ndarray of shape (S, 1 + 2m)
        The structures.
    theta : ndarray of shape (S, p_max)
        Their parameters.
    args : dict
        ``first_lag``, ``horizon`` and ``limit``.

    Returns
    -------
    tuple of ndarray
        ``(sse, n, diverged)`` per structure on these logs.
    """
    d = parts[0] if which == "est" else parts[1]
    layout, theta = _aligned(layout, np.int64), _aligned(theta, np.float64)
    rms, n, _, diverged = _core.simulate_structures(
        *_arrays(d), layout, [], theta, args["first_lag"], args["horizon"], n_threads=1, limit=args["limit"]
    )
    return rms * rms * n, n, diverged


class DaskEngine:
    """Runs the core of a sweep over a fleet on a Dask cluster (called as ``_core.sweep`` is).

    Each task loads a share of the logs once and keeps them on its worker; the factors of the shares
    are combined in a QR tree; every structure is solved from the final R on the client; then every
    share simulates the structures on its own logs and sends back their squared-error sums.

    Parameters
    ----------
    client : dask.distributed.Client
        The cluster.
    sources : sequence
        The logs.
    read : dict or callable or None
        As in :func:`load_experiment`.
    validation : float or None
        Fraction of each log held out.
    """

    def __init__(self, client: Any, sources: Sequence[Any], read: Any, validation: Any):
        self.client, self.sources, self.read, self.validation = client, list(sources), read, validation
        self._loaded: list | None = None

    def merged(self) -> tuple[IOData, IOData | None]:
        """The estimation and validation parts of every log, read on the client (for the result).

        The workers start reading their shares first, so both read at the same time.

        Returns
        -------
        tuple of (IOData, IOData or None)
        """
        if self.client is not None:
            self._loaded = self._load()
        split = [split_experiment(d, self.validation) for d in load_logs(self.sources, self.read)]
        est = IOData.merge([e for e, _ in split])
        val = None if self.validation is None else IOData.merge([v for _, v in split if v is not None])
        return est, val

    def _load(self) -> list:
        """Futures of every share's parts (:func:`load_split`), two shares per worker."""
        workers = max(1, len(self.client.scheduler_info()["workers"]))
        n_tasks = min(len(self.sources), 2 * workers)
        chunks = [self.sources[i::n_tasks] for i in range(n_tasks)]
        return [self.client.submit(load_split, c, self.read, self.validation, pure=False) for c in chunks]

    def _shares(self, layout: np.ndarray) -> list:
        loaded = self._loaded if self._loaded is not None else self._load()
        return [self.client.submit(with_factors, part, layout, pure=False) for part in loaded]

    def factors(self, shares: list, layout: np.ndarray) -> tuple:
        """The combined factors of every log: partials where the logs are, then a QR tree.

        Parameters
        ----------
        shares : list of futures
            From :func:`with_factors`.
        layout : ndarray
            The grid.

        Returns
        -------
        tuple
            ``(R_est, n_est, R_val, n_val, peak_est, peak_val)``.
        """
        # Only the factors leave the workers (the grid travels inside the tasks, not scattered:
        # scattered data die with their worker).
        futures = [self.client.submit(operator.itemgetter(2), s) for s in shares]
        return reduce_tree(self.client, futures, combine_factors)

    def simulate(self, shares: list, which: str, layout: np.ndarray, theta: np.ndarray, args: dict) -> tuple:
        """Scores of every given structure over all logs: each share simulates its own logs.

        Parameters
        ----------
        shares : list of futures
        which : {"est", "val"}
        layout : ndarray of shape (S, 1 + 2m)
        theta : ndarray of shape (S, p_max)
        args : dict
            ``first_lag``, ``horizon`` and ``limit``.

        Returns
        -------
        tuple of ndarray
            ``(rms, n, norm, diverged)`` as the core's sweep gives them for the merged logs.
        """
        outs = self.client.gather([self.client.submit(simulate_parts, s, which, layout, theta, args) for s in shares])
        sse = np.sum([o[0] for o in outs], axis=0)
        n = np.sum([o[1] for o in outs], axis=0)
        diverged = np.any([o[2] for o in outs], axis=0)
        with np.errstate(all="ignore"):
            rms = np.where(diverged | (n == 0), np.nan, np.sqrt(sse / n))
        return rms, n, np.full(len(n), np.nan), diverged

    def __call__(self, y, u, starts, layout, terms, **kw) -> Any:
        """The fleet's ``_core.sweep``: the arrays of the merged data are not used (the workers read
        the logs); the options are those of ``_core.sweep``.

        Parameters
        ----------
        y, u, starts
            The merged estimation data (unused: the same data as the logs).
        layout : ndarray of shape (S, 1 + 2m)
        terms : list
            Output terms (a fleet sweep supports none).
        **kw
            ``top``, ``horizon``, ``simulate_estimation`` as ``_core.sweep``.

        Returns
        -------
        FleetOutput
        """
        if terms:
            raise DataError("a fleet sweep takes no effects yet; sweep the merged IOData in process instead")
        shares = self._shares(layout)
        self._loaded = None  # the shares hold the parts now; nothing else keeps them on the workers
        r_est, n_est, r_val, n_val, peak_est, peak_val = self.factors(shares, layout)
        out, simulate = _core.sweep_factors(r_est, n_est, layout, [], r_val=r_val, n_val=n_val, top=kw.get("top"))
        result = FleetOutput.from_core(out)
        fitted = np.array([i for i in simulate if out.errors[i] is None], dtype=int)
        sets = (["est"] if kw.get("simulate_estimation", True) else []) + (["val"] if r_val is not None else [])
        for which in sets:
            peak = peak_est if which == "est" else peak_val
            limit = _core.divergence_limit(np.array([peak]))
            args = {"first_lag": out.first_lag, "horizon": kw.get("horizon"), "limit": limit}
            result.fill(which, fitted, self.simulate(shares, which, layout[fitted], out.theta[fitted], args))
        return result


@dataclass
class FleetOutput:
    """The attributes of ``_core.SweepOutput``, filled from factors and distributed simulations."""

    theta: np.ndarray
    rss_est: np.ndarray
    rss_val: np.ndarray
    rms_sim_est: np.ndarray
    rms_sim_val: np.ndarray
    n_sim_est: np.ndarray
    n_sim_val: np.ndarray
    norm_sim_est: np.ndarray
    norm_sim_val: np.ndarray
    diverged_est: np.ndarray
    diverged_val: np.ndarray
    errors: list
    n_est: int
    n_val: int
    first_lag: int
    envelope: tuple
    stage: np.ndarray

    @classmethod
    def from_core(cls, out: Any) -> FleetOutput:
        """A writable copy of a core output whose simulations are still to run.

        Parameters
        ----------
        out : _core.SweepOutput

        Returns
        -------
        FleetOutput
        """
        fields = {k: getattr(out, k) for k in cls.__dataclass_fields__}
        arrays = {k: np.array(v) for k, v in fields.items() if isinstance(v, np.ndarray)}
        return cls(**{**fields, **arrays})

    def fill(self, which: str, idx: np.ndarray, scores: tuple) -> None:
        """Stores the scores of the structures ``idx`` on the estimation or validation data.

        Parameters
        ----------
        which : {"est", "val"}
        idx : ndarray of int
        scores : tuple of ndarray
            ``(rms, n, norm, diverged)``.
        """
        rms, n, norm, diverged = scores
        getattr(self, f"rms_sim_{which}")[idx] = rms
        getattr(self, f"n_sim_{which}")[idx] = n
        getattr(self, f"norm_sim_{which}")[idx] = norm
        getattr(self, f"diverged_{which}")[idx] = diverged


@dataclass(frozen=True)
class FleetSweep:
    """One sweep per log (``per_experiment=True``) and how the chosen structure varies.

    Attributes
    ----------
    tables : tuple of SweepResult
        One ranked sweep per log, in the order of the logs.
    names : tuple of str
        The logs (file names, or ``log 1``, ``log 2``, ...).
    chosen : tuple of str
        The best structure of each log (``select(sane=False)``; ``-`` when none qualified).
    """

    tables: tuple
    names: tuple
    chosen: tuple

    @property
    def counts(self) -> dict:
        """How many logs chose each structure, most frequent first."""
        return dict(Counter(self.chosen).most_common())

    def summary(self) -> str:
        """How the chosen structure varies across the fleet, as text.

        Returns
        -------
        str
        """
        n = len(self.chosen)
        lines = [f"{n} logs swept separately; chosen structure:"]
        for name, k in self.counts.items():
            lines.append(f"  {name}: {k} of {n} logs ({100 * k / n:.0f} %)")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _choice(res: Any) -> str:
    try:
        return res.select(sane=False).structure
    except Exception:  # noqa: BLE001 - a log with no usable structure is reported as such
        return "-"


def log_name(source: Any, i: int) -> str:
    """How messages and tables name a log: its file name, or ``log 1``, ``log 2``, ... for IOData.

    Parameters
    ----------
    source : IOData or path
    i : int
        Its position in the list (from 0).

    Returns
    -------
    str
    """
    return os.path.basename(os.fspath(source)) if not isinstance(source, IOData) else f"log {i + 1}"


def sweep_one(source: Any, read: Any, validation: Any, sweep: Callable, options: dict) -> Any:
    """One log's sweep (on a worker in per-experiment mode).

    Parameters
    ----------
    source : IOData or path
    read, validation
        As in :func:`partial_factors`.
    sweep : callable
        :func:`arxid.sweep`.
    options : dict
        Its keyword arguments.

    Returns
    -------
    SweepResult
    """
    data = load_experiment(source, read)
    return sweep(data, validation=validation, **options)


def sweep_each(
    sources: Sequence[Any], client: Any, read: Any, validation: Any, sweep: Callable, options: dict
) -> FleetSweep:
    """Every log swept separately, on the workers when there is a client.

    Parameters
    ----------
    sources : sequence
    client : dask.distributed.Client or None
    read, validation
        As in :func:`partial_factors`.
    sweep : callable
        :func:`arxid.sweep`.
    options : dict
        Its keyword arguments (``progress`` is turned off on workers).

    Returns
    -------
    FleetSweep
    """
    if client is None:
        tables = [sweep_one(s, read, validation, sweep, options) for s in sources]
    else:
        opts = {**options, "progress": False, "n_threads": 1}
        futures = [client.submit(sweep_one, s, read, validation, sweep, opts, pure=False) for s in sources]
        tables = client.gather(futures)
    names = tuple(log_name(s, i) for i, s in enumerate(sources))
    return FleetSweep(tuple(tables), names, tuple(_choice(t) for t in tables))


def check_validation(validation: Any) -> float | None:
    """The per-log validation fraction of a fleet sweep.

    Parameters
    ----------
    validation : float or None

    Returns
    -------
    float or None

    Raises
    ------
    DataError
        For anything but None or a fraction in (0, 1).
    """
    if validation is None:
        return None
    if isinstance(validation, bool) or not isinstance(validation, (int, float)) or not 0 < validation < 1:
        raise DataError(
            f"for a list of logs, validation must be a fraction of each log (0 < v < 1) or None, got {validation!r}"
        )
    return float(validation) if math.isfinite(validation) else None
