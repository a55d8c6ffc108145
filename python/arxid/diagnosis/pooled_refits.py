"""Refits and validation errors of ARX models pooled over records kept where they are (a fleet's
logs on a Dask cluster): the two steps of the missing-effect diagnosis that need the samples, done
where the records are, and only their sums brought back.

A refit reduces each share's regressors ``[Φ | y]`` (on the rows an in-process fit with the same
``first_lag`` uses, :func:`arxid.models.regressors.regressor_matrix`) to its triangular factor; the
factors are combined by QR and the model is solved from the final R by the routine that finishes
every fit of logs kept elsewhere (:func:`arxid.models.arx_solver.solve_factor`). Its parameters
equal those of the in-process fit of the merged logs to rounding.

A validation error cannot be reduced to statistics of the regressors: a free run depends on its own
past. Each share simulates the model on its own logs (every log is an experiment of its own, so no
run crosses two logs) and sends back a few sums (:func:`share_scores`); the client pools them into
the RMS, the fit percent and the divergence verdict of the merged logs (:class:`PooledScore`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._base import _core, metrics
from ..checks.comparison import prediction_error
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..fleet import cluster
from ..fleet.fit import combine_share_factors
from ..models.arx_model import ArxModel
from ..models.arx_solver import solve_factor
from ..models.effects import compile_effects
from ..models.regressors import max_lag, regressor_matrix, regressor_names, row_bound

__all__ = ["PooledRefits", "FleetRefits", "PooledScore", "aligned", "share_refit_factor", "share_scores"]


def share_refit_factor(share: tuple, na: int, nb: tuple, nk: tuple, effects: tuple, first_lag: int) -> tuple:
    """The factor of a share's regressors for one refit: R of ``[Φ | y]`` with its row counts, as
    :func:`arxid.fleet.fit.share_factor` gives it for a fit, on the rows a refit of the model uses
    (from ``first_lag`` on, around missing samples); combined as it by
    :func:`~arxid.fleet.fit.combine_share_factors`.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.fleet.cluster.load_share`.
    na : int
    nb, nk : tuple of int
    effects : tuple of str
    first_lag : int
        Rows start this far into each log at least (the fitted model's ``first_lag_``).

    Returns
    -------
    tuple
        ``(R, rows, rows at most available, effect layout without its samples, samples)``.
    """
    data = share[0]
    layout = compile_effects(effects, data, nb, nk)
    phi, y, rows = regressor_matrix(data, na, layout, first_lag)
    r = cluster.square_factor(np.column_stack([phi, y]))
    lag = max(first_lag, max_lag(na, layout))
    bare = replace(layout, u=np.empty((0, layout.u.shape[1])))  # not a view: it would hold the samples
    return r, len(rows), row_bound(data, lag), bare, data.n_samples


def share_refit_factors(share: tuple, structures: Sequence[tuple]) -> list[tuple]:
    """:func:`share_refit_factor` of several refits in one task.

    Parameters
    ----------
    share : tuple
    structures : sequence of (na, nb, nk, effects, first_lag)

    Returns
    -------
    list of tuple
    """
    return [share_refit_factor(share, *s) for s in structures]


def _combine_refits(a: list, b: list) -> list:
    return [combine_share_factors(x, y) for x, y in zip(a, b, strict=True)]


def share_scores_many(share: tuple, models: Sequence[Any], specs: Sequence[tuple]) -> list[list[tuple]]:
    """:func:`share_scores` of several models in one task.

    Parameters
    ----------
    share : tuple
    models : sequence of ArxModel
    specs : sequence of (part, horizon, initial)

    Returns
    -------
    list of list of tuple
    """
    return [share_scores(share, m, specs) for m in models]


def share_scores(share: tuple, model: Any, specs: Sequence[tuple]) -> list[tuple]:
    """What a share's logs contribute to the model's validation errors, one entry per ``specs``.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.fleet.cluster.load_share`.
    model : ArxModel
    specs : sequence of (part, horizon, initial)
        ``part`` is ``"est"`` or ``"val"``; ``horizon`` None (free run) or k; ``initial`` as in
        :func:`arxid.checks.prediction_error`.

    Returns
    -------
    list of tuple
        ``(sum of squared errors, samples, largest |prediction|, prediction reached inf, largest
        measured |y|, fit-percent part)`` (see :func:`arxid._base.metrics.fit_percent_part`).
    """
    out = []
    for part, horizon, initial in specs:
        d = aligned(share[0] if part == "est" else share[1])
        pred, err, _ = prediction_error(model, d, horizon, initial)
        with np.errstate(all="ignore"):
            e = err[np.isfinite(err)]
            p = pred[np.isfinite(pred)]
            out.append(
                (
                    float(np.sum(e * e)),
                    int(e.size),
                    float(np.max(np.abs(p))) if p.size else 0.0,
                    bool(np.isinf(pred).any()),
                    metrics.finite_peak(d.y),
                    metrics.fit_percent_part(d.y, pred),
                )
            )
    return out


def aligned(d: IOData) -> IOData:
    """``d`` with C-contiguous, aligned samples (arrays deserialised on a worker may be neither,
    and the core takes only those), copied only when needed.

    Parameters
    ----------
    d : IOData

    Returns
    -------
    IOData
    """

    def ok(a: np.ndarray) -> bool:
        return bool(a.flags.c_contiguous and a.flags.aligned)

    if ok(d.y) and ok(d.u) and all(ok(v) for v in d.extra.values()):
        return d
    extra = {k: np.require(v, np.float64, ["C", "A"]) for k, v in d.extra.items()}
    y, u = np.require(d.y, np.float64, ["C", "A"]), np.require(d.u, np.float64, ["C", "A"])
    return dataclasses.replace(d, y=y, u=u, extra=extra)


@dataclass(frozen=True)
class PooledScore:
    """A model's prediction error over every log, pooled from the shares' sums.

    Attributes
    ----------
    rms : float
        As :func:`arxid.checks.error_rms` on the merged logs: ``inf`` when the prediction diverged,
        NaN without a predicted sample.
    fit : float
        As :func:`arxid._base.metrics.fit_percent` on the merged logs.
    diverged : bool
    """

    rms: float
    fit: float
    diverged: bool

    @classmethod
    def of(cls, parts: Sequence[tuple]) -> PooledScore:
        """The pooled score of the shares' entries (:func:`share_scores`).

        Parameters
        ----------
        parts : sequence of tuple

        Returns
        -------
        PooledScore
        """
        sse = sum(p[0] for p in parts)
        n = sum(p[1] for p in parts)
        peak = max(p[4] for p in parts)
        # The divergence limit depends on the largest measured |y| only (as the fleet sweep uses it).
        limit = float(_core.divergence_limit(np.array([peak])))
        diverged = any(p[3] for p in parts) or max(p[2] for p in parts) > limit
        rms = math.inf if diverged else (math.sqrt(sse / n) if n else math.nan)
        return cls(rms, metrics.fit_percent_of_parts([p[5] for p in parts]), diverged)


class PooledRefits:
    """ARX refits and validation errors over the logs of a :class:`arxid.fleet.cluster.WorkerLogs`.

    Parameters
    ----------
    logs : WorkerLogs
        The fleet, read by the workers, with its validation parts.
    """

    def __init__(self, logs: cluster.WorkerLogs):
        self.logs = logs

    def fit(self, na: int, nb: tuple, nk: tuple, effects: Sequence[str], first_lag: int = 0) -> ArxModel:
        """The ARX model fitted on every log's estimation part, as ``ArxModel(...).fit(merged,
        first_lag=first_lag)`` fits it in process (to rounding).

        Parameters
        ----------
        na : int
        nb, nk : tuple of int
        effects : sequence of str
        first_lag : int

        Returns
        -------
        ArxModel
            Without ``data_``; ``fit_percent_`` is the one-step fit over every log.

        Raises
        ------
        ArxidError
            When the model cannot be fitted (too few rows, collinear regressors).
        """
        out = self.fit_many([(na, tuple(nb), tuple(nk), tuple(effects), first_lag)])[0]
        if isinstance(out, ArxidError):
            raise out
        return out[0]

    def fit_many(self, structures: Sequence[tuple], specs: Sequence[tuple] = ()) -> list[Any]:
        """Several refits in two round trips: the factors of all, then the scores of all.

        Parameters
        ----------
        structures : sequence of (na, nb, nk, effects, first_lag)
        specs : sequence of (part, horizon, initial)
            Scores wanted besides the one-step fit percent on the estimation parts.

        Returns
        -------
        list
            Per structure ``(ArxModel, [PooledScore per spec])``, or the ArxidError its fit raised.
        """
        structures = [(na, tuple(nb), tuple(nk), tuple(e), lag) for na, nb, nk, e, lag in structures]
        futures = self.logs.each(share_refit_factors, structures)
        combined = cluster.reduce_tree(self.logs.client, futures, _combine_refits)
        sig = self.logs.signals
        models: list[Any] = []
        for (na, nb, nk, effects, lag), (r, n_rows, usable, layout, _) in zip(structures, combined, strict=True):
            names = regressor_names(sig.output_name, na, layout)
            try:
                res = solve_factor(r, n_rows, usable, na, layout, names)
            except ArxidError as exc:
                models.append(exc)
                continue
            model = ArxModel(na=na, nb=list(nb), nk=list(nk), effects=list(effects))
            # The one solve of a fit from factors, as ArxModel.fit with client= stores it (first_lag
            # kept); the one-step fit percent comes with the scores below.
            model._store(sig, (na, nb, nk), layout, names, lag, res, fit_percent=lambda m: math.nan)
            models.append(model)
        fitted = [m for m in models if isinstance(m, ArxModel)]
        wanted = [("est", 1, "zero"), *specs]
        outs = self.logs.client.gather(self.logs.each(share_scores_many, fitted, wanted)) if fitted else []
        scores = iter(
            [[PooledScore.of([o[i][j] for o in outs]) for j in range(len(wanted))] for i in range(len(fitted))]
        )
        result: list[Any] = []
        for m in models:
            if isinstance(m, ArxModel):
                pooled = next(scores)
                m.fit_percent_ = pooled[0].fit
                result.append((m, pooled[1:]))
            else:
                result.append(m)
        return result

    def scores(self, model: ArxModel, specs: Sequence[tuple]) -> list[PooledScore]:
        """The model's prediction errors over every log, one per ``specs`` (one round trip).

        Parameters
        ----------
        model : ArxModel
        specs : sequence of (part, horizon, initial)
            See :func:`share_scores`.

        Returns
        -------
        list of PooledScore
        """
        outs = self.logs.client.gather(self.logs.each(share_scores, model, list(specs)))
        return [PooledScore.of([o[i] for o in outs]) for i in range(len(specs))]


#: The name this class had while only a fleet used it.
FleetRefits = PooledRefits
