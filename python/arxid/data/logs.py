"""Logs as :class:`IOData`: one log read from an IOData, a ``.npz`` or ``.csv`` file or a function of
its path (:func:`load_experiment`); a fleet's logs checked to share their sampling time and signals;
and the logs merged into one IOData with one experiment per log, so that no regressor straddles two
logs (:func:`merge_logs`), optionally split first into estimation and validation parts
(:func:`merged_parts`).

File paths: ``.npz`` files holding ``y`` (N,), ``u`` (N, m) and ``ts``, or ``.csv`` files read
with ``read=dict(output=..., inputs=[...])`` (the arguments of :meth:`IOData.from_csv`); ``read``
may also be a function of the path returning an IOData.
"""

from __future__ import annotations

import math
import os
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..exceptions import ArxidError, DataError
from .iodata import IOData
from .samples import freeze_owned

__all__ = [
    "LogSignals",
    "check_alike",
    "load_experiment",
    "load_logs",
    "log_name",
    "merge_logs",
    "merge_split",
    "merged_parts",
    "read_log",
    "split_experiment",
]


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
        # The file is opened here so that it is closed even when numpy cannot read it (a corrupt or
        # truncated archive), not left to the garbage collector with the traceback.
        with open(path, "rb") as fh, np.load(fh) as z:
            # Arrays read just now, held by nobody else: IOData takes them without a copy.
            return IOData(freeze_owned(z["y"]), freeze_owned(z["u"]), ts=float(z["ts"]))
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


def load_logs(sources: Sequence[Any], read: Any = None, names: Sequence[str] | None = None) -> list[IOData]:
    """Every log read and checked to share its sampling time and signals with the first.

    Parameters
    ----------
    sources : sequence of IOData or paths
    read : dict or callable, optional
        As in :func:`load_experiment`.
    names : sequence of str, optional
        The logs' names in messages (default :func:`log_name` of each, by its position).

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
    names = list(names) if names is not None else [log_name(s, i) for i, s in enumerate(sources)]
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


def merged_parts(sources: Sequence[Any], read: Any, validation: float | None) -> tuple[IOData, IOData | None]:
    """The estimation and validation parts of every log, each merged with one experiment per log.

    Parameters
    ----------
    sources : sequence of IOData or paths
    read : dict or callable or None
        As in :func:`load_experiment`.
    validation : float or None
        Fraction of each log held out (the last samples of each).

    Returns
    -------
    tuple of (IOData, IOData or None)

    Raises
    ------
    DataError
        Naming the log that cannot be read or does not match the first.
    """
    return merge_split([split_experiment(d, validation) for d in load_logs(sources, read)])


def merge_split(split: Sequence[tuple[IOData, IOData | None]]) -> tuple[IOData, IOData | None]:
    """Logs split by :func:`split_experiment`, merged part by part (one experiment per log).

    Parameters
    ----------
    split : sequence of (IOData, IOData or None)

    Returns
    -------
    tuple of (IOData, IOData or None)
        The estimation parts merged, and the validation parts merged (None without validation).
    """
    vals = [v for _, v in split if v is not None]
    return IOData.merge([e for e, _ in split]), (IOData.merge(vals) if vals else None)


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
