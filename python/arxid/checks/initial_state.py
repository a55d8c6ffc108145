"""The free run of an ARX model from estimated initial conditions (``initial="estimate"``).

An ARX model's free run starts, in each run of the data, from the outputs just before its first
predicted sample: with ``initial="zero"`` they are the measured ones, noise included. With
``initial="estimate"`` they are fitted instead, by least squares on the run's own free-run error,
as MATLAB's ``compare`` estimates the initial state: a record that starts mid-transient, or whose
first samples are noisy, is not held against the model. The predicted samples are the same as with
``"zero"``, so the two measures compare sample for sample, and the estimated error is never larger
for a model that is linear in the output.

The free run is affine in those initial outputs when the model has no term of the output (effects
of the inputs and logged signals, ``const`` and ``time`` included): one simulation per initial
output gives the exact least-squares fit. With terms of the output (``y^3``, ``sign(dy)``) it is
fitted by a few damped Gauss-Newton steps from the measured values, each kept only when it lowers
the error. A k-step prediction restarts from the measured outputs k steps back and is returned as
with ``"zero"``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._base import metrics
from ..data.iodata import IOData
from ..models.arx_model import ArxModel

__all__ = ["estimated_free_run", "GAUSS_NEWTON_STEPS"]

#: Largest number of Gauss-Newton steps for a model with terms of the output.
GAUSS_NEWTON_STEPS = 12


def estimated_free_run(model: ArxModel, data: IOData, horizon: int | None = None) -> np.ndarray:
    """The model's prediction on ``data``, its free run started from fitted initial outputs.

    Parameters
    ----------
    model : ArxModel
        A fitted ARX model, with or without effect terms.
    data : IOData
        Measured data.
    horizon : int or None
        None: free run from estimated initial outputs; k: the k-step prediction (which restarts
        from measured outputs, as with ``initial="zero"``).

    Returns
    -------
    ndarray of shape (n_samples,)
        NaN where no prediction exists (the same samples as :meth:`ArxModel.predict`).
    """
    with np.errstate(all="ignore"):
        base = np.asarray(model.predict(data, horizon), dtype=float)
    if horizon is not None or not np.isfinite(base).any() or np.isinf(base).any():
        return base
    linear = not model.layout_.output_terms
    idx, run_of = _initial_outputs(base, max(model.na_, 0 if linear else 2))
    if not idx.size:
        return base
    measured = data.y[idx[:, 0]]
    start = np.where(np.isfinite(measured), measured, 0.0)
    x, pred, sse = start, base, _error(data, base)
    # affine: any step is exact (a large one keeps rounding small); else a small difference step
    delta = (float(np.nanstd(data.y)) or 1.0) * (1.0 if linear else 1e-3)
    for _ in range(1 if linear else GAUSS_NEWTON_STEPS):
        dx = _gauss_newton_step(model, data, (idx, run_of), x, pred, delta)
        if dx is None:
            break
        if linear:
            return _simulate(model, data, idx, x + dx)
        for shrink in (1.0, 0.5, 0.25, 0.125):  # damped: a step is kept only when it lowers the error
            trial = _simulate(model, data, idx, x + shrink * dx)
            if _error(data, trial) < sse:
                break
        else:
            break
        x, pred, old = x + shrink * dx, trial, sse
        sse = _error(data, pred)
        if sse > (1.0 - 1e-9) * old:
            break
    return pred


def _initial_outputs(pred: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """``(sample, run)`` of the ``m`` samples before each start of a predicted run, shape (n, 2),
    and the run each predicted sample belongs to (-1 for none)."""
    ok = np.isfinite(pred)
    starts = np.flatnonzero(ok & ~np.r_[False, ok[:-1]])
    run_of = np.full(pred.size, -1)
    idx = []
    ends = np.r_[starts[1:], pred.size]
    for r, (s, e) in enumerate(zip(starts, ends)):
        run_of[s:e] = np.where(ok[s:e], r, -1)
        idx += [(i, r) for i in range(max(s - m, 0), s)]
    return np.array(idx, dtype=int).reshape(-1, 2), run_of


def _simulate(model: ArxModel, data: IOData, idx: np.ndarray, values: np.ndarray) -> np.ndarray:
    y = data.y.copy()
    y[idx[:, 0]] = values
    with np.errstate(all="ignore"):
        return np.asarray(model.predict(replace(data, y=y), None), dtype=float)


def _gauss_newton_step(
    model: ArxModel,
    data: IOData,
    runs: tuple[np.ndarray, np.ndarray],
    x: np.ndarray,
    pred: np.ndarray,
    delta: float,
) -> np.ndarray | None:
    """The Gauss-Newton step of the initial outputs ``x`` (one block per run); None when the
    prediction is not finite. The runs do not interact, so the k-th initial output of every run is
    moved in the same simulation: ``m`` simulations give the whole Jacobian."""
    idx, run_of = runs
    first = {int(r): int(idx[idx[:, 1] == r, 0].min()) for r in np.unique(idx[:, 1])}
    offset = idx[:, 0] - np.array([first[int(r)] for r in idx[:, 1]])
    cols = {}
    for k in np.unique(offset):
        moved = x + delta * (offset == k)
        cols[int(k)] = (_simulate(model, data, idx, moved) - pred) / delta
    if not all(np.isfinite(c[run_of >= 0]).all() for c in cols.values()):
        return None
    dx = np.zeros_like(x)
    resid = data.y - pred
    for r in np.unique(idx[:, 1]):
        mine = np.flatnonzero(idx[:, 1] == r)
        rows = np.flatnonzero((run_of == r) & np.isfinite(resid))
        if not rows.size:
            continue
        jac = np.column_stack([cols[int(offset[j])][rows] for j in mine])
        dx[mine] = np.linalg.lstsq(jac, resid[rows], rcond=None)[0]
    return dx


def _error(data: IOData, pred: np.ndarray) -> float:
    """Sum of squared errors over the predicted samples (inf for a diverged prediction)."""
    if metrics.diverged(data.y, pred):
        return np.inf
    e = data.y - pred
    e = e[np.isfinite(e)]
    return float(e @ e)
