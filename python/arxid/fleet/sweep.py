"""One sweep over a fleet of logs on a Dask cluster: the core of :func:`arxid.sweep` run where the logs are.

The logs are read by the workers and kept there (:class:`arxid.cluster.WorkerLogs`). Each share
adds the columns of the sweep's effects to its inputs (:class:`EffectColumns`, computed within each
experiment as in process) and reduces its logs to the triangular factor R of the grid's largest
regressor (regressors never straddle two logs); the factors are combined by QR in a tree, and every
structure is solved from the final R on the client. The free-run simulation is spread over the
workers too: each share simulates the structures on its own logs (judged by the divergence limit of
the whole fleet) and sends back their squared-error sums and the moments of its validation output,
so no log moves between workers.

What travels over the network: the grid, the logs' shapes, R factors of ``q × q`` numbers (``q`` =
columns of the largest regressor), the parameters and the scores of each structure; never the
samples, when the workers read their own files. The client does not read the logs: the
:class:`~arxid.SweepResult` holds them as :class:`arxid.cluster.LogsOnDemand`, read when first used
(by ``model``, ``summary``'s step checks or ``extend``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._base import _core, metrics
from ..data.iodata import IOData
from ..models.effects import compile_effects
from . import cluster

__all__ = ["DaskEngine", "EffectColumns", "FleetOutput"]


def _aligned(a: np.ndarray, dtype: Any) -> np.ndarray:
    """A C-contiguous, aligned copy when needed (arrays deserialised on a worker may be neither)."""
    return np.require(a, dtype=dtype, requirements=["C", "A"])


def _arrays(d: IOData) -> tuple[np.ndarray, np.ndarray, list[int]]:
    return _aligned(d.y, np.float64), _aligned(d.u, np.float64), list(d.experiment_starts)


def _peak(d: IOData | None) -> float:
    """Largest measured |y| of a part (0 without one): its share of the fleet's divergence limit."""
    return metrics.finite_peak(d.y) if d is not None else 0.0


@dataclass(frozen=True)
class EffectColumns:
    """How a worker builds the inputs of its parts: the measured inputs followed by the columns of
    the sweep's effects, computed within each experiment (as the in-process sweep does).

    Attributes
    ----------
    effects : tuple of str
    nb, nk : tuple of int
        Orders of one structure of the grid (the columns do not depend on them).
    """

    effects: tuple = ()
    nb: tuple = ()
    nk: tuple = ()

    def arrays(self, d: IOData) -> tuple[np.ndarray, np.ndarray, list[int]]:
        """``(y, inputs with the effect columns, experiment starts)`` of ``d`` for the core."""
        y, u, starts = _arrays(d)
        if self.effects:
            u = compile_effects(self.effects, d, self.nb, self.nk).u
        return y, u, starts


def share_factors(share: tuple, layout: np.ndarray, terms: list, columns: EffectColumns) -> tuple:
    """The factors of a share's estimation and validation parts, and their largest |y|.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.cluster.load_share`.
    layout : ndarray of shape (S, 1 + 2m)
        The grid.
    terms : list
        Output terms of the effects.
    columns : EffectColumns

    Returns
    -------
    tuple
        ``(R_est, n_est, R_val, n_val, peak_est, peak_val)`` (R_val None without validation).
    """
    est, val = share[0], share[1]
    layout = _aligned(layout, np.int64)
    r_est, n_est = _core.grid_factor(*columns.arrays(est), layout, terms)
    r_val, n_val = _core.grid_factor(*columns.arrays(val), layout, terms) if val is not None else (None, 0)
    return r_est, n_est, r_val, n_val, _peak(est), _peak(val)


def combine_factors(a: tuple, b: tuple) -> tuple:
    """Two shares' factors combined by QR of their stacked factors (one node of the reduction tree).

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
        cluster.stack_factors(a[0], b[0]),
        a[1] + b[1],
        cluster.stack_factors(a[2], b[2]),
        a[3] + b[3],
        max(a[4], b[4]),
        max(a[5], b[5]),
    )


def simulate_share(share: tuple, which: str, layout: np.ndarray, theta: np.ndarray, args: dict) -> tuple:
    """Every structure simulated on a share's logs, judged by the whole fleet's divergence limit.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.cluster.load_share`.
    which : {"est", "val"}
        The parts to simulate on.
    layout : ndarray of shape (S, 1 + 2m)
        The structures.
    theta : ndarray of shape (S, p_max)
        Their parameters.
    args : dict
        ``first_lag``, ``horizon``, ``limit`` (the limit of ``which``), ``terms`` (output terms) and
        ``columns`` (:class:`EffectColumns`).

    Returns
    -------
    tuple
        ``(sse, n, moments, diverged)``: per structure its squared-error sum, the samples it scored,
        and ``(n, mean, m2)`` of the measured output over them (:mod:`arxid._metrics`: the parts of
        its fit percent's norm).
    """
    d = share[0] if which == "est" else share[1]
    layout, theta = _aligned(layout, np.int64), _aligned(theta, np.float64)
    y, u, starts = args["columns"].arrays(d)
    rms, n, norm, mean, diverged = _core.simulate_structures(
        y, u, starts, layout, args["terms"], theta, args["first_lag"], args["horizon"], n_threads=1, limit=args["limit"]
    )
    # The core gives the output's norm only where it scored a subset (missing samples); elsewhere a
    # structure scores every finite sample from the first lag on, whose moments are the share's.
    _, whole_mean, whole_m2 = metrics.scored_moments(d.y, d.segments, args["first_lag"])
    subset = np.isfinite(norm)
    moments = np.column_stack([n, np.where(subset, mean, whole_mean), np.where(subset, norm * norm, whole_m2)])
    return rms * rms * n, n, moments, diverged


def simulate_share_parts(share: tuple, parts: dict, layout: np.ndarray, theta: np.ndarray) -> dict:
    """:func:`simulate_share` on each of the share's ``parts`` in one task (one round trip).

    Parameters
    ----------
    share : tuple
    parts : dict
        ``{"est" or "val": args}`` (see :func:`simulate_share`).
    layout, theta : ndarray

    Returns
    -------
    dict
        The scores of each part.
    """
    return {which: simulate_share(share, which, layout, theta, args) for which, args in parts.items()}


class DaskEngine:
    """Runs the core of a sweep over a fleet on a Dask cluster, where the logs are.

    The factors of the shares are combined in a QR tree; every structure is solved from the final R
    on the client; then every share simulates the structures on its own logs and sends back their
    squared-error sums and output moments.

    Parameters
    ----------
    logs : WorkerLogs
        The fleet, read by the workers.
    terms : list
        Output terms of the sweep's effects.
    columns : EffectColumns
        How the workers add the effect columns to the inputs.
    """

    def __init__(self, logs: cluster.WorkerLogs, terms: list, columns: EffectColumns):
        self.logs, self.terms, self.columns = logs, terms, columns

    def factors(self, layout: np.ndarray) -> tuple:
        """The combined factors of every log: partials where the logs are, then a QR tree.

        Parameters
        ----------
        layout : ndarray
            The grid.

        Returns
        -------
        tuple
            ``(R_est, n_est, R_val, n_val, peak_est, peak_val)``.
        """
        # Only the factors leave the workers (the grid travels inside the tasks, not scattered:
        # scattered data die with their worker).
        futures = self.logs.each(share_factors, layout, self.terms, self.columns)
        return cluster.reduce_tree(self.logs.client, futures, combine_factors)

    def simulate(self, parts: dict, layout: np.ndarray, theta: np.ndarray) -> dict:
        """Scores of every given structure over all logs: each share simulates its own logs.

        Parameters
        ----------
        parts : dict
            ``{"est" or "val": {"first_lag", "horizon", "limit"}}``: the parts to simulate on.
        layout : ndarray of shape (S, 1 + 2m)
        theta : ndarray of shape (S, p_max)

        Returns
        -------
        dict
            For each part ``(rms, n, norm, diverged)``: ``norm`` is ‖y − ȳ‖ over the samples each
            structure scored.
        """
        outs = self.logs.client.gather(self.logs.each(simulate_share_parts, parts, layout, theta))
        return {which: _pooled_scores([o[which] for o in outs]) for which in parts}

    def __call__(self, layout: np.ndarray, top: int | None, horizon: int | None, simulate_estimation: bool) -> Any:
        """The fleet's ``_core.sweep`` of the grid ``layout`` (options as ``_core.sweep`` takes them).

        Parameters
        ----------
        layout : ndarray of shape (S, 1 + 2m)
        top : int or None
            Structures validated in free run (two stages), or None for all.
        horizon : int or None
            Prediction horizon, None for free run.
        simulate_estimation : bool
            Also simulate on the estimation parts.

        Returns
        -------
        FleetOutput
        """
        r_est, n_est, r_val, n_val, peak_est, peak_val = self.factors(layout)
        out, simulate = _core.sweep_factors(r_est, n_est, layout, self.terms, r_val=r_val, n_val=n_val, top=top)
        result = FleetOutput.from_core(out)
        errors = out.errors  # one conversion: each attribute read converts the whole list
        fitted = np.array([i for i in simulate if errors[i] is None], dtype=int)
        peaks = {"est": peak_est} if simulate_estimation else {}
        peaks.update({"val": peak_val} if r_val is not None else {})
        common = {"first_lag": out.first_lag, "horizon": horizon, "terms": self.terms, "columns": self.columns}
        parts = {which: {**common, "limit": _core.divergence_limit(np.array([peak]))} for which, peak in peaks.items()}
        for which, scores in self.simulate(parts, layout[fitted], out.theta[fitted]).items():
            result.fill(which, fitted, scores)
        return result


def _pooled_scores(outs: list) -> tuple:
    """The scores of every share (:func:`simulate_share`) as those of all the logs together."""
    sse = np.sum([o[0] for o in outs], axis=0)
    n = np.sum([o[1] for o in outs], axis=0)
    diverged = np.any([o[3] for o in outs], axis=0)
    pooled = metrics.pooled_moments([o[2] for o in outs])[:, 2]
    with np.errstate(all="ignore"):
        rms = np.where(diverged | (n == 0), np.nan, np.sqrt(sse / n))
        norm = np.where(diverged, np.nan, np.sqrt(pooled))
    return rms, n, norm, diverged


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
    r_est: np.ndarray | None = None

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
        fields: dict[str, Any] = {k: getattr(out, k, None) for k in cls.__dataclass_fields__}
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
