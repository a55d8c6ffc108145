"""The validation errors of many linear ARX models on one record in one pass of the Rust core:
the lanes a sweep scores its structures with (several free runs side by side in the registers).

Models with different effects share lanes through the union of their columns: each reads its own
and gives the others no lag. The error of each is the one its own prediction gives, to rounding
(:func:`arxid.checks.error_rms`); a diagnosis validates dozens of refitted models this way instead
of one free run each.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from ..exceptions import ArxidError
from .arx_model import ArxModel
from .envelope import envelope_inputs

__all__ = ["lane_rms"]


def lane_rms(models: Sequence[ArxModel], data: IOData, horizon: int | None) -> np.ndarray | None:
    """The RMS of each model's free run (or ``horizon``-step prediction) on ``data``, from the
    models' common first lag, inf where it diverged.

    Parameters
    ----------
    models : sequence of ArxModel
        Fitted models on the same rows (one ``first_lag_``), linear in the output.
    data : IOData
        The validation record.
    horizon : int or None
        None: free run; k: k-step-ahead prediction.

    Returns
    -------
    ndarray of shape (len(models),) or None
        None when the models cannot share lanes: an output term, another first lag, a missing
        sample, or columns the union lists in another order than a model does.
    """
    if not models or len({m.first_lag_ for m in models}) != 1:
        return None
    if any(m.layout_.output_terms or m.measured_input_names != data.input_names for m in models):
        return None
    labels = _union([list(m.layout_.column_labels) for m in models])
    if labels is None:
        return None
    at = {label: j for j, label in enumerate(labels)}
    width = len(labels)
    rows = np.zeros((len(models), 1 + 2 * width), dtype=np.int64)
    theta = np.full((len(models), max(m.n_params for m in models)), np.nan)
    for i, m in enumerate(models):
        cols = [at[label] for label in m.layout_.column_labels]
        rows[i, 0] = m.na_
        rows[i, 1 + np.array(cols, dtype=np.intp)] = m.layout_.nb
        rows[i, 1 + width + np.array(cols, dtype=np.intp)] = m.layout_.nk
        theta[i, : m.n_params] = m.parameters_
    try:
        u = envelope_inputs(data, labels)
    except ArxidError:  # a missing sample: each model by its own prediction
        return None
    y = np.require(data.y, requirements=["C", "A"])
    rms, _, _, _, diverged = _core.simulate_structures(
        y, u, list(data.experiment_starts), rows, [], theta, models[0].first_lag_, horizon
    )
    return np.where(diverged, math.inf, rms)


def _union(orders: list[list[str]]) -> list[str] | None:
    """Every model's columns in one order that keeps each model's own (its parameters follow it),
    first seen first where the models leave the order free; None when two models order two columns
    differently. ``[u1, u1*vbat, const]`` and ``[through(u1*vbat), const]`` give ``[u1, u1*vbat,
    through(u1*vbat), const]``, where first seen first alone would put ``const`` before the shape."""
    seen = list(dict.fromkeys(label for order in orders for label in order))
    rank = {label: j for j, label in enumerate(seen)}
    after: dict[str, set[str]] = {label: set() for label in seen}
    before = dict.fromkeys(seen, 0)
    for order in orders:
        for a, b in zip(order, order[1:]):
            if b not in after[a]:
                after[a].add(b)
                before[b] += 1
    ready = [label for label in seen if not before[label]]
    out: list[str] = []
    while ready:
        label = min(ready, key=rank.__getitem__)
        ready.remove(label)
        out.append(label)
        for b in after[label]:
            before[b] -= 1
            if not before[b]:
                ready.append(b)
    return out if len(out) == len(seen) else None
