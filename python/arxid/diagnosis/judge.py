"""The validated refits (steps 3 and 4 of the procedure in :mod:`arxid.diagnosis.suspects`): the
best candidates refitted and judged by the validation error, a suspect below the best one kept only
if it still helps once the best one is in the model, and a pair only if it beats its single."""

from __future__ import annotations

import math
from dataclasses import replace

from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel
from .extension import Candidate, refit_and_validate
from .result import Suspect

__all__ = ["Judge", "demote_pairs", "TIE_SHARE"]

#: Validation errors within this share of the lowest count as a tie between suspects of a
#: polynomial model (the one adding fewer parameters is then the best).
TIE_SHARE = 0.01


class Judge:
    """Refits candidates and judges them by the validation error at the baseline's horizon."""

    def __init__(
        self,
        model: ArxModel,
        data: IOData,
        validation: IOData,
        horizon: int | None,
        base_rms: float,
        min_improvement: float,
        initial: str = "zero",
    ):
        self.model, self.data, self.validation = model, data, validation
        self.horizon, self.base_rms, self.min_improvement = horizon, base_rms, min_improvement
        self.initial = initial

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
                fitted, after = refit_and_validate(
                    self.model, self.data, self.validation, c, self.horizon, self.initial
                )
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
        both = Candidate(f"{top.effect}+{s.effect}", tuple(dict.fromkeys(top.effects + s.effects)), na, nb, nk, "pair")
        try:
            after = refit_and_validate(m, self.data, self.validation, both, self.horizon, self.initial)[1]
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
                c = Candidate(s.effect, s.effects, s.na, s.nb, s.nk, s.kind)
                after = refit_and_validate(top.model, self.data, self.validation, c, self.horizon, self.initial)[1]
            except ArxidError:
                pass
        if math.isfinite(after) and after <= (1.0 - self.min_improvement) * top.rms_sim_val_after:
            return s
        return replace(
            s, significant=False, note=f"explained by {top.effect}: no gain once it is added", explained_by=top.effect
        )


def demote_pairs(suspects: list[Suspect], min_improvement: float) -> list[Suspect]:
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
