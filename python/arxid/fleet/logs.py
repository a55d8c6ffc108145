"""Sweeps over fleets of logs, in process or on a Dask cluster.

:func:`arxid.sweep` accepts a list of experiments (:class:`~arxid.IOData` objects or file paths)
and, optionally, ``client=`` (a ``dask.distributed.Client``; ``pip install 'arxid[dask]'``).

Merged (one sweep over every log). In process, the logs are read, checked to share their sampling
time and signals, split (the last ``validation`` fraction of each log validates) and merged part by
part (:func:`arxid.data.logs.merged_parts`); the sweep is that of the merged data. With ``client=``,
the workers read the logs and the core of the sweep runs where they are (:mod:`arxid.fleet.sweep`).

Per log (``per_experiment=True``): each log is swept separately on a worker; the result is a
:class:`FleetSweep`, one table per log and a summary of how the chosen structure varies.

Point it at a real cluster with ``Client("scheduler-address:8786")``; the workers need arxid
installed and, for file paths, the files at the same paths (read as
:func:`arxid.data.logs.load_experiment` reads them).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

# Reading and merging logs is the data layer's (arxid.data.logs); the fleet code and the tests
# that know these names as ``arxid.fleet.logs.<name>`` find them here too.
from ..data.logs import (
    LogSignals,
    load_experiment,
    log_name,
    merge_logs,
    merge_split,
    merged_parts,
    read_log,
    split_experiment,
)
from ..exceptions import ArxidError, DataError

__all__ = [
    "FleetSweep",
    "check_validation",
    "sweep_each",
    "sweep_one",
    "LogSignals",
    "load_experiment",
    "read_log",
    "merge_logs",
    "merge_split",
    "merged_parts",
    "split_experiment",
]


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
    failed : tuple of (str, str)
        The logs that could not be swept (a corrupt or truncated file, too few samples), each with
        the reason; they are not in ``tables``, ``names`` or ``chosen``.
    """

    tables: tuple
    names: tuple
    chosen: tuple
    failed: tuple = ()

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
        if self.failed:
            lines.append(f"{len(self.failed)} log(s) could not be swept:")
            lines += [f"  {name}: {reason}" for name, reason in self.failed]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def _choice(res: Any) -> str:
    try:
        return res.select(sane=False).structure
    except Exception:  # noqa: BLE001 - a log with no usable structure is reported as such
        return "-"


def sweep_one(source: Any, read: Any, validation: Any, sweep: Callable, options: dict) -> Any:
    """One log's sweep (on a worker in per-experiment mode).

    Parameters
    ----------
    source : IOData or path
    read, validation
        As in :func:`load_experiment` and :func:`split_experiment`.
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


def _sweep_or_reason(source: Any, name: str, read: Any, validation: Any, sweep: Callable, options: dict) -> Any:
    """The sweep of one log, or the sentence of the :class:`ArxidError` that stopped it (a log that
    cannot be read or swept is reported, and the others complete)."""
    try:
        return sweep(read_log(source, read, name), validation=validation, **options)
    except ArxidError as exc:
        return str(exc)


def sweep_again(sweep: Callable, sources: Sequence[Any], client: Any, read: Any, fraction: Any, **settings: Any) -> Any:
    """The fleet's sweep of another grid (``settings``: the orders and a result's settings) on the
    workers of ``client``, where the first one ran.

    Parameters
    ----------
    sweep : callable
        :func:`arxid.sweep`.
    sources : sequence
    client : dask.distributed.Client
    read, fraction
        As in :func:`load_experiment` and :func:`split_experiment`.
    **settings
        The grid and the settings of :attr:`arxid.SweepResult.settings` (whose validation part,
        the merged logs, gives way to ``fraction``).

    Returns
    -------
    SweepResult
    """
    settings.pop("validation", None)
    return sweep(list(sources), client=client, read=read, validation=fraction, **settings)


def sweep_each(
    sources: Sequence[Any], client: Any, read: Any, validation: Any, sweep: Callable, options: dict
) -> FleetSweep:
    """Every log swept separately, on the workers when there is a client.

    Parameters
    ----------
    sources : sequence
    client : dask.distributed.Client or None
    read, validation
        As in :func:`load_experiment` and :func:`split_experiment`.
    sweep : callable
        :func:`arxid.sweep`.
    options : dict
        Its keyword arguments (``progress`` is turned off on workers).

    Returns
    -------
    FleetSweep
    """
    names = [log_name(s, i) for i, s in enumerate(sources)]
    if client is None:
        outcomes = [
            _sweep_or_reason(s, n, read, validation, sweep, options) for s, n in zip(sources, names, strict=True)
        ]
    else:
        # A worker lost mid-sweep (killed, out of memory) is not an error here: the scheduler runs
        # its tasks again on the other workers (distributed's allowed-failures), with the same result.
        opts = {**options, "progress": False, "n_threads": 1}
        futures = [
            client.submit(_sweep_or_reason, s, n, read, validation, sweep, opts, pure=False)
            for s, n in zip(sources, names, strict=True)
        ]
        outcomes = client.gather(futures)
    failed = tuple((n, o) for n, o in zip(names, outcomes, strict=True) if isinstance(o, str))
    if len(failed) == len(names) and names:
        raise DataError(f"no log of the fleet could be swept; {failed[0][0]}: {failed[0][1]}")
    done = [(n, o) for n, o in zip(names, outcomes, strict=True) if not isinstance(o, str)]
    tables = tuple(o for _, o in done)
    return FleetSweep(tables, tuple(n for n, _ in done), tuple(_choice(t) for t in tables), failed)


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
