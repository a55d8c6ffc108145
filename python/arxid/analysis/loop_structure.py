"""The structure of a closed-loop analysis: sweep, choice and refit by a method that stays
consistent under feedback (see :mod:`arxid.analysis.closed_loop` for the methods and why).

:func:`closed_loop_structure` returns the chosen plant with the data the rest of the analysis
(the diagnosis, its ladder and the checks) must read. The estimation data stay the measured ones.
With a reference the validation data are the two-stage data, whose inputs are the reference-driven
parts: every refit of the diagnosis is judged there, so a candidate that only absorbs the feedback
validates worse, and none is named for it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..data.iodata import IOData
from ..diagnosis.suspects import diagnose
from ..exceptions import ArxidError, OrderError
from ..models.two_stage import reference_driven
from ..selection.search import SweepResult, sweep
from .choice import Choice, OrderGrid, choose, grid_of
from .closed_loop import (
    ClosedLoopMethod,
    closed_loop_grid,
    direct_method,
    direct_refit,
    iv_method,
    iv_refit,
    loop_signal_names,
    operating_point,
    remove_operating_point,
)

__all__ = ["LoopStructure", "closed_loop_structure", "loop_closing_sentences"]

#: The choice rule in closed loop: the IV fits of neighbouring structures differ by their variance
#: more than by their bias, so the fewest parameters within the noise of the best is taken.
LOOP_RULE = "smallest-within-noise"

#: A pole and a zero of one input closer than this cancel: the structure has one pole and one zero
#: too many, and the pair shifts the static gain by (1 - z) / (1 - p) without changing the fit.
CANCELLATION = 0.02


@dataclass(frozen=True, eq=False)
class LoopStructure:
    """The chosen plant of a closed-loop analysis and the data the analysis goes on with.

    Attributes
    ----------
    sweep : SweepResult
    model : ArxModel or PolynomialModel
        The plant refitted by the method (IV4, or Box–Jenkins by prediction error).
    choice : Choice
    grid : dict
        The grid swept.
    estimation, validation : IOData
        The data of the diagnosis and the checks (the validation data two-stage with a reference).
    method : ClosedLoopMethod
    """

    sweep: SweepResult
    model: Any
    choice: Choice
    grid: OrderGrid
    estimation: IOData
    validation: IOData
    method: ClosedLoopMethod


def _grid(orders: Sequence | None, grid: Mapping | None) -> OrderGrid:
    if orders is None:
        g = grid_of(grid)
        return g if grid is not None else OrderGrid(**closed_loop_grid(g))  # type: ignore[typeddict-item]
    try:
        na, nb, nk = orders
    except (TypeError, ValueError):
        raise OrderError(f"orders must be (na, nb, nk), got {orders!r}") from None
    return grid_of({"na": [na], "nb": [nb], "nk": [nk]})


def closed_loop_structure(
    est: IOData,
    val: IOData,
    references: Sequence[str],
    orders: Sequence | None,
    grid: Mapping | None,
    horizon: int | None,
    expect: str | None,
    progress: bool,
    still: Sequence[str] = (),
) -> LoopStructure:
    """Sweep, choose and refit the plant of closed-loop data.

    Parameters
    ----------
    est, val : IOData
        Estimation and validation data, logged in closed loop.
    references : sequence of str
        The logged references (empty: the direct method).
    orders : (na, nb, nk) or None
        A fixed structure (then only it is fitted).
    grid : mapping or None
        The grid to sweep (None: the default grid with delays from one sample).
    horizon : int or None
    expect : str or None
    progress : bool
    still : sequence of str
        Logged references that do not move (named in the direct method's reason).

    Returns
    -------
    LoopStructure
    """
    point = operating_point(est)
    est, val = remove_operating_point(est, point), remove_operating_point(val, point)
    loop = loop_signal_names(est, references)
    g = _grid(orders, grid)
    kw: dict[str, Any] = {"horizon": horizon, "expect": expect, "progress": progress}
    if references:
        val_hat = reference_driven(val, references)
        res = sweep(est, validation=val_hat, method="iv", instruments=list(references), **kw, **g)
        chosen, choice = _without_cancellation(res, *choose(res, LOOP_RULE))
        model = iv_refit(chosen, est, references, val_hat, res.horizon)
        how = (
            "refitted by IV4 with the reference as instrument"
            if model.iterations > 0
            else "fitted by basic IV with the reference as instrument (IV4 did not validate better)"
        )
        method = iv_method(references, loop, point)
        return LoopStructure(res, model, _said(choice, how, model), g, est, val_hat, method)
    res = sweep(est, validation=val, **kw, **g)
    chosen, choice = choose(res, LOOP_RULE)
    try:
        model = direct_refit(chosen, est)
        how = "refitted as a Box-Jenkins model by prediction error (the direct method)"
    except ArxidError as exc:
        model, how = chosen, f"kept as least squares fitted it: the Box-Jenkins refit failed ({exc})"
    return LoopStructure(res, model, _said(choice, how, model), g, est, val, direct_method(loop, point, still))


def _cancelling_pair(model: Any) -> tuple[float, float] | None:
    """A real pole and zero of a single-input model closer than :data:`CANCELLATION` (None if none)."""
    if len(model.nb_) != 1 or model.na_ < 1 or model.nb_[0] < 2:
        return None
    b = np.trim_zeros(np.asarray(model.b[0], dtype=float), "f")
    poles, zeros = np.roots(model.a), np.roots(b) if b.size > 1 else np.zeros(0)
    pairs = [(abs(p - z), p, z) for p in poles for z in zeros if abs(p.imag) < 1e-9 and abs(z.imag) < 1e-9]
    close = [pair for pair in pairs if pair[0] < CANCELLATION]
    return None if not close else (float(min(close)[1].real), float(min(close)[2].real))


def _without_cancellation(res: SweepResult, model: Any, choice: Choice) -> tuple[Any, Choice]:
    """The chosen structure, or, while a pole and a zero of it cancel, the structure with one pole
    and one zero fewer (when the sweep holds it and its step response passes)."""
    while (pair := _cancelling_pair(model)) is not None:
        na, nb, nk = model.na_ - 1, model.nb_[0] - 1, model.nk_[0]
        rank = next((i for i in range(len(res)) if (res.na[i], res.nb[i][0], res.nk[i][0]) == (na, nb, nk)), None)
        if rank is None or res.sanity(rank).reasons:
            break
        why = (
            f"{model.structure_name()} has a pole at {pair[0]:.3f} and a zero at {pair[1]:.3f} that cancel, "
            f"so {res.structure_name(rank)} was kept"
        )
        model = res.model(rank)
        choice = replace(choice, structure=model.structure_name(), rank=rank, reason=f"{choice.reason}; {why}")
    return model, choice


def _said(choice: Choice, how: str, model: Any) -> Choice:
    """The choice as the refitted model: its name, and the reason with how it was refitted."""
    return replace(choice, structure=model.structure_name(), reason=f"{choice.reason}; {how}")


def loop_closing_sentences(
    model: Any, est: IOData, val: IOData, method: ClosedLoopMethod, horizon: int | None, initial: str
) -> tuple[str, ...]:
    """The loop signals that would "explain" the model's error if taken as extra inputs.

    Parameters
    ----------
    model : ArxModel or PolynomialModel
    est, val : IOData
    method : ClosedLoopMethod
    horizon : int or None
    initial : str

    Returns
    -------
    tuple of str
        One sentence per such signal: how much error it would remove, and that this is the loop
        closing through it, not a missing effect.
    """
    names = [n for n in method.loop_signals if n.isidentifier()]
    if not names:
        return ()
    try:
        d = diagnose(model, est, val, candidates=names, horizon=horizon, initial=initial)
    except ArxidError:
        return ()
    out = []
    for s in d.suspects:
        if not s.significant or not d.rms_sim_val > 0:
            continue
        fall = 100.0 * (1.0 - s.rms_sim_val_after / d.rms_sim_val)
        out.append(
            f"The logged signal {s.effect} would remove {fall:.0f} % of the validation error as an extra input. "
            "It is not proposed: it belongs to the loop (a reference, or a signal the controller computes from "
            "the output), so it explains the output because the loop closes through it, not because the plant "
            "misses an effect."
        )
    return tuple(out)
