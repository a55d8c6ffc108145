"""Which physical effect is the model missing? :func:`diagnose`, :class:`Diagnosis`, :class:`Ladder`.

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
5. Strong candidates are also tried together with ``const`` (asymmetric Coulomb friction is
   c·sign(v) plus an offset); the pair is reported as one suspect, ``sign(dy)+const``.

:class:`Ladder` then adds the best significant suspect, re-diagnoses, and repeats — the error falls
step by step.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, cast

import numpy as np

from .._base import metrics
from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from ..checks import ResidualAnalysis, error_rms, prediction_error, residuals
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from ..models.arguments import check_data, check_horizon, check_model
from ..models.arx_model import ArxModel
from ..models.effects import compile_effects, format_threshold, parse_effect
from ..models.polynomial import PolynomialModel
from ..models.regressors import max_lag, regressor_matrix, regressor_names
from .added_variable import AddedVariableResult, AddedVariableTest, holm
from .candidates import auto_candidates, candidate_input_names, output_integrates, physics, scan_threshold
from .nonlinearity import NonlinearDependence, dependence_sentence, nonlinear_dependence
from .polynomial import refit_structure, refit_with_effects, score_effects, score_structure

if TYPE_CHECKING:
    from .ladder import Ladder

__all__ = ["diagnose", "Diagnosis", "Suspect", "auto_candidates", "INTEGRATING_HORIZON"]

#: Validation errors within this share of the lowest count as a tie between suspects of a
#: polynomial model (the one adding fewer parameters is then the best).
TIE_SHARE = 0.01

#: k used for the validation error of a plant with an integrator (free run drifts).
INTEGRATING_HORIZON = 10


# ---------------------------------------------------------------------------------------------
# candidates
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Candidate:
    label: str
    effects: tuple[str, ...]
    na: int
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    kind: str  # "effect", "pair", "dynamics" or "scan" (a threshold to find: dz(u1), sat(u1))


def _dynamics(label: str, model: ArxModel) -> _Candidate | None:
    na, nb, nk = model.na_, list(model.nb_), list(model.nk_)
    if label == "na+1":
        return _Candidate(label, (), na + 1, tuple(nb), tuple(nk), "dynamics")
    mt = re.fullmatch(r"(nb|nk)(?:\((?P<name>[^)]+)\))?(?P<sign>[+-])1", label)
    if not mt:
        return None
    name = mt["name"]
    if name is None:
        idx = list(range(len(nb)))
    elif name in model.input_names:
        idx = [model.input_names.index(name)]
    else:
        raise OrderError(f"candidate {label!r}: no input named {name!r}; inputs: {list(model.input_names)}")
    step = 1 if mt["sign"] == "+" else -1
    for i in idx:
        if mt[1] == "nb":
            nb[i] += step
        else:
            nk[i] += step
    if min(nb) < 0 or min(nk) < 0:
        raise OrderError(f"candidate {label!r} would make an order negative")
    return _Candidate(label, (), na, tuple(nb), tuple(nk), "dynamics")


def _parse_candidate(label: str, model: ArxModel, data: IOData) -> _Candidate:
    if not isinstance(label, str) or not label.strip():
        raise OrderError(f"a candidate must be a non-empty string such as 'u1^2', 'y^3' or 'na+1', got {label!r}")
    label = label.replace(" ", "")
    if isinstance(model, PolynomialModel) and _POLY_CHANGE.fullmatch(label):
        return _Candidate(label, (), model.na_, model.nb_, model.nk_, "dynamics")
    dyn = _dynamics(label, model)
    if dyn is not None:
        return dyn
    scan = _SCAN.fullmatch(label)
    if scan:
        parse_effect(f"{scan['op']}({scan['signal']},1)", data)  # the signal must exist
        return _Candidate(label, (), model.na_, model.nb_, model.nk_, "scan")
    parts = tuple(p for p in label.split("+") if p)
    for p in parts:
        parse_effect(p, data)  # raises OrderError with a readable message
    # An effect the model already has is not named again: "sign(y)+const" on a model with sign(y) is "const".
    new = tuple(p for p in parts if p not in model.effects) or parts
    kind = "pair" if len(new) > 1 else "effect"
    return _Candidate("+".join(new), new, model.na_, model.nb_, model.nk_, kind)


#: A structure change of a polynomial model (one more pole of A or F, one more zero, another delay).
_POLY_CHANGE = re.compile(r"(na|nb|nf|nk)(\([^)]+\))?[+-]1")
#: A threshold candidate whose threshold the diagnosis scans for.
_SCAN = re.compile(r"(?P<op>dz|sat)\((?P<signal>[A-Za-z_]\w*)\)")


def _has_threshold(model: ArxModel, signal: str) -> bool:
    return any(e.startswith((f"dz({signal},", f"sat({signal},")) for e in model.effects)


def _layout_for(c: _Candidate, model: ArxModel, data: IOData):
    effects = tuple(model.effects) + tuple(e for e in c.effects if e not in model.effects)
    layout = compile_effects(effects, data, c.nb, c.nk)
    return effects, layout


# ---------------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Suspect:
    """One candidate explanation of the model's error.

    Attributes
    ----------
    effect : str
        What is added: an effect (``u1^2``), a pair (``sign(dy)+const``) or a structure change
        (``na+1``, ``nb+1``, ``nk-1``).
    kind : str
        ``"effect"``, ``"pair"`` or ``"dynamics"``.
    score : float
        Added-variable (partial) correlation with the one-step residual, in [0, 1]; its square is
        the share of residual energy the candidate removes on the estimation data.
    f_statistic : float
        Partial F statistic of the added columns.
    p_value_raw, p_value : float
        F-test p-value, and the same corrected for the number of candidates (Holm).
    n_columns : int
        Regressor columns the candidate adds.
    rms_sim_val_after : float
        Validation error (free run, or k-step) of the model refitted with the candidate; NaN when
        it was not refitted, inf when its simulation diverges.
    improvement : float
        1 − rms_after / rms_before (0.6 = the validation error fell by 60%).
    significant : bool
        Corrected p-value below ``alpha`` and improvement of at least ``min_improvement``.
    note : str
        Why a candidate could not be scored or refitted, or why it is not significant, if so.
    physics : str
        What the candidate stands for (``"Coulomb friction on a speed output"``; see
        :data:`arxid.candidates.CATALOGUE`).
    explained_by : str
        The suspect that makes this one unnecessary (``""`` when none): once it is in the model,
        adding this one gains less than ``min_improvement``.
    """

    effect: str
    kind: str
    effects: tuple[str, ...]
    na: int
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    score: float
    f_statistic: float
    p_value_raw: float
    p_value: float
    n_columns: int
    rms_sim_val_after: float
    improvement: float
    significant: bool
    note: str = ""
    model: ArxModel | None = field(default=None, repr=False, compare=False)
    physics: str = ""
    explained_by: str = ""

    @property
    def refitted(self) -> bool:
        """True when the model was refitted with the candidate (``rms_sim_val_after`` is not NaN)."""
        return not math.isnan(self.rms_sim_val_after)

    def to_dict(self) -> dict:
        """The CLI contract: ``effect``, ``score``, ``p_value``, ``significant``, ``rms_sim_val_after``.

        Returns
        -------
        dict
            Those keys plus ``kind``, ``improvement``, ``note`` and ``explained_by`` (None when no
            other suspect explains it); NaN and inf become None.
        """
        return {
            "effect": self.effect,
            "kind": self.kind,
            "score": finite_or_none(float(self.score)),
            "p_value": finite_or_none(float(self.p_value)),
            "significant": bool(self.significant),
            "rms_sim_val_after": finite_or_none(float(self.rms_sim_val_after)),
            "improvement": finite_or_none(float(self.improvement)),
            "note": self.note,
            "physics": self.physics,
            "explained_by": self.explained_by or None,
        }


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Ranked suspects for a model's error, with the baseline they are judged against.

    Attributes
    ----------
    model : ArxModel
        The model diagnosed.
    data, validation : IOData
        Estimation data (scores) and validation data (refits are judged on it).
    horizon : int or None
        Validation error measure: None = free run; k = k-step (chosen automatically for plants with
        an integrator, or when the baseline's free run diverges).
    rms_sim_val, rms_pred_val, fit_val : float
        Baseline validation error at ``horizon``, one-step validation RMS, and fit percent at
        ``horizon``.
    suspects : tuple of Suspect
        Significant suspects first (lowest validation error first), then the other refitted ones
        by validation error, then the rest by p-value.
    residual_tests : ResidualAnalysis or None
        Residual analysis of the model on the validation data.
    alpha, min_improvement : float
    n_tested : int
        Number of hypotheses in the multiple-comparison correction.
    validation_is_estimation : bool
        True when no separate validation data were given.
    nonlinear_dependence : tuple of NonlinearDependence
        Signals and lags on which the model's residual still depends nonlinearly
        (:func:`arxid.nonlinearity.nonlinear_dependence`, on the estimation data).
    """

    model: ArxModel
    data: IOData = field(repr=False)
    validation: IOData = field(repr=False)
    horizon: int | None
    rms_sim_val: float
    rms_pred_val: float
    fit_val: float
    suspects: tuple[Suspect, ...]
    residual_tests: ResidualAnalysis | None = field(default=None, repr=False)
    alpha: float = 0.01
    min_improvement: float = 0.05
    n_tested: int = 0
    validation_is_estimation: bool = False
    nonlinear_dependence: tuple[NonlinearDependence, ...] = ()

    @property
    def unexplained(self) -> str:
        """The sentence for a nonlinear dependence no candidate removes (``""`` when there is a
        significant suspect, or no such dependence)."""
        return "" if self.significant else dependence_sentence(self.nonlinear_dependence)

    @property
    def significant(self) -> tuple[Suspect, ...]:
        """The significant suspects, best first (empty: no missing effect found)."""
        return tuple(s for s in self.suspects if s.significant)

    @property
    def top(self) -> Suspect | None:
        """The best significant suspect, or None."""
        sig = self.significant
        return sig[0] if sig else None

    def suspect(self, effect: str) -> Suspect:
        """The suspect for ``effect`` (e.g. ``"y^3"``).

        Parameters
        ----------
        effect : str
            The suspect's name as listed (an effect, a pair or a structure change such as ``na+1``).

        Returns
        -------
        Suspect

        Raises
        ------
        ArxidError
            When there is no such suspect.
        """
        for s in self.suspects:
            if s.effect == effect:
                return s
        raise ArxidError(f"no suspect {effect!r}; suspects: {[s.effect for s in self.suspects]}")

    def rank(self, effect: str) -> int:
        """0-based rank of ``effect`` among the suspects.

        Parameters
        ----------
        effect : str
            The suspect's name (see :meth:`suspect`).

        Returns
        -------
        int
            Its position in ``suspects`` (0 = best).

        Raises
        ------
        ArxidError
            When there is no such suspect.
        """
        return self.suspects.index(self.suspect(effect))

    def apply(self, k: int | str = 0) -> ArxModel:
        """The model refitted on the estimation data with suspect ``k`` added.

        Parameters
        ----------
        k : int or str
            Rank (0 = best) or the suspect's name (``"y^3"``).

        Returns
        -------
        ArxModel
            The extended model (the refit made during the diagnosis when there was one).

        Raises
        ------
        ArxidError
            When there are no suspects, or ``k`` names or indexes none.
        """
        if isinstance(k, str):
            s = self.suspect(k)
        else:
            if not self.suspects:
                raise ArxidError("there are no suspects to apply")
            try:
                s = self.suspects[k]
            except (IndexError, TypeError):
                raise ArxidError(
                    f"suspect index {k!r} is out of range: there are {len(self.suspects)} suspects"
                ) from None
        if s.model is not None:
            return s.model
        return _refit(self.model, self.data, s)

    def why(self, s: Suspect) -> str:
        """Why ``s`` is or is not significant, in one phrase (its ``note`` when it has one).

        Parameters
        ----------
        s : Suspect

        Returns
        -------
        str
            e.g. ``explained by y^3+const: no gain once it is added`` or ``validation error falls
            only 2 % (needs 5 %)``.
        """
        if s.note:
            return s.note
        need = f"{100 * self.min_improvement:.0f} %"
        if not math.isfinite(s.p_value) or s.p_value >= self.alpha:
            return f"p-value {s.p_value:.2g} is not below {self.alpha:g}: no evidence it is missing"
        if not s.refitted:
            return "not refitted: only the best-scored candidates are judged on validation data"
        if not math.isfinite(s.improvement):
            return "the free run with it diverges"
        if s.significant:
            return f"validation error falls {100 * s.improvement:.0f} %"
        if s.improvement < 0:
            return f"validation error rises {-100 * s.improvement:.0f} % (needs to fall {need})"
        return f"validation error falls only {100 * s.improvement:.1f} % (needs {need})"

    def __str__(self) -> str:
        base = (
            f"diagnosis of {self.model.structure_name()}: validation error ({horizon_label(self.horizon)}) "
            f"{self.rms_sim_val:.4g}, fit {self.fit_val:.2f}%, one-step rms {self.rms_pred_val:.4g}"
        )
        lines = [base]
        if self.validation_is_estimation:
            lines.append("  (no validation data given: judged on the estimation data)")
        if self.residual_tests is not None:
            rt = self.residual_tests
            lines.append(
                f"  residual: Ljung–Box p = {rt.ljung_box_p_value:.3g} ({'white' if rt.is_white else 'not white'})"
            )
        rows = []
        for i, s in enumerate(self.suspects[:15]):
            rows.append(
                (
                    i,
                    s.effect,
                    s.score,
                    s.p_value,
                    s.rms_sim_val_after,
                    f"{100 * s.improvement:+.1f}%" if s.refitted and math.isfinite(s.improvement) else "",
                    "yes" if s.significant else "",
                    s.note if len(s.note) <= 48 else s.note[:45] + "...",
                )
            )
        lines.append(
            text_table(
                ["#", "suspect", "score", "p (Holm)", "val rms after", "change", "significant", "note"], rows, digits=3
            )
        )
        if not self.significant:
            lines.append(
                "no significant missing effect: no candidate passes both the corrected F-test "
                f"(alpha {self.alpha}) and a {100 * self.min_improvement:.0f}% validation improvement"
            )
            if self.unexplained:
                lines.append(self.unexplained)
        else:
            top = self.significant[0]
            what = f" — {top.physics}" if top.physics else ""
            lines.append(
                f"best: add {top.effect}{what} (validation error {self.rms_sim_val:.4g} -> "
                f"{top.rms_sim_val_after:.4g}); diagnosis.apply(0) refits with it"
            )
        return "\n".join(lines)

    def to_dict(self, ladder: Ladder | None = None) -> dict:
        """The machine-readable report (the ``arxid diagnose --json`` contract).

        Keys ``model`` (na, nb, nk, effects), ``baseline`` (rms_sim_val, rms_pred_val, fit_val,
        horizon), ``residual_tests``, ``suspects`` (effect, score, p_value, significant,
        rms_sim_val_after) and ``ladder`` (effects, rms_sim_val); without ``ladder`` the ladder holds
        the diagnosed model only.

        Parameters
        ----------
        ladder : Ladder, optional
            Steps to report under ``ladder`` (see :meth:`Ladder.to_list`).

        Returns
        -------
        dict
            JSON-ready; NaN and inf become None.
        """
        m = self.model
        if ladder is None:
            steps = [{"effects": list(m.effects), "rms_sim_val": finite_or_none(float(self.rms_sim_val))}]
        else:
            steps = ladder.to_list()
        return {
            "model": {
                "na": m.na_,
                "nb": list(m.nb_),
                "nk": list(m.nk_),
                "structure": m.structure_name(),
                "effects": list(m.effects),
                **_polynomial_orders(m),
            },
            "baseline": {
                "rms_sim_val": finite_or_none(float(self.rms_sim_val)),
                "rms_pred_val": finite_or_none(float(self.rms_pred_val)),
                "fit_val": finite_or_none(float(self.fit_val)),
                "horizon": self.horizon,
            },
            "residual_tests": self.residual_tests.to_dict() if self.residual_tests is not None else {},
            "suspects": [{**s.to_dict(), "why": self.why(s)} for s in self.suspects],
            "ladder": steps,
            "nonlinear_dependence": (ladder.diagnoses[-1] if ladder and ladder.diagnoses else self).dependence_dict(),
        }

    def dependence_dict(self) -> dict:
        """``{"signals": [...], "unexplained": sentence}``: where the residual still depends nonlinearly.

        Returns
        -------
        dict
            ``signals`` one dict per :class:`~arxid.nonlinearity.NonlinearDependence`;
            ``unexplained`` the sentence of :attr:`unexplained`.
        """
        return {"signals": [d.to_dict() for d in self.nonlinear_dependence], "unexplained": self.unexplained}

    def to_json(self, indent: int | None = 2, ladder: Ladder | None = None) -> str:
        """JSON of :meth:`to_dict` (the ``arxid diagnose --json`` output).

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.
        ladder : Ladder, optional
            Steps to report under ``ladder``.

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(ladder), indent=indent)

    def to_pandas(self):
        """One row per suspect: score, p-values, validation error after, improvement, significant.

        Returns
        -------
        pandas.DataFrame
            Rows in ranked order; columns ``suspect``, ``kind``, ``score``, ``f_statistic``,
            ``p_value_raw``, ``p_value``, ``rms_sim_val_after``, ``improvement``, ``significant``, ``note``.
        """
        pd = require_pandas()
        return pd.DataFrame(
            [
                {
                    "suspect": s.effect,
                    "kind": s.kind,
                    "score": s.score,
                    "f_statistic": s.f_statistic,
                    "p_value_raw": s.p_value_raw,
                    "p_value": s.p_value,
                    "rms_sim_val_after": s.rms_sim_val_after,
                    "improvement": s.improvement,
                    "significant": s.significant,
                    "note": s.note,
                }
                for s in self.suspects
            ]
        )

    def plot(self, n: int = 12):
        """Scores and validation change of the top ``n`` suspects.

        Parameters
        ----------
        n : int
            Suspects to show, best first.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_diagnosis

        return plot_diagnosis(self, n)


def _polynomial_orders(m: ArxModel) -> dict:
    """A polynomial model's class and orders beyond na, nb, nk (nothing for ARX: its contract is fixed)."""
    if not isinstance(m, PolynomialModel):
        return {}
    return {"kind": m.kind, "nc": m.nc_, "nd": m.nd_, "nf": list(m.nf_)}


# ---------------------------------------------------------------------------------------------
# the procedure
# ---------------------------------------------------------------------------------------------
def _refit(model: ArxModel, data: IOData, c) -> ArxModel:
    if isinstance(model, PolynomialModel):  # a structure change, or effects as extra inputs
        if c.kind == "dynamics":
            label = c.label if isinstance(c, _Candidate) else c.effect
            return cast(ArxModel, refit_structure(model, data, label, candidate_input_names(data)))
        return cast(ArxModel, refit_with_effects(model, data, c.effects))
    effects = tuple(model.effects) + tuple(e for e in c.effects if e not in model.effects)
    return ArxModel(na=c.na, nb=c.nb, nk=c.nk, effects=effects).fit(data, first_lag=model.first_lag_)


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
) -> Diagnosis:
    """Rank the physical effects (and structure changes) the model is missing.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
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
    'u1^2'
    """
    model = check_model(model)
    polynomial = isinstance(model, PolynomialModel)
    data, validation, same = _data_pair(model, data, validation)
    horizon = check_horizon(horizon)
    if not 0 < alpha < 1:
        raise ArxidError(f"alpha must be between 0 and 1, got {alpha}")
    if not 0 <= min_improvement < 1:
        raise ArxidError(f"min_improvement must be in [0, 1), got {min_improvement}")
    base = _baseline(model, validation, horizon, residual_max_lag)
    cands, auto = _candidate_list(candidates, model, data)
    scoring = None if polynomial else _Scoring(model, data, cands)
    scored, notes = _score_polynomial(model, data, cands) if scoring is None else scoring.run(alpha, n_pairs)
    judge = _Judge(model, data, validation, base.horizon, base.rms, min_improvement)
    suspects = judge.suspects(scored, notes, alpha, n_refit if auto else None)
    suspects = _demote_pairs(suspects, min_improvement)
    suspects = judge.conditional_on_top(suspects)
    if scoring is not None and auto and not any(s.significant for s in suspects):
        # Two effects can hide each other: try the strongest candidate with its strongest partner.
        masked = scoring.masked_pairs(scored, alpha)
        suspects = _demote_pairs(suspects + judge.suspects(masked, notes, alpha, None), min_improvement)
    suspects += _unscored(notes, cands, suspects)
    suspects = sorted((replace(s, physics=physics(s.effect, data)) for s in suspects), key=_rank_key)
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
        () if polynomial else _dependence(model, data, alpha),
    )


def _score_polynomial(model, data: IOData, cands: list[_Candidate]) -> tuple[list[dict], dict[str, str]]:
    """Score tests on a polynomial model (see arxid.polynomial_diagnosis): effects of the inputs and
    of the simulated output as extra inputs, threshold scans, and structure changes."""
    scored: list[dict] = []
    notes: dict[str, str] = {}
    names = candidate_input_names(data)
    for c in cands:
        try:
            if c.kind == "scan":
                res, why = _scan_polynomial(model, data, c, notes)
            elif c.kind == "dynamics":
                res, why = score_structure(model, data, c.label, names)
            else:
                res, why = score_effects(model, data, c.effects)
        except (OrderError, DataError) as exc:
            res, why = None, str(exc)
        if res is None:
            notes[c.label] = why
        elif isinstance(res, tuple) and any(x["c"].label == res[0].label for x in scored):
            continue  # dz(u) and sat(u) scanned to the same threshold and shape
        else:
            scored.append(_scored(res[0], res[1]) if isinstance(res, tuple) else _scored(c, res))
            if isinstance(res, tuple):
                scored[-1]["p"] = min(1.0, scored[-1]["p"] * res[2])
    for s, pa in zip(scored, holm(np.array([s["p"] for s in scored]))):
        s["p_adj"] = float(pa)
    return scored, notes


def _scan_polynomial(model, data: IOData, c: _Candidate, notes: dict[str, str]):
    """The threshold of ``dz(u)`` / ``sat(u)`` on a polynomial model by the grid scan of
    :func:`arxid.candidates.scan_threshold` on the score test. With u in the model through the same
    B/F, ``dz(u,c)`` and ``sat(u,c)`` add the same gradient span (sat = u − dz): one scan serves
    both, and the shape is named from the refit's static gains (a dead zone answers small inputs
    with less gain than large ones, a saturation with more)."""
    op, signal = c.label[: c.label.index("(")], c.label[c.label.index("(") + 1 : -1]
    x = np.asarray(data.signal(signal), dtype=float)

    def label(shape: str, t: float) -> str:
        return f"{shape}({signal},{format_threshold(t)})"

    def score(t: float) -> float:
        res = score_effects(model, data, [label(op, t)])[0]
        return math.nan if res is None else res.score

    t, n = scan_threshold(x, score)
    if not math.isfinite(t):
        return None, "no threshold could be tested" if n else f"|{signal}| takes too few distinct values to scan"
    best = label(_threshold_shape(model, data, signal, label(op, t)), t)
    res, why = score_effects(model, data, [best])
    if res is None:
        return None, why
    notes[best] = f"threshold scanned over {n} quantiles of |{signal}| (p-value x {n})"
    cand = _Candidate(best, (best,), model.na_, model.nb_, model.nk_, "effect")
    return (cand, res, n), ""


def _threshold_shape(model, data: IOData, signal: str, effect: str) -> str:
    """``dz`` or ``sat`` for a threshold on input ``signal``: the small-signal gain (|u| < c) against
    the large-signal one (|u| > c) of ``model`` refitted with ``effect`` beside the input."""
    op = effect[: effect.index("(")]
    names = candidate_input_names(data)
    if signal not in names:
        return op
    try:
        gains = refit_with_effects(model, data, [effect]).dc_gain()
    except ArxidError:
        return op
    own, extra = float(gains[names.index(signal)]), float(gains[-1])
    small, large = (own, own + extra) if op == "dz" else (own + extra, own)
    return "dz" if abs(small) < abs(large) else "sat"


def _refit_and_validate(model, data: IOData, validation: IOData, c, horizon: int | None) -> tuple[ArxModel, float]:
    """The model refitted with candidate ``c`` and its validation error at ``horizon``."""
    fitted = _refit(model, data, c)
    return fitted, error_rms(fitted, validation, horizon)


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


def _baseline(model: ArxModel, validation: IOData, horizon: int | None, max_lag: int) -> _Baseline:
    """The model's validation errors; a free run that drifts or diverges is measured k steps ahead."""
    if horizon is None and output_integrates(model):
        horizon = INTEGRATING_HORIZON
    rms = error_rms(model, validation, horizon)
    if math.isnan(rms):  # no sample of the validation data has a prediction
        raise DataError(
            f"the validation data ({validation.n_samples} samples) are too short for a prediction by "
            f"{model.structure_name()}; give longer validation data (or a smaller estimation fraction)"
        )
    if horizon is None and math.isinf(rms):
        horizon = INTEGRATING_HORIZON
        rms = error_rms(model, validation, horizon)
    pred, _, _ = prediction_error(model, validation, horizon)
    try:
        rtests = residuals(model, validation, max_lag=max_lag)
    except ArxidError:
        rtests = None
    return _Baseline(horizon, rms, error_rms(model, validation, 1), metrics.fit_percent(validation.y, pred), rtests)


def _candidate_list(candidates, model: ArxModel, data: IOData) -> tuple[list[_Candidate], bool]:
    auto = isinstance(candidates, str)
    if auto:
        if candidates != "auto":
            raise ArxidError(f"candidates must be 'auto' or a list of effect strings, got {candidates!r}")
        labels = auto_candidates(model, data)
    else:
        labels = list(candidates)
        if not labels:
            raise ArxidError("candidates is empty: give 'auto' or at least one effect such as 'u1^2'")
    cands: dict[str, _Candidate] = {}
    for lab in labels:
        c = _parse_candidate(lab, model, data)
        if c.kind in ("effect", "pair") and all(e in model.effects for e in c.effects):
            continue
        if c.kind == "scan" and _has_threshold(model, c.label[c.label.index("(") + 1 : -1]):
            continue
        cands.setdefault(c.label, c)
    return list(cands.values()), auto


class _Scoring:
    """Added-variable tests of every candidate against the model's regressors on common rows."""

    def __init__(self, model: ArxModel, data: IOData, cands: list[_Candidate]):
        self.model, self.data, self.cands = model, data, cands
        self.notes: dict[str, str] = {}
        self.base_layout = compile_effects(model.effects, data, model.nb_, model.nk_)
        self.base_names = set(regressor_names(data.output_name, model.na_, self.base_layout))
        lag = max(model.first_lag_, max_lag(model.na_, self.base_layout))
        self.prepared = []
        self.scans: dict[str, list[_Candidate]] = {}
        for c in cands:
            if c.kind == "scan":
                self.scans.setdefault(c.label[c.label.index("(") + 1 : -1], []).append(c)
                continue
            try:
                _, lay = _layout_for(c, model, data)
            except (OrderError, DataError) as exc:
                self.notes[c.label] = str(exc)
                continue
            lag = max(lag, max_lag(c.na, lay))
            self.prepared.append((c, lay))
        self.lag = lag
        self.phi0, self.y0, self.rows0 = regressor_matrix(data, model.na_, self.base_layout, lag)
        if len(self.rows0) <= self.phi0.shape[1] + 2:
            raise DataError(
                f"too few regression rows ({len(self.rows0)}) to diagnose a model with {self.phi0.shape[1]} parameters"
            )
        self.proj0 = AddedVariableTest(self.phi0, self.y0)
        self.single_z: dict[str, np.ndarray] = {}

    def run(self, alpha: float, n_pairs: int) -> tuple[list[dict], dict[str, str]]:
        scored = [s for s in (self._score(c, lay) for c, lay in self.prepared) if s is not None]
        scored += [s for s in (self._scan(sig, group) for sig, group in self.scans.items()) if s is not None]
        scored = self._one_direction_term(scored)
        if "const" not in self.model.effects and n_pairs > 0:
            scored += self._pairs_with_offset(scored, alpha, n_pairs)
        for s, pa in zip(scored, holm(np.array([s["p"] for s in scored]))):
            s["p_adj"] = float(pa)
        return scored, self.notes

    def _columns(self, c: _Candidate, lay) -> tuple[np.ndarray, np.ndarray]:
        names = regressor_names(self.data.output_name, c.na, lay)
        phi, _, rows = regressor_matrix(self.data, c.na, lay, self.lag)
        new = [i for i, nm in enumerate(names) if nm not in self.base_names]
        return phi[:, new], rows

    def _score(self, c: _Candidate, lay) -> dict | None:
        z, rows = self._columns(c, lay)
        if z.shape[1] == 0:
            self.notes[c.label] = "adds no regressor"
            return None
        proj = self.proj0
        if not (len(rows) == len(self.rows0) and np.array_equal(rows, self.rows0)):
            # a candidate with missing samples: test on the rows both have
            common, i0, i1 = np.intersect1d(self.rows0, rows, return_indices=True)
            if len(common) <= self.phi0.shape[1] + z.shape[1] + 2:
                self.notes[c.label] = "too few rows where its signal exists"
                return None
            proj, z = AddedVariableTest(self.phi0[i0], self.y0[i0]), z[i1]
        res, why = proj.test(z)
        if res is None:
            self.notes[c.label] = why
            return None
        if proj is self.proj0:
            self.single_z[c.label] = z
        return _scored(c, res)

    def _threshold_columns(self, op: str, signal: str, c: float) -> tuple[_Candidate, np.ndarray]:
        """The candidate ``op(signal,c)`` and its columns on the common rows, read straight off the
        effect's series (the scan tries some forty thresholds, so no regressor matrix is rebuilt)."""
        label = f"{op}({signal},{format_threshold(c)})"
        cand = _Candidate(label, (label,), self.model.na_, self.model.nb_, self.model.nk_, "effect")
        lay = compile_effects((label,), self.data, self.model.nb_, self.model.nk_)
        col, b, k = lay.u[:, -1], lay.nb[-1], lay.nk[-1]
        z = np.column_stack([col[self.rows0 - k - j] for j in range(b)]) if b else np.zeros((len(self.rows0), 0))
        return cand, z

    def _scan(self, signal: str, group: list[_Candidate]) -> dict | None:
        """The threshold of ``dz`` / ``sat`` on ``signal`` by a grid scan (:func:`arxid.candidates.scan_threshold`).

        With the input in the model, ``dz(u,c)`` and ``sat(u,c)`` add the same span, so the two are
        one hypothesis: one scan, then the name of the shape that alone replaces the input better.
        """
        ops = [c.label[: c.label.index("(")] for c in group]
        x = np.asarray(self.data.signal(signal), dtype=float)

        def score(c: float) -> float:
            z = self._threshold_columns(ops[0], signal, c)[1]
            return self.proj0.share(z) if z.shape[1] and np.isfinite(z).all() else math.nan

        c, n = scan_threshold(x, score)
        if not math.isfinite(c):
            for cand in group:
                why = "no threshold could be tested" if n else f"|{signal}| takes too few distinct values to scan"
                self.notes[cand.label] = why
            return None
        op = self._threshold_shape(signal, c) if len(ops) > 1 else ops[0]
        cand, z = self._threshold_columns(op, signal, c)
        res, why = self.proj0.test(z)
        if res is None:
            self.notes[group[0].label] = why
            return None
        self.single_z[cand.label] = z
        self.notes[cand.label] = f"threshold scanned over {n} quantiles of |{signal}| (p-value x {n})"
        scored = _scored(cand, res)
        scored["p"] = min(1.0, scored["p"] * n)
        return scored

    def _one_direction_term(self, scored: list[dict]) -> list[dict]:
        """``abs(u)`` and ``pos(u)`` are one hypothesis when u is in the model (|u| = 2 pos(u) − u):
        keep ``abs(u)`` when the fitted gains for u > 0 and u < 0 have opposite signs (a response
        that ignores the direction), else ``pos(u)`` (different gains for the two directions)."""
        by_label = {s["c"].label: s for s in scored}
        names = self.data.input_names
        drop = set()
        for label in by_label:
            m = re.fullmatch(r"pos\((\w+)\)", label)
            if not m or f"abs({m[1]})" not in by_label or label not in self.single_z:
                continue
            sig = m[1]
            idx = names.index(sig) if sig in names else int(sig[1:]) - 1 if sig[1:].isdigit() else -1
            base = regressor_names(self.data.output_name, self.model.na_, self.base_layout)
            own = [j for j, nm in enumerate(base) if 0 <= idx < len(names) and nm.startswith(f"{names[idx]}(")]
            z = self.single_z[label]
            coef = np.linalg.lstsq(np.column_stack([self.phi0, z]), self.y0, rcond=None)[0]
            negative = float(np.sum(coef[own]))
            positive = negative + float(np.sum(coef[self.phi0.shape[1] :]))
            drop.add(f"abs({sig})" if positive * negative >= 0 else label)
        return [s for s in scored if s["c"].label not in drop]

    def _threshold_shape(self, signal: str, c: float) -> str:
        """``dz`` or ``sat``: whichever, in place of the input itself, leaves the smaller residual."""
        names = self.data.input_names
        idx = names.index(signal) if signal in names else int(signal[1:]) - 1 if signal[1:].isdigit() else -1
        if not 0 <= idx < len(names):
            return "dz"
        rss = {}
        for op in ("dz", "sat"):
            cand, _ = self._threshold_columns(op, signal, c)
            _, lay = _layout_for(cand, self.model, self.data)
            cols = regressor_names(self.data.output_name, cand.na, lay)
            phi, y, _ = regressor_matrix(self.data, cand.na, lay, self.lag)
            keep = [j for j, nm in enumerate(cols) if not nm.startswith(f"{names[idx]}(")]
            coef = np.linalg.lstsq(phi[:, keep], y, rcond=None)[0]
            rss[op] = float(np.sum((y - phi[:, keep] @ coef) ** 2))
        return min(rss, key=lambda k: rss[k])

    def masked_pairs(self, scored: list[dict], alpha: float, n_partners: int = 3) -> list[dict]:
        """Pairs for two effects that hide each other (each alone barely lowers the free-run error).

        The strongest significant effect by score is put beside the model's regressors; every other
        effect is scored again given it, and the ``n_partners`` strongest that pass ``alpha``
        (Bonferroni over those re-tests) form pairs with it. A pair's p-value is the joint F-test of
        both, Bonferroni-corrected by every hypothesis tried; it is then validated like any candidate.
        """
        singles = [s for s in scored if s["c"].kind == "effect" and s["c"].label in self.single_z]
        strong = [s for s in singles if s["p_adj"] < alpha and s["c"].label not in ("const", "time")]
        if not strong:
            return []
        first = max(strong, key=lambda s: s["score"])["c"]
        z1 = self.single_z[first.label]
        given = AddedVariableTest(np.column_stack([self.phi0, z1]), self.y0)
        n_tests = len(singles) - 1
        partners = []
        for s in singles:
            res = given.test(self.single_z[s["c"].label])[0] if s["c"] is not first else None
            if res is not None and res.p_value * n_tests < alpha:
                partners.append((res.score, s["c"]))
        out = []
        for _, c in sorted(partners, key=lambda t: -t[0])[:n_partners]:
            res = self.proj0.test(np.column_stack([z1, self.single_z[c.label]]))[0]
            if res is None:
                continue
            pair = _Candidate(f"{first.label}+{c.label}", first.effects + c.effects, c.na, c.nb, c.nk, "pair")
            scored_pair = _scored(pair, res)
            scored_pair["p_adj"] = min(1.0, res.p_value * (len(scored) + n_partners))
            out.append(scored_pair)
        return out

    def _pairs_with_offset(self, scored: list[dict], alpha: float, n_pairs: int) -> list[dict]:
        """Strong effects tried together with ``const`` (asymmetric Coulomb friction, an output
        that was not detrended: the effect only helps together with a constant)."""
        adj = holm(np.array([s["p"] for s in scored]))
        strong = sorted(
            (
                s
                for s, pa in zip(scored, adj)
                if pa < alpha
                and s["c"].kind == "effect"
                and s["c"].label not in ("const", "time")
                and s["c"].label in self.single_z
            ),
            key=lambda s: s["p"],
        )
        have = {s["c"].label for s in scored}
        out = []
        for s in strong[:n_pairs]:
            c = s["c"]
            if f"{c.label}+const" in have:
                continue
            z = np.column_stack([self.single_z[c.label], np.ones(len(self.rows0))])
            res, _ = self.proj0.test(z)
            if res is not None:
                pc = _Candidate(f"{c.label}+const", c.effects + ("const",), c.na, c.nb, c.nk, "pair")
                out.append(_scored(pc, res))
        return out


def _scored(c: _Candidate, res: AddedVariableResult) -> dict:
    return {"c": c, "score": res.score, "f": res.f_statistic, "p": res.p_value, "q": res.n_columns}


class _Judge:
    """Refits candidates and judges them by the validation error at the baseline's horizon."""

    def __init__(
        self,
        model: ArxModel,
        data: IOData,
        validation: IOData,
        horizon: int | None,
        base_rms: float,
        min_improvement: float,
    ):
        self.model, self.data, self.validation = model, data, validation
        self.horizon, self.base_rms, self.min_improvement = horizon, base_rms, min_improvement

    def _improvement(self, after: float) -> float:
        if math.isfinite(after) and math.isfinite(self.base_rms) and self.base_rms > 0:
            return 1.0 - after / self.base_rms
        return -math.inf if math.isinf(after) else math.nan

    def suspects(self, scored: list[dict], notes: dict[str, str], alpha: float, n_refit: int | None) -> list[Suspect]:
        """Every candidate that passes the corrected test is refitted (only those can be significant),
        and the best ``n_refit`` by p-value so the table shows their effect (all when None)."""
        order = sorted(range(len(scored)), key=lambda i: (scored[i]["p"], -scored[i]["score"]))
        chosen = (
            set(range(len(scored)))
            if n_refit is None
            else set(order[:n_refit]) | {i for i, s in enumerate(scored) if s["p_adj"] < alpha}
        )
        return [self._suspect(s, notes.get(s["c"].label, ""), alpha, i in chosen) for i, s in enumerate(scored)]

    def _suspect(self, s: dict, note: str, alpha: float, refit: bool) -> Suspect:
        c = s["c"]
        after, fitted = math.nan, None
        if refit:
            try:
                fitted, after = _refit_and_validate(self.model, self.data, self.validation, c, self.horizon)
                if not math.isfinite(after):
                    note = "free run diverges"
            except ArxidError as exc:
                note = str(exc).split(":")[0]
        improvement = self._improvement(after)
        sig = bool(s["p_adj"] < alpha and math.isfinite(improvement) and improvement >= self.min_improvement)
        return Suspect(
            c.label,
            c.kind,
            c.effects,
            c.na,
            c.nb,
            c.nk,
            s["score"],
            s["f"],
            s["p"],
            s["p_adj"],
            s["q"],
            after,
            improvement,
            sig,
            note,
            fitted,
        )

    def conditional_on_top(self, suspects: list[Suspect]) -> list[Suspect]:
        """Keep a suspect significant only if it still helps once the best suspect is in the model.

        With a large missing effect, many candidates lower the validation error a little simply by
        soaking up part of it (a drift, a correlated signal); they are not missing themselves. Each
        significant suspect below the best one is refitted together with it and must lower the
        error of the best one alone by ``min_improvement`` as well, else it is "explained by" it.
        """
        sig = [s for s in suspects if s.significant and s.refitted and math.isfinite(s.rms_sim_val_after)]
        if len(sig) < 2:
            return suspects
        top = min(sig, key=lambda s: s.rms_sim_val_after)
        if isinstance(self.model, PolynomialModel):
            # a tie goes to the simpler change: a delay that fits as well as one more coefficient
            near = [s for s in sig if s.rms_sim_val_after <= (1.0 + TIE_SHARE) * top.rms_sim_val_after]
            top = min(near, key=lambda s: (self._added_parameters(s), s.rms_sim_val_after))
        return [s if not s.significant or s is top else self._given_top(s, top) for s in suspects]

    def _added_parameters(self, s: Suspect) -> int:
        return s.model.n_params - self.model.n_params if s.model is not None else s.n_columns

    def _given_top(self, s: Suspect, top: Suspect) -> Suspect:
        m = self.model
        if isinstance(m, PolynomialModel):
            return self._given_top_polynomial(s, top)
        na = max(top.na + s.na - m.na_, 0)
        nb = tuple(max(t + x - b, 0) for t, x, b in zip(top.nb, s.nb, m.nb_))
        nk = tuple(max(t + x - k, 0) for t, x, k in zip(top.nk, s.nk, m.nk_))
        both = _Candidate(f"{top.effect}+{s.effect}", tuple(dict.fromkeys(top.effects + s.effects)), na, nb, nk, "pair")
        try:
            after = _refit_and_validate(m, self.data, self.validation, both, self.horizon)[1]
        except ArxidError:
            after = math.nan
        if math.isfinite(after) and after <= (1.0 - self.min_improvement) * top.rms_sim_val_after:
            return s
        return replace(
            s, significant=False, note=f"explained by {top.effect}: no gain once it is added", explained_by=top.effect
        )

    def _given_top_polynomial(self, s: Suspect, top: Suspect) -> Suspect:
        """``s`` applied to the refit with ``top`` (a structure change or effects on top of it)."""
        after = math.nan
        if top.model is not None:
            try:
                c = _Candidate(s.effect, s.effects, s.na, s.nb, s.nk, s.kind)
                after = _refit_and_validate(top.model, self.data, self.validation, c, self.horizon)[1]
            except ArxidError:
                pass
        if math.isfinite(after) and after <= (1.0 - self.min_improvement) * top.rms_sim_val_after:
            return s
        return replace(
            s, significant=False, note=f"explained by {top.effect}: no gain once it is added", explained_by=top.effect
        )


def _demote_pairs(suspects: list[Suspect], min_improvement: float) -> list[Suspect]:
    """A pair must earn its extra parameter: it stays significant only when it beats its single
    candidate's validation error by ``min_improvement`` as well (else the single is the suspect)."""
    by_label = {s.effect: s for s in suspects}
    out = []
    for s in suspects:
        parts: list[str] = []
        if s.kind == "pair" and s.significant:
            parts = [s.effect.rsplit("+", 1)[0]] if s.effect.endswith("+const") else list(s.effects)
        for single in (by_label.get(p) for p in parts):
            if (
                single is not None
                and single.refitted
                and math.isfinite(single.rms_sim_val_after)
                and s.rms_sim_val_after > (1.0 - min_improvement) * single.rms_sim_val_after
            ):
                s = replace(
                    s, significant=False, note=f"no better than {single.effect} alone", explained_by=single.effect
                )
                break
        out.append(s)
    return out


def _unscored(notes: dict[str, str], cands: list[_Candidate], suspects: list[Suspect]) -> list[Suspect]:
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
