"""Several outputs as one set of signals: the arrays and the stretches without missing samples
that state-space estimation and prediction read (an :class:`~arxid.IOData` of several outputs, or
one per output)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = ["Signals", "gather"]


@record
class Signals:
    """Inputs and outputs as arrays, with the stretches free of missing samples."""

    u: np.ndarray  # (N, nu), NaN replaced by 0 (never read outside `segments`)
    y: np.ndarray  # (N, ny), likewise
    y_with_gaps: np.ndarray  # (N, ny) as measured
    segments: list[tuple[int, int]]  # runs without a missing sample, inside one experiment
    ts: float
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]


def _outputs(data: Any) -> list[IOData]:
    if isinstance(data, IOData):
        return [data]
    if isinstance(data, Sequence) and data and all(isinstance(d, IOData) for d in data):
        return list(data)
    raise DataError(
        "data must be an IOData or a sequence of IOData, one per output, that share their inputs "
        f"(got {type(data).__name__})"
    )


def gather(data: Any) -> Signals:
    """The inputs, the outputs and the stretches without missing samples of ``data``.

    Parameters
    ----------
    data : IOData or sequence of IOData
        Data of one or several outputs, or a sequence of them with the same inputs, sampling time
        and experiments (their outputs side by side).
    """
    parts = _outputs(data)
    first = parts[0]
    for d in parts[1:]:
        if d.ts != first.ts or d.experiment_starts != first.experiment_starts or d.u.shape != first.u.shape:
            raise DataError("the outputs' data must share their sampling time, experiments and inputs")
        if not np.array_equal(d.u, first.u, equal_nan=True):
            raise DataError(
                f"output(s) {list(d.output_names)} come with other input samples than {list(first.output_names)}"
            )
    names = tuple(name for d in parts for name in d.output_names)
    if len(set(names)) != len(names):
        raise DataError(f"output names must be unique, got {list(names)}")
    y = np.column_stack([d.outputs for d in parts])  # a new array: the caller's data stay as they are
    u = np.array(first.u, dtype=float)
    finite = np.isfinite(y).all(axis=1) & np.isfinite(u).all(axis=1)
    segments = []
    for a, b in first.segments:
        edges = np.flatnonzero(np.diff(np.concatenate([[0], finite[a:b].astype(np.int8), [0]])))
        segments += [(a + int(s), a + int(e)) for s, e in zip(edges[::2], edges[1::2], strict=True)]
    y_clean, u_clean = np.where(np.isfinite(y), y, 0.0), np.where(np.isfinite(u), u, 0.0)
    return Signals(u_clean, y_clean, y, segments, first.ts, first.input_names, names)
