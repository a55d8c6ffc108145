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
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from .._base import metrics
from .._base.background import Background, one_blas_thread
from ..checks import ResidualAnalysis, prediction, residuals
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.arguments import check_data, check_horizon, check_model
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel, check_initial
from ..models.state_space import StateSpaceModel
from .candidates import auto_candidates, output_integrates, physics
from .disturbance import Disturbance, remaining_disturbance
from .extension import Candidate, candidate_list
from .judge import SIMPLE_EXPLANATIONS, Judge, demote_pairs
from .nonlinearity import NonlinearDependence, nonlinear_dependence
from .polynomial_scoring import score_polynomial
from .result import Diagnosis, Suspect
from .scoring import Scoring
from .sensor_shapes import rank_sensors, sensor_suspects
from .shapes import ValidationEvidence, prefer_shapes, score_shapes

__all__ = ["diagnose", "Diagnosis", "Suspect", "auto_candidates", "INTEGRATING_HORIZON", "NOT_FOR_STATE_SPACE"]

#: Why a state-space model has no search for a missing effect, and what to use instead.
NOT_FOR_STATE_SPACE = (
    "the search for a missing effect is not available for a state-space model: it adds candidate terms "
    "to the regressors of an ARX or polynomial model, which a state-space model does not have. Check it "
    "with arxid.residuals and arxid.where_it_fails (each output), or diagnose an ARX model of one output: "
    "arxid.diagnose(arxid.arx(data.output(name), na, nb, nk))"
)

#: k used for the validation error of a plant with an integrator (free run drifts).
INTEGRATING_HORIZON = 10


@one_blas_thread()  # the baseline runs beside the scoring on the cores BLAS's threads would take
def diagnose(
    model: ArxModel,
    data: IOData | None = None,
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
) -> Diagnosis:
    """Rank the physical effects (and structure changes) the model is missing.

    Parameters
    ----------
    model : ArxModel
        A fitted model (ARX or polynomial; a state-space model is refused with what to use
        instead, :data:`NOT_FOR_STATE_SPACE`).
    data : IOData, optional
        Estimation data (default: the data the model was fitted on).
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

    Returns
    -------
    Diagnosis
        ``suspects`` ranked by validated improvement; ``apply(k)`` refits with suspect k.

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
    if isinstance(model, StateSpaceModel):
        raise ArxidError(NOT_FOR_STATE_SPACE)
    model = check_model(model)
    polynomial = isinstance(model, PolynomialModel)
    data, validation, same = _data_pair(model, data, validation)
    horizon = check_horizon(horizon)
    initial = check_initial(initial)
    if not 0 < alpha < 1:
        raise ArxidError(f"alpha must be between 0 and 1, got {alpha}")
    if not 0 <= min_improvement < 1:
        raise ArxidError(f"min_improvement must be in [0, 1), got {min_improvement}")
    # The baseline reads the validation data only: beside the scoring, on the second core.
    baseline = Background(_baseline, model, validation, horizon, residual_max_lag, initial)
    try:
        cands, auto = candidate_list(candidates, model, data, tuple(loop_signals))
        scoring = None if polynomial else Scoring(model, data, cands)
        scored, notes = score_polynomial(model, data, cands) if scoring is None else scoring.run(alpha, n_pairs)
    except Exception:
        baseline.result()  # the baseline's error first, as when it ran before the scoring
        raise
    base = baseline.result()
    if scoring is not None and auto:  # shapes that replace an input compete on equal terms
        evidence = ValidationEvidence(model, validation, base.horizon, initial)
        scored = scored + score_shapes(model, data, evidence, tuple(loop_signals))
    judge = Judge(model, data, validation, base.horizon, base.rms, min_improvement, initial)
    suspects = judge.suspects(scored, notes, alpha, n_refit if auto else None)
    suspects = judge.simplest_first(demote_pairs(suspects, min_improvement), simple_explanations)
    suspects = judge.conditional_on_top(prefer_shapes(suspects, data, min_improvement))
    if scoring is not None and auto and not any(s.significant for s in suspects):
        # Two effects can hide each other: try the strongest candidate with its strongest partner.
        masked = scoring.masked_pairs(scored, alpha)
        suspects = demote_pairs(suspects + judge.suspects(masked, notes, alpha, None), min_improvement)
        suspects = judge.simplest_first(suspects, simple_explanations)
    if scoring is not None and auto:  # the output read through a static shape (Wiener)
        sensors = sensor_suspects(model, data, validation, base.horizon, initial, base.rms)
        suspects = rank_sensors(suspects, sensors, alpha, min_improvement)
    suspects = finish_suspects(notes, cands, suspects, data)
    # The dependence test runs when the diagnosis is first asked for it (a ladder asks its last
    # diagnosis only), never beside the scoring: its design (~0.4 GiB at 2M rows) on top of the
    # other stages' arrays would take the analysis of a 4M-sample record past 1 GiB.
    dependence = () if polynomial else partial(_dependence, model, data, alpha)
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
        same,
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


@dataclass(frozen=True)
class _Baseline:
    horizon: int | None
    rms: float
    rms_one_step: float
    fit: float
    residual_tests: ResidualAnalysis | None
    disturbance: Disturbance | None


def _baseline(model: ArxModel, validation: IOData, horizon: int | None, max_lag: int, initial: str) -> _Baseline:
    """The model's validation errors; a free run that drifts or diverges is measured k steps ahead.
    Each prediction is made once (a free run of a long record is a pass over it) and measured as
    :func:`arxid.checks.error_rms` measures it."""
    made: dict[tuple[int | None, str], tuple[np.ndarray, bool]] = {}

    def predicted(k: int | None, init: str) -> tuple[np.ndarray, bool]:
        if (k, init) not in made:
            pred, diverged = prediction(model, validation, k, init)
            made[k, init] = (pred, diverged)
        return made[k, init]

    def rms(k: int | None, init: str) -> float:
        return metrics.prediction_rms(validation.y, predicted(k, init)[0])  # inf when it diverged

    if horizon is None and output_integrates(model, _free_run_fit(model, validation, predicted)):
        horizon = INTEGRATING_HORIZON
    base_rms = rms(horizon, initial)
    if math.isnan(base_rms):  # no sample of the validation data has a prediction
        raise DataError(
            f"the validation data ({validation.n_samples} samples) are too short for a prediction by "
            f"{model.structure_name()}; give longer validation data (or a smaller estimation fraction)"
        )
    if horizon is None and math.isinf(base_rms):
        horizon = INTEGRATING_HORIZON
        base_rms = rms(horizon, initial)
    pred, _ = predicted(horizon, initial)
    try:
        rtests = residuals(model, validation, max_lag=max_lag)
    except ArxidError:
        rtests = None
    rest = None
    if rtests is not None:
        rest = remaining_disturbance(model, validation, validation.y - pred, rtests.is_white)
    fit = metrics.fit_percent(validation.y, pred)
    return _Baseline(horizon, base_rms, rms(1, "zero"), fit, rtests, rest)


def _free_run_fit(
    model: ArxModel, validation: IOData, predicted: Callable[[int | None, str], tuple[np.ndarray, bool]]
) -> float | None:
    """The model's free-run fit on the validation data, percent (None when it diverges or has a
    pole on or outside the unit circle: then there is no settling to speak of); ``predicted(k,
    initial)`` gives (prediction, diverged)."""
    if not model.is_stable:
        return None
    pred, diverged = predicted(None, "zero")
    return None if diverged else metrics.fit_percent(validation.y, pred)


def _unscored(notes: dict[str, str], cands: list[Candidate], suspects: list[Suspect]) -> list[Suspect]:
    """Candidates that could not be scored, with the reason, so the table says why they are absent."""
    have = {s.effect for s in suspects}
    by_label = {c.label: c for c in cands}
    nan = math.nan
    return [
        Suspect(lab, c.kind, c.effects, c.na, c.nb, c.nk, nan, nan, nan, nan, 0, nan, nan, False, why, None)
        for lab, why in notes.items()
        if lab not in have and (c := by_label.get(lab)) is not None
    ]


def _rank_key(s: Suspect) -> tuple:
    """Significant first (lowest validation error first), then refitted by error, then by p-value."""
    after = s.rms_sim_val_after
    refitted = not math.isnan(after)
    p = s.p_value if math.isfinite(s.p_value) else 2.0
    return (not s.significant, not refitted, after if refitted else 0.0, p, -np.nan_to_num(s.score))


def finish_suspects(
    notes: dict[str, str], cands: list[Candidate], suspects: list[Suspect], data: IOData
) -> list[Suspect]:
    """The last step of :func:`diagnose`, shared with the diagnosis of a fleet: the candidates that
    could not be scored added with their reason, the physics of each suspect, and the ranking.

    Parameters
    ----------
    notes : dict of str to str
        Why a candidate was not scored, by label.
    cands : list of Candidate
    suspects : list of Suspect
        The judged suspects.
    data : IOData
        The estimation data (their signal names tell inputs from logged signals).

    Returns
    -------
    list of Suspect
        Ranked: significant first, then refitted by validation error, then by p-value.
    """
    suspects = suspects + _unscored(notes, cands, suspects)
    return sorted((replace(s, physics=s.physics or physics(s.effect, data)) for s in suspects), key=_rank_key)
