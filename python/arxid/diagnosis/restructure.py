"""The structure re-chosen once the ladder adds an effect (:func:`rechoose_structure`).

The sweep chose (na, nb, nk) for the model without effects. An effect the ladder adds can change
which structure is best: a model that had to spend an input lag on a slow drift no longer needs it,
or a missing effect hid the benefit of one more lag. So after an effect is accepted the orders are
swept again around the current ones, with the effects in every model, every model fitted on the
same rows and judged by the same validation measure as the ladder.

The neighbourhood of the orders is every (na ± 1, nb ± 1, nk ± 1) for one input (26 structures);
with several inputs, na ± 1 and each input's nb ± 1, nk ± 1 and (nb + 1, nk − 1), (nb − 1, nk + 1)
(the same last lag). A neighbour may replace the current structure only when

* its validation error is lower by at least ``min_improvement`` (5 %, the fall a structure change
  needs to be a significant suspect of :func:`arxid.diagnose`; less keeps the structure the sweep
  chose), and
* the current structure's error is significantly larger than its own by the Diebold-Mariano test
  of :mod:`arxid.selection.parsimony` (one-sided 5 %, on the same validation samples).

Of those, the one with the fewest parameters whose error is not significantly larger than the
lowest (the sweep's "smallest within noise" rule) is taken, provided its step sanity check
(:func:`arxid.sanity.step_sanity`, with the sweep's expectation) raises no flag the current model
does not raise already (else the next smallest).

The search moves to the new structure and repeats, at most ``max_rounds`` times.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import partial

import numpy as np

from .._base import metrics
from .._base.background import in_two
from .._base.records import record
from ..checks import prediction, prediction_error
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.envelope import EnvelopeFactor
from ..models.lanes import lane_rms
from ..selection.parsimony import diebold_mariano
from ..selection.sanity import step_sanity

__all__ = ["Rechoice", "rechoose_structure", "order_change", "linear_name"]

Orders = tuple[int, tuple[int, ...], tuple[int, ...]]


@record(eq=False)
class Rechoice:
    """The outcome of :func:`rechoose_structure`.

    Attributes
    ----------
    model : ArxModel
        The model at the chosen structure (the given model itself when it did not change).
    before : ArxModel
        The given model.
    rms_before, rms_after : float
        Validation error of ``before`` and ``model`` at the ladder's measure.
    tried : int
        Structures fitted and validated.
    """

    model: ArxModel
    before: ArxModel
    rms_before: float
    rms_after: float
    tried: int

    @property
    def changed(self) -> bool:
        """True when the structure changed."""
        return self.model is not self.before

    @property
    def change(self) -> str:
        """The change of orders in words, e.g. ``"nb+1"`` or ``"na+1, nk-2"`` (``""`` when none)."""
        return order_change(self.before, self.model) if self.changed else ""


def linear_name(model: ArxModel) -> str:
    """The structure without its effects.

    Parameters
    ----------
    model : ArxModel
        A fitted model.

    Returns
    -------
    str
        e.g. ``ARX(4,2,5)``.
    """
    return ArxModel(na=model.na_, nb=model.nb_, nk=model.nk_).structure_name()


def order_change(before: ArxModel, after: ArxModel) -> str:
    """How the orders of ``after`` differ from those of ``before``, e.g. ``"nb+1, nk-1"``.

    Parameters
    ----------
    before, after : ArxModel
        Fitted models with the same inputs.

    Returns
    -------
    str
        One ``name±d`` per order that changed (``nb(u2)+1`` with several inputs); ``""`` when none did.
    """
    names = before.input_names
    parts = [f"na{after.na_ - before.na_:+d}"] if after.na_ != before.na_ else []
    for key in ("nb", "nk"):
        old, new = getattr(before, key + "_"), getattr(after, key + "_")
        for i, (a, b) in enumerate(zip(old, new)):
            if a != b:
                parts.append(f"{key}{'' if len(old) == 1 else f'({names[i]})'}{b - a:+d}")
    return ", ".join(parts)


def _neighbours(orders: Orders) -> list[Orders]:
    na, nb, nk = orders
    out: list[Orders]
    if len(nb) == 1:
        steps = itertools.product((-1, 0, 1), repeat=3)
        out = [(na + a, (nb[0] + b,), (nk[0] + k,)) for a, b, k in steps if (a, b, k) != (0, 0, 0)]
    else:
        out = [(na - 1, nb, nk), (na + 1, nb, nk)]
        for i in range(len(nb)):
            for db, dk in ((-1, 0), (1, 0), (0, -1), (0, 1), (1, -1), (-1, 1)):
                b, k = list(nb), list(nk)
                b[i], k[i] = b[i] + db, k[i] + dk
                out.append((na, tuple(b), tuple(k)))
    low_b = tuple(min(1, b) for b in nb)
    return [o for o in out if o[0] >= 0 and all(b >= lb for b, lb in zip(o[1], low_b)) and min(o[2]) >= 0]


def _lag(orders: Orders, output_terms: bool) -> int:
    na, nb, nk = orders
    return max(na, max((b + k - 1 for b, k in zip(nb, nk) if b > 0), default=0), 2 if output_terms else 0)


@dataclass
class _Search:
    """Fits and judges the structures of one neighbourhood."""

    data: IOData
    validation: IOData
    horizon: int | None
    initial: str
    expect: str | None

    def fit(self, model: ArxModel, orders: Orders, first_lag: int) -> ArxModel:
        na, nb, nk = orders
        return ArxModel(na=na, nb=nb, nk=nk, effects=model.effects).fit(self.data, first_lag=first_lag)

    def fit_all(self, model: ArxModel, structures: list[Orders], first_lag: int) -> list[ArxModel | None]:
        """Each structure with the model's effects, fitted on the same rows (None where it cannot be):
        from one factor of their envelope (:mod:`arxid.models.envelope`) when the data have no
        gaps, else one by one."""
        try:
            specs = [(na, nb, nk, model.effects) for na, nb, nk in structures]
            env: EnvelopeFactor | None = EnvelopeFactor(self.data, specs, first_lag)
        except ArxidError:
            env = None
        out: list[ArxModel | None] = []
        for i, (na, nb, nk) in enumerate(structures):
            try:
                m = ArxModel(na=na, nb=nb, nk=nk, effects=model.effects)
                if env is not None and env.has(i) and env.first_lag == first_lag:
                    out.append(m.fit_in(env, i))
                else:
                    out.append(self.fit(model, (na, nb, nk), first_lag))
            except ArxidError:
                out.append(None)
        return out

    def errors(self, model: ArxModel) -> tuple[np.ndarray, float]:
        """The model's validation errors and their RMS (every error and the RMS inf when its free
        run diverged)."""
        _, err, diverged = prediction_error(model, self.validation, self.horizon, self.initial)
        return (np.full_like(err, np.inf), math.inf) if diverged else (err, metrics.rms(err))

    def measured(self, model: ArxModel, keep_below: float = math.inf) -> tuple[float, ArxModel, np.ndarray | None]:
        """(RMS, model, errors) of ``model`` on the validation data; the errors (an array the size
        of the record) only when the RMS is at most ``keep_below``, else None."""
        pred, _ = prediction(model, self.validation, self.horizon, self.initial)
        rms = metrics.prediction_rms(self.validation.y, pred)  # inf when it diverged, as errors()
        if not rms <= keep_below:
            return rms, model, None
        with np.errstate(all="ignore"):
            return rms, model, self.validation.y - pred

    def screened(self, models: list[ArxModel], keep_below: float) -> list[tuple[float, ArxModel, np.ndarray | None]]:
        """:meth:`measured` of each model. Neighbours with the same effects on the same rows, linear
        in the output, on complete data: every RMS from one pass of the core's lanes over the
        validation data (as a sweep scores its structures, to rounding), then the errors and the
        RMS of its own prediction only for a model that can pass ``keep_below``."""
        lanes = None if self.initial != "zero" else lane_rms(models, self.validation, self.horizon)
        if lanes is None:  # each by its own prediction, two at a time
            return in_two(partial(self.measured, keep_below=keep_below), models)
        near = [m for m, rms in zip(models, lanes, strict=True) if rms <= keep_below]
        exact = {id(m): got for m, got in zip(near, in_two(partial(self.measured, keep_below=keep_below), near))}
        return [exact.get(id(m), (rms, m, None)) for m, rms in zip(models, lanes, strict=True)]

    def flags(self, model: ArxModel) -> set[str]:
        return set(step_sanity(model, self.validation, expect=self.expect).flags)


def rechoose_structure(
    model: ArxModel,
    data: IOData,
    validation: IOData,
    horizon: int | None = None,
    *,
    initial: str = "zero",
    expect: str | None = None,
    min_improvement: float = 0.05,
    max_rounds: int = 3,
) -> Rechoice:
    """Re-choose the orders of ``model`` (with its effects) by a local sweep around them.

    Parameters
    ----------
    model : ArxModel
        A fitted model, normally just refitted with a new effect.
    data, validation : IOData
        Estimation and validation data.
    horizon : int or None
        Validation error measure: None = free run; k = k-step prediction.
    initial : {"zero", "estimate"}
        Initial conditions of the validation error (see :func:`arxid.compare`).
    expect : {None, "stable", "integrating", "double-integrating"}
        What the step sanity check assumes (the sweep's expectation).
    min_improvement : float
        Relative fall of the validation error a new structure must bring (0.05 = 5 %), as a
        structure change suspect of :func:`arxid.diagnose` must.
    max_rounds : int
        Largest number of moves to a neighbouring structure.

    Returns
    -------
    Rechoice
        The model at the chosen structure, with the errors before and after.
    """
    search = _Search(data, validation, horizon, initial, expect)
    terms = bool(model.layout_.output_terms)
    current, tried = model, 0
    err_current, rms_current = search.errors(current)
    rms_first = rms_current
    for _ in range(int(max_rounds)):
        orders = (current.na_, tuple(current.nb_), tuple(current.nk_))
        cands = _neighbours(orders)
        first_lag = max([current.first_lag_, _lag(orders, terms)] + [_lag(o, terms) for o in cands])
        models = search.fit_all(current, [orders, *cands], first_lag)
        # the current structure on the same rows as its neighbours
        base = current if first_lag == current.first_lag_ else models[0]
        if base is None:
            break
        # the current model's errors are known (a free run of the validation data costs a pass)
        if base is current:
            err_base, rms_base = err_current, rms_current
        else:
            err_base, rms_base = search.errors(base)
        # Each neighbour is validated by a free run of the validation data: two at a time. Only one
        # that can be better (its RMS low enough) keeps its errors, for the paired test.
        fitted = search.screened([m for m in models[1:] if m is not None], (1.0 - min_improvement) * rms_base)
        tried += len(fitted)
        kept = [(rms, m, err) for rms, m, err in fitted if err is not None]
        better = [f for f in kept if _better(f[0], f[2], rms_base, err_base, min_improvement)]
        if not better:
            break
        lowest = min(better, key=lambda f: f[0])
        # the smallest structure not significantly worse than the lowest error, as the sweep's
        # "smallest-within-noise" rule: one more order is taken only when it is needed
        near = [f for f in better if f is lowest or not diebold_mariano(f[2], lowest[2]).worse]
        flags = search.flags(base)
        ranked = sorted(near, key=lambda f: (f[1].n_params, f[0]))
        chosen = next((f for f in ranked if not search.flags(f[1]) - flags), None)
        if chosen is None:
            break
        rms_current, current, err_current = chosen
    return Rechoice(current, model, rms_first, rms_current, tried)


def _better(new: float, err_new: np.ndarray, old: float, err_old: np.ndarray, min_improvement: float) -> bool:
    """``err_new`` (RMS ``new``) lower by ``min_improvement`` than ``err_old`` (RMS ``old``: each
    error's RMS is taken once) and ``err_old`` significantly larger (Diebold-Mariano)."""
    if not (math.isfinite(new) and new <= (1.0 - min_improvement) * old):
        return False
    return math.isinf(old) or diebold_mariano(err_old, err_new).worse
