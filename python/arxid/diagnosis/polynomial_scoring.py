"""Scoring the candidates of a polynomial model (ARMAX, OE, BJ): the score tests of
:mod:`arxid.diagnosis.polynomial` on effects as extra inputs and on structure changes, and the
threshold scans of ``dz(u)`` / ``sat(u)``, in the form :class:`~arxid.diagnosis.scoring.Scoring`
gives for an ARX model."""

from __future__ import annotations

import math

import numpy as np

from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from ..models.effects import format_threshold
from .added_variable import holm
from .candidates import candidate_input_names, scan_threshold
from .extension import Candidate
from .polynomial import refit_with_effects, score_effects, score_structure
from .scoring import scored_entry

__all__ = ["score_polynomial"]


def score_polynomial(model, data: IOData, cands: list[Candidate]) -> tuple[list[dict], dict[str, str]]:
    """Score tests on a polynomial model (see :mod:`arxid.diagnosis.polynomial`): effects of the inputs and
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
            scored.append(scored_entry(res[0], res[1]) if isinstance(res, tuple) else scored_entry(c, res))
            if isinstance(res, tuple):
                scored[-1]["p"] = min(1.0, scored[-1]["p"] * res[2])
    for s, pa in zip(scored, holm(np.array([s["p"] for s in scored]))):
        s["p_adj"] = float(pa)
    return scored, notes


def _scan_polynomial(model, data: IOData, c: Candidate, notes: dict[str, str]):
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

    t, n = scan_threshold(x, lambda ts: np.array([score(float(t)) for t in ts]))
    if not math.isfinite(t):
        return None, "no threshold could be tested" if n else f"|{signal}| takes too few distinct values to scan"
    best = label(_threshold_shape(model, data, signal, label(op, t)), t)
    res, why = score_effects(model, data, [best])
    if res is None:
        return None, why
    notes[best] = f"threshold scanned over {n} quantiles of |{signal}| (p-value x {n})"
    cand = Candidate(best, (best,), model.na_, model.nb_, model.nk_, "effect")
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
