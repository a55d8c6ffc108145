"""The samples a polynomial model's filters run on: the runs of finite samples (a missing sample
restarts the filters, as a new experiment would), how the filters start in each run (the
initial-condition option), and the checks that the runs can determine the parameters."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._base.limits import check_order
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError

__all__ = ["INITIAL", "check_initial", "check_size", "finite_segments", "per_input"]

#: The initial-condition options (MATLAB's ``InitialCondition``).
INITIAL = ("zero", "estimate")


def check_initial(initial: Any) -> str:
    """The initial-condition option checked: ``"zero"`` or ``"estimate"`` (MATLAB's names).

    Parameters
    ----------
    initial : str

    Returns
    -------
    str
    """
    if initial not in INITIAL:
        raise ArxidError(f"initial must be 'zero' or 'estimate' (MATLAB's InitialCondition), got {initial!r}")
    return str(initial)


def per_input(name: str, value: Any, m: int) -> tuple[int, ...]:
    """One checked order per input, from a sequence of them or one for all."""
    if isinstance(value, (list, tuple, np.ndarray)):
        vals = tuple(check_order(f"{name}[{i}]", v) for i, v in enumerate(value))
        if len(vals) != m:
            raise OrderError(f"{name} has {len(vals)} entries but the data have {m} inputs; give one per input")
        return vals
    return (check_order(name, value),) * m


def finite_segments(data: IOData, lag: int, need_output: bool = True) -> list[tuple[int, int]]:
    """Runs of finite samples inside each experiment that are longer than ``lag``.

    A missing sample (NaN) ends a run: filters restart from rest after it, as a new experiment,
    and the first ``lag`` samples of every run are initial conditions.

    Parameters
    ----------
    data : IOData
    lag : int
        Samples at the start of each run that are not scored.
    need_output : bool
        Also require a finite output (prediction needs it; free-run simulation does not).

    Returns
    -------
    list of (start, end)
        Half-open sample ranges.
    """
    ok = np.isfinite(data.u).all(axis=1)
    if need_output:
        ok &= np.isfinite(data.y)
    out = []
    for a, b in data.segments:
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok[a:b].astype(np.int8), [0]])))
        out += [(a + int(s), a + int(e)) for s, e in zip(edges[::2], edges[1::2]) if e - s > lag]
    return out


def check_size(orders: tuple, segments: list[tuple[int, int]], lag: int, data: IOData) -> None:
    """Enough scored samples for the parameters, counted before the core allocates anything."""
    p = orders[0] + sum(orders[1]) + orders[2] + orders[3] + sum(orders[4])
    usable = sum(b - a - lag for a, b in segments)
    if usable < p + 1:
        raise DataError(
            f"too few samples for the orders: {p} parameters need at least {p + 1} scored samples, but the "
            f"{data.n_samples} samples leave {usable} after the first {lag} of each run of finite samples; lower "
            f"the orders or use more data"
        )
