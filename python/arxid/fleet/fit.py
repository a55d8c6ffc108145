"""One ARX model fitted to a fleet of logs, in process or on a Dask cluster; or one model per log.

:func:`arxid.arx` and :meth:`ArxModel.fit` accept a list of experiments (:class:`~arxid.IOData`
objects or file paths, read as :func:`arxid.data.logs.load_experiment` reads them) and, optionally,
``client=`` (a ``dask.distributed.Client``; ``pip install 'arxid[dask]'``).

Merged, in process. The logs are read, checked to share their sampling time and signal names, and
merged into one IOData with one experiment per log (:meth:`IOData.merge`: no regressor straddles two
logs). The model is the fit of that IOData.

Merged, on a Dask cluster. Each task reads a share of the logs and keeps it on its worker. It builds
the model's regressors on its logs (effect terms included: every effect, ``time`` and differences
too, is computed within each experiment) and reduces them to the triangular factor R of
``[Φ | y]`` (q × q numbers, q = parameters + 1). The factors are combined by QR in a tree, and the
model is solved from the final R by the same core routine that finishes an in-process fit, so
parameters, covariance, noise variance and criteria equal the in-process fit to rounding. The
one-step fit percent is computed where the logs are; each share sends back eight sums. What travels
over the network: the names and sampling time of each log, one q × q factor per share, the model's
parameters and those sums; never the samples, when the workers read their own files. The fitted
model keeps no ``data_`` (as a model read from a file): pass the data to ``predict``, ``report`` and
the diagnostics.

Per log (``per_experiment=True``). Each log is fitted separately (on a worker with a client; the
models come back without their data). The result is a :class:`FleetModels`: the models, and for
every parameter its mean, standard deviation, range, how its spread compares with its standard
errors, and the logs whose value is an outlier (:func:`outlier_logs`: modified z-score above 3.5
and more than 3 standard errors from the fleet's median).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._base import _core, metrics
from .._base.formatting import require_pandas, text_table
from ..data.iodata import IOData
from ..data.logs import LogSignals, check_alike, load_logs, log_name, read_log
from ..exceptions import ArxidError, DataError
from ..models import many_logs
from ..models.effects import compile_effects
from ..models.regressors import max_lag, row_bound
from . import cluster

__all__ = ["ClusterLogs", "FleetModels", "ParameterSpread", "fit_each", "outlier_logs", "OUTLIER_Z", "OUTLIER_SE"]

#: A log's parameter is an outlier when its modified z-score exceeds this (Iglewicz & Hoaglin)...
OUTLIER_Z = 3.5
#: ... and it lies more than this many of its standard errors from the fleet's median.
OUTLIER_SE = 3.0


# ----------------------------------------------------------------------------- merged, on a cluster
def share_factor(share: tuple, na: int, nb: tuple, nk: tuple, effects: Sequence[str]) -> tuple:
    """The factor of a share's regressors: R of ``[Φ | y]`` on its logs, with its row counts.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.cluster.load_share`.
    na : int
    nb, nk : tuple of int
        One per input.
    effects : sequence of str

    Returns
    -------
    tuple
        ``(R (q × q), regression rows, rows at most available, effect layout without its samples,
        samples)``.
    """
    data = share[0]
    layout = compile_effects(effects, data, nb, nk)
    structure = np.array([[na, *layout.nb, *layout.nk]], dtype=np.int64)
    terms = list(layout.output_terms)
    r, n = _core.grid_factor(np.ascontiguousarray(data.y), layout.u, list(data.experiment_starts), structure, terms)
    bare = replace(layout, u=np.empty((0, layout.u.shape[1])))  # not a view: it would hold the samples
    return r, n, row_bound(data, max_lag(na, layout)), bare, data.n_samples


def combine_share_factors(a: tuple, b: tuple) -> tuple:
    """Two shares' factors as one (a node of the reduction tree).

    Parameters
    ----------
    a, b : tuple
        From :func:`share_factor`.

    Returns
    -------
    tuple
        The same for the rows of both.
    """
    return cluster.stack_factors(a[0], b[0]), a[1] + b[1], a[2] + b[2], a[3], a[4] + b[4]


def share_fit_part(share: tuple, model: Any) -> np.ndarray:
    """A share's contribution to the model's one-step fit percent.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.cluster.load_share`.
    model : ArxModel
        The fitted model.

    Returns
    -------
    ndarray of shape (8,)
        See :func:`arxid._metrics.fit_percent_part`.
    """
    data = share[0]
    return metrics.fit_percent_part(data.y, model.predict(data, horizon=1))


class ClusterLogs(cluster.WorkerLogs):
    """A fleet's logs kept on the workers of a Dask cluster (:class:`arxid.cluster.WorkerLogs`), with the
    steps of a merged fit done where the logs are."""

    def factor(self, na: int, nb: tuple, nk: tuple, effects: Sequence[str]) -> tuple:
        """The factor of the model's regressors over every log: a partial per share, then a QR tree.

        Parameters
        ----------
        na : int
        nb, nk : tuple of int
        effects : sequence of str

        Returns
        -------
        tuple
            As :func:`share_factor`, for all logs.
        """
        futures = self.each(share_factor, na, nb, nk, tuple(effects))
        return cluster.reduce_tree(self.client, futures, combine_share_factors)

    def fit_percent(self, model: Any) -> float:
        """:meth:`arxid.models.many_logs.FactorSource.fit_percent`, each log's part computed where the log is."""
        parts = self.client.gather(self.each(share_fit_part, model))
        return metrics.fit_percent_of_parts(parts)


# ----------------------------------------------------------------------------- one model per log
def outlier_logs(
    values: np.ndarray, errors: np.ndarray, names: Sequence[str], z: float = OUTLIER_Z, k: float = OUTLIER_SE
) -> tuple[str, ...]:
    """The logs whose value of one parameter stands out from the fleet's.

    Parameters
    ----------
    values : ndarray of shape (n_logs,)
        One parameter, one value per log.
    errors : ndarray of shape (n_logs,)
        Its standard error in each log.
    names : sequence of str
    z : float
        Threshold of the modified z-score.
    k : float
        Least distance from the fleet's median, in the log's own standard errors.

    Returns
    -------
    tuple of str

    Notes
    -----
    A log is an outlier when both hold: its modified z-score (Iglewicz & Hoaglin, 1993)
    ``M = 0.6745 (θ − median) / MAD`` exceeds ``z`` in magnitude, MAD being the median absolute
    deviation (when more than half of the logs share one value, MAD = 0 and
    ``M = (θ − median) / (1.253314 · mean |θ − median|)``); and θ is more than ``k`` of its own
    standard errors from the median, so that estimation noise alone does not flag a log of a
    fleet whose other logs happen to agree closely.
    """
    dev = values - np.median(values)
    mad = float(np.median(np.abs(dev)))
    if mad > 0:
        score = 0.6745 * dev / mad
    else:
        mean_ad = float(np.mean(np.abs(dev)))
        score = dev / (1.253314 * mean_ad) if mean_ad > 0 else np.zeros_like(dev)
    far = np.abs(dev) > k * errors
    return tuple(n for n, s, f in zip(names, score, far, strict=True) if abs(s) > z and f)


@dataclass(frozen=True)
class ParameterSpread:
    """How one parameter varies across a fleet's logs.

    Attributes
    ----------
    name : str
        The regressor it multiplies.
    mean, std, min, max : float
        Across the logs (``std`` with N − 1; NaN for one log).
    spread_ratio : float
        ``std`` over the median of the logs' standard errors: near 1 the logs agree within their
        estimation noise, well above 1 they differ.
    outliers : tuple of str
        Logs whose value is an outlier (:func:`outlier_logs`).
    """

    name: str
    mean: float
    std: float
    min: float
    max: float
    spread_ratio: float
    outliers: tuple


@dataclass(frozen=True)
class FleetModels:
    """One model per log (``per_experiment=True``) and how each parameter varies across the fleet.

    Attributes
    ----------
    models : tuple of ArxModel
        In the order of the logs.
    names : tuple of str
        The logs (file names, or ``log 1``, ``log 2``, ...).
    """

    models: tuple
    names: tuple

    @property
    def parameters(self) -> np.ndarray:
        """Parameters of every log's model, shape (n_logs, n_params)."""
        return np.array([m.parameters_ for m in self.models])

    @property
    def regressor_names(self) -> tuple[str, ...]:
        """The regressor each parameter multiplies."""
        return tuple(self.models[0].regressor_names_)

    def spread(self) -> list[ParameterSpread]:
        """How every parameter varies across the logs.

        Returns
        -------
        list of ParameterSpread
        """
        theta = self.parameters
        se = np.array([m.standard_errors_ for m in self.models])
        std = theta.std(axis=0, ddof=1) if len(theta) > 1 else np.full(theta.shape[1], np.nan)
        typical = np.median(se, axis=0)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(typical > 0, std / typical, np.nan)
        return [
            ParameterSpread(
                name,
                float(theta[:, j].mean()),
                float(std[j]),
                float(theta[:, j].min()),
                float(theta[:, j].max()),
                float(ratio[j]),
                outlier_logs(theta[:, j], se[:, j], self.names),
            )
            for j, name in enumerate(self.regressor_names)
        ]

    def summary(self) -> str:
        """How each parameter varies across the fleet, as text.

        Returns
        -------
        str
        """
        rows = [
            [s.name, s.mean, s.std, s.min, s.max, s.spread_ratio, ", ".join(s.outliers) or "-"] for s in self.spread()
        ]
        title = (
            f"{len(self.models)} logs fitted separately with {self.models[0].structure_name()}; parameters across "
            f"the fleet (std/s.e. near 1: the logs agree within their noise; outlier: modified z-score > {OUTLIER_Z} "
            f"and more than {OUTLIER_SE:g} standard errors from the median)"
        )
        return text_table(["parameter", "mean", "std", "min", "max", "std/s.e.", "outlier logs"], rows, title)

    def to_pandas(self) -> Any:
        """The parameters as a pandas DataFrame, one row per log.

        Returns
        -------
        pandas.DataFrame
        """
        pd = require_pandas()
        return pd.DataFrame(self.parameters, index=list(self.names), columns=list(self.regressor_names))

    def __str__(self) -> str:
        return self.summary()


def _fit_named(fit: Callable, data: IOData, name: str) -> Any:
    """``fit(data)``, with the log's name in front of any error's message (its type kept)."""
    try:
        return fit(data)
    except ArxidError as exc:
        exc.args = (f"log {name!r}: {exc.args[0] if exc.args else exc}",) + exc.args[1:]
        raise


def fit_log(source: Any, read: Any, name: str, fit: Callable) -> tuple:
    """One log's model fitted on a worker; it comes back without the log's samples.

    Parameters
    ----------
    source : IOData or path
    read : dict or callable or None
    name : str
    fit : callable
        Of an IOData, returning the fitted model.

    Returns
    -------
    tuple
        ``(model, LogSignals of the log)``.
    """
    data = read_log(source, read, name)
    model = _fit_named(fit, data, name)
    model.fit_percent_ = model.fit_percent_  # an ArxModel computes it when first read: while the log is here
    model.data_ = None
    return model, LogSignals.of(data)


def fit_each(sources: Sequence[Any], client: Any, read: Any, fit: Callable) -> FleetModels:
    """Every log fitted separately, on the workers when there is a client.

    Parameters
    ----------
    sources : sequence of IOData or paths
    client : dask.distributed.Client or None
    read : dict or callable or None
        As in :func:`arxid.data.logs.load_experiment`.
    fit : callable
        Of an IOData, returning the fitted model (picklable when there is a client).

    Returns
    -------
    FleetModels

    Raises
    ------
    DataError
        For an empty list, or naming a log that cannot be read or whose signals differ.
    """
    sources = list(sources)
    names = [log_name(s, i) for i, s in enumerate(sources)]
    if client is None:
        logs = load_logs(sources, read)
        models = [_fit_named(fit, d, n) for d, n in zip(logs, names, strict=True)]
    else:
        if not sources:
            raise DataError("the list of logs is empty; give at least one IOData or file path")
        futures = [client.submit(fit_log, s, read, n, fit, pure=False) for s, n in zip(sources, names, strict=True)]
        out = client.gather(futures)
        check_alike([o[1] for o in out], names)
        models = [o[0] for o in out]
    return FleetModels(tuple(models), tuple(names))


# The models fit lists of logs on a cluster, or one model per log, through these: they are stated in
# the model layer (arxid.models.many_logs), which cannot import this one.
many_logs.provide(many_logs.LogsFitting(cluster_logs=ClusterLogs, fit_each=fit_each))
