"""Exhaustive ARX order sweeps: :func:`sweep` fits and validates every (na, nb, nk) structure of a
grid from one factorization in the Rust core and ranks them in a :class:`SweepResult`.

The parts of a sweep live beside it: the grid and its defaults (:mod:`.grid`), the engine that runs
the core (:mod:`.engine`), the ranking (:mod:`.ranking`), the table of the result (:mod:`.table`),
the choice of a structure (:mod:`.choice`) and the output-error refinement (:mod:`.refine`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import field
from typing import TYPE_CHECKING, Any, Literal, cast, overload

import numpy as np

from .._base import _core, metrics
from .._base.limits import check_order
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, ArxidWarning, DataError, OrderError
from ..models.arx_model import ArxModel
from ..models.excitation import check_excitation
from . import choice, stages
from .choice import Selection
from .engine import Runner, check_validation_length, core_inputs, fleet_engine, fleet_parts, validation_split
from .grid import DEFAULT_GRID, Grid, check_grid_size, check_top, order_range, per_input_ranges
from .growth import DEFAULT_GROWTH_SECONDS, GROWTH_ORDER_LIMIT, MIN_GROWTH_GAIN, GridGrowth, grow, grows
from .integrator import (
    VOTERS,
    IntegratorTest,
    SettlingEvidence,
    integrator_test,
    slowest_time_constant,
    unit_root_t,
)
from .iv_engine import IvRunner, iv_settings
from .ranking import SORT_KEYS, first_in_order, ranked_columns
from .sanity import EXPECTATIONS, SanityLimits
from .table import SweepTable

if TYPE_CHECKING:  # the output-error refinement is imported when asked for (refine="oe")
    from .refine import RefinedSweep

__all__ = ["sweep", "SweepResult", "Selection", "DEFAULT_GRID", "SORT_KEYS"]


@record(eq=False, repr=False)  # repr: the table's one line, not every column
class SweepResult(SweepTable):
    """Every structure of a sweep, ranked (row 0 is the best).

    Attributes
    ----------
    na : ndarray of shape (S,)
    nb, nk : ndarray of shape (S, n_inputs)
    parameters : list of ndarray
        Parameters per structure (a's, b's per input, effect terms), ranked order.
    n_params : ndarray of shape (S,)
    rms_est_one_step, rms_val_one_step : ndarray of shape (S,)
        One-step prediction RMS on estimation and validation rows.
    rms_est, rms_val : ndarray of shape (S,)
        Free-run (or k-step, see ``horizon``) RMS on estimation and validation data; NaN when diverged.
    fit_val : ndarray of shape (S,)
        Validation fit in percent, 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖), of the same simulation.
    fpe, aic, bic : ndarray of shape (S,)
        Akaike's FPE, AIC and BIC of the estimation fit (MATLAB ``fpe`` / ``aic``; also
        ``est_aic`` / ``est_bic``).
    selstruc_aic, selstruc_mdl : ndarray of shape (S,)
        MATLAB ``selstruc``'s criteria ``V (1 + 2d/N)`` and ``V (1 + d log N / N)``, V the one-step
        loss on the validation data (estimation data without them), d the parameters, N the
        estimation rows (see docs/selection.md).
    stable : ndarray of bool, max_pole : ndarray (properties, computed on first use)
        All poles inside the unit circle; largest pole magnitude.
    diverged_est, diverged_val : ndarray of bool
        The simulation left a plausible range and was stopped (its RMS is NaN, not a number).
    errors : tuple of (str or None)
        Why a structure could not be fitted (collinear regressors), else None.
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction (integrating plants).
    integrating : bool
        The plant was expected or detected to integrate.
    integrating_reason : str
        Why it was (or was not) called integrating, with the unit-root test's numbers.
    integrator : IntegratorTest or None
        The unit-root test of the best structures (None when ``expect`` decided).
    grid : dict
        The orders swept: ``{"na": tuple, "nb": [tuple per input], "nk": [tuple per input]}``.
    settings : dict
        The other arguments of :func:`sweep` (what :meth:`extend` re-runs with).
    sort_by : str
    first_lag : int
        The grid's largest lag: every structure uses rows from here on.
    row_orders : tuple (na, nb, nk)
        Orders (per effect-layout column) of the grid's envelope, the largest regressor: rows where
        it touches a NaN are left out for every structure.
    n_est, n_val : int
        Regression rows of estimation and validation data.
    stage : ndarray of shape (S,)
        Which stage ranked each row: 2 = fitted by QR and simulated, 1 = ranked by its one-step
        error only (two-stage sweeps of grids larger than ``top``; its simulation columns are NaN).
    estimation_factor : ndarray of shape (q, q) or None
        Upper-triangular factor R of the envelope's regressor ``[Φ | y]`` on the estimation rows:
        every structure's parameters and their covariance follow from it without the data.
    seconds : float
        Wall time of the sweep that made this result (NaN when unknown).
    growth : GridGrowth or None
        After :meth:`extend`: every grid tried, and why growing stopped (None before).
    """

    seconds: float = field(default=math.nan, repr=False)
    growth: GridGrowth | None = field(default=None, repr=False)

    # The columns and their reading are the table's (:class:`~arxid.selection.table.SweepTable`); a
    # result adds the choice of a structure and the sweep of a grown grid, which re-runs :func:`sweep`.

    def select(self, sane: bool = True, rule: str = "lowest") -> Selection:
        """The best-ranked usable structure; with ``sane``, the best one whose step sanity passes.

        Parameters
        ----------
        sane : bool
            Also skip structures whose step sanity checks fail (which include stability for a
            plant that is not integrating, and a free run that diverged); without it, only
            structures that were not fitted or have no finite ranking error are skipped (and, for
            a free-run criterion, those whose simulation diverged).
        rule : {"lowest", "smallest-within-noise"}
            ``"lowest"``: the best-ranked one. ``"smallest-within-noise"``: then the structure with
            the fewest parameters (that also qualifies) whose validation error is not
            significantly worse than that one's (Diebold–Mariano test, :mod:`arxid.parsimony`).

        Returns
        -------
        Selection
            The chosen rank and structure, and the better-ranked structures skipped for failed checks.

        Raises
        ------
        ArxidError
            When no structure qualifies (the message lists why the best ones were rejected).
        """
        return choice.select(self, sane, rule)

    def best(self, sane: bool = False, *, rule: str = "lowest", explain: bool = True) -> ArxModel:
        """The best-ranked structure as a fitted :class:`~arxid.ArxModel`.

        Parameters
        ----------
        sane : bool
            Skip structures flagged by the step sanity checks (see :mod:`arxid.sanity`).
        rule : {"lowest", "smallest-within-noise"}
            See :meth:`select`. For control design prefer ``"smallest-within-noise"`` when the
            top of the ranking is flat: the fewest parameters whose validation error the data
            cannot tell from the best's give a controller fewer states and a model less fitted to
            noise. ``"lowest"`` is the default: it is MATLAB's ``selstruc`` pick, and parsimony
            trades structure for parameters without regard to what a controller needs most, the
            delay (on the simulated quadrotor roll axis it gives ARX(3,1,9) for ARX(3,2,8), one
            coefficient fewer and one sample more dead time than the plant has).
        explain : bool
            With ``sane``, warn (:class:`~arxid.ArxidWarning`) which better-ranked structures were
            skipped and why.
            The same is in the model's attribute ``selection_`` (a :class:`Selection`).

        Returns
        -------
        ArxModel
            The chosen structure, fitted on the sweep's rows, with ``selection_`` set.

        Raises
        ------
        ArxidError
            When no structure qualifies (see :meth:`select`).
        """
        sel = self.select(sane, rule)
        if sane and explain and sel.skipped:
            warnings.warn(f"arxid.sweep best(sane=True): {sel}", ArxidWarning, stacklevel=2)
        model = self.model(sel.rank)
        model.selection_ = sel
        return model

    def grid_edge_text(self, i: int) -> str:
        """One sentence when ranked structure ``i`` sits on a grid edge, with the ranges to try, or
        (after :meth:`extend` found that a larger grid did not pay) what the larger grid gave; else "".

        Parameters
        ----------
        i : int
            Rank of the structure.

        Returns
        -------
        str
        """
        edges = self.grid_edges(i)
        if edges and self.growth is not None and self.growth.stop in ("no-gain", "integrates", "insane"):
            return self.growth.edge_note(self.structure_name(i), "; ".join(str(e) for e in edges))
        return super().grid_edge_text(i)

    def extend(
        self,
        max_rounds: int | None = None,
        limit: int = GROWTH_ORDER_LIMIT,
        sane: bool = True,
        *,
        max_seconds: float | None = DEFAULT_GROWTH_SECONDS,
        min_gain: float = MIN_GROWTH_GAIN,
        sweeper: Callable[..., SweepResult] | None = None,
    ) -> SweepResult:
        """Grow the grid past the edges the chosen structure sits on, while it sits on one and improves.

        Each round re-runs :func:`sweep` with the same data and settings on the grid whose edge
        ranges are grown by ``max(2, ⌈len/2⌉)`` values, poles and zeros together (an edge on na or
        nb grows both; :func:`arxid.selection.grid_edges.grown_grid`). The re-runs keep this
        sweep's measure (free run, or k-step with its k) and integrator verdict, so the grids
        compare like with like. Growing stops when the
        choice lies inside the grid, when a growth lowered its validation error by less than
        ``min_gain``, at the order ``limit``, after ``max_rounds``, or before a sweep that would
        take the search past ``max_seconds`` (predicted from the measured time of the last sweep);
        see :mod:`arxid.selection.growth`.

        Parameters
        ----------
        max_rounds : int or None
            Largest number of re-runs (None: no limit, the other rules stop it; 0: none).
        limit : int
            Largest na, nb or nk tried (default 30).
        sane : bool
            Judge the choice as :meth:`select` with ``sane`` does.
        max_seconds : float or None
            Time budget of the whole search in seconds, this sweep included (default 30; None: none).
        min_gain : float
            Smallest relative fall of the choice's validation error for which growing goes on
            (default 0.01, 1 %).
        sweeper : callable, optional
            Sweeps a grid (``na=, nb=, nk=`` and the settings): a fleet's sweep on its cluster
            (default: :func:`sweep` of this result's estimation data).

        Returns
        -------
        SweepResult
            The last sweep (this one when the choice is already inside the grid), with ``growth``
            set: every grid tried, its size, time and best structure, and why growing stopped.
        """

        # Like with like: the larger grids keep this sweep's measure and integrator verdict (a
        # verdict re-made on a larger grid could switch free run to k-step, or change k, between
        # rounds). The re-runs declare it and the results carry this sweep's reasons.
        settings = dict(self.settings)
        if self.expect is None:
            settings["expect"] = "integrating" if self.integrating else "stable"
            settings["horizon"] = self.horizon if self.horizon is not None else settings.get("horizon")

        def rerun(grid: dict) -> SweepResult:
            again = sweeper or functools.partial(sweep, self.estimation)
            res = again(na=grid["na"], nb=grid["nb"], nk=grid["nk"], **settings)
            return dataclasses.replace(
                res,
                expect=self.expect,
                integrating_reason=self.integrating_reason,
                integrator=self.integrator,
                settings=self.settings,
            )

        res, growth = grow(
            self,
            rerun,
            first_seconds=self.seconds,
            max_rounds=max_rounds,
            limit=limit,
            sane=sane,
            max_seconds=max_seconds,
            min_gain=min_gain,
        )
        return dataclasses.replace(cast(SweepResult, res), growth=growth)


def _parameters_and_covariance(result: SweepResult, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Parameters and covariance of ranked structure ``i``: from the sweep's estimation factor
    (microseconds), or by refitting where there is none or effect columns change the layout."""
    if result.estimation_factor is None or result.effects or result.settings.get("method") == "iv":
        m = result.model(i)
        return m.parameters_, m.covariance_
    orders = (int(result.na[i]), [int(v) for v in result.nb[i]], [int(v) for v in result.nk[i]])
    na_env, nb_env, nk_env = result.row_orders
    envelope = (int(na_env), list(nb_env), list(nk_env))
    fit = _core.fit_from_factor(result.estimation_factor, result.n_est, envelope, orders, [])
    return np.asarray(fit.theta), metrics.parameter_covariance(fit.inv_gram, fit.rss, fit.n_rows)


def _integrator_verdict(result: SweepResult) -> IntegratorTest:
    """Unit-root test (:mod:`arxid.selection.integrator`) of the best structures by FPE of a sweep,
    with the settling evidence of its best free-run structures when it ran in free run."""
    fpe = np.where(np.isfinite(result.fpe), result.fpe, np.inf)
    names: list[str] = []
    t_values: list[float] = []
    taus: list[float] = []
    # The voters are among the first few by FPE unless many of those have no poles or failed.
    candidates = first_in_order(fpe, 16 * VOTERS)
    usable = sum(result.errors[i] is None and result.na[i] > 0 for i in candidates)
    if usable < VOTERS and candidates.size < fpe.size:
        candidates = np.argsort(fpe, kind="stable")
    for i in candidates:
        if len(names) == VOTERS or not np.isfinite(fpe[i]):
            break
        if result.errors[i] is not None or result.na[i] == 0:
            continue
        theta, covariance = _parameters_and_covariance(result, int(i))
        names.append(result.structure_name(int(i)))
        t_values.append(unit_root_t(theta, covariance, int(result.na[i])))
        taus.append(slowest_time_constant(theta, int(result.na[i])))
    return integrator_test(names, t_values, taus, result.n_est, _settling_evidence(result))


def _settling_evidence(result: SweepResult) -> SettlingEvidence | None:
    """The best structures by free-run validation error of a free-run sweep: their slowest
    time constants and free-run fits (None for a k-step sweep or without validation errors)."""
    if result.horizon is not None:
        return None
    score = np.where(np.isfinite(result.rms_val) & np.isfinite(result.fit_val), result.rms_val, np.inf)
    best = [int(i) for i in first_in_order(score, VOTERS)[:VOTERS] if np.isfinite(score[i])]
    if not best:
        return None
    taus = [
        float("inf") if pole >= 1.0 else slowest_time_constant(result.parameters[i], int(result.na[i]))
        for i, pole in zip(best, result.max_pole_of(best))
    ]
    return SettlingEvidence(
        tuple(result.structure_name(i) for i in best),
        tuple(taus),
        tuple(float(result.fit_val[i]) for i in best),
        result.n_est,
    )


def _with_verdict(result: SweepResult, verdict: IntegratorTest) -> SweepResult:
    return dataclasses.replace(
        result, integrating=verdict.integrating, integrating_reason=verdict.reason, integrator=verdict
    )


def _has_sane(result: SweepResult) -> bool:
    """Some structure of the sweep passes the step sanity checks."""
    try:
        result.select(sane=True)
    except ArxidError:
        return False
    return True


def _detected(first: SweepResult, rerun: Callable[[IntegratorTest], SweepResult], revise: bool = True) -> SweepResult:
    """The free-run sweep ``first`` under the detected verdict, redone with k steps (``rerun``)
    for an integrating plant. A verdict under which no structure is sane is revised when the other
    verdict has one: the choice is never left empty by a borderline test (the reason says so).
    Without ``revise`` (a fleet on a cluster, whose samples the client does not read) it stands."""
    verdict = _integrator_verdict(first)
    if not revise:
        return rerun(verdict) if verdict.integrating else _with_verdict(first, verdict)
    if not verdict.integrating:
        stable = _with_verdict(first, verdict)
        if _has_sane(stable):
            return stable
        integ = rerun(verdict.revised(True, "as a stable plant no structure's step response passes the sanity checks"))
        return integ if _has_sane(integ) else stable
    integ = rerun(verdict)
    if _has_sane(integ):
        return integ
    stable = _with_verdict(
        first, verdict.revised(False, "as an integrating plant no structure's step response passes the sanity checks")
    )
    return stable if _has_sane(stable) else integ


@overload
def sweep(
    data: IOData,
    na=...,
    nb=...,
    nk=...,
    *,
    validation=...,
    sort_by: str = ...,
    n_threads: int = ...,
    progress: bool = ...,
    effects: Sequence[str] = ...,
    expect: str | None = ...,
    horizon: int | None = ...,
    max_memory: int | None = ...,
    limits: SanityLimits | None = ...,
    simulate_estimation: bool = ...,
    auto_extend: bool | None = ...,
    growth_seconds: float | None = ...,
    refine: None = None,
    refine_top: int = ...,
    top: int | None = ...,
    max_seconds: float | None = ...,
    client: Any = ...,
    per_experiment: bool = ...,
    read: Any = ...,
    method: str = ...,
    instruments: str | Sequence[str] | None = ...,
) -> SweepResult: ...


@overload
def sweep(
    data: IOData,
    na=...,
    nb=...,
    nk=...,
    *,
    validation=...,
    sort_by: str = ...,
    n_threads: int = ...,
    progress: bool = ...,
    effects: Sequence[str] = ...,
    expect: str | None = ...,
    horizon: int | None = ...,
    max_memory: int | None = ...,
    limits: SanityLimits | None = ...,
    simulate_estimation: bool = ...,
    auto_extend: bool | None = ...,
    growth_seconds: float | None = ...,
    refine: Literal["oe"],
    refine_top: int = ...,
    top: int | None = ...,
    max_seconds: float | None = ...,
    client: Any = ...,
    per_experiment: bool = ...,
    read: Any = ...,
    method: str = ...,
    instruments: str | Sequence[str] | None = ...,
) -> RefinedSweep: ...


def sweep(
    data: IOData,
    na=None,
    nb=None,
    nk=None,
    *,
    validation=None,
    sort_by: str = "val_sim",
    n_threads: int = 0,
    progress: bool = True,
    effects: Sequence[str] = (),
    expect: str | None = None,
    horizon: int | None = None,
    max_memory: int | None = None,
    limits: SanityLimits | None = None,
    simulate_estimation: bool = True,
    auto_extend: bool | None = None,
    growth_seconds: float | None = DEFAULT_GROWTH_SECONDS,
    refine: Literal["oe"] | None = None,
    refine_top: int = 5,
    top: int | None = stages.DEFAULT_TOP,
    max_seconds: float | None = 3600.0,
    client: Any = None,
    per_experiment: bool = False,
    read: Any = None,
    method: str = "arx",
    instruments: str | Sequence[str] | None = None,
) -> Any:
    """Fit and validate every ARX structure of a grid (MATLAB ``arxstruc`` / ``selstruc``, faster).

    Parameters
    ----------
    data : IOData
        Estimation data.
    na : int or iterable of int
        Numbers of poles to try (default ``DEFAULT_GRID["na"]``).
    nb, nk : int, iterable of int, or list of iterables (one per input)
        Input orders and delays to try (default ``DEFAULT_GRID``). One iterable is shared by every
        input (each input still ranges over it independently); the grid is the cartesian product of
        all ranges.
    validation : None, IOData or float
        Validation data, or the fraction of ``data`` (its end) to hold out. None validates on the
        estimation data only (``sort_by="val_sim"`` then ranks by estimation error).
    sort_by : {"val_sim", "val_one_step", "est_sim", "est_one_step", "fpe", "aic", "bic"}
        Ranking measure. ``*_sim`` is the free-run RMS (the k-step RMS for integrating plants).
    n_threads : int
        Threads (0 = all cores). Results are identical for any number of threads.
    progress : bool
        Show a tqdm progress bar (only when stderr is a terminal).
    effects : sequence of str
        Effect terms added to every structure; input-derived terms take the orders of their input.
    expect : {None, "stable", "integrating", "double-integrating"}
        What the physics says. Integrating expectations rank by k-step prediction error; None
        detects integrators (a pole at 1 in most of the 5 best structures by FPE).
    horizon : int, optional
        Rank by the k-step-ahead prediction error with this k instead of free run. Integrating
        plants use k-step prediction anyway, by default with ``k = max(10, 2 × largest lag)``.
    max_memory : int, optional
        Refuse grids needing more bytes than this (default: half the available memory).
    limits : SanityLimits, optional
        Thresholds of the step sanity checks.
    simulate_estimation : bool
        Also simulate every structure on the estimation data (``rms_est``).
    auto_extend : bool or None
        Grow the grid past the edge the best sane structure sits on and sweep again, while it does
        and improves (:meth:`SweepResult.extend`; ``growth`` of the result says what was tried).
        None (default): the default grid grows (no ``na``, ``nb``, ``nk`` given; a list of logs where
        they are), a given grid is swept as it is: the rule of ``arxid sweep`` and :func:`arxid.analyse`.
    growth_seconds : float or None
        Time budget of the growing search in seconds, first sweep included (``--max-seconds``).
    refine : {None, "oe"}
        ``"oe"`` refits the ``refine_top`` best ARX structures (and a small grid of nb, nf, nk) as
        output-error models and ranks all of them by validation free-run error
        (:func:`arxid.refine`); the table says which model class each row is.
    refine_top : int
        Number of best ARX structures refined when ``refine`` is given.

    top : int or None
        Grids larger than this run in two stages (see :mod:`arxid.stages`): every structure is
        ranked by its one-step validation error (MATLAB ``arxstruc``), and only the best ``top`` are
        fitted again and simulated; ``stage`` says which rows. None simulates every structure.
    max_seconds : float or None
        Refuse grids whose estimated run time exceeds this many seconds, before anything is
        allocated (None: no limit).
    client : dask.distributed.Client, optional
        With a list of logs as ``data``: run on this Dask cluster, where the workers read the logs
        (see :mod:`arxid.fleet_sweep`). The client reads none during the sweep; the result's
        ``estimation`` and ``validation`` are read on the client when first needed
        (:class:`arxid.cluster.LogsOnDemand`). Effects are computed by the workers, within each log.
    per_experiment : bool
        With a list of logs: sweep each log separately and return a :class:`arxid.fleet.FleetSweep`.
    read : dict or callable, optional
        With file paths in ``data``: how to read them (see :func:`arxid.fleet.load_experiment`).
    method : {"arx", "iv"}
        ``"arx"``: least squares. ``"iv"``: instrumental variables (:func:`arxid.iv`, first IV
        step, instruments common to the grid), consistent with coloured noise and, with
        ``instruments``, in closed loop; no effects, refinement or lists of logs.
    instruments : None, str or sequence of str
        With ``method="iv"``: the measured reference signal(s) of a closed loop (None: open loop,
        instruments from the input).

    Returns
    -------
    SweepResult
        For a list of logs, the sweep of all of them at once (a :class:`arxid.fleet.FleetSweep`
        with ``per_experiment=True``); a RefinedSweep when ``refine`` is given.

    Notes
    -----
    Every structure uses the regression rows from the grid's largest lag on (as ``arxstruc``), and
    its free-run simulation starts there from measured outputs, so all errors compare on the same
    samples. The Rust core reduces ``[Φ_max | y]`` once to a triangular R by Householder QR and
    solves each structure from its columns of R; the simulation of linear structures runs several
    structures of neighbouring ``na`` side by side in SIMD lanes. A simulation that leaves
    ±``DIVERGENCE_FACTOR`` (1000) times the largest measured output of its data set is stopped and
    reported as diverged (the one divergence rule, see :mod:`arxid._metrics`).

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(3000)
    >>> y = np.zeros(3000)
    >>> for t in range(3, 3000):
    ...     y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 3] + 0.01 * rng.standard_normal()
    >>> res = arxid.sweep(arxid.IOData(y, u, ts=0.01), na=range(1, 4), nb=range(1, 3), nk=range(0, 5),
    ...                   validation=0.3, sort_by="bic", progress=False)
    >>> res.structure_name(0)
    'ARX(2,1,3)'
    """
    started = time.perf_counter()
    growing = grows(auto_extend, na is None and nb is None and nk is None)
    na, nb, nk = (DEFAULT_GRID[k] if v is None else v for k, v in (("na", na), ("nb", nb), ("nk", nk)))
    workers: Any = None  # a fleet's logs on a Dask cluster
    sweeper: Callable[..., SweepResult] | None = None  # how to sweep a fleet's logs again
    if isinstance(data, (list, tuple)):
        from ..fleet import logs as fleet  # here: a sweep of one record does not load arxid.fleet

        options = dict(na=na, nb=nb, nk=nk, sort_by=sort_by, n_threads=n_threads, progress=progress, effects=effects)
        options.update(expect=expect, horizon=horizon, max_memory=max_memory, limits=limits, top=top)
        options.update(simulate_estimation=simulate_estimation, max_seconds=max_seconds, auto_extend=growing)
        fraction = fleet.check_validation(validation)
        if per_experiment:
            return fleet.sweep_each(data, client, read, fraction, sweep, options | {"growth_seconds": growth_seconds})
        if client is not None:  # a larger grid is swept where the logs are too (in process: the merged logs)
            sweeper = functools.partial(fleet.sweep_again, sweep, list(data), client, read, fraction)
        workers, (data, validation) = fleet_parts(client, data, read, fraction)
    if not isinstance(data, IOData):
        raise DataError(
            f"sweep needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
        )
    horizon, n_threads = _checked_settings(sort_by, expect, refine, horizon, n_threads)
    est, val = validation_split(data, validation)
    m = est.n_inputs
    nas, nbs, nks = order_range("na", na), per_input_ranges("nb", nb, m), per_input_ranges("nk", nk, m)
    if workers is None:  # a fleet on a cluster: the logs stay on the workers
        check_excitation(est, [max(r) for r in nbs], remedy="leave it out of the inputs")
    effects = tuple(effects)
    top = check_top(top)
    n_structures, p_max, q = check_grid_size(est, val, nas, nbs, nks, effects, int(n_threads), max_memory)
    n_val = val.n_samples if val is not None else 0
    n_sim = n_val + (est.n_samples if simulate_estimation else 0)
    seconds = stages.estimated_seconds(n_structures, top, p_max, q, est.n_samples + n_val, n_sim, int(n_threads))
    stages.check_time_budget(n_structures, top, seconds, max_seconds)
    g = Grid.build(est, nas, nbs, nks, effects)
    # A fleet on a cluster: the workers hold the samples and compute the effect columns, the client none.
    if workers is None:
        inputs, engine = core_inputs(est, val, g, effects), None
        terms = inputs.terms
    else:
        inputs, engine = None, fleet_engine(workers, est, g, effects)
        terms = engine.terms
    first_lag, _ = _core.grid_envelope(g.layout, terms)
    check_validation_length(val, first_lag)
    least_squares = Runner(est, val, g, inputs, int(n_threads), progress, simulate_estimation, top, engine)
    run = least_squares if method == "arx" else IvRunner.of(least_squares, method, instruments, refine)
    # Integrating plants: an expectation decides the measure up front; otherwise the free-run sweep
    # runs first and, when the unit-root test calls the plant integrating, is redone with k steps.
    integrating = expect in ("integrating", "double-integrating")
    reason = f"expect={expect!r}: declared" + (" integrating" if integrating else " (not tested)")
    k_default = int(horizon) if horizon is not None else max(10, 2 * first_lag)
    k_step = k_default if integrating else (int(horizon) if horizon is not None else None)
    grid = {"na": nas, "nb": nbs, "nk": nks}
    settings: dict[str, Any] = dict(validation=val, sort_by=sort_by, n_threads=n_threads, progress=progress)
    settings.update(effects=effects, expect=expect, horizon=horizon, max_memory=max_memory, limits=limits)
    settings.update(simulate_estimation=simulate_estimation, top=top, max_seconds=max_seconds)
    settings.update(iv_settings(method, instruments))
    build = _ResultBuilder(g, terms, est, val, sort_by, effects, expect, limits or SanityLimits(), m, grid, settings)
    result = build(run(k_step), k_step, integrating, reason)
    if expect is None and k_step is None:

        def rerun(verdict: IntegratorTest) -> SweepResult:
            return build(run(k_default), k_default, verdict.integrating, verdict.reason, verdict)

        result = _detected(result, rerun, revise=workers is None)
    elif expect is None:  # the user's horizon fixes the measure; the verdict is stated
        result = _with_verdict(result, _integrator_verdict(result))
    result = dataclasses.replace(result, seconds=time.perf_counter() - started)
    if growing:
        result = result.extend(max_seconds=growth_seconds, sweeper=sweeper)
    if refine is None:
        return result
    from .refine import refine as refine_sweep

    return refine_sweep(result, refine, top=refine_top)


def _checked_settings(sort_by: str, expect: Any, refine: Any, horizon: Any, n_threads: Any) -> tuple[int | None, int]:
    """The horizon and thread count as integers, after a typed error for any setting out of its range."""
    if sort_by not in SORT_KEYS:
        raise ArxidError(f"sort_by must be one of {SORT_KEYS}, got {sort_by!r}")
    if expect not in EXPECTATIONS:
        raise ArxidError(f"expect must be one of {EXPECTATIONS}, got {expect!r}")
    if refine not in (None, "oe"):
        raise ArxidError(f"refine must be None or 'oe' (output-error refinement), got {refine!r}")
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, numbers.Integral) or horizon < 1):
        raise OrderError(f"horizon must be an integer >= 1, got {horizon!r}")
    if isinstance(n_threads, bool) or not isinstance(n_threads, numbers.Integral) or n_threads < 0:
        raise OrderError(f"n_threads must be an integer >= 0 (0 = all cores), got {n_threads!r}")
    return (None if horizon is None else check_order("horizon", horizon)), check_order("n_threads", n_threads)


@record
class _ResultBuilder:
    """Everything but the core's output a :class:`SweepResult` needs."""

    g: Grid
    terms: list
    est: IOData
    val: IOData | None
    sort_by: str
    effects: tuple[str, ...]
    expect: str | None
    limits: SanityLimits
    m: int
    grid: dict
    settings: dict

    def __call__(
        self,
        res: _core.SweepOutput,
        k_step: int | None,
        integrating: bool,
        reason: str,
        verdict: IntegratorTest | None = None,
    ) -> SweepResult:
        return SweepResult(
            **ranked_columns(res, self.g, len(self.terms), self.val, self.sort_by, self.m),
            horizon=k_step,
            integrating=integrating,
            integrating_reason=reason,
            effects=self.effects,
            expect=self.expect,
            limits=self.limits,
            estimation=self.est,
            validation=self.val,
            integrator=verdict,
            grid=self.grid,
            settings=self.settings,
        )
