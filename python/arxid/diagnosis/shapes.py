"""Shapes that replace an input: the candidates of a diagnosis that make the input act *through*
f(u) (a Hammerstein model, :mod:`arxid.models.input_shapes`), scored beside the additive effects.

For each input the named families are fitted with the model's own dynamics (orders and lags), the
input replaced by the shape and an offset added when the model has none (a power law's zero is
the input's zero, not the output's):

* power u^p (an input that is never negative), signed power sign(u)·|u|^p (one that changes sign);
* saturation at two levels, clip(u, lo, hi); dead zone dz(u, c);
* the input times each logged signal, u·x (duty × battery voltage), with no parameter.

**What identifies a shape.** The evidence comes from either record, and the smaller p-value is
doubled (Bonferroni over the two tests), then multiplied by the number of shapes and of the values
a scan tried:

* the estimation data's encompassing test: the shape's columns (and the offset), added *beside*
  the input with its lags, lower the one-step error (partial F-test, from one reduction of the
  model's columns: :mod:`.shape_beside`): the input acts nonlinearly;
* the validation data's Diebold–Mariano test of the shape model's errors against the model's: a
  staircase's estimation data may hold too few levels to show a shape, the validation data hold
  others.

Whether the input acts *through* the shape or beside it is the validation error's to say, the
fewer parameters preferred: an additive term of the same input is named only when it lowers the
validation error by ``min_improvement`` more (:func:`prefer_shapes`).

On an input with at least ``MIN_SCAN_LEVELS`` distinct values a shape's parameter is found on the
estimation data (a grid, then a local search). On a staircase of a few levels it cannot be: every
shape with a gain, an offset and one parameter passes through three levels, and the additive
polynomials u, u², const span the same values. Physics breaks that tie: only the power laws with a
physical name are tried there (the square law, the square root, the cube law), with no exponent
fitted; a saturation's or dead zone's level is still scanned (the steps beyond a level all give
the same f, so the level shows when two steps lie on each side of it).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .._base import _core
from .._base.local_search import bounded_minimum, simplex_minimum
from .._base.order_statistics import distinct, median
from .._base.probabilities import f_sf
from ..checks import prediction
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.effects import parse_effect
from ..models.envelope import EnvelopeFactor
from ..models.input_shapes import InputShape
from ..models.iv import IvModel
from ..selection.parsimony import comparison_from_sums, diebold_mariano
from .candidates import candidate_input_names, changes_sign
from .extension import Candidate
from .result import Suspect
from .scan_sample import scan_sample
from .shape_beside import Beside, BesideFit, beside_from_factor
from .shape_cost import ShapeCost

__all__ = [
    "MIN_SCAN_LEVELS",
    "PHYSICAL_POWERS",
    "shape_candidates",
    "score_shapes",
    "input_levels",
    "prefer_shapes",
    "validation_p",
    "ValidationEvidence",
    "ShapeFits",
]

#: Distinct values an input needs before a shape's parameter is estimated from the data.
MIN_SCAN_LEVELS = 20
#: The power laws with a physical name tried on an input of few levels: square law, square root, cube.
PHYSICAL_POWERS = (2.0, 0.5, 3.0)
#: The exponents of the scan on a rich input (refined around the best).
POWER_GRID = np.geomspace(0.25, 4.0, 25)
#: Values of a level tried across the input's range (a dead zone's half-width, a saturation's level).
THRESHOLD_STEPS = 16


def input_levels(x: np.ndarray) -> np.ndarray:
    """The distinct finite values of an input, ascending."""
    return distinct(x[np.isfinite(x)])


def level_count(x: np.ndarray) -> int:
    """The number of distinct finite values of an input, up to :data:`MIN_SCAN_LEVELS` (a rich
    input shows that many in its first samples: no sort of a long record)."""
    head = input_levels(x[:_HEAD_SAMPLES]).size
    if head >= MIN_SCAN_LEVELS or x.size <= _HEAD_SAMPLES:
        return min(head, MIN_SCAN_LEVELS)
    return min(input_levels(x).size, MIN_SCAN_LEVELS)


#: The samples :func:`level_count` reads first.
_HEAD_SAMPLES = 4096


def _replaced(model: ArxModel, data: IOData) -> set[str]:
    """Inputs the model already feeds through a shape."""
    shapes = (parse_effect(e, data).shape for e in model.effects if e.startswith("through("))
    return {s.signal for s in shapes if s is not None}


def shape_candidates(model: ArxModel, data: IOData, loop_signals: Sequence[str] = ()) -> list[tuple[InputShape, int]]:
    """The shapes worth fitting on ``data``, each with the number of parameter values its family
    tries (before the scan picks one on a rich input).

    Parameters
    ----------
    model : ArxModel
    data : IOData
    loop_signals : sequence of str
        Logged signals of a feedback loop: never a modulating signal.

    Returns
    -------
    list of (InputShape, int)
        On a staircase input, one shape per physical law or threshold (count 1); on a rich input one
        per family with a placeholder parameter (the scan fills it in) and its grid size.
    """
    names = candidate_input_names(data)
    done = _replaced(model, data)
    extras = [k for k in data.extra if k.isidentifier() and k not in {*names, *loop_signals, data.output_name}]
    out: list[tuple[InputShape, int]] = []
    for i, name in enumerate(names):
        if name in done or model.nb_[i] == 0:
            continue
        x = np.asarray(data.u[:, i], dtype=float)
        levels = level_count(x)
        if levels < 3:
            continue
        lo, hi = float(np.nanmin(x)), float(np.nanmax(x))
        out += _power_shapes(name, x, levels, lo) + _threshold_shapes(name, lo, hi)
        out += [(InputShape("product", name, (), v), 1) for v in extras]
    return out


def _power_shapes(name: str, x: np.ndarray, levels: int, lo: float) -> list[tuple[InputShape, int]]:
    kind = "signed power" if changes_sign(x) else "power" if lo >= 0 else None
    if kind is None:  # a one-sided input below zero: no power law about its zero
        return []
    if levels < MIN_SCAN_LEVELS:
        return [(InputShape(kind, name, (p,)), 1) for p in PHYSICAL_POWERS]
    return [(InputShape(kind, name, (1.0,)), POWER_GRID.size)]


def _threshold_shapes(name: str, lo: float, hi: float) -> list[tuple[InputShape, int]]:
    """A saturation and a dead zone, their levels scanned on the data (a level between two steps of
    a staircase still shows: the steps beyond it all give the same f)."""
    return [
        (InputShape("saturation", name, (lo - 1.0, hi + 1.0)), 4 * THRESHOLD_STEPS),
        (InputShape("dead zone", name, (0.0,)), 2 * THRESHOLD_STEPS),
    ]


def _scan(
    model: ArxModel, data: IOData, sample: IOData, shape: InputShape, const: bool, shared: dict | None = None
) -> InputShape:
    """The shape's parameters with the lowest one-step error on ``sample`` (:func:`scan_sample` of
    ``data``): a grid across the whole record's input (a saturation's two levels in turn), then a
    local search from its best point (each value tried costs a refit's loss: :class:`ShapeCost`)."""
    x = np.asarray(data.u[:, candidate_input_names(data).index(shape.signal)], dtype=float)
    x = x[np.isfinite(x)]
    kind, name = shape.kind, shape.signal

    loss = ShapeCost(model, sample, kind, name, const, shared)

    def cost(params) -> float:
        return loss(np.atleast_1d(params).tolist())  # Python floats, as ShapeCost reads them

    def best(values: np.ndarray, make) -> InputShape:
        shapes = [make(float(v)) for v in values]
        return shapes[int(np.argmin(loss.many([s.params for s in shapes])))]

    if kind == "saturation":
        lo, hi = float(np.min(x)), float(np.max(x))
        mid, span = float(median(x)), hi - lo
        uppers = np.append(np.linspace(mid, hi, THRESHOLD_STEPS + 1)[1:], hi + span)
        lowers = np.append(np.linspace(lo, mid, THRESHOLD_STEPS + 1)[:-1], lo - span)
        up = best(uppers, lambda h: InputShape(kind, name, (lo - span, h)))
        down = best(lowers, lambda v: InputShape(kind, name, (v, up.params[1])))
        step = span / THRESHOLD_STEPS
        start = np.array(down.params)
        simplex = [start, start + [step, 0.0], start + [0.0, step]]
        found, fun = simplex_minimum(cost, np.array(simplex), maxfev=60, xatol=1e-3 * step)
        found = found if fun <= cost(start) else start
        return InputShape(kind, name, (float(min(found)), float(max(found))))
    grid = POWER_GRID if kind in ("power", "signed power") else _half_widths(x)
    first = best(grid, lambda v: InputShape(kind, name, (v,)))
    i = int(np.argmin(np.abs(grid - first.params[0])))
    bounds = (grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)])
    at, fun = bounded_minimum(cost, bounds, xatol=1e-4 * bounds[1])
    return InputShape(kind, name, (float(at),)) if fun <= cost(first.params) else first


def _half_widths(x: np.ndarray) -> np.ndarray:
    """The dead-zone half-widths of the grid: across the input's magnitudes."""
    return np.linspace(0.0, float(np.max(np.abs(x))), THRESHOLD_STEPS + 2)[1:-1]


def score_shapes(
    model: ArxModel, data: IOData, evidence: ValidationEvidence, loop_signals: Sequence[str] = ()
) -> list[dict]:
    """The shapes of :func:`shape_candidates` fitted and scored as the judge reads candidates.

    Parameters
    ----------
    model : ArxModel
    data : IOData
        Estimation data.
    evidence : ValidationEvidence
        The model's validation errors, against which each shape's are tested.
    loop_signals : sequence of str

    Returns
    -------
    list of dict
        ``{"c": Candidate, "score", "f", "p", "p_adj", "q"}`` per shape, as
        :meth:`arxid.diagnosis.judge.Judge.suspects` takes them.
    """
    if isinstance(model, IvModel):  # closed loop: a shape's refit would need its own instruments
        return []
    shapes = shape_candidates(model, data, loop_signals)
    if not shapes:
        return []
    offsets = (False, True) if "const" not in model.effects else (False,)
    n_shapes = len(shapes) * len(offsets)
    sample = scan_sample(data).data
    # the offset a shape may need is in the scan: the parameter is found with it
    shared: dict = {}  # the scans' projections (one model, one sample, one offset)
    shapes = [(_scan(model, data, sample, shape, offsets[-1], shared) if n > 1 else shape, n) for shape, n in shapes]
    fits = ShapeFits(model, data, [(shape, const) for shape, _ in shapes for const in offsets])
    beside = BesideFit(model, data)
    out = []
    for shape, n in shapes:
        tried = n_shapes * n  # Bonferroni: every shape, and every value a scan tried
        for const in offsets:
            entry = _scored(model, shape, const, evidence, beside, fits)
            if entry is not None:
                out.append({**entry, "p_adj": min(1.0, entry["p"] * tried)})
    return out


class ShapeFits:
    """The models with an input replaced by each shape (and an offset), fitted from one factor of
    their envelope (:mod:`arxid.models.envelope`: one pass of the core over the data, not one per
    shape); on data with gaps each is refitted on its own rows."""

    def __init__(self, model: ArxModel, data: IOData, shapes: Sequence[tuple[InputShape, bool]]):
        self.model, self.data = model, data
        m = model
        # the model itself first: its columns in the factor give each shape's beside fit too
        self.specs = [(m.na_, m.nb_, m.nk_, list(m.effects))] + [self._spec(shape, const) for shape, const in shapes]
        self.envelope: EnvelopeFactor | None = None
        if len(self.specs) > 1:
            try:
                self.envelope = EnvelopeFactor(data, self.specs, model.first_lag_)
            except ArxidError:  # data with gaps, or a shape that cannot be compiled
                self.envelope = None

    def _spec(self, shape: InputShape, const: bool) -> tuple:
        m = self.model
        return (m.na_, m.nb_, m.nk_, [*m.effects, shape.effect] + (["const"] if const else []))

    def fit(self, shape: InputShape, const: bool) -> ArxModel:
        """The model with ``shape`` (raises as its own fit raises)."""
        spec = self._spec(shape, const)
        fitted = ArxModel(na=spec[0], nb=spec[1], nk=spec[2], effects=spec[3])
        i = self.specs.index(spec) if spec in self.specs else -1
        if self.envelope is not None and i >= 0 and self.envelope.has(i):
            return fitted.fit_in(self.envelope, i)
        return fitted.fit(self.data, first_lag=self.model.first_lag_)

    def beside(self, shape: InputShape, const: bool) -> Beside | None:
        """The model with ``shape``'s columns (and an offset) beside its own, from the envelope's
        factor (:func:`beside_from_factor`); None without one (raises as the refit raises)."""
        spec = self._spec(shape, const)
        if self.envelope is None or spec not in self.specs:
            return None
        return beside_from_factor(self.envelope, self.model, 0, self.specs.index(spec))


class ValidationEvidence:
    """The model's validation errors, found once, against which each shape's are tested: their
    squares are kept (NaN where the error is not finite), and the core forms a shape's loss
    differences and their lagged sums over its prediction in one call (``_core.loss_difference``).
    ``prediction``: the model's validation prediction when the baseline made it (else made here)."""

    def __init__(
        self,
        model: ArxModel,
        validation: IOData,
        horizon: int | None,
        initial: str,
        prediction: np.ndarray | None = None,
    ):
        self.model, self.validation, self.horizon, self.initial = model, validation, horizon, initial
        self._squares: np.ndarray | None = None
        self._made = prediction

    def _prediction(self, model: ArxModel) -> np.ndarray:
        """The validation prediction (a new array)."""
        return prediction(model, self.validation, self.horizon, self.initial)[0]

    def p_value(self, fitted: ArxModel) -> float:
        """One-sided p-value that ``fitted``'s validation error is below the model's (as
        :func:`validation_p`)."""
        y = np.ascontiguousarray(self.validation.y, dtype=float)
        if self._squares is None:
            made, self._made = self._made, None
            base = np.subtract(y, self._prediction(self.model) if made is None else made)
            known = np.isfinite(base)
            self._squares = np.square(base, out=base)
            self._squares[~known] = np.nan  # an infinite error is no evidence either
        pred = np.require(self._prediction(fitted), dtype=float, requirements=["C", "A", "W"])
        n, mean, sums = _core.loss_difference(y, self._squares, pred)  # overwrites pred
        return _normal_tail(comparison_from_sums(n, mean, sums).statistic)


def _scored(
    model: ArxModel, shape: InputShape, const: bool, evidence: ValidationEvidence, fit: BesideFit, fits: ShapeFits
) -> dict | None:
    """One shape as the judge reads a candidate, with the smaller p-value of its two tests, doubled."""
    try:
        beside = fits.beside(shape, const)  # the shape's columns (and the offset) beside the input's
        if beside is None:
            beside = fit(shape, const)
        p_val = evidence.p_value(fits.fit(shape, const))
    except ArxidError:
        return None
    q = model.nb_[fit.names.index(shape.signal)] + int(const)
    f, p_est = _f_test(model.rss_, beside.rss, q, beside.n_rows - beside.n_params)
    p = min(1.0, 2 * min(p_est, p_val))
    label = shape.effect + ("+const" if const else "")
    effects = (shape.effect, "const") if const else (shape.effect,)
    c = Candidate(label, effects, model.na_, tuple(model.nb_), tuple(model.nk_), "shape")
    score = math.sqrt(max(0.0, 1.0 - beside.rss / model.rss_)) if model.rss_ > 0 else 0.0
    return {"c": c, "score": score, "f": f, "p": p, "q": q}


def _f_test(rss0: float, rss1: float, q: int, dof: int) -> tuple[float, float]:
    """Partial F statistic of ``q`` added parameters and its p-value."""
    if dof <= 0 or not rss1 > 0 or not math.isfinite(rss0):
        return math.nan, 1.0
    f = max(0.0, (rss0 - rss1) / q) / (rss1 / dof)
    return f, f_sf(f, q, dof)


def validation_p(base_err: np.ndarray, shape_err: np.ndarray) -> float:
    """One-sided p-value that the shape's validation error is below the model's (Diebold–Mariano)."""
    return _normal_tail(diebold_mariano(base_err, shape_err).statistic)


def _normal_tail(stat: float) -> float:
    """The standard normal's tail beyond ``stat`` (0 or 1 beyond the float range)."""
    if not math.isfinite(stat):
        return 0.0 if stat > 0 else 1.0
    return 0.5 * math.erfc(stat / math.sqrt(2.0))  # the normal tail beyond stat


def prefer_shapes(suspects: list[Suspect], data: IOData, min_improvement: float) -> list[Suspect]:
    """A shape is the simpler explanation of its input: it replaces the input's columns where an
    additive term (``u^2``, ``u^3``, ``sign(du)``, ``u*y`` ...) adds its own beside them. An additive
    term of an input that has a significant shape stays significant only when its validation error
    is ``min_improvement`` below the best shape's; of several shapes of one input, the one with the
    lowest validation error stays.

    Parameters
    ----------
    suspects : list of Suspect
        Judged suspects.
    data : IOData
        The estimation data (to read which input each term involves).
    min_improvement : float

    Returns
    -------
    list of Suspect
    """
    suspects = [_product_as_term(s, suspects, data, min_improvement) for s in suspects]
    groups: dict[str, list[Suspect]] = {}
    for s in suspects:
        if s.kind == "shape" and s.refitted and math.isfinite(s.rms_sim_val_after):
            groups.setdefault(_shape_of(s, data).signal, []).append(s)
    best = {
        name: _simplest(group, data, min_improvement)
        for name, group in groups.items()
        if any(s.significant for s in group)
    }
    suspects = [replace(s, significant=True) if s in best.values() else s for s in suspects]
    best = {name: replace(s, significant=True) for name, s in best.items()}
    if not best:
        return suspects
    return [_against_shapes(s, best, data, min_improvement) for s in suspects]


def _simplest(group: list[Suspect], data: IOData, min_improvement: float) -> Suspect:
    """Of one input's shapes, the one with the fewest fitted parameters unless one with more lowers
    the validation error by ``min_improvement`` (on a staircase a named power law has none, and a
    dead zone at the right level can pass through the same steps as the square law)."""
    ranked = sorted(group, key=lambda s: (fitted_parameters(s, data), s.rms_sim_val_after))
    chosen = ranked[0]
    for s in ranked[1:]:
        more = fitted_parameters(s, data) > fitted_parameters(chosen, data)
        if s.rms_sim_val_after < (1.0 - min_improvement if more else 1.0) * chosen.rms_sim_val_after:
            chosen = s
    return chosen


def fitted_parameters(s: Suspect, data: IOData) -> int:
    """Parameters a shape suspect fitted beyond the gains: its scanned ones and the offset (a power
    law on a staircase is a named law, with none)."""
    shape = _shape_of(s, data)
    scanned = 0 if shape.kind == "product" else len(shape.params)
    if shape.kind in ("power", "signed power") and level_count(data.signal(shape.signal)) < MIN_SCAN_LEVELS:
        scanned = 0
    return scanned + int("const" in s.effects)


def _product_as_term(s: Suspect, suspects: list[Suspect], data: IOData, min_improvement: float) -> Suspect:
    """A product shape, through(u*x), says what the additive term u*x says (the gain scales with x),
    and the additive form contains it: the term keeps the name unless the shape beats it by the margin."""
    if s.kind != "shape" or not s.significant or _shape_of(s, data).kind != "product":
        return s
    shape = _shape_of(s, data)
    terms = {f"{shape.signal}*{shape.other}", f"{shape.other}*{shape.signal}"}
    for t in suspects:
        if t.significant and t.effect.removesuffix("+const") in terms:
            if s.rms_sim_val_after > (1.0 - min_improvement) * t.rms_sim_val_after:
                return replace(s, significant=False, note=f"no better than the term {t.effect}", explained_by=t.effect)
    return s


def _shape_of(s: Suspect, data: IOData) -> InputShape:
    shape = parse_effect(s.effects[0], data).shape
    assert shape is not None
    return shape


def _against_shapes(s: Suspect, best: dict[str, Suspect], data: IOData, min_improvement: float) -> Suspect:
    if not s.significant or s.kind == "dynamics":
        return s
    if s.kind == "shape":
        rival = best[_shape_of(s, data).signal]
        if rival.effect == s.effect:
            return s
        return replace(s, significant=False, note=f"{rival.effect} fits this input better", explained_by=rival.effect)
    names = {f.signal for e in s.effects if e not in ("const", "time") for f in parse_effect(e, data).factors}
    for name in names & set(best):
        rival = best[name]
        if s.rms_sim_val_after > (1.0 - min_improvement) * rival.rms_sim_val_after:
            note = f"no better than {rival.effect}, which feeds {name} through a shape with fewer parameters"
            return replace(s, significant=False, note=note, explained_by=rival.effect)
    return s
