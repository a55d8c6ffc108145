"""A candidate as the extension of a model it stands for: the effects and orders the model has with
it (:class:`Candidate`), read from its label, and the model refitted with it (:func:`refit`).

Labels are effects (``u1^2``), pairs (``sign(dy)+const``), structure changes (``na+1``, ``nb(u1)-1``;
``nf+1`` on a polynomial model) and thresholds to scan (``dz(u1)``, ``sat(u1)``).
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import cast

from .._base.records import record
from ..checks import error_rms
from ..data.iodata import IOData
from ..exceptions import ArxidError, OrderError
from ..models.arx_model import ArxModel
from ..models.arx_solver import per_input
from ..models.effects import compile_effects, parse_effect
from ..models.envelope import EnvelopeFactor
from ..models.iv import IvModel
from ..models.lanes import lane_rms
from ..models.polynomial import PolynomialModel
from .candidates import auto_candidates, candidate_input_names

__all__ = ["Candidate", "Refits", "candidate_list", "layout_for", "refit", "refit_and_validate"]

#: A structure change of a polynomial model (one more pole of A or F, one more zero, another delay).
_POLY_CHANGE = re.compile(r"(na|nb|nf|nk)(\([^)]+\))?[+-]1")
#: A threshold candidate whose threshold the diagnosis scans for.
_SCAN = re.compile(r"(?P<op>dz|sat)\((?P<signal>[A-Za-z_]\w*)\)")


@record
class Candidate:
    """One candidate: its label, the effects it adds and the orders of the model with it."""

    label: str
    effects: tuple[str, ...]
    na: int
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    kind: str  # "effect", "pair", "dynamics" or "scan" (a threshold to find: dz(u1), sat(u1))


def _dynamics(label: str, model: ArxModel) -> Candidate | None:
    na, nb, nk = model.na_, list(model.nb_), list(model.nk_)
    if label == "na+1":
        return Candidate(label, (), na + 1, tuple(nb), tuple(nk), "dynamics")
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
    return Candidate(label, (), na, tuple(nb), tuple(nk), "dynamics")


def _parse_candidate(label: str, model: ArxModel, data: IOData) -> Candidate:
    if not isinstance(label, str) or not label.strip():
        raise OrderError(f"a candidate must be a non-empty string such as 'u1^2', 'y^3' or 'na+1', got {label!r}")
    label = label.replace(" ", "")
    if isinstance(model, PolynomialModel) and _POLY_CHANGE.fullmatch(label):
        return Candidate(label, (), model.na_, model.nb_, model.nk_, "dynamics")
    dyn = _dynamics(label, model)
    if dyn is not None:
        return dyn
    scan = _SCAN.fullmatch(label)
    if scan:
        parse_effect(f"{scan['op']}({scan['signal']},1)", data)  # the signal must exist
        return Candidate(label, (), model.na_, model.nb_, model.nk_, "scan")
    parts = tuple(p for p in label.split("+") if p)
    for p in parts:
        parse_effect(p, data)  # raises OrderError with a readable message
    # An effect the model already has is not named again: "sign(y)+const" on a model with sign(y) is "const".
    new = tuple(p for p in parts if p not in model.effects) or parts
    kind = "pair" if len(new) > 1 else "effect"
    return Candidate("+".join(new), new, model.na_, model.nb_, model.nk_, kind)


def _has_threshold(model: ArxModel, signal: str) -> bool:
    return any(e.startswith((f"dz({signal},", f"sat({signal},")) for e in model.effects)


def layout_for(c: Candidate, model: ArxModel, data: IOData, samples: bool = True):
    """The effects of the model with ``c`` (the model's first) and their compiled layout (without
    its samples when ``samples`` is False)."""
    effects = tuple(model.effects) + tuple(e for e in c.effects if e not in model.effects)
    layout = compile_effects(effects, data, c.nb, c.nk, samples=samples)
    return effects, layout


def candidate_list(
    candidates, model: ArxModel, data: IOData, loop_signals: Sequence[str] = ()
) -> tuple[list[Candidate], bool]:
    """The candidates to test, without those the model already has, and whether they were ``"auto"``
    (automatic candidates leave out the ``loop_signals``, see :func:`auto_candidates`)."""
    auto = isinstance(candidates, str)
    if auto:
        if candidates != "auto":
            raise ArxidError(f"candidates must be 'auto' or a list of effect strings, got {candidates!r}")
        labels = auto_candidates(model, data, loop_signals)
    else:
        labels = list(candidates)
        if not labels:
            raise ArxidError("candidates is empty: give 'auto' or at least one effect such as 'u1^2'")
    cands: dict[str, Candidate] = {}
    for lab in labels:
        c = _parse_candidate(lab, model, data)
        if c.kind in ("effect", "pair") and all(e in model.effects for e in c.effects):
            continue
        if c.kind == "scan" and _has_threshold(model, c.label[c.label.index("(") + 1 : -1]):
            continue
        cands.setdefault(c.label, c)
    return list(cands.values()), auto


def refit(model: ArxModel, data: IOData, c) -> ArxModel:
    """``model`` refitted on ``data`` with candidate ``c`` (a :class:`Candidate`, or a suspect
    reporting one) added."""
    extended = getattr(model, "extended", None)
    if extended is not None:  # one output of a state-space model refits itself (its effects as inputs)
        return extended(data, c.effects)
    if isinstance(model, PolynomialModel):  # a structure change, or effects as extra inputs
        from .polynomial import refit_structure, refit_with_effects

        if c.kind == "dynamics":
            label = c.label if isinstance(c, Candidate) else c.effect
            return cast(ArxModel, refit_structure(model, data, label, candidate_input_names(data)))
        return cast(ArxModel, refit_with_effects(model, data, c.effects))
    if _closed_loop_iv(model):  # instruments from the reference: consistent in closed loop
        from ..models.iv_effects import iv_with_effects

        nb, nk = per_input("nb", c.nb, data.n_inputs), per_input("nk", c.nk, data.n_inputs)
        return iv_with_effects(data, c.na, nb, nk, _with(model, c), _references(model), model.first_lag_)
    return ArxModel(na=c.na, nb=c.nb, nk=c.nk, effects=_with(model, c)).fit(data, first_lag=model.first_lag_)


def _references(model: ArxModel) -> tuple[str, ...]:
    """The logged references an IV model's instruments come from (empty otherwise)."""
    refs = getattr(model, "instruments", None) if isinstance(model, IvModel) else None
    return (refs,) if isinstance(refs, str) else tuple(refs or ())


def _closed_loop_iv(model: ArxModel) -> bool:
    """Whether ``model`` was fitted by instrumental variables from logged references."""
    return bool(_references(model))


def _with(model: ArxModel, c) -> tuple[str, ...]:
    """The effects of ``model`` refitted with candidate ``c``: the model's first."""
    return tuple(model.effects) + tuple(e for e in c.effects if e not in model.effects)


def refit_and_validate(
    model, data: IOData, validation: IOData, c, horizon: int | None, initial: str = "zero"
) -> tuple[ArxModel, float]:
    """The model refitted with candidate ``c`` and its validation error at ``horizon`` (from the
    ``initial`` conditions, see :func:`arxid.checks.prediction_error`)."""
    fitted = refit(model, data, c)
    return fitted, error_rms(fitted, validation, horizon, initial)


#: Kinds of candidates refitted from the shared factor: every one that keeps the model's rows (a
#: shape that replaces an input is one more column, like an effect).
_IN_FACTOR = ("effect", "pair", "dynamics", "shape")


class Refits:
    """The model refitted with each of several candidates and validated.

    Candidates that keep the model's regression rows are fitted from one factor of their envelope
    (:mod:`arxid.models.envelope`: one pass over the data for all of them, the same fits to
    rounding); the others, a polynomial model's, and all of them on data with gaps, one by one.

    Parameters
    ----------
    model : ArxModel
        The model being diagnosed.
    data : IOData
        Estimation data.
    cands : sequence of Candidate
        The candidates that will be refitted.
    reuse : Refits, optional
        Refits of the same model and data whose envelope may hold these candidates too: then they
        are fitted from its factor (no other pass over the data).
    """

    def __init__(self, model: ArxModel, data: IOData, cands: Sequence[Candidate], reuse: Refits | None = None):
        self.model, self.data = model, data
        self.index: dict[str, int] = {}
        self._validated: dict[tuple, tuple[ArxModel, float]] = {}  # found by validate_all
        self.envelope: EnvelopeFactor | None = None
        if isinstance(model, PolynomialModel) or _closed_loop_iv(model):  # refitted one by one
            return
        specs: list[tuple] = []
        for c in cands:
            if c.kind in _IN_FACTOR and c.label not in self.index:
                self.index[c.label] = len(specs)
                specs.append((c.na, c.nb, c.nk, _with(model, c)))
        if len(specs) > 1 and not self._from(reuse, specs):
            try:
                self.envelope = EnvelopeFactor(data, specs, model.first_lag_)
            except ArxidError:  # gaps in the data, or an effect that cannot be compiled: one by one
                self.envelope = None

    def _from(self, reuse: Refits | None, specs: list[tuple]) -> bool:
        """Fit every structure of ``specs`` from the factor of ``reuse`` (the same model and data)
        when its envelope holds them all: no other pass over the data."""
        env = reuse.envelope if reuse is not None else None
        if env is None or reuse is None or reuse.model is not self.model or reuse.data is not self.data:
            return False
        if env.given_first_lag != self.model.first_lag_:
            return False
        at = [env.add(spec) for spec in specs]
        if any(i is None for i in at):
            return False
        self.envelope = env
        self.index = {label: at[i] for label, i in self.index.items()}  # type: ignore[misc]
        return True

    def has(self, c) -> bool:
        """Whether candidate ``c`` is fitted from the shared factor.

        Parameters
        ----------
        c : Candidate

        Returns
        -------
        bool
        """
        i = self.index.get(getattr(c, "label", ""))
        return self.envelope is not None and i is not None and self.envelope.has(i)

    def validate_all(self, cands: Sequence, validation: IOData, horizon: int | None, initial: str = "zero") -> None:
        """Fit every candidate of ``cands`` the shared factor holds and find their validation errors
        together, in one pass of the core's lanes over the validation data (:mod:`arxid.models.lanes`;
        each the error of its own prediction to rounding); :meth:`validated` then returns them.
        Nothing is found when the candidates cannot share lanes (they are validated one by one).

        Parameters
        ----------
        cands : sequence of Candidate
        validation : IOData
        horizon : int or None
        initial : {"zero", "estimate"}
            Lanes start every free run from the measured outputs: ``"zero"`` only.
        """
        if self.envelope is None or initial != "zero":
            return
        fitted: dict[str, ArxModel] = {}
        for c in cands:
            if self.has(c) and c.label not in fitted:
                try:
                    m = ArxModel(na=c.na, nb=c.nb, nk=c.nk, effects=_with(self.model, c))
                    fitted[c.label] = m.fit_in(self.envelope, self.index[c.label])
                except ArxidError:
                    continue
        fitted = {label: m for label, m in fitted.items() if not m.layout_.output_terms}  # those run alone
        rms = lane_rms(list(fitted.values()), validation, horizon) if len(fitted) > 1 else None
        if rms is not None:
            for (label, m), r in zip(fitted.items(), rms, strict=True):
                self._validated[label, id(validation), horizon, initial] = (m, float(r))

    def validated(self, c, validation: IOData, horizon: int | None, initial: str = "zero") -> tuple[ArxModel, float]:
        """As :func:`refit_and_validate`, from the envelope's factor when ``c`` is in it.

        Parameters
        ----------
        c : Candidate
        validation : IOData
        horizon : int or None
        initial : {"zero", "estimate"}

        Returns
        -------
        (ArxModel, float)
            The refitted model and its validation error.
        """
        if not self.has(c) or self.envelope is None:
            return refit_and_validate(self.model, self.data, validation, c, horizon, initial)
        known = self._validated.get((c.label, id(validation), horizon, initial))
        if known is not None:
            return known
        i = self.index[c.label]
        fitted = ArxModel(na=c.na, nb=c.nb, nk=c.nk, effects=_with(self.model, c)).fit_in(self.envelope, i)
        return fitted, error_rms(fitted, validation, horizon, initial)
