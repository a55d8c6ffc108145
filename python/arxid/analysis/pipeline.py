"""The one analysis pipeline: sweep, choose, compare, test, locate, diagnose, climb the ladder.

:func:`analyse` runs every stage once and returns a frozen :class:`Analysis` that holds the result
objects themselves (the :class:`~arxid.SweepResult`, the chosen :class:`~arxid.ArxModel`, the
:class:`~arxid.validation.Comparison`, :class:`~arxid.validation.ResidualAnalysis`,
:class:`~arxid.validation.FailureAnalysis`, :class:`~arxid.Diagnosis` and :class:`~arxid.Ladder`).
``arxid diagnose``, ``arxid report``, ``arxid demo`` and :func:`arxid.report.render_html` all render
this object and compute nothing of their own, so every number they show is the API's.

Examples
--------
>>> import numpy as np, arxid
>>> rng = np.random.default_rng(0)
>>> u = rng.uniform(0.5, 1.5, 3000)
>>> y = np.zeros(3000)
>>> for t in range(1, 3000):
...     y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 1] ** 2 + 0.01 * rng.standard_normal()
>>> a = arxid.analyse(arxid.IOData(y, u, ts=0.01), grid={"na": [1, 2], "nb": [1], "nk": [0, 1]}, max_steps=1)
>>> a.model.structure_name(), a.ladder.steps[-1].added
('ARX(2,1,1)', 'through(u1^2.005)')
"""

from __future__ import annotations

import importlib
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from functools import cached_property, partial
from typing import TYPE_CHECKING, Any

from .._base.array_memory import kept_blocks
from .._base.background import Background, in_two, one_blas_thread
from .._base.formatting import format_value, horizon_label
from .._base.heap import map_large_arrays
from .._base.records import record
from ..checks import Comparison, FailureAnalysis, ResidualAnalysis, compare, where_it_fails
from ..checks.bands import ResponseBand, free_run_band
from ..checks.feedback import FeedbackTest
from ..checks.frequency import FrequencyCheck, frequency_check
from ..data.iodata import IOData
from ..diagnosis.ladder import Ladder
from ..exceptions import ArxidError, OrderError
from ..models.arguments import check_data, check_horizon
from ..models.arx_model import ArxModel, arx
from ..models.polynomial import PolynomialModel, check_initial
from ..models.wiener import added_effects, linear_part
from ..selection.growth import DEFAULT_GROWTH_SECONDS, GridGrowth, grid_text
from ..selection.search import SweepResult, sweep
from .choice import Choice, OrderGrid, choose, given_model, grid_lists, grid_of
from .closed_loop import (
    GIVEN_ORDERS,
    OPEN_LOOP,
    WEAK_EVIDENCE,
    ClosedLoopMethod,
    beyond_the_sample,
    feedback_check,
    feedback_notes,
    loop_signal_names,
    reference_candidates,
    reference_names,
    still_references,
)
from .conclusion import Conclusion, concluded
from .verdicts import delay_notes, ladder_headline, negative_fit_note, residual_sentences

if TYPE_CHECKING:
    from ..frequency_domain import FrequencyResponse
    from .loop_structure import LoopStructure

__all__ = ["Analysis", "Choice", "OrderGrid", "analyse", "choose", "grid_of", "DEFAULT_SPLIT"]

#: Share of the data used for estimation when no separate validation data are given (the rest validates).
DEFAULT_SPLIT = 0.7


@record(eq=False, kw_only=True)
class Analysis(Conclusion):
    """Everything arxid concludes about one data set, as result objects.

    Attributes
    ----------
    estimation, validation : IOData
        The data the models were fitted on and judged on.
    grid : dict of str to tuple of int, or None
        The order grid asked for (None when the orders or the model were given); the grids swept
        when it was grown are in ``grid_growth``.
    sweep : SweepResult or None
        Every structure of the last grid swept, ranked (None when the orders or the model were given).
    choice : Choice
        Which structure was chosen and why.
    model : ArxModel or PolynomialModel
        The chosen structure (or the given model), without added effects.
    horizon : int or None
        The validation error measure of every number below: None = free-run simulation, k =
        k-step-ahead prediction (integrating plants, or a chosen model whose free run diverges).
    diagnosis : Diagnosis
        Suspects for the chosen model's error; holds the residual tests.
    ladder : Ladder
        The models as the significant suspects are added, with their validation errors.
    comparison : Comparison
        Measured output against the chosen model and (when effects were added) the final model.
    failures : tuple of FailureAnalysis
        Where each model of ``comparison`` fails, in the same order.
    timings : dict of str to float
        Seconds spent in each stage: ``sweep``, ``diagnose`` (the ladder), ``checks and
        frequency`` (the two run side by side; the feedback test runs beside all of them).
    notes : tuple of str
        What the reader should know (the measure switched to k-step, ...).
    frequency : tuple of FrequencyCheck
        Where each model of ``comparison`` misses the data in frequency (empty when the validation
        data are too short for a spectrum).
    bands : tuple of ResponseBand
        Free-run simulation of each model of ``comparison`` on the validation data with its 99 %
        band from the parameter covariance (empty for a k-step measure).
    initial : {"zero", "estimate"}
        Initial conditions of every validation error (see :func:`arxid.compare`).
    feedback : FeedbackTest or None
        The feedback test of the estimation data (:func:`arxid.feedback`; None when too short);
        its meaning for the model is in ``notes``.
    closed_loop : ClosedLoopMethod or None
        How the plant was identified given that verdict (open loop, IV with the reference, or the
        direct method), why, and the validation criterion; None when the model was given. In
        closed loop ``estimation`` and ``validation`` are the data the analysis read: without the
        operating point, and with a reference the validation inputs replaced by their
        reference-driven parts.
    """

    estimation: IOData
    validation: IOData
    comparison: Comparison
    failures: tuple[FailureAnalysis, ...]
    frequency: tuple[FrequencyCheck, ...] = ()
    bands: tuple[ResponseBand, ...] = ()
    initial: str = "zero"
    feedback: FeedbackTest | None = None
    closed_loop: ClosedLoopMethod | None = None

    @cached_property
    def bode(self) -> FrequencyResponse | None:
        """The plant's frequency response measured on the validation data (:func:`arxid.frf`), for
        the Bode view: from the reference in closed loop (S_ry / S_ru), else H1 = S_uy / S_uu.

        Computed when first asked for (the report asks); None when it cannot be estimated (data
        too short, or several inputs without a reference each).
        """
        from ..frequency_domain import frf  # the report's view: the command line never asks

        refs = list(self.closed_loop.references) if self.closed_loop is not None else []
        try:
            return frf(self.validation, reference=refs or None)
        except ArxidError:
            return None

    @cached_property
    def bode_misses(self) -> tuple[tuple[float, float], ...]:
        """Frequency bands [Hz] where the final model's response leaves the band of :attr:`bode`
        while the coherence is at least 0.5 (empty without a Bode view)."""
        from ..frequency_domain import model_response
        from ..plots.bode import miss_bands

        fr = self.bode
        return () if fr is None else miss_bands(fr, model_response(linear_part(self.final_model), fr.frequency))

    @cached_property
    def input_shapes(self) -> tuple:
        """Each shape the final model feeds an input through, with the input's static map
        (:func:`arxid.diagnosis.static_map.shape_maps`) for the report's plot."""
        from ..diagnosis.static_map import shape_maps

        return shape_maps(linear_part(self.final_model), self.estimation)

    @property
    def grid_text(self) -> str:
        """The order ranges of the last grid swept as text, e.g. ``na 1..4, nb 1..3, nk 0..5`` (empty
        when orders were given)."""
        if self.grid is None:
            return ""
        if self.sweep is not None and self.sweep.grid:
            return grid_text(self.sweep.grid)
        return ", ".join(f"{k} {min(v)}..{max(v)}" for k, v in grid_lists(self.grid).items())

    @property
    def grid_growth(self) -> GridGrowth | None:
        """Every grid swept (the first, then each grown one), and why growing stopped (None
        without a sweep)."""
        return None if self.sweep is None else self.sweep.growth

    @property
    def residual_tests(self) -> ResidualAnalysis | None:
        """Residual tests of the chosen model on the validation data (those of the diagnosis)."""
        return self.diagnosis.residual_tests

    @property
    def error_fall(self) -> float | None:
        """Relative fall of the validation error from the first to the last ladder step (0..1)."""
        errors = self.ladder.errors
        if len(errors) < 2 or not (math.isfinite(errors[0]) and errors[0] > 0 and math.isfinite(errors[-1])):
            return None
        return float(1.0 - errors[-1] / errors[0])

    def to_dict(self) -> dict:
        """The machine-readable result (the ``arxid diagnose --json`` and ``report --json`` contract).

        Keys ``model``, ``baseline``, ``residual_tests``, ``suspects`` and ``ladder`` as
        :meth:`Diagnosis.to_dict`; ``choice``, ``grid``, ``grid_growth`` (every grid swept, see
        :meth:`arxid.selection.growth.GridGrowth.to_dict`), ``sweep`` (summary and best rows),
        ``comparison``, ``where_it_fails`` (one per compared model), ``notes``,
        ``frequency_check`` (one per compared model, see :meth:`FrequencyCheck.to_dict`) and
        ``error_fall`` (see :meth:`Ladder.error_fall`).

        Returns
        -------
        dict
        """
        import json

        from ..diagnosis.static_map import shape_map_dict

        out = super().to_dict()
        out.update(
            {
                "grid_growth": None if self.grid_growth is None else self.grid_growth.to_dict(),
                "sweep": None if self.sweep is None else self.sweep.summary(),
                "comparison": self.comparison.to_dict(),
                "where_it_fails": [f.to_dict() for f in self.failures],
                "frequency_check": [{"model": f.model_name, **f.to_dict()} for f in self.frequency],
                "feedback": None if self.feedback is None else json.loads(self.feedback.to_json()),
                "closed_loop": None if self.closed_loop is None else self.closed_loop.to_dict(),
                "input_shapes": [shape_map_dict(*pair) for pair in self.input_shapes],
            }
        )
        return out

    def _head_lines(self) -> list[str]:
        """Model, choice, validation, notes, residual tests and frequency checks."""
        d = self.diagnosis
        lines = [f"model: {self.model.structure_name()} ({self.choice.reason})"]
        lines += [f"  skipped {s}: {w}" for s, w in self.choice.skipped[:3]]
        if self.choice.grid_edge:
            lines.append(f"  {self.choice.grid_edge}")
        if self.grid_growth is not None and (self.grid_growth.grew or self.grid_growth.stop != "inside"):
            lines += [f"  {line}" for line in self.grid_growth.lines()]
        lines.append(self._validation_line())
        if negative_fit_note(d.fit_val):
            lines.append(f"  ({negative_fit_note(d.fit_val)})")
        lines += self.notes
        if self.residual_tests is not None:
            lines += ["", "residual tests:"] + [f"  {t}" for t in residual_sentences(self.residual_tests, d)]
            lines += ["", "details:", str(self.residual_tests)]
        lines += ["", *[f"frequency check of {f.model_name}: {f.summary}" for f in self.frequency]]
        return lines

    def short_summary(self) -> list[str]:
        """Three lines for ``arxid report``: the model and its fit, what the ladder removed, and
        where the final model still misses the data in frequency.

        Returns
        -------
        list of str
        """
        d = self.diagnosis
        fit = f"validation fit {format_value(d.fit_val, 3)} % ({horizon_label(self.horizon)})"
        if negative_fit_note(d.fit_val):
            fit += ", worse than the output's mean"
        missing = f"missing effect: {self.missing_effect}" if self.missing_effect else "no significant missing effect"
        ladder = ladder_headline(self.ladder) or "Nothing was added: the first model is the final one."
        freq = (
            f"Final model {self.frequency[-1].model_name}: {self.frequency[-1].summary}."
            if self.frequency
            else "No frequency check (the validation data are too short)."
        )
        return [f"Model {self.model.structure_name()}: {fit}; {missing}.", ladder, freq]


# ----------------------------------------------------------------------------------------- stages
def _split(data: IOData, validation: IOData | float | None, split: float) -> tuple[IOData, IOData]:
    data = check_data(data)
    if isinstance(validation, (int, float)) and not isinstance(validation, bool):
        raise ArxidError(
            f"validation must be an IOData record, got the number {validation!r}; to split one record into "
            f"estimation and validation parts, pass split={validation!r} (the estimation fraction) instead"
        )
    if validation is not None:
        return data, check_data(validation, "validation")
    if isinstance(split, bool) or not isinstance(split, (int, float)) or not 0 < split < 1:
        raise ArxidError(f"split must be the estimation fraction between 0 and 1, e.g. {DEFAULT_SPLIT}, got {split!r}")
    return data.split(float(split))


def _structure(
    est: IOData,
    val: IOData,
    orders: Sequence | None,
    grid: Mapping | None,
    horizon: int | None,
    expect: str | None,
    progress: bool,
    given: ArxModel | PolynomialModel | str | None = None,
    grow: bool | None = None,
    max_seconds: float | None = DEFAULT_GROWTH_SECONDS,
) -> tuple[SweepResult | None, ArxModel, Choice, OrderGrid | None]:
    if given is not None:
        model, choice = given_model(est, given, orders, grid)
        return None, model, choice, None
    options: dict[str, Any] = dict(horizon=horizon, expect=expect, progress=progress, growth_seconds=max_seconds)
    options.update(auto_extend=grow)
    return chosen_structure(orders, grid, partial(arx, est), partial(sweep, est, validation=val), options)


def chosen_structure(
    orders: Sequence | None,
    grid: Mapping | None,
    fit: Callable[[Any, Any, Any], ArxModel],
    swept: Callable[..., SweepResult],
    options: dict[str, Any],
) -> tuple[SweepResult | None, ArxModel, Choice, OrderGrid | None]:
    """The structure of an analysis, wherever its records are: the given orders fitted, or the
    choice of the sweep (the default grid grown by :func:`arxid.sweep`'s rule, a given grid as given).

    Parameters
    ----------
    orders : (na, nb, nk) or None
    grid : mapping or None
    fit : callable
        ``fit(na, nb, nk)``: the model of the given orders fitted on the estimation records.
    swept : callable
        ``swept(**options)``: the sweep of the records (its grid among the options when one was given).
    options : dict
        Keyword arguments of the sweep; ``growth_seconds`` is the budget of the grid's growth.

    Returns
    -------
    tuple of (SweepResult or None, ArxModel, Choice, OrderGrid or None)
    """
    if orders is not None:
        if grid is not None:
            raise OrderError("give either orders or grid, not both")
        try:
            na, nb, nk = orders
        except (TypeError, ValueError):
            raise OrderError(f"orders must be (na, nb, nk), got {orders!r}") from None
        model = fit(na, nb, nk)
        return None, model, Choice(model.structure_name(), None, "the orders were given"), None
    g = grid_of(grid)
    res = swept(**options, **({} if grid is None else grid_lists(g)))
    # the record of the growth: why the grid did not grow, when it was not grown
    res = res if res.growth is not None else res.extend(max_rounds=0, max_seconds=options["growth_seconds"])
    model, choice = choose(res)
    return res, model, choice, g


def _checks(
    model: ArxModel, final: ArxModel, val: IOData, horizon: int | None, initial: str = "zero"
) -> tuple[
    Comparison, tuple[FailureAnalysis, ...], tuple[FrequencyCheck, ...], tuple[ResponseBand, ...], tuple[str, ...]
]:
    """The comparison of the chosen and final models, where each fails, their frequency checks and
    free-run bands: independent passes over the validation data, two at a time."""
    models = {model.structure_name(): model}
    if final is not model:
        models["+ " + ", ".join(added_effects(final))] = final
    # The longest first, the comparison (a free run per model) last: the two threads end together.
    tasks: list[Callable[[], Any]] = [
        partial(where_it_fails, m, val, horizon, initial=initial) for m in models.values()
    ]
    # A linear model's response against the data's: not made for a model read through a sensor shape,
    # whose clipped or bent output has no frequency response of its own.
    linear = [m for m in models.values() if linear_part(m) is m]
    tasks += [partial(_frequency, m, val, horizon) for m in linear]
    tasks.append(lambda: compare(models, val, horizon, initial))
    *done, cmp = in_two(lambda task: task(), tasks)
    failures, frequency = tuple(done[: len(models)]), done[len(models) :]
    problem = next((f for f in frequency if isinstance(f, str)), None)
    if problem is not None:
        return cmp, failures, (), (), (problem,)
    bands = tuple(band for _, band in frequency if band is not None)
    return cmp, failures, tuple(check for check, _ in frequency), bands if len(bands) == len(models) else (), ()


def _frequency(model: ArxModel, val: IOData, horizon: int | None) -> tuple[FrequencyCheck, ResponseBand | None] | str:
    """A model's frequency check and free-run band (None for a k-step prediction, or when it cannot
    be made); the note when the check cannot be made."""
    try:
        check = frequency_check(model, val)
    except ArxidError as exc:
        return f"No frequency check: {exc}"
    if horizon is not None:  # a k-step prediction has no free-run band
        return check, None
    try:
        return check, free_run_band(model, val)
    except ArxidError:
        return check, None


def measure_notes(res: SweepResult | None, horizon: int | None, requested: int | None) -> tuple[str, ...]:
    """Why the validation errors are k-step errors, when they are (the sweep found an integrating
    plant, or the chosen model's free run diverges), wherever the records are.

    Parameters
    ----------
    res : SweepResult or None
    horizon : int or None
        The ladder's measure.
    requested : int or None
        The measure asked for.

    Returns
    -------
    tuple of str
    """
    notes = []
    if res is not None and res.integrating:
        notes.append(
            f"The sweep found an integrating plant ({res.integrating_reason}); free-run error drifts, so "
            f"validation errors are {res.horizon}-step-ahead prediction errors."
        )
    elif horizon != requested and horizon is not None:
        notes.append(
            f"The chosen model's free run diverges or it has a pole at 1, so validation errors are "
            f"{horizon}-step-ahead prediction errors."
        )
    return tuple(notes)


def _ladder(
    chosen: ArxModel,
    est: IOData,
    val: IOData,
    res: SweepResult | None,
    max_steps: int,
    horizon: int | None,
    initial: str,
    diagnose_kwargs: dict[str, Any],
) -> Ladder:
    """The ladder from the chosen model; a structure the sweep chose is re-chosen as effects are added."""
    return Ladder.run(
        chosen,
        est,
        val,
        max_steps=max_steps,
        horizon=horizon,
        initial=initial,
        restructure=res is not None,
        expect=None if res is None else res.expectation,
        **diagnose_kwargs,
    )


#: The analysis of a fleet on a Dask cluster, provided by :mod:`arxid.analysis.fleet_analysis`
#: (which imports this module) under the key ``"analyse"``.
FLEET_ANALYSIS: dict[str, Any] = {}


@one_blas_thread()  # its stages run beside each other on the cores BLAS's threads would take
@kept_blocks()  # its temporaries reuse the blocks of those freed before them
def analyse(
    data: IOData,
    validation: IOData | None = None,
    *,
    split: float = DEFAULT_SPLIT,
    orders: Sequence | None = None,
    grid: Mapping[str, Any] | None = None,
    horizon: int | None = None,
    expect: str | None = None,
    max_steps: int = 3,
    progress: bool = False,
    model: ArxModel | PolynomialModel | str | None = None,
    initial: str = "zero",
    grow: bool | None = None,
    max_seconds: float | None = DEFAULT_GROWTH_SECONDS,
    client: Any = None,
    read: Any = None,
    reference: str | Sequence[str] | None = None,
    **diagnose_kwargs: Any,
) -> Analysis:
    """Sweep (unless ``orders`` or a ``model`` are given), choose, compare, test, diagnose and climb the ladder.

    Parameters
    ----------
    data : IOData
        Estimation data, or all data when ``validation`` is None (then split at ``split``).
    validation : IOData, optional
        Separate validation data.
    split : float
        Estimation share of ``data`` when no validation data are given (default 0.7).
    orders : (na, nb, nk), optional
        A fixed structure; skips the sweep.
    grid : mapping with keys na, nb, nk, optional
        Sweep grid; missing keys take :data:`arxid.DEFAULT_GRID`. A given grid is swept as it is
        (``grow=True`` grows it too).
    horizon : int, optional
        Validation error measure: None = free run (k-step for an integrating plant, as the sweep
        and the diagnosis detect it); k = k-step-ahead prediction.
    expect : {None, "stable", "integrating", "double-integrating"}
        What the physics says; passed to the sweep's step sanity check.
    max_steps : int
        Largest number of effects the ladder adds.
    progress : bool
        Progress bar of the sweep on stderr.
    model : ArxModel, PolynomialModel or str, optional
        A model to analyse instead of sweeping: a fitted one (``arxid.oe(est, 2, 2, 3)``, used as it
        is), or a structure written as in :mod:`arxid.model_spec` (``"oe:2,2,3"``,
        ``"bj:2,1,1,2,3"``, ``"armax:2,2,1,3"``, ``"arx:2,2,1"``), fitted on the estimation data.
        The diagnosis refits it with each candidate in its own class (an effect of an OE model
        becomes one more input with its own B/F).
    initial : {"zero", "estimate"}
        Initial conditions of every validation error after the sweep (the comparison, the
        diagnosis' validated refits and the ladder): ``"zero"`` (default) starts each free run from
        the measured outputs (a polynomial model from rest); ``"estimate"`` fits the initial
        conditions first, as :func:`arxid.compare` does, so a validation record that starts
        mid-transient is not held against the model.
    grow : bool or None
        Grow the grid while the chosen structure sits on an edge of it and growing improves its
        validation error (:meth:`arxid.SweepResult.extend`: poles and zeros together, orders up to
        30). None (default): grow the default grid, not a given ``grid``; True: grow either; False:
        never. ``Analysis.grid_growth`` says what was tried and why it stopped.
    max_seconds : float or None
        Time budget of the grid search in seconds, the first sweep included (default 30): no
        larger grid is started whose predicted time would pass it. None: no budget.
    client : dask.distributed.Client, optional
        With a list of logs (IOData or file paths, read with ``read``): analyse the fleet where the
        logs are, each log's last ``1 - split`` validating (:mod:`arxid.analysis.fleet_analysis`;
        returns a :class:`~arxid.analysis.fleet_analysis.FleetAnalysis`).
    read : dict or callable, optional
        How the workers read file paths (see :func:`arxid.data.logs.load_experiment`).
    reference : str or sequence of str, optional
        The logged reference or setpoint of a feedback loop (an extra signal, e.g. ``"roll_sp"``).
        Default: recognised from the extra signals' names (``setpoint``, ``_sp``, ``ref``, ``des``
        ...). When the feedback test finds the data closed loop, the chain identifies the plant by
        a method that stays consistent (:mod:`arxid.analysis.closed_loop`): with a reference,
        instrumental variables from it and validation on the reference-driven input; without one,
        the direct Box–Jenkins method. A reference, and any logged signal the controller computes,
        is never proposed as an extra input. ``Analysis.closed_loop`` says which method ran and why.
    **diagnose_kwargs
        Passed to :func:`arxid.diagnose` (``alpha``, ``min_improvement``, ``candidates`` ...).

    Returns
    -------
    Analysis
        (a :class:`~arxid.analysis.fleet_analysis.FleetAnalysis` with ``client=``)

    Notes
    -----
    When the structure comes from the sweep, the ladder re-chooses it around the chosen orders each
    time it adds an effect (:func:`arxid.diagnosis.restructure.rechoose_structure`); given orders
    or a given model keep theirs.

    For an output-error model the residual tests report whiteness without expecting it (the model
    has no noise model); the independence of the inputs is its test (see :func:`arxid.residuals`).

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> u = np.sign(rng.standard_normal(3000))
    >>> y = lfilter([0, 0, 0, 0.5, 0.3], [1, -1.5, 0.7], u)
    >>> data = arxid.IOData(y + 0.2 * np.std(y) * rng.standard_normal(3000), u, ts=0.01)
    >>> a = arxid.analyse(data, model="oe:2,2,3", max_steps=1)
    >>> a.model.structure_name(), a.choice.rank, a.residual_tests.whiteness_expected
    ('OE(2,2,3)', None, False)
    """
    if client is not None:
        if validation is not None or model is not None:
            given = "validation data" if validation is not None else "a model"
            raise ArxidError(
                f"with client=, analyse takes no {given}: give the logs as a list (the last share of each log, "
                f"1 - split, validates), with orders=, a grid= or neither (the default grid, grown as in process)"
            )
        kw: dict[str, Any] = dict(orders=orders, grid=grid, horizon=horizon, expect=expect, max_steps=max_steps)
        kw.update(initial=initial, grow=grow, max_seconds=max_seconds)
        if not FLEET_ANALYSIS:  # by name: fleet_analysis imports this module
            importlib.import_module("arxid.analysis.fleet_analysis")
        return FLEET_ANALYSIS["analyse"](data, client, split=split, read=read, **kw, **diagnose_kwargs)
    est, val = _split(data, validation, split)
    map_large_arrays()  # the record's long columns come and go: their pages go back when freed
    requested = check_horizon(horizon)
    initial = check_initial(initial)
    refs = reference_names(est, reference, val)
    named = [reference] if isinstance(reference, str) else list(reference or reference_candidates(est))
    still = still_references(est, val, named)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    # The verdict steers the chain: with a reference it is awaited before any sweep; without one it
    # runs beside the least-squares sweep (open-loop data pay nothing), which closed loop redoes.
    pending = Background(feedback_check, est)
    fb = pending.result() if refs and model is None else None
    loop = _loop_structure(fb, est, val, refs, orders, grid, requested, expect, progress, model)
    if loop is None:
        res, chosen, choice, g = _structure(
            est, val, orders, grid, requested, expect, progress, model, grow=grow, max_seconds=max_seconds
        )
        fb = pending.result() if fb is None else fb
        loop = _loop_structure(fb, est, val, (), orders, grid, requested, expect, progress, model, still)
    method = _open_loop_method(fb, model, orders)
    if loop is not None:
        res, chosen, choice, g = loop.sweep, loop.model, loop.choice, loop.grid
        est, val, method = loop.estimation, loop.validation, loop.method
    if refs and reference is not None:  # a named reference is never a plant input, whatever the verdict
        diagnose_kwargs.setdefault("loop_signals", loop_signal_names(est, refs))
    elif method is not None and method.closed:
        diagnose_kwargs.setdefault("loop_signals", method.loop_signals)
    measure = res.horizon if res is not None else requested
    timings["sweep"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    ladder = _ladder(chosen, est, val, None if loop else res, max_steps, measure, initial, diagnose_kwargs)
    timings["diagnose"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    cmp, failures, freq, bands, freq_notes = _checks(chosen, ladder.final_model, val, ladder.horizon, initial)
    timings["checks and frequency"] = time.perf_counter() - t0
    if method is not None and method.closed:
        from .loop_structure import loop_closing_sentences

        closing = loop_closing_sentences(chosen, est, val, method, ladder.horizon, initial)
        method = replace(method, loop_closing=closing)
    notes = measure_notes(res, ladder.horizon, requested) + freq_notes + feedback_notes(fb, est, method)
    return Analysis(
        **concluded(g, res, choice, chosen, ladder, timings),
        estimation=est,
        validation=val,
        comparison=cmp,
        failures=failures,
        notes=notes + delay_notes(chosen, est, method is not None and method.closed),
        frequency=freq,
        bands=bands,
        initial=initial,
        feedback=fb,
        closed_loop=method,
    )


def _open_loop_method(fb: FeedbackTest | None, given: Any, orders: Sequence | None) -> ClosedLoopMethod | None:
    """What the open-loop chain says it did (None when the model was given or the test could not run)."""
    if fb is None or given is not None:
        return None
    if not fb.feedback:
        return OPEN_LOOP
    return GIVEN_ORDERS if orders is not None else WEAK_EVIDENCE


def _loop_structure(
    fb: FeedbackTest | None,
    est: IOData,
    val: IOData,
    refs: Sequence[str],
    orders: Sequence | None,
    grid: Mapping | None,
    horizon: int | None,
    expect: str | None,
    progress: bool,
    given: Any,
    still: Sequence[str] = (),
) -> LoopStructure | None:
    """The closed-loop structure when feedback was found and the structure is not given (else None).

    With a logged reference the loop is known, so feedback within the sample counts; without one
    it must show beyond the sample, since a plant with a direct feedthrough looks the same within
    it (:func:`~arxid.analysis.closed_loop.beyond_the_sample`), and given orders keep their ARX
    structure."""
    if given is not None or fb is None or not fb.feedback:
        return None
    if not refs and (orders is not None or not beyond_the_sample(est, fb)):
        return None  # given ARX orders without a reference stay ARX (the notes say what feedback means)
    from .loop_structure import closed_loop_structure

    return closed_loop_structure(est, val, refs, orders, grid, horizon, expect, progress, still)
