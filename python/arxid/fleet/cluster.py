"""A fleet's logs kept on the workers of a Dask cluster, and what the client knows of them.

Each task reads a share of the logs once (:func:`load_share`), checks that they share their signals,
splits each log into its estimation and validation parts and keeps the merged parts on its worker.
The client receives only a :class:`LogShape` per log (signals, lengths, experiment starts) and the
first samples of the first log: enough to check the fleet, size a sweep against its memory and time
budgets and build its result, without reading a sample. :class:`LogsOnDemand` is the merged data as
an :class:`~arxid.IOData` whose samples are read from the logs on the client when first used (for
example by ``SweepResult.model``); with 500 logs the client never needs to hold them all.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..data.iodata import IOData
from ..data.logs import LogSignals, check_alike, load_logs, log_name, merge_split, merged_parts, split_experiment
from ..exceptions import DataError

__all__ = ["LogShape", "LogsOnDemand", "WorkerLogs", "load_share", "reduce_tree", "stack_factors"]

#: Samples of the first log the client keeps (to probe effect layouts and signal names).
HEAD = 8


@dataclass(frozen=True)
class LogShape:
    """One log as the client knows it without its samples.

    Attributes
    ----------
    signals : LogSignals
    est_starts, val_starts : tuple of int
        Experiment starts of its estimation and validation parts (``val_starts`` empty without
        validation).
    n_est, n_val : int
        Their samples.
    est_measured, val_measured : bool
        Whether its estimation / validation part has a measured (finite) output sample.
    """

    signals: LogSignals
    est_starts: tuple
    n_est: int
    val_starts: tuple
    n_val: int
    est_measured: bool
    val_measured: bool

    @classmethod
    def of(cls, log: IOData, est: IOData, val: IOData | None) -> LogShape:
        """The shape of a log split into ``est`` and ``val``.

        Parameters
        ----------
        log, est : IOData
        val : IOData or None

        Returns
        -------
        LogShape
        """
        return cls(
            LogSignals.of(log),
            est.experiment_starts,
            est.n_samples,
            val.experiment_starts if val is not None else (),
            val.n_samples if val is not None else 0,
            est.output_measured,
            val is not None and val.output_measured,
        )


def load_share(sources: Sequence[Any], names: Sequence[str], read: Any, validation: float | None) -> tuple:
    """A task's logs read on its worker, checked alike, split, and merged part by part (kept there).

    Parameters
    ----------
    sources : sequence of IOData or paths
    names : sequence of str
        The logs' names in messages.
    read : dict or callable or None
        As in :func:`arxid.data.logs.load_experiment`.
    validation : float or None
        Fraction of each log held out.

    Returns
    -------
    tuple
        ``(estimation parts merged, validation parts merged or None, [LogShape of each log], the first
        samples of the first log's estimation part)``.
    """
    logs = load_logs(sources, read, names)
    split = [split_experiment(d, validation) for d in logs]
    est, val = merge_split(split)
    shapes = [LogShape.of(d, e, v) for d, (e, v) in zip(logs, split, strict=True)]
    return est, val, shapes, split[0][0][: min(HEAD, split[0][0].n_samples)]


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


def square_factor(a: np.ndarray) -> np.ndarray:
    """R of ``a`` as a square q × q factor (zero rows below when ``a`` has fewer rows than columns):
    what a share sends of its rows, whatever their number.

    Parameters
    ----------
    a : ndarray of shape (n, q)

    Returns
    -------
    ndarray of shape (q, q)
    """
    q = a.shape[1]
    r = np.asarray(np.linalg.qr(a, mode="r")) if a.shape[0] else np.zeros((0, q))
    return np.vstack([r, np.zeros((q - r.shape[0], q))]) if r.shape[0] < q else r


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


class WorkerLogs:
    """A fleet's logs read by the workers of a Dask cluster and kept there, in shares (two per worker
    thread).

    Creating it starts the reading and waits for the logs' shapes; the samples stay on the workers.

    Parameters
    ----------
    client : dask.distributed.Client
    sources : sequence of IOData or paths
    read : dict or callable or None
        As in :func:`arxid.data.logs.load_experiment`.
    validation : float or None
        Fraction of each log held out for validation.

    Attributes
    ----------
    shares : list of futures
        Of :func:`load_share`.
    names : list of str
    groups : list of list of int
        The logs (indices into ``sources``) of each share, in the share's order.
    shapes : list of LogShape
        One per log, in the order of ``sources``.
    signals : LogSignals
        What every log shares (checked on creation, naming any log that differs).
    head : IOData
        The first samples of the first log's estimation part.

    Raises
    ------
    DataError
        For an empty list, a log that cannot be read, or logs that differ in their signals.
    """

    def __init__(self, client: Any, sources: Sequence[Any], read: Any = None, validation: float | None = None):
        self.sources = list(sources)
        if not self.sources:
            raise DataError("the list of logs is empty; give at least one IOData or file path")
        self.client, self.read, self.validation = client, read, validation
        self.names = [log_name(s, i) for i, s in enumerate(self.sources)]
        # Two shares per worker thread: every thread loads, factors and simulates, and a lost worker
        # costs only its shares. (client.nthreads() lists every worker; scheduler_info() may not.)
        threads = max(1, sum(client.nthreads().values()))
        n_tasks = min(len(self.sources), 2 * threads)
        groups = [list(range(i, len(self.sources), n_tasks)) for i in range(n_tasks)]
        self.groups = groups  # the logs of each share, in its order
        self.shares = [
            client.submit(
                load_share, [self.sources[j] for j in g], [self.names[j] for j in g], read, validation, pure=False
            )
            for g in groups
        ]
        described = client.gather([client.submit(_described, s) for s in self.shares])
        self.shapes: list = [None] * len(self.sources)
        for g, (shapes, _) in zip(groups, described, strict=True):
            for j, shape in zip(g, shapes, strict=True):
                self.shapes[j] = shape
        check_alike([s.signals for s in self.shapes], self.names)
        self.signals = self.shapes[0].signals
        self.head = described[0][1]

    def each(self, fn: Callable, *args: Any) -> list:
        """``fn(share, *args)`` submitted for every share, where the share is.

        Parameters
        ----------
        fn : callable
        *args
            Passed to ``fn`` after the share.

        Returns
        -------
        list of futures
        """
        return [self.client.submit(fn, s, *args, pure=False) for s in self.shares]

    def on_demand(self) -> tuple[IOData, IOData | None]:
        """The merged estimation and validation parts as the client sees them: shapes now, samples
        read from the logs on first use.

        Returns
        -------
        tuple of (LogsOnDemand, LogsOnDemand or None)
        """
        est = LogsOnDemand.of(self, "est")
        return est, (LogsOnDemand.of(self, "val") if self.validation is not None else None)


def _described(share: tuple) -> tuple:
    """What the client receives of a share: the shapes of its logs and its first samples."""
    return share[2], share[3]


def read_part(sources: Sequence[Any], read: Any, validation: float | None, which: str) -> IOData | None:
    """The estimation (``"est"``) or validation (``"val"``) parts of the logs read here, merged.

    Parameters
    ----------
    sources : sequence
    read : dict or callable or None
    validation : float or None
    which : {"est", "val"}

    Returns
    -------
    IOData
    """
    est, val = merged_parts(sources, read, validation)
    return est if which == "est" else val


class LogsOnDemand(IOData):
    """The merged parts of a fleet's logs whose samples are read on the client when first used.

    Sizes, experiment starts, sampling time, signal names and the first samples are known from the
    workers. ``y``, ``u`` and ``extra`` are read from the logs on first access (the files must be
    readable on the client then), checked to have the sizes the workers saw, and kept. Anything
    derived from the data (a slice, a split, ``detrend``) is an ordinary IOData of the read samples.
    """

    _read: Callable[[], IOData]
    _n: int
    _m: int
    _measured: bool
    _head: IOData | None

    @classmethod
    def of(cls, logs: WorkerLogs, which: str) -> LogsOnDemand:
        """The estimation (``"est"``) or validation (``"val"``) parts of ``logs``.

        Parameters
        ----------
        logs : WorkerLogs
        which : {"est", "val"}

        Returns
        -------
        LogsOnDemand
        """
        starts: list[int] = []
        n = 0
        for shape in logs.shapes:
            part = (shape.est_starts, shape.n_est) if which == "est" else (shape.val_starts, shape.n_val)
            starts += [n + s for s in part[0]]
            n += part[1]
        head = logs.head if which == "est" else None
        sig = logs.signals
        self = object.__new__(cls)
        for name, value in (
            ("ts", sig.ts),
            ("output_name", sig.output_name),
            ("input_names", sig.input_names),
            ("output_unit", sig.output_unit),
            ("input_units", sig.input_units),
            ("experiment_starts", tuple(starts)),
            ("_read", functools.partial(read_part, logs.sources, logs.read, logs.validation, which)),
            ("_n", n),
            ("_m", len(sig.input_names)),
            ("_measured", any(s.est_measured if which == "est" else s.val_measured for s in logs.shapes)),
            ("_head", head),
        ):
            object.__setattr__(self, name, value)
        return self

    def __getattr__(self, name: str) -> Any:
        # Only reached for attributes not set yet: the samples, before their first use.
        if name not in ("y", "u", "extra", "extra_units") or "_read" not in self.__dict__:
            raise AttributeError(name)
        data = self._read()
        if data.n_samples != self._n or data.experiment_starts != self.experiment_starts:
            raise DataError(
                f"the logs changed since the workers read them: {data.n_samples:,} samples in "
                f"{data.n_experiments} experiments now, {self._n:,} in {len(self.experiment_starts)} then; "
                "run the sweep again"
            )
        for key in ("y", "u", "extra", "extra_units"):
            object.__setattr__(self, key, getattr(data, key))
        return self.__dict__[name]

    @property
    def n_samples(self) -> int:
        return self._n if "_n" in self.__dict__ else super().n_samples

    @property
    def n_inputs(self) -> int:
        return self._m if "_m" in self.__dict__ else super().n_inputs

    @property
    def output_measured(self) -> bool:
        return self._measured if "y" not in self.__dict__ else super().output_measured

    def __getitem__(self, key: Any) -> IOData:
        head = self.__dict__.get("_head")
        if head is not None and isinstance(key, slice) and key.step in (None, 1):
            start, stop, _ = key.indices(self.n_samples)
            if 0 <= start <= stop <= head.n_samples and "y" not in self.__dict__:
                return head[start:stop]
        return super().__getitem__(key)
