"""The validated refits (steps 3 and 4 of the procedure in :mod:`arxid.diagnosis.suspects`): the
best candidates refitted and judged by the validation error, an effect kept only if it beats the
simple explanations (an offset, a trend), a suspect below the best one kept only if it still helps
once the best one is in the model, and a pair only if it beats its single."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Protocol

from .._base.background import in_two
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel
from .extension import Candidate, Refits, refit_and_validate
from .result import Suspect

__all__ = [
    "CandidateRefits",
    "Judge",
    "RecordRefits",
    "demote_pairs",
    "refit_indices",
    "TIE_SHARE",
    "SIMPLE_EXPLANATIONS",
]

#: Validation errors within this share of the lowest count as a tie between suspects of a
#: polynomial model (the one adding fewer parameters is then the best).
TIE_SHARE = 0.01

#: The simple explanations, simplest first, that every other effect must beat before it is named:
#: an offset, then a trend (see :meth:`Judge.simplest_first`).
SIMPLE_EXPLANATIONS = ("const", "time")

_IN_WORDS = {"const": "an offset (const)", "time": "a slow trend (time)"}


class CandidateRefits(Protocol):
    """The model refitted with candidates and validated where the records are: :class:`RecordRefits`
    on one record in this process, or
    :class:`~arxid.diagnosis.cluster_records.ClusterRefits` on a fleet's logs."""

    def prepare(self, cands: Sequence[Candidate], simple: Sequence[Candidate], initial: str) -> None:
        """The candidates :meth:`Judge.suspects` is about to refit (and the simple explanations it
        may compare them with), made together where that saves passes over the data or round trips.

        Parameters
        ----------
        cands, simple : sequence of Candidate
        initial : {"zero", "estimate"}
        """

    def hold(self, cands: Sequence[Candidate]) -> None:
        """Candidates that may be refitted next (the suspects paired with the best one).

        Parameters
        ----------
        cands : sequence of Candidate
        """

    def validated(self, model: ArxModel, c: Candidate, initial: str) -> tuple[ArxModel, float]:
        """``model`` refitted with candidate ``c`` and its validation error at the judge's horizon
        from the ``initial`` conditions.

        Parameters
        ----------
        model : ArxModel
        c : Candidate
        initial : {"zero", "estimate"}

        Returns
        -------
        tuple of (ArxModel, float)
        """
        raise NotImplementedError


class RecordRefits:
    """:class:`CandidateRefits` on one record in this process: the candidates that keep the model's
    rows fitted from one shared factor (:class:`~arxid.diagnosis.extension.Refits`), the others one
    by one.

    Parameters
    ----------
    model : ArxModel
    data, validation : IOData
    horizon : int or None
    """

    def __init__(self, model: ArxModel, data: IOData, validation: IOData, horizon: int | None):
        self.model, self.data, self.validation, self.horizon = model, data, validation, horizon
        self.shared = Refits(model, data, ())

    def prepare(self, cands: Sequence[Candidate], simple: Sequence[Candidate], initial: str) -> None:
        """The simple explanations in the shared factor too (every effect is compared with them),
        from the factor of the last refits when it holds these candidates (the masked pairs'); every
        refit's validation error from one pass over the validation data, where they can."""
        self.shared = Refits(self.model, self.data, [*cands, *simple], self.shared)
        self.shared.validate_all(cands, self.validation, self.horizon, initial)

    def hold(self, cands: Sequence[Candidate]) -> None:
        """The pairs from the factor the suspects were refitted from, when it holds them."""
        self.shared = Refits(self.model, self.data, cands, self.shared)

    def validated(self, model: ArxModel, c: Candidate, initial: str) -> tuple[ArxModel, float]:
        """From the shared factor when it holds ``c`` (a refit of the judged model), else one by one."""
        if model is self.model and self.shared.has(c):
            return self.shared.validated(c, self.validation, self.horizon, initial)
        return refit_and_validate(model, self.data, self.validation, c, self.horizon, initial)


class Judge:
    """Refits candidates and judges them by the validation error at the baseline's horizon.

    Parameters
    ----------
    model : ArxModel
    data, validation : IOData
    horizon : int or None
    base_rms, min_improvement : float
    initial : {"zero", "estimate"}
    refits : CandidateRefits, optional
        Where the refits are made (default: :class:`RecordRefits` on ``data`` and ``validation``).
    """

    def __init__(
        self,
        model: ArxModel,
        data: IOData,
        validation: IOData,
        horizon: int | None,
        base_rms: float,
        min_improvement: float,
        initial: str = "zero",
        refits: CandidateRefits | None = None,
    ):
        self.model, self.data, self.validation = model, data, validation
        self.horizon, self.base_rms, self.min_improvement = horizon, base_rms, min_improvement
        self.initial = initial
        self.refits = RecordRefits(model, data, validation, horizon) if refits is None else refits

    def _improvement(self, after: float) -> float:
        if math.isfinite(after) and math.isfinite(self.base_rms) and self.base_rms > 0:
            return 1.0 - after / self.base_rms
        return -math.inf if math.isinf(after) else math.nan

    def suspects(self, scored: list[dict], notes: dict[str, str], alpha: float, n_refit: int | None) -> list[Suspect]:
        """Every candidate that passes the corrected test is refitted (only those can be significant),
        and the best ``n_refit`` by p-value so the table shows their effect (all when None)."""
        chosen = refit_indices(scored, alpha, n_refit)
        m = self.model
        simple = [Candidate(n, (n,), m.na_, m.nb_, m.nk_, "effect") for n in SIMPLE_EXPLANATIONS]
        self.refits.prepare([scored[i]["c"] for i in sorted(chosen)], simple, self.initial)
        # Each refit is validated by a free run of the validation data: two at a time.
        return in_two(
            lambda i: self._suspect(scored[i], notes.get(scored[i]["c"].label, ""), alpha, i in chosen),
            range(len(scored)),
        )

    def _suspect(self, s: dict, note: str, alpha: float, refit: bool) -> Suspect:
        c = s["c"]
        after, fitted = math.nan, None
        if refit:
            try:
                fitted, after = self.refits.validated(self.model, c, self.initial)
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

    def simplest_first(self, suspects: list[Suspect], simple: Sequence[str] = SIMPLE_EXPLANATIONS) -> list[Suspect]:
        """Keep an effect significant only when it beats the simpler explanations by ``min_improvement``.

        An offset and a trend explain much of what a slow unlogged disturbance does to the output: a
        logged signal that barely moves (a temperature near 25 °C), or a term whose mean shifts the
        output (|y|, y², an effect paired with an offset), lowers the validation error about as much
        as a constant does, and is then no physical effect. Each significant effect or pair is
        compared with the explanations before it in ``simple`` (``time`` with ``const``, every other
        effect with both), each refitted and judged on the validation data like any candidate. Its
        validation error must be at most (1 − ``min_improvement``) times the lower of theirs: the same
        margin an effect needs against the model itself, with the simple explanation as the model.
        Else it is "no better than" that explanation, which is named instead when it is significant.
        Structure changes are not compared (they add no signal).
        """
        simple = [n for n in simple if n not in self.model.effects]
        judged = [s for s in suspects if s.significant and s.kind != "dynamics" and s.effect not in simple[:1]]
        if not simple or not judged:
            return suspects
        refs = self._references(suspects, simple)
        return [self._against_simple(s, simple, refs) for s in suspects]

    def _references(self, suspects: list[Suspect], simple: Sequence[str]) -> dict[str, float]:
        """Validation error of the model refitted with each simple explanation (from its suspect when
        it was refitted, else refitted here)."""
        by_label = {s.effect: s for s in suspects}
        refs = {}
        for name in simple:
            s = by_label.get(name)
            after = s.rms_sim_val_after if s is not None and s.refitted else math.nan
            if s is None or not s.refitted:
                m = self.model
                try:
                    c = Candidate(name, (name,), m.na_, m.nb_, m.nk_, "effect")
                    after = self.refits.validated(m, c, "zero")[1]
                except ArxidError:
                    after = math.nan
            if math.isfinite(after):
                refs[name] = after
        return refs

    def _against_simple(self, s: Suspect, simple: Sequence[str], refs: dict[str, float]) -> Suspect:
        if not s.significant or s.kind == "dynamics" or not math.isfinite(s.rms_sim_val_after):
            return s
        before = simple[: simple.index(s.effect)] if s.effect in simple else simple
        rivals = [(refs[n], n) for n in before if n in refs]
        if not rivals:
            return s
        best, name = min(rivals)
        if s.rms_sim_val_after <= (1.0 - self.min_improvement) * best:
            return s
        gain = 1.0 - s.rms_sim_val_after / best if best > 0 else 0.0
        how = f"only {100 * gain:.1f} % below" if gain >= 0 else f"{-100 * gain:.1f} % above"
        note = (
            f"no better than {_IN_WORDS.get(name, name)}: validation error {how} the refit with {name} "
            f"(needs {100 * self.min_improvement:.0f} % below)"
        )
        return replace(s, significant=False, note=note, explained_by=name)

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
        if not isinstance(self.model, PolynomialModel):
            self.refits.hold([self._with_top(s, top) for s in sig if s is not top])
        return [s if not s.significant or s is top else self._given_top(s, top) for s in suspects]

    def _added_parameters(self, s: Suspect) -> int:
        return s.model.n_params - self.model.n_params if s.model is not None else s.n_columns

    def _with_top(self, s: Suspect, top: Suspect) -> Candidate:
        """The candidate of ``s`` and ``top`` together (their changes of orders added)."""
        m = self.model
        na = max(top.na + s.na - m.na_, 0)
        nb = tuple(max(t + x - b, 0) for t, x, b in zip(top.nb, s.nb, m.nb_))
        nk = tuple(max(t + x - k, 0) for t, x, k in zip(top.nk, s.nk, m.nk_))
        return Candidate(f"{top.effect}+{s.effect}", tuple(dict.fromkeys(top.effects + s.effects)), na, nb, nk, "pair")

    def _given_top(self, s: Suspect, top: Suspect) -> Suspect:
        m = self.model
        if isinstance(m, PolynomialModel):
            return self._given_top_polynomial(s, top)
        both = self._with_top(s, top)
        try:
            after = self.refits.validated(m, both, self.initial)[1]
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
                after = self.refits.validated(top.model, c, self.initial)[1]
            except ArxidError:
                pass
        if math.isfinite(after) and after <= (1.0 - self.min_improvement) * top.rms_sim_val_after:
            return s
        return replace(
            s, significant=False, note=f"explained by {top.effect}: no gain once it is added", explained_by=top.effect
        )


def refit_indices(scored: list[dict], alpha: float, n_refit: int | None) -> set[int]:
    """Which scored candidates :meth:`Judge.suspects` refits: those passing the corrected test and
    the best ``n_refit`` by p-value (all when None).

    Parameters
    ----------
    scored : list of dict
    alpha : float
    n_refit : int or None

    Returns
    -------
    set of int
    """
    if n_refit is None:
        return set(range(len(scored)))
    order = sorted(range(len(scored)), key=lambda i: (scored[i]["p"], -scored[i]["score"]))
    return set(order[:n_refit]) | {i for i, s in enumerate(scored) if s["p_adj"] < alpha}


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
