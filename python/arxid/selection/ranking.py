"""Ranking a sweep: the criteria (:data:`SORT_KEYS`, :func:`criteria`), the column each one ranks by
(:func:`ranking_column`) and the core's output put in ranked order (:func:`ranked_columns`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._base import _core, metrics
from .._base.order_statistics import distinct
from .._base.records import record
from ..data.iodata import IOData
from . import stages
from .grid import Grid

__all__ = [
    "FREE_RUN_KEYS",
    "SORT_KEYS",
    "SORT_TEXT",
    "Columns",
    "criteria",
    "effective_key",
    "first_in_order",
    "max_poles",
    "ranked_columns",
    "ranking_column",
]

#: Ranking criteria. ``aic`` and ``mdl`` are MATLAB ``selstruc``'s, on the validation loss when there are
#: validation data; ``est_aic`` and ``est_bic`` (alias ``bic``) are MATLAB ``aic``'s on the estimation fit.
SORT_KEYS = ("val_sim", "val_one_step", "est_sim", "est_one_step", "fpe", "aic", "mdl", "est_aic", "est_bic", "bic")

#: Criteria that judge a free-run (or k-step) simulation: only these move diverged structures last.
FREE_RUN_KEYS = ("val_sim", "est_sim")

#: Each criterion in words, for the tables and the messages.
SORT_TEXT = {
    "val_sim": "validation RMS",
    "val_one_step": "validation one-step RMS",
    "est_sim": "estimation RMS",
    "est_one_step": "estimation one-step RMS",
    "fpe": "FPE",
    "aic": "AIC (MATLAB selstruc, validation loss)",
    "mdl": "MDL (MATLAB selstruc, validation loss)",
    "est_aic": "AIC of the estimation fit",
    "est_bic": "BIC of the estimation fit",
    "bic": "BIC of the estimation fit",
}


@record
class Columns:
    """The ranking columns of the core's output, in grid order (before the ranking)."""

    rms_val: np.ndarray
    rms_est: np.ndarray
    est_one_step: np.ndarray
    val_one_step: np.ndarray
    fpe: np.ndarray
    aic: np.ndarray
    bic: np.ndarray
    selstruc_aic: np.ndarray
    selstruc_mdl: np.ndarray


def ranking_column(r: Any, key: str) -> np.ndarray:
    """The column criterion ``key`` ranks by.

    Parameters
    ----------
    r : SweepResult or Columns
        A sweep's ranked columns, or the core's columns before the ranking.
    key : str
        One of :data:`SORT_KEYS`.

    Returns
    -------
    ndarray of shape (S,)
    """
    one = {"val_one_step": "rms_val_one_step", "est_one_step": "rms_est_one_step"}
    if isinstance(r, Columns):
        one = {"val_one_step": "val_one_step", "est_one_step": "est_one_step"}
    name = {
        "val_sim": "rms_val",
        "est_sim": "rms_est",
        **one,
        "fpe": "fpe",
        "aic": "selstruc_aic",
        "mdl": "selstruc_mdl",
        "est_aic": "aic",
        "est_bic": "bic",
        "bic": "bic",
    }[key]
    return getattr(r, name)


def effective_key(sort_by: str, has_validation: bool) -> str:
    """The criterion a sweep ranks by: ``bic`` is ``est_bic``; without validation data the validation
    keys rank the estimation data.

    Parameters
    ----------
    sort_by : str
        One of :data:`SORT_KEYS`, as given.
    has_validation : bool
        The sweep has validation data.

    Returns
    -------
    str
    """
    if sort_by == "bic":
        return "est_bic"
    if not has_validation and sort_by in ("val_sim", "val_one_step"):
        return "est_sim" if sort_by == "val_sim" else "est_one_step"
    return sort_by


def criteria(res: _core.SweepOutput, p: np.ndarray) -> dict[str, np.ndarray]:
    """Every ranking column but the simulations (one definition each in :mod:`arxid._base.metrics`).

    Parameters
    ----------
    res : SweepOutput
        The core's output.
    p : ndarray of shape (S,)
        Parameters of each structure.

    Returns
    -------
    dict of str to ndarray
        One-step RMS on estimation and validation rows, FPE, AIC, BIC and ``selstruc``'s AIC and MDL.
    """
    s = len(p)
    n_est, n_val = res.n_est, res.n_val
    with np.errstate(all="ignore"):
        v_val = res.rss_val / n_val if n_val else res.rss_est / n_est  # arxstruc's V
        return {
            "est_one_step": np.sqrt(res.rss_est / n_est),
            "val_one_step": np.sqrt(res.rss_val / n_val) if n_val else np.full(s, np.nan),
            "fpe": np.asarray(metrics.fpe(res.rss_est, n_est, p)),
            "aic": np.asarray(metrics.aic(res.rss_est, n_est, p)),
            "bic": np.asarray(metrics.bic(res.rss_est, n_est, p)),
            "selstruc_aic": np.asarray(metrics.selstruc(v_val, n_est, p, 2.0)),
            "selstruc_mdl": np.asarray(metrics.selstruc(v_val, n_est, p, math.log(n_est))),
        }


def _ranked_errors(errors: list, failed: np.ndarray, order: np.ndarray) -> tuple:
    """``errors`` in ranked ``order``, touching only the ``failed`` structures (a million-row grid)."""
    ranked: list = [None] * len(order)
    rank = np.empty(len(order), dtype=np.intp)
    rank[order] = np.arange(len(order))
    for i in failed:
        ranked[rank[i]] = errors[i]
    return tuple(ranked)


def _scored_norm(d: IOData, lag: int) -> float:
    """‖y − ȳ‖ over the samples a sweep scores (from ``lag`` into each experiment, finite)."""
    n, _, m2 = metrics.scored_moments(d.y, d.segments, lag)
    return math.sqrt(m2) if n else math.nan


#: Companion matrices per eigenvalue call in :func:`max_poles`.
_POLES_PER_CALL = 1000


def max_poles(na: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Largest pole magnitude of every structure (companion matrices, batched per na).

    Parameters
    ----------
    na : ndarray of int, shape (S,)
        Poles of each structure.
    theta : ndarray of shape (S, max na)
        The a coefficients of each structure in its first ``na`` columns.

    Returns
    -------
    ndarray of shape (S,)
        0 for a structure without poles, NaN where a coefficient is not finite.
    """
    out = np.zeros(len(na))
    for k in distinct(na):
        if k == 0:
            continue
        every = np.flatnonzero(na == k)
        # A thousand matrices per call: one numpy call is not interruptible, and 6,000 structures
        # of one na took most of a second on a loaded machine (a Ctrl-C waited for it).
        for idx in np.array_split(every, -(-len(every) // _POLES_PER_CALL)):
            a = theta[idx, :k]
            ok = np.isfinite(a).all(axis=1)
            comp = np.zeros((len(idx), k, k))
            comp[:, 0, :] = -np.where(ok[:, None], a, 0.0)
            if k > 1:
                comp[:, np.arange(1, k), np.arange(k - 1)] = 1.0
            mags = np.abs(np.linalg.eigvals(comp)).max(axis=1)
            out[idx] = np.where(ok, mags, np.nan)
    return out


def _validation_fit(res: _core.SweepOutput, rms_val: np.ndarray, val: IOData | None, first_lag: int) -> np.ndarray:
    """Validation fit percent of every structure from the core's error and output norms."""
    if val is None:
        return np.full(len(rms_val), np.nan)
    # With missing validation samples the core scores a subset per structure and gives its norm.
    per_structure = res.norm_sim_val
    # Structures that scored every finite sample share one norm; computed only when one needs it
    # (a fleet on a cluster gives every norm, and its client holds no samples).
    shared = ~np.isfinite(per_structure) & np.isfinite(rms_val)
    norm = np.where(shared, _scored_norm(val, first_lag) if shared.any() else np.nan, per_structure)
    with np.errstate(all="ignore"):
        return np.asarray(metrics.fit_percent_from_norms(rms_val * np.sqrt(res.n_sim_val), norm))


def ranked_columns(
    res: _core.SweepOutput, g: Grid, n_terms: int, val: IOData | None, sort_by: str, m: int
) -> dict[str, Any]:
    """The core's output in ranked order: the columns of a :class:`~arxid.SweepResult` that follow
    from it.

    Parameters
    ----------
    res : SweepOutput
        The core's output, in grid order.
    g : Grid
        The structures swept.
    n_terms : int
        Output terms of the effects (parameters every structure has besides its orders).
    val : IOData or None
        Validation data.
    sort_by : str
        The criterion asked for (one of :data:`SORT_KEYS`).
    m : int
        Inputs of the data.

    Returns
    -------
    dict
        Orders, parameters, errors, criteria, divergence flags, failures and stages, best first
        (failed structures, and diverged ones for a free-run criterion, last); ``sort_by`` is the
        criterion in effect (:func:`effective_key`).
    """
    grid = g.layout
    s = len(grid)
    mc = (grid.shape[1] - 1) // 2
    na = grid[:, 0].copy()
    p = na + grid[:, 1 : 1 + mc].sum(axis=1) + n_terms
    crit = criteria(res, p)
    div_est, div_val = res.diverged_est, res.diverged_val
    rms_est = np.where(div_est, np.nan, res.rms_sim_est)
    rms_val = np.where(div_val, np.nan, res.rms_sim_val)
    errors = res.errors
    failed = (
        np.zeros(0, dtype=np.intp)
        if errors.count(None) == len(errors)  # the usual case, at C speed on a million-row grid
        else np.array([i for i, e in enumerate(errors) if e is not None], dtype=np.intp)
    )
    fit_val = _validation_fit(res, rms_val, val, res.first_lag)
    key = effective_key(sort_by, val is not None)
    score = ranking_column(Columns(rms_val=rms_val, rms_est=rms_est, **crit), key)
    bad = np.zeros(s, dtype=bool)
    bad[failed] = True
    if key in FREE_RUN_KEYS:  # a diverged simulation has no free-run error to rank by
        bad = bad | div_val | div_est
    # Stage-1 rows of a two-stage sweep (not simulated) follow the ranked ones, by one-step error.
    order = stages.rank_order(
        score, bad | ~np.isfinite(score), res.stage, crit["val_one_step" if val is not None else "est_one_step"]
    )
    nbm = np.asarray(g.user_nb, dtype=int).reshape(s, m)
    nkm = np.asarray(g.user_nk, dtype=int).reshape(s, m)
    return dict(
        na=na[order],
        nb=nbm[order],
        nk=nkm[order],
        parameters=stages.RankedParameters(res.theta, p, order),
        n_params=p[order],
        rms_est_one_step=crit["est_one_step"][order],
        rms_val_one_step=crit["val_one_step"][order],
        rms_est=rms_est[order],
        rms_val=rms_val[order],
        fit_val=fit_val[order],
        fpe=crit["fpe"][order],
        aic=crit["aic"][order],
        bic=crit["bic"][order],
        selstruc_aic=crit["selstruc_aic"][order],
        selstruc_mdl=crit["selstruc_mdl"][order],
        diverged_est=div_est[order],
        diverged_val=div_val[order],
        errors=_ranked_errors(errors, failed, order),
        sort_by=key,
        first_lag=res.first_lag,
        row_orders=res.envelope,
        n_est=res.n_est,
        n_val=res.n_val,
        stage=res.stage[order],
        estimation_factor=getattr(res, "r_est", None),
    )


def first_in_order(values: np.ndarray, k: int) -> np.ndarray:
    """The first indices of ``np.argsort(values, kind="stable")``, at least ``k`` of them (every
    value tied with the k-th smallest included), without sorting all of ``values``: the few best
    structures of a grid of hundreds of thousands.

    Parameters
    ----------
    values : ndarray of shape (S,)
        The measure, smallest first (NaN sorts last, as in ``np.argsort``).
    k : int
        How many are needed.

    Returns
    -------
    ndarray of int
        A prefix of the stable sort's order, of length ``min(k, S)`` or more.
    """
    if k >= values.size:
        return np.argsort(values, kind="stable")
    kth = np.partition(values, k - 1)[k - 1]
    idx = np.flatnonzero(values <= kth) if not np.isnan(kth) else np.arange(values.size)
    return idx[np.argsort(values[idx], kind="stable")]
