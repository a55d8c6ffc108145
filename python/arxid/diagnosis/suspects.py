"""Which physical effect is the model missing? :func:`diagnose` returns a :class:`Diagnosis`.

The procedure (see ``DESIGN.md``, *Diagnosing a missing effect*):

1. Take the model's one-step residual e on the estimation data.
2. For each candidate (an effect such as ``u1^2``, ``y^3``, ``sign(dy)``, ``u1*vbat``, or more
   dynamics ``na+1``, ``nb+1``, ``nk±1``), project its regressor columns z on the model's
   regressors and keep the remainder z̃. The added-variable (partial) correlation of z̃ with e is the
   score; its square is the share of residual energy the candidate removes. An F-test gives a
   p-value, corrected for the number of candidates tried (Holm).
3. Refit the best candidates and judge them by free-run error on validation data (k-step error for
   plants with an integrator): one-step error barely moves when a real effect is added, free-run
   error falls a lot, and a candidate that only tracks a drift makes validation worse.
4. A suspect is *significant* only when its corrected p-value passes ``alpha`` **and** it lowers the
   validation error by at least ``min_improvement`` (5%), and — below the best suspect — only if it
   still lowers the error by that much once the best one is in the model (else it is "explained
   by" the best). With no missing effect, none is.
5. The simplest explanation first: an effect is named only when its validation error is at least
   ``min_improvement`` below that of the model refitted with an offset (``const``) and with a trend
   (``time``) — a logged signal that does no better than a constant is not a physical effect.
6. Strong candidates are also tried together with ``const`` (asymmetric Coulomb friction is
   c·sign(v) plus an offset); the pair is reported as one suspect, ``sign(dy)+const``.
7. When nothing is significant and the residuals are not white, the diagnosis says how much of the
   remaining validation error is slower than the model's slowest mode: an unlogged disturbance
   that no candidate explains (:mod:`~arxid.diagnosis.disturbance`).

:func:`diagnose` runs these steps; they live in :mod:`~arxid.diagnosis.extension` (a candidate
and the model refitted with it), :mod:`~arxid.diagnosis.scoring` (step 2 and the pairs, ARX) or
:mod:`~arxid.diagnosis.polynomial_scoring` (step 2 for a polynomial model),
:mod:`~arxid.diagnosis.judge` (steps 3 and 4) and :mod:`~arxid.diagnosis.result` (the suspects and
the diagnosis). :class:`~arxid.diagnosis.ladder.Ladder` then adds the best significant suspect,
re-diagnoses, and repeats — the error falls step by step.

The procedure is written once, wherever the records are (:class:`Records`): one record in this
process (:class:`OneRecord`, what :func:`diagnose` makes of ``data`` and ``validation``), or a fleet's
logs on a Dask cluster (:class:`~arxid.diagnosis.cluster_records.ClusterRecords`), whose scoring,
refits and validation errors come from sums made where the logs are. The stages that need the
samples in this process (shapes, masked pairs, sensor shapes, residual tests, the dependence table)
run for a record here only.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import field
from functools import partial
from importlib import import_module
from typing import Any, Protocol, overload, runtime_checkable

import numpy as np

from .._base import metrics
from .._base.array_memory import kept_blocks
from .._base.background import Background, one_blas_thread
from .._base.records import record
from ..checks import PerOutput, ResidualAnalysis, prediction, residuals
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.arguments import check_data, check_horizon, check_model
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel, check_initial
from ..models.state_space import StateSpaceModel
from .candidates import INTEGRATING_HORIZON, auto_candidates, output_integrates
from .disturbance import Disturbance, remaining_disturbance
from .extension import Candidate, candidate_list
from .judge import SIMPLE_EXPLANATIONS, Judge, demote_pairs
from .nonlinearity import NonlinearDependence, nonlinear_dependence
from .ranking import finish_suspects
from .result import Diagnosis, Suspect
from .scoring import CandidateScoring, Scoring
from .sensor_shapes import rank_sensors, sensor_suspects
from .shapes import ValidationEvidence, prefer_shapes, score_shapes

__all__ = [
    "diagnose",
    "Baseline",
    "Diagnosis",
    "Records",
    "Suspect",
    "auto_candidates",
    "baseline_errors",
    "INTEGRATING_HORIZON",
]


@overload
def diagnose(
    model: StateSpaceModel,
    data: IOData | None = ...,
    validation: IOData | None = ...,
    *,
    candidates: str | Sequence[str] = ...,
    horizon: int | None = ...,
    alpha: float = ...,
    min_improvement: float = ...,
    n_refit: int = ...,
    n_pairs: int = ...,
    residual_max_lag: int = ...,
    simple_explanations: Sequence[str] = ...,
    initial: str = ...,
    loop_signals: Sequence[str] = ...,
) -> Diagnosis | PerOutput[Diagnosis]: ...


@overload
def diagnose(
    model: ArxModel,
    data: IOData | Records | None = ...,
    validation: IOData | None = ...,
    *,
    candidates: str | Sequence[str] = ...,
    horizon: int | None = ...,
    alpha: float = ...,
    min_improvement: float = ...,
    n_refit: int = ...,
    n_pairs: int = ...,
    residual_max_lag: int = ...,
    simple_explanations: Sequence[str] = ...,
    initial: str = ...,
    loop_signals: Sequence[str] = ...,
    client: Any = ...,
) -> Diagnosis: ...


@one_blas_thread()  # the baseline runs beside the scoring on the cores BLAS's threads would take
@kept_blocks()  # its temporaries reuse the blocks of those freed before them
def diagnose(
    model: ArxModel | StateSpaceModel,
    data: IOData | Records | None = None,
    validation: IOData | None = None,
    *,
    candidates: str | Sequence[str] = "auto",
    horizon: int | None = None,
    alpha: float = 0.01,
    min_improvement: float = 0.05,
    n_refit: int = 8,
    n_pairs: int = 8,
    residual_max_lag: int = 25,
    simple_explanations: Sequence[str] = SIMPLE_EXPLANATIONS,
    initial: str = "zero",
    loop_signals: Sequence[str] = (),
    client: Any = None,
) -> Diagnosis | PerOutput[Diagnosis]:
    """Rank the physical effects (and structure changes) the model is missing.

    Parameters
    ----------
    model : ArxModel or StateSpaceModel
        A fitted model: ARX, polynomial, or state-space (each output diagnosed on its own, see
        :mod:`arxid.diagnosis.state_space`).
    data : IOData or Records, optional
        Estimation data (default: the data the model was fitted on; required, with every output,
        for a state-space model); or the records of a fleet
        (:class:`arxid.diagnosis.cluster_records.ClusterRecords`: every stage runs where its logs
        are, and the stages that need the samples in this process are left out).
    validation : IOData, optional
        Data the refitted candidates are judged on (default: ``data``; give separate data —
        a drift-tracking candidate only shows its harm there).
    candidates : "auto" or sequence of str
        ``"auto"`` builds them from the data's signals (:func:`auto_candidates`); a list may hold
        effects (``"u1*vbat"``), pairs (``"sign(dy)+const"``) and ``"na+1"``, ``"nb+1"``,
        ``"nk-1"``, ``"nk+1"``.
    horizon : int or None
        Validation error: None = free run (switched to ``INTEGRATING_HORIZON``-step for a plant
        with a pole at 1 or a baseline whose free run diverges); k = k-step prediction.
    alpha : float
        Level of the Holm-corrected F-test.
    min_improvement : float
        Relative fall of the validation error a suspect needs to be significant (0.05 = 5%).
    n_refit : int
        Candidates passing the corrected test are all refitted and validated, plus the best
        ``n_refit`` by p-value (every candidate when ``candidates`` is a list).
    n_pairs : int
        Largest number of strong effects also tried together with ``const`` (when the model has
        no offset).
    residual_max_lag : int
        Largest lag of the residual tests reported in ``residual_tests``.
    simple_explanations : sequence of str
        Effects every other effect must beat before it is named, simplest first (default ``("const",
        "time")``: an offset, then a trend): a suspect whose validation error is not at least
        ``min_improvement`` below that of the model refitted with one of them is "no better than" it
        (see :meth:`~arxid.diagnosis.judge.Judge.simplest_first`). ``()`` turns the comparison off.
    initial : {"zero", "estimate"}
        Initial conditions of every validation error (the baseline's and the refits'): ``"zero"``
        (default) starts each free run from the measured outputs (a polynomial model from rest);
        ``"estimate"`` fits them first, so a validation record that starts mid-transient is not held
        against the models (see :func:`arxid.compare`).
    loop_signals : sequence of str
        Logged signals of a feedback loop (its reference or setpoint, the controller's terms) that
        ``"auto"`` never proposes as extra inputs: they explain the output because the loop closes
        through them, not because the plant misses an effect.
    client : dask.distributed.Client, optional
        With a list of logs as ``data`` (IOData or file paths): diagnose the fleet where the logs are,
        the last 30 % of each validating (:func:`arxid.diagnosis.cluster_records.diagnose_logs`, which
        returns a :class:`~arxid.diagnosis.cluster_records.FleetDiagnosis`).

    Returns
    -------
    Diagnosis
        ``suspects`` ranked by validated improvement; ``apply(k)`` refits with suspect k. For a
        state-space model of several outputs, a :class:`~arxid.checks.PerOutput` of diagnoses by
        output name.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(0.5, 1.5, 3000).repeat(1)
    >>> y = np.zeros(3000)
    >>> for t in range(1, 3000):
    ...     y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 1] ** 2 + 0.01 * rng.standard_normal()
    >>> est, val = arxid.IOData(y, u, ts=0.01).split(0.6)
    >>> d = arxid.diagnose(arxid.arx(est, 1, 1, 1), est, val)
    >>> d.top.effect
    'through(u1^2.005)'
    """
    options: dict[str, Any] = dict(candidates=candidates, horizon=horizon, alpha=alpha, initial=initial)
    options.update(min_improvement=min_improvement, n_refit=n_refit, residual_max_lag=residual_max_lag)
    options.update(simple_explanations=simple_explanations, loop_signals=loop_signals)
    if isinstance(model, StateSpaceModel):  # each output on its own (a fleet's logs are refused there)
        from .state_space import diagnose_state_space

        return diagnose_state_space(model, data, validation, **options)  # type: ignore[arg-type]
    if client is not None:  # by name: cluster_records imports this module
        diagnose_logs = import_module("arxid.diagnosis.cluster_records").diagnose_logs
        return diagnose_logs(model, data, client, validation=validation, n_pairs=n_pairs, **options)
    model = check_model(model)
    if isinstance(data, Records):  # the records of a fleet, or one record already checked
        if validation is not None:
            raise ArxidError("records hold their own validation data: give no validation= with them")
        records = data
    else:
        records = OneRecord(*_data_pair(model, data, validation))
    records.check(model)
    polynomial = isinstance(model, PolynomialModel)
    horizon, initial = check_horizon(horizon), check_initial(initial)
    if not 0 < alpha < 1:
        raise ArxidError(f"alpha must be between 0 and 1, got {alpha}")
    if not 0 <= min_improvement < 1:
        raise ArxidError(f"min_improvement must be in [0, 1), got {min_improvement}")
    data, validation, loop_signals = records.estimation, records.validation, tuple(loop_signals)
    pending = records.baseline(model, horizon, initial, residual_max_lag)
    try:
        cands, auto = records.candidates(candidates, model, loop_signals)
        scoring = None if polynomial else records.scoring(model, cands)
        if scoring is None:
            from .polynomial_scoring import score_polynomial

            scored, notes = score_polynomial(model, data, cands)
        else:
            scored, notes = scoring.run(alpha, n_pairs)
    except Exception:
        pending.result()  # the baseline's error first, as when it ran before the scoring
        raise
    base = pending.result()
    samples = records.here and isinstance(scoring, Scoring) and auto  # the stages that read the samples here
    # The output read through a static shape (Wiener) depends on the baseline alone: scanned beside
    # the input shapes and the judge, which leave most of a second core free.
    if samples:  # shapes that replace an input compete on equal terms
        sensors = Background(sensor_suspects, model, data, validation, base.horizon, initial, base.rms, base.prediction)
        evidence = ValidationEvidence(model, validation, base.horizon, initial, base.prediction)
        scored = scored + score_shapes(model, data, evidence, loop_signals)
    judge = records.judge(model, base.horizon, base.rms, min_improvement, initial)
    suspects = judge.suspects(scored, notes, alpha, n_refit if auto else None)
    suspects = judge.simplest_first(demote_pairs(suspects, min_improvement), simple_explanations)
    suspects = judge.conditional_on_top(prefer_shapes(suspects, records.head, min_improvement))
    if samples and isinstance(scoring, Scoring) and not any(s.significant for s in suspects):
        # Two effects can hide each other: try the strongest candidate with its strongest partner.
        masked = scoring.masked_pairs(scored, alpha)
        suspects = demote_pairs(suspects + judge.suspects(masked, notes, alpha, None), min_improvement)
        suspects = judge.simplest_first(suspects, simple_explanations)
    if samples:
        suspects = rank_sensors(suspects, sensors.result(), alpha, min_improvement)
    suspects = finish_suspects(notes, cands, suspects, records.head)
    # The dependence test runs when the diagnosis is first asked for it (a ladder asks its last
    # diagnosis only), never beside the scoring: its design (~0.4 GiB at 2M rows) on top of the
    # other stages' arrays would take the analysis of a 4M-sample record past 1 GiB.
    dependence = partial(_dependence, model, data, alpha) if records.here and not polynomial else ()
    return Diagnosis(
        model,
        data,
        validation,
        base.horizon,
        base.rms,
        base.rms_one_step,
        base.fit,
        tuple(suspects),
        base.residual_tests,
        alpha,
        min_improvement,
        len(scored),
        records.same,
        dependence,
        base.disturbance,
    )


def _dependence(model: ArxModel, data: IOData, alpha: float) -> tuple[NonlinearDependence, ...]:
    try:
        return nonlinear_dependence(model, data, alpha)
    except ArxidError:  # too few rows for the extra lags: nothing to say
        return ()


# ---------------------------------------------------------------------------------------------
# stages of the procedure
# ---------------------------------------------------------------------------------------------
def _data_pair(model: ArxModel, data: IOData | None, validation: IOData | None) -> tuple[IOData, IOData, bool]:
    """The estimation and validation data, checked alike, and whether they are the same."""
    if data is None:
        data = model.data_
        if data is None:
            raise ArxidError(
                "this model was loaded without its data: pass the estimation data to diagnose(model, data)"
            )
    data = check_data(data)
    same = validation is None
    validation = data if same else check_data(validation, "validation")
    if validation.input_names != data.input_names:
        raise DataError(
            f"validation inputs {list(validation.input_names)} differ from the estimation inputs "
            f"{list(data.input_names)}"
        )
    return data, validation, same


@record
class Baseline:
    """The model's validation errors, before any candidate: at ``horizon`` (None: free run), one
    step ahead, the fit percent at ``horizon``, and the residual tests and slow disturbance (None
    where the residual sequence is not in this process); ``prediction`` at ``horizon`` where it
    was made in this process (the shapes' and sensors' evidence is measured against it)."""

    horizon: int | None
    rms: float
    rms_one_step: float
    fit: float
    residual_tests: ResidualAnalysis | None = None
    disturbance: Disturbance | None = None
    prediction: np.ndarray | None = field(default=None, compare=False, repr=False)


def baseline_errors(
    model: ArxModel,
    horizon: int | None,
    initial: str,
    rms: Callable[[int | None, str], tuple[float, bool]],
    fit: Callable[[int | None, str], float],
    too_short: str,
) -> tuple[int | None, float]:
    """The baseline's rule, wherever the records are: a free run that drifts or diverges is measured
    :data:`INTEGRATING_HORIZON` steps ahead.

    Parameters
    ----------
    model : ArxModel
    horizon : int or None
    initial : {"zero", "estimate"}
    rms : callable
        ``rms(k, initial)``: the validation RMS (inf when the prediction diverged, NaN without a
        predicted sample) and whether it diverged.
    fit : callable
        ``fit(k, initial)``: the validation fit percent (of the free run, for the settling evidence).
    too_short : str
        The message when no validation sample has a prediction.

    Returns
    -------
    tuple of (int or None, float)
        The horizon of the validation error, and the error there.
    """
    if horizon is None:
        free = None  # no settling to speak of without a stable, converging free run
        if model.is_stable and not rms(None, "zero")[1]:
            free = fit(None, "zero")
        horizon = INTEGRATING_HORIZON if output_integrates(model, free) else None
    base_rms = rms(horizon, initial)[0]
    if math.isnan(base_rms):
        raise DataError(too_short)
    if horizon is None and math.isinf(base_rms):
        horizon = INTEGRATING_HORIZON
        base_rms = rms(horizon, initial)[0]
    return horizon, base_rms


def _baseline(model: ArxModel, validation: IOData, horizon: int | None, max_lag: int, initial: str) -> Baseline:
    """The model's validation errors (:func:`baseline_errors`) and residual tests on one record.
    Each prediction is made once (a free run of a long record is a pass over it) and measured as
    :func:`arxid.checks.error_rms` measures it."""
    made: dict[tuple[int | None, str], tuple[np.ndarray, bool]] = {}

    def predicted(k: int | None, init: str) -> tuple[np.ndarray, bool]:
        if (k, init) not in made:
            made[k, init] = prediction(model, validation, k, init)
        return made[k, init]

    def rms(k: int | None, init: str) -> tuple[float, bool]:
        pred, diverged = predicted(k, init)
        return metrics.prediction_rms(validation.y, pred), diverged  # inf when it diverged

    def fit(k: int | None, init: str) -> float:
        return metrics.fit_percent(validation.y, predicted(k, init)[0])

    too_short = (
        f"the validation data ({validation.n_samples} samples) are too short for a prediction by "
        f"{model.structure_name()}; give longer validation data (or a smaller estimation fraction)"
    )
    horizon, base_rms = baseline_errors(model, horizon, initial, rms, fit, too_short)
    pred = predicted(horizon, initial)[0]
    try:
        rtests = residuals(model, validation, max_lag=max_lag)
    except ArxidError:
        rtests = None
    rest = None if rtests is None else remaining_disturbance(model, validation, validation.y - pred, rtests.is_white)
    # the one-step prediction last: it is not held while the residual tests run
    one_step = rms(1, "zero")[0]
    return Baseline(horizon, base_rms, one_step, metrics.fit_percent(validation.y, pred), rtests, rest, pred)


@runtime_checkable
class Records(Protocol):
    """Where the records of a diagnosis are, and how each stage that reads them runs there:
    :class:`OneRecord` in this process, or a fleet's logs on a cluster
    (:class:`arxid.diagnosis.cluster_records.ClusterRecords`)."""

    estimation: IOData  # as this process sees them (a fleet's: names and sizes, samples on demand)
    validation: IOData
    head: IOData  # the first samples of the estimation data: the signals' names and units
    same: bool  # the validation data are the estimation data
    here: bool  # the samples are in this process

    def check(self, model: ArxModel) -> None:
        """Raise :class:`~arxid.ArxidError` for a model these records cannot diagnose.

        Parameters
        ----------
        model : ArxModel
        """

    def baseline(self, model: ArxModel, horizon: int | None, initial: str, max_lag: int) -> Any:
        """Start the model's validation errors (:class:`Baseline`, with its residual tests up to
        ``max_lag`` where the residuals are here).

        Parameters
        ----------
        model : ArxModel
        horizon : int or None
        initial : {"zero", "estimate"}
        max_lag : int

        Returns
        -------
        object
            Its ``result()`` is the :class:`Baseline` (awaited after the scoring).
        """

    def candidates(
        self, candidates: str | Sequence[str], model: ArxModel, loop_signals: tuple[str, ...]
    ) -> tuple[list[Candidate], bool]:
        """The candidates to test (``"auto"``: from the records' signals) and whether they were automatic.

        Parameters
        ----------
        candidates : "auto" or sequence of str
        model : ArxModel
        loop_signals : tuple of str
            Signals ``"auto"`` leaves out.

        Returns
        -------
        tuple of (list of Candidate, bool)
        """
        raise NotImplementedError

    def scoring(self, model: ArxModel, cands: list[Candidate]) -> CandidateScoring:
        """The added-variable tests of the candidates, where the records are.

        Parameters
        ----------
        model : ArxModel
        cands : list of Candidate

        Returns
        -------
        CandidateScoring
        """
        raise NotImplementedError

    def judge(
        self, model: ArxModel, horizon: int | None, base_rms: float, min_improvement: float, initial: str
    ) -> Judge:
        """The judge that refits and validates candidates on these records.

        Parameters
        ----------
        model : ArxModel
        horizon : int or None
        base_rms, min_improvement : float
        initial : {"zero", "estimate"}

        Returns
        -------
        Judge
        """
        raise NotImplementedError

    def measure(self, model: ArxModel, horizon: int | None, initial: str) -> tuple[float, float]:
        """The model's validation RMS and fit percent at ``horizon`` (a ladder's step).

        Parameters
        ----------
        model : ArxModel
        horizon : int or None
        initial : {"zero", "estimate"}

        Returns
        -------
        tuple of (float, float)
        """
        raise NotImplementedError


class OneRecord:
    """One record in this process: its estimation and validation data (a fleet of one). Each
    method is that of :class:`Records`.

    Parameters
    ----------
    estimation, validation : IOData
    same : bool
        ``validation`` is ``estimation``.
    """

    here = True

    def __init__(self, estimation: IOData, validation: IOData, same: bool = False):
        self.estimation, self.validation, self.same = estimation, validation, same
        self.head = estimation

    def check(self, model: ArxModel) -> None:
        """Every model can be diagnosed on one record."""

    def baseline(self, model: ArxModel, horizon: int | None, initial: str, max_lag: int) -> Background:
        """The baseline, started beside the scoring (it reads the validation data only)."""
        return Background(_baseline, model, self.validation, horizon, max_lag, initial)

    def candidates(
        self, candidates: str | Sequence[str], model: ArxModel, loop_signals: tuple[str, ...]
    ) -> tuple[list[Candidate], bool]:
        """:func:`~arxid.diagnosis.extension.candidate_list` on the estimation data."""
        return candidate_list(candidates, model, self.estimation, loop_signals)

    def scoring(self, model: ArxModel, cands: list[Candidate]) -> Scoring:
        """The scoring on the record's rows."""
        return Scoring(model, self.estimation, cands)

    def judge(
        self, model: ArxModel, horizon: int | None, base_rms: float, min_improvement: float, initial: str
    ) -> Judge:
        """The judge refitting on the record."""
        return Judge(model, self.estimation, self.validation, horizon, base_rms, min_improvement, initial)

    def measure(self, model: ArxModel, horizon: int | None, initial: str) -> tuple[float, float]:
        """As :meth:`Records.measure`, from one prediction."""
        pred, _ = prediction(model, self.validation, horizon, initial)
        return metrics.prediction_rms(self.validation.y, pred), metrics.fit_percent(self.validation.y, pred)
