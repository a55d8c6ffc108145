"""The sweep engine: one call of the Rust core over every structure of a grid (:class:`Runner`), in
process on the samples, or where a fleet's logs are (:func:`fleet_parts`, :func:`fleet_engine`: the
Dask workers that read them)."""

from __future__ import annotations

import numbers
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from .._base import _core
from .._base.optional import optional
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError
from ..models.arguments import check_same_signals
from ..models.effects import compile_effects
from .grid import Grid

if TYPE_CHECKING:
    from ..fleet.sweep import DaskEngine

# arxid.fleet is imported by the functions of a fleet: a sweep of one record does not load it.

__all__ = ["CoreInputs", "Runner", "check_validation_length", "core_inputs", "fleet_engine", "fleet_parts"]


@record
class CoreInputs:
    """What the core reads besides the outputs: the inputs with the effect columns, and the output terms."""

    u_est: np.ndarray
    u_val: np.ndarray | None
    terms: list


def core_inputs(est: IOData, val: IOData | None, g: Grid, effects: tuple[str, ...]) -> CoreInputs:
    """The inputs the core reads, with the effect columns of the grid's first structure.

    Parameters
    ----------
    est, val : IOData, IOData or None
        Estimation and validation data.
    g : Grid
        The structures (the effects' columns follow from the first one's orders).
    effects : tuple of str
        Effect terms added to every structure.

    Returns
    -------
    CoreInputs
        Without effects the core reads the inputs in place (no copy).
    """
    if not effects:
        return CoreInputs(
            np.ascontiguousarray(est.u, dtype=float),
            None if val is None else np.ascontiguousarray(val.u, dtype=float),
            [],
        )
    nb0, nk0 = list(g.user_nb[0]), list(g.user_nk[0])
    lay_est = compile_effects(effects, est, nb0, nk0)
    u_val = None if val is None else compile_effects(effects, val, nb0, nk0).u
    return CoreInputs(lay_est.u, u_val, list(lay_est.output_terms))


def check_validation_length(val: IOData | None, first_lag: int) -> None:
    """Refuse validation data that leave no sample to score from the grid's largest lag on.

    Parameters
    ----------
    val : IOData or None
        Validation data (None: nothing to check).
    first_lag : int
        The grid's largest lag, where every structure starts in each experiment.

    Raises
    ------
    DataError
        When no sample is left to validate on, or none of the outputs is finite.
    """
    if val is None:
        return
    if sum(max(0, b - a - first_lag) for a, b in val.segments) == 0:
        raise DataError(
            f"the validation data have {val.n_samples} samples, but every structure starts at the grid's largest lag "
            f"{first_lag} into each experiment, which leaves none to validate on; use longer validation data or "
            f"smaller orders"
        )
    if not val.output_measured:
        raise DataError(
            "the validation data hold no finite output sample (all NaN); pass validation data with a measured output"
        )


class Runner:
    """One call of the core's sweep at a given horizon, with an optional progress bar.

    Parameters
    ----------
    est, val : IOData, IOData or None
        Estimation and validation data.
    g : Grid
        The structures.
    inputs : CoreInputs or None
        The inputs the core reads; None when ``engine`` runs where a fleet's logs are.
    n_threads : int
        Threads (0 = all cores).
    progress : bool
        Show a progress bar on an interactive terminal.
    simulate_estimation : bool
        Also simulate every structure on the estimation data.
    top : int or None
        Structures simulated after the one-step ranking (None: every one).
    engine : callable, optional
        A fleet's engine (:func:`fleet_engine`), used when ``inputs`` is None.
    """

    def __init__(
        self,
        est: IOData,
        val: IOData | None,
        g: Grid,
        inputs: CoreInputs | None,
        n_threads: int,
        progress: bool,
        simulate_estimation: bool,
        top: int | None = None,
        engine: Any = None,
    ):
        self.est, self.val, self.g, self.inputs = est, val, g, inputs
        self.n_threads, self.progress, self.simulate_estimation = n_threads, progress, simulate_estimation
        self.top, self.engine = top, engine

    def __call__(self, k: int | None) -> Any:
        if self.inputs is None:  # a fleet on a cluster: the engine runs where the logs are
            return self.engine(self.g.layout, self.top, k, bool(self.simulate_estimation))
        inputs = self.inputs
        n = len(self.g.layout)
        bar = _progress_bar(n, k) if self.progress else None
        report = None
        if bar is not None:
            progress_bar = bar

            def report(done: int) -> None:
                if done > progress_bar.n:  # reports may arrive out of order from the worker threads
                    progress_bar.update(done - progress_bar.n)

        val = self.val
        try:
            return _core.sweep(
                np.ascontiguousarray(self.est.y),
                inputs.u_est,
                list(self.est.experiment_starts),
                self.g.layout,
                inputs.terms,
                yv=np.ascontiguousarray(val.y) if val is not None else None,
                uv=inputs.u_val,
                starts_v=list(val.experiment_starts) if val is not None else None,
                simulate_estimation=bool(self.simulate_estimation),
                horizon=k,
                n_threads=self.n_threads,
                chunk=max(64, n // 100),
                progress=report,
                top=self.top,
            )
        finally:
            if bar is not None:
                bar.close()


def _progress_bar(n: int, k: int | None) -> Any:
    """A tqdm bar on an interactive terminal; None when stderr is not a terminal or tqdm is not
    installed (then one ArxidWarning per process names the extra)."""
    if not sys.stderr.isatty():
        return None
    auto = optional("tqdm.auto", "the progress bar of arxid.sweep")
    if auto is None:
        return None
    return auto.tqdm(total=n, desc="arxid.sweep" + (f" ({k}-step)" if k else ""), unit="structure", leave=False)


# ---------------------------------------------------------------------------------------------- fleet
def fleet_parts(client: Any, logs: Sequence, read: Any, fraction: float | None) -> tuple[Any, tuple]:
    """The merged parts of a fleet's logs, and the logs on the workers of ``client`` (None in process).

    With a client the workers read the logs; the parts are :class:`arxid.cluster.LogsOnDemand`
    (shapes now, samples read on the client only when a result needs them).

    Parameters
    ----------
    client : dask.distributed.Client or None
        Where the logs are read; None reads them in process.
    logs : sequence
        The logs (paths or IOData).
    read : dict or callable, optional
        How to read file paths (see :func:`arxid.fleet.load_experiment`).
    fraction : float or None
        Fraction of each log held out for validation.

    Returns
    -------
    tuple
        The logs on the workers (None in process), and the (estimation, validation) parts.
    """
    from ..fleet import cluster
    from ..fleet import logs as fleet

    if client is None:
        return None, fleet.merged_parts(logs, read, fraction)
    on_workers = cluster.WorkerLogs(client, logs, read, fraction)
    return on_workers, on_workers.on_demand()


def fleet_engine(workers: Any, est: IOData, g: Grid, effects: tuple[str, ...]) -> DaskEngine:
    """The engine that sweeps a fleet where its logs are, with the effect columns and output terms
    the in-process sweep would use (the terms follow from the first samples alone).

    Parameters
    ----------
    workers : arxid.cluster.WorkerLogs
        The logs on the workers (from :func:`fleet_parts`).
    est : IOData
        The merged estimation part (its first samples tell how the effects expand).
    g : Grid
        The structures.
    effects : tuple of str
        Effect terms added to every structure.

    Returns
    -------
    arxid.fleet.sweep.DaskEngine
    """
    from ..fleet import sweep as fleet_sweep

    columns = fleet_sweep.EffectColumns(effects, tuple(g.user_nb[0]), tuple(g.user_nk[0]))
    head = est[: min(est.n_samples, 8)]
    terms = list(compile_effects(effects, head, columns.nb, columns.nk).output_terms) if effects else []
    return fleet_sweep.DaskEngine(workers, terms, columns)


def validation_split(data: IOData, validation: Any) -> tuple[IOData, IOData | None]:
    """The estimation and validation data of a sweep: ``validation`` as given (an IOData with the
    same signals), None, or the fraction of ``data`` (its end) held out."""
    if isinstance(validation, IOData):
        if validation.n_inputs != data.n_inputs:
            raise DataError(f"validation data have {validation.n_inputs} inputs, the estimation data {data.n_inputs}")
        check_same_signals(data.ts, data.output_name, data.input_names, validation, "the validation data")
        return data, validation
    if validation is None:
        return data, None
    if isinstance(validation, numbers.Real) and not isinstance(validation, bool):
        fraction = float(validation)
        if not 0 < fraction < 1:
            raise DataError(f"validation as a fraction must be between 0 and 1, got {validation}")
        return data.split(1 - fraction)
    raise DataError(f"validation must be None, an IOData or a fraction, got {type(validation).__name__}")
