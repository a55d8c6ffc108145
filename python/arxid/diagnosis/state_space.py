"""The missing-effect diagnosis of a state-space model, one output at a time.

:func:`arxid.diagnose` of a :class:`~arxid.StateSpaceModel` runs the procedure of
:mod:`arxid.diagnosis.suspects` on each output, with the same candidates, test and judgement:

1. the candidates are the effects :func:`~arxid.diagnosis.candidates.auto_effects` builds from
   the signals of that output's data (``y`` is that output); a structure change is the model's
   order, which :func:`arxid.ssest` chooses, so none is offered;
2. each is scored by the whitened partial F-test of its columns beside the output's own B, D and
   x0 columns, A and C held (:class:`~arxid.diagnosis.state_space_output.OutputRegressors`), and
   the p-values are Holm-corrected over that output's candidates;
3. the best are refitted (B, D and the initial states of every output re-estimated with the term as
   one more input, A, C and K held) and judged by the output's free-run error on the validation
   data (k-step for an unstable model) by :class:`~arxid.diagnosis.judge.Judge`: the same
   ``min_improvement``, the simple explanations first, a suspect below the best kept only if it
   still helps once the best is in the model.

An effect may matter for one output and not another: each output gets its own
:class:`~arxid.Diagnosis` (one output: that diagnosis; several: a
:class:`~arxid.checks.PerOutput` of them by output name). Threshold scans (``dz(u1)``), pairs with an
offset and the stages that read a single-output model's regressors (shapes, sensors, the nonlinear
dependence test) are not run for a state-space model.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from .._base import metrics
from ..checks import residuals
from ..checks.state_space import PerOutput, in_model_order
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from ..models.arguments import check_horizon
from ..models.derived_inputs import uses_output
from ..models.state_space import StateSpaceModel
from .added_variable import holm
from .candidates import INTEGRATING_HORIZON, auto_effects
from .disturbance import remaining_disturbance
from .extension import Candidate, candidate_list
from .judge import SIMPLE_EXPLANATIONS, Judge, demote_pairs
from .ranking import finish_suspects
from .result import Diagnosis
from .scoring import scored_entry
from .state_space_output import OutputRegressors, StateSpaceOutput

__all__ = ["diagnose_state_space", "StateSpaceRefits", "NOT_A_STATE_SPACE_CANDIDATE"]

#: Why a structure change or a threshold scan is not a candidate for a state-space model.
NOT_A_STATE_SPACE_CANDIDATE = (
    "is not a candidate for a state-space model: its structure is its order (give another order to "
    "arxid.ssest), and a threshold is tested at a value, e.g. dz(u1,0.2)"
)
_SCAN = re.compile(r"(dz|sat)\([A-Za-z_]\w*\)")


class StateSpaceRefits:
    """Where the judge of one output of a state-space model refits (a
    :class:`~arxid.diagnosis.judge.CandidateRefits`): every refit is the diagnosed model with the
    candidate's effects as inputs (:meth:`StateSpaceOutput.extended`), validated on that output.

    ``fits`` holds the refitted models by their effects, shared by the judges of all outputs: a
    refit is one model of every output, so an effect that does not read the output is refitted once.
    """

    def __init__(
        self, data: IOData, validation: IOData, horizon: int | None, fits: dict[tuple, StateSpaceOutput]
    ) -> None:
        self.data, self.validation, self.horizon, self.fits = data, validation, horizon, fits

    def prepare(self, cands: Sequence[Candidate], simple: Sequence[Candidate], initial: str) -> None:
        """Nothing to make ahead: each refit is one least-squares fit of B, D and x0."""

    def hold(self, cands: Sequence[Candidate]) -> None:
        """Nothing to hold (see :meth:`prepare`)."""

    def validated(self, model: Any, c: Candidate, initial: str) -> tuple[Any, float]:
        """``model`` (a :class:`StateSpaceOutput`) refitted with ``c``'s effects, and the output's
        validation error at the judge's horizon from ``initial`` (the baseline's initial state).

        Parameters
        ----------
        model : StateSpaceOutput
        c : Candidate
        initial : {"zero", "estimate"}

        Returns
        -------
        tuple of (StateSpaceOutput, float)
        """
        one = self.data.output(model.output)
        reads_output = any(uses_output(e, one) for e in c.effects)
        key = (tuple(sorted(c.effects)), model.output if reads_output else "")
        if key not in self.fits:
            self.fits[key] = model.extended(self.data, c.effects)
        fitted = replace(self.fits[key], output=model.output)
        return fitted, fitted.validation_rms(self.validation, self.horizon, initial)


def diagnose_state_space(
    model: StateSpaceModel,
    data: IOData | None,
    validation: IOData | None,
    *,
    candidates: str | Sequence[str] = "auto",
    horizon: int | None = None,
    alpha: float = 0.01,
    min_improvement: float = 0.05,
    n_refit: int = 8,
    residual_max_lag: int = 25,
    simple_explanations: Sequence[str] = SIMPLE_EXPLANATIONS,
    initial: str = "zero",
    loop_signals: Sequence[str] = (),
) -> Diagnosis | PerOutput[Diagnosis]:
    """The diagnosis of each output of ``model`` (the arguments of :func:`arxid.diagnose`).

    Parameters
    ----------
    model : StateSpaceModel
    data : IOData
        Estimation data with every output of the model (a state-space model does not keep them).
    validation : IOData, optional
        Validation data with every output (default: ``data``).
    candidates : "auto" or sequence of str
        Effects and pairs only (no structure change, no threshold scan).
    horizon : int or None
    alpha, min_improvement : float
    n_refit, residual_max_lag : int
    simple_explanations : sequence of str
    initial : {"zero", "estimate"}
        Initial state of every validation error: zero, or fitted to the validation data.
    loop_signals : sequence of str

    Returns
    -------
    Diagnosis or PerOutput of Diagnosis
        One output: its diagnosis; several: one per output, by name.
    """
    if data is None:
        raise ArxidError(
            "a state-space model does not keep its data: pass the estimation data (all of its outputs) "
            "to diagnose(model, data, validation)"
        )
    same = validation is None
    data = in_model_order(model, data, "the estimation data")
    validation = data if validation is None else in_model_order(model, validation, "the validation data")
    horizon = check_horizon(horizon)
    if initial not in ("zero", "estimate"):
        raise DataError(f'initial must be "zero" or "estimate", got {initial!r}')
    if not 0 < alpha < 1:
        raise ArxidError(f"alpha must be between 0 and 1, got {alpha}")
    if not 0 <= min_improvement < 1:
        raise ArxidError(f"min_improvement must be in [0, 1), got {min_improvement}")
    if horizon is None and not model.is_stable:
        horizon = INTEGRATING_HORIZON  # an unstable or integrating free run drifts away
    settings = (alpha, min_improvement, n_refit, residual_max_lag, tuple(simple_explanations), initial)
    tests = _residual_tests(model, validation, residual_max_lag)
    fits: dict[tuple, StateSpaceOutput] = {}  # the refits by effects: one model of every output
    shared = (tuple(loop_signals), tests, fits)
    found = {
        name: _one_output(StateSpaceOutput(model, name), data, validation, same, candidates, horizon, shared, settings)
        for name in model.output_names
    }
    return found[model.output_names[0]] if len(found) == 1 else PerOutput(found)


def _residual_tests(model: StateSpaceModel, validation: IOData, max_lag: int) -> dict[str, Any]:
    """The residual analysis of each output on the validation data (empty when it cannot run)."""
    try:
        found = residuals(model, validation, max_lag=max_lag)
    except ArxidError:
        return {}
    return dict(found) if isinstance(found, PerOutput) else {model.output_names[0]: found}


def _one_output(
    view: StateSpaceOutput,
    data: IOData,
    validation: IOData,
    same: bool,
    candidates: str | Sequence[str],
    horizon: int | None,
    shared: tuple[tuple[str, ...], dict[str, Any], dict[tuple, StateSpaceOutput]],
    settings: tuple,
) -> Diagnosis:
    alpha, min_improvement, n_refit, _, simple, initial = settings
    loop_signals, tests, fits = shared
    one = data.output(view.output)
    y_val = validation.outputs[:, view.index]
    pred = view.predict(validation, horizon, initial)
    base_rms = metrics.prediction_rms(y_val, pred)
    if math.isnan(base_rms):
        raise DataError(f"the validation data ({validation.n_samples} samples) are too short for a prediction")
    if horizon is None and math.isinf(base_rms):
        horizon = INTEGRATING_HORIZON
        pred = view.predict(validation, horizon, initial)
        base_rms = metrics.prediction_rms(y_val, pred)
    cands, auto = _candidates(candidates, view, one, loop_signals)
    scored, notes = _score(OutputRegressors(view, data, [e for c in cands for e in c.effects]), cands)
    refits = StateSpaceRefits(data, validation, horizon, fits)
    judge = Judge(view, data, validation, horizon, base_rms, min_improvement, initial, refits=refits)  # type: ignore[arg-type]
    suspects = judge.suspects(scored, notes, alpha, n_refit if auto else None)
    suspects = judge.simplest_first(demote_pairs(suspects, min_improvement), simple)
    suspects = judge.conditional_on_top(suspects)
    suspects = finish_suspects(notes, cands, suspects, one)
    rtests = tests.get(view.output)
    val_one = validation.output(view.output)
    rest = None if rtests is None else remaining_disturbance(view, val_one, y_val - pred, rtests.is_white)  # type: ignore[arg-type]
    return Diagnosis(
        view,  # type: ignore[arg-type]
        data,  # all outputs: apply(k) refits the model of all of them
        validation,
        horizon,
        base_rms,
        metrics.prediction_rms(y_val, view.predict(validation, 1, initial)),
        metrics.fit_percent(y_val, pred),
        tuple(suspects),
        rtests,
        alpha,
        min_improvement,
        len(scored),
        same,
        (),
        rest,
    )


def _candidates(
    candidates: str | Sequence[str], view: StateSpaceOutput, one: IOData, loop_signals: tuple[str, ...]
) -> tuple[list[Candidate], bool]:
    """The effects to test on one output, and whether they were ``"auto"``."""
    auto = isinstance(candidates, str)
    if auto:
        if candidates != "auto":
            raise ArxidError(f"candidates must be 'auto' or a list of effect strings, got {candidates!r}")
        labels = [e for e in auto_effects(one, lambda: _integrates(view), loop_signals) if not _SCAN.fullmatch(e)]
    else:
        labels = list(candidates)
        for label in labels:
            if isinstance(label, str) and _SCAN.fullmatch(label.replace(" ", "")):
                raise OrderError(f"{label!r} {NOT_A_STATE_SPACE_CANDIDATE}")
    cands, _ = candidate_list(labels, view, one)  # type: ignore[arg-type]
    for c in cands:
        if c.kind not in ("effect", "pair"):
            raise OrderError(f"{c.label!r} {NOT_A_STATE_SPACE_CANDIDATE}")
    return cands, auto


def _integrates(view: StateSpaceOutput) -> bool:
    """Whether the model has a pole at 1 (within 1e-3): its output is then a position."""
    return bool(np.any(np.abs(view.model.poles - 1.0) < 1e-3))


def _score(regressors: OutputRegressors, cands: list[Candidate]) -> tuple[list[dict], dict[str, str]]:
    """The score test of each candidate on one output, with Holm-corrected p-values."""
    scored: list[dict] = []
    notes: dict[str, str] = {}
    for c in cands:
        try:
            res, why = regressors.test(c.effects)
        except (OrderError, DataError) as exc:
            res, why = None, str(exc)
        if res is None:
            notes[c.label] = why
        else:
            scored.append(scored_entry(c, res))
    for s, p in zip(scored, holm(np.array([s["p"] for s in scored]))):
        s["p_adj"] = float(p)
    return scored, notes
