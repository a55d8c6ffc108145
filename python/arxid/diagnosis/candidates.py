"""The catalogue of candidate effects the missing-effect diagnosis tries, with their physics.

Each candidate suits one kind of signal, and the kinds are read from the data so that the list
stays short (every candidate tried costs the others some significance in the multiple-comparison
correction):

* **input** — an actuator command. Dead zone, saturation, asymmetric gain, square law.
* **output as a speed** — the output changes sign (a bidirectional motor's speed) and the model does
  not integrate it: Coulomb friction is c·sign(y), direction-independent losses c·|y|.
* **output as a position** — friction acts on the motion, sign(dy); an output the model integrates
  (a pole at 1) is a position, never a speed, so sign(y) is not tried for it.
* **logged signal** — an extra signal (battery voltage, temperature): as an input, or scaling one.

Thresholds (``dz``, ``sat``) are nonlinear in one parameter. :func:`threshold_grid` gives the
values tried: the 5 %, 10 %, …, 95 % quantiles of |x|; the diagnosis scores each value as an
ordinary regressor, refines around the best one on a grid ten times finer, multiplies the chosen
threshold's p-value by the number of values tried (Bonferroni, so a scan never buys significance),
and then validates the chosen threshold like every other candidate. A rate limit has no form that
is linear in its parameter (the limited signal depends on its own past), so it is not a candidate.
"""

from __future__ import annotations

import re
import weakref
from collections.abc import Callable, Sequence

import numpy as np

from .._base.order_statistics import distinct, sorted_quantiles
from .._base.records import record
from ..data.iodata import IOData
from ..models.arx_model import ArxModel
from ..models.effects import Factor, parse_effect
from ..models.polynomial import PolynomialModel
from ..selection.integrator import structure_integrates

__all__ = [
    "CATALOGUE",
    "CatalogueEntry",
    "INTEGRATING_HORIZON",
    "auto_candidates",
    "auto_effects",
    "candidate_input_names",
    "changes_sign",
    "output_integrates",
    "physics",
    "scan_threshold",
    "threshold_grid",
]

#: Share of samples needed on each side of zero for a signal to count as changing sign.
SIGN_CHANGE_SHARE = 0.02
#: Distinct values of |x| needed before a threshold is scanned on x.
MIN_THRESHOLD_LEVELS = 20
#: k used for the validation error of a plant with an integrator (free run drifts).
INTEGRATING_HORIZON = 10


@record
class CatalogueEntry:
    """One kind of candidate: how it is written, what it stands for, which signal it suits.

    Attributes
    ----------
    written : str
        The candidate in the effect grammar (``u`` stands for each input, ``x`` for a logged signal).
    physics : str
        What it stands for, in a control engineer's words.
    signal_kind : str
        ``"input"``, ``"output (speed)"``, ``"output (position)"``, ``"output"``, ``"logged signal"``
        or ``"model"``.
    offered_when : str
        When :func:`auto_candidates` proposes it.
    """

    written: str
    physics: str
    signal_kind: str
    offered_when: str = "always"


CATALOGUE: tuple[CatalogueEntry, ...] = (
    CatalogueEntry("x", "a logged signal acting as an extra input", "logged signal"),
    CatalogueEntry("u*x", "input gain scaled by a logged signal (battery sag)", "input, logged signal"),
    CatalogueEntry("u1*u2", "interaction of two inputs", "input", "two or more inputs"),
    CatalogueEntry("u*y", "input gain that depends on the output (bilinear)", "input, output"),
    CatalogueEntry("u^2", "square law (propeller thrust ∝ ω², heating power ∝ V²)", "input"),
    CatalogueEntry("u^3", "cubic input nonlinearity", "input"),
    CatalogueEntry("y^2", "quadratic output term (drag ∝ v·|v| on a one-way speed)", "output"),
    CatalogueEntry("y^3", "hardening or softening spring (cubic stiffness)", "output"),
    CatalogueEntry("abs(u)", "direction-independent effect of the input", "input", "u changes sign"),
    CatalogueEntry("abs(y)", "direction-independent losses (drag ∝ |v|)", "output (speed)", "y changes sign"),
    CatalogueEntry(
        "sign(y)",
        "Coulomb friction on a speed output",
        "output (speed)",
        "y changes sign and the model does not integrate",
    ),
    CatalogueEntry("sign(dy)", "Coulomb friction on a position output", "output (position)"),
    CatalogueEntry("sign(du)", "a reversal of the input's direction (backlash-like)", "input"),
    CatalogueEntry("dz(u,c)", "dead zone of the actuator (no response while |u| < c)", "input", "|u| takes 20+ values"),
    CatalogueEntry(
        "sat(u,c)", "actuator saturation (response flattens above |u| > c)", "input", "|u| takes 20+ values"
    ),
    CatalogueEntry("pos(u)", "different gains for positive and negative inputs", "input", "u changes sign"),
    CatalogueEntry("const", "offset (bias, ambient level)", "model", "the model has no offset"),
    CatalogueEntry("time", "slow drift", "model"),
    CatalogueEntry("X+const", "the effect X together with an offset (asymmetric friction)", "model", "X is strong"),
    CatalogueEntry("na+1", "one more pole (more output dynamics)", "model"),
    CatalogueEntry("nf+1", "one more pole of the input's transfer function B/F", "model", "the model has F (OE, BJ)"),
    CatalogueEntry("nb+1", "one more input lag", "model"),
    CatalogueEntry("nk-1, nk+1", "a delay one sample shorter or longer", "model"),
)


def changes_sign(x: np.ndarray) -> bool:
    """True when at least ``SIGN_CHANGE_SHARE`` of the finite samples lie on each side of zero.

    Parameters
    ----------
    x : ndarray

    Returns
    -------
    bool
    """
    x = x[np.isfinite(x)]
    return bool(x.size > 0 and min(np.mean(x < 0), np.mean(x > 0)) >= SIGN_CHANGE_SHARE)


def output_integrates(model: ArxModel, free_run_fit: float | None = None) -> bool:
    """True when the model's output integrates (a position): the sweep's integrator rule
    (:func:`arxid.selection.integrator.structure_integrates`) applied to this one model.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    free_run_fit : float, optional
        Its free-run fit on validation data, percent: a stable model whose free run settles within
        the record and follows the data is not integrating, whatever its unit-root statistic.

    Returns
    -------
    bool
    """
    return structure_integrates(model.parameters_, model.covariance_, model.na_, model.n_rows_, free_run_fit)


def threshold_grid(x: np.ndarray) -> np.ndarray:
    """Thresholds tried for ``dz(x,c)`` and ``sat(x,c)``: the 5 %, …, 95 % quantiles of |x|.

    Parameters
    ----------
    x : ndarray
        The signal (NaN ignored).

    Returns
    -------
    ndarray
        Distinct positive thresholds, ascending (empty when |x| takes fewer than
        ``MIN_THRESHOLD_LEVELS`` values).
    """
    a = np.sort(np.abs(x[np.isfinite(x)]))  # one sort serves the count of levels and the quantiles
    if a.size == 0 or 1 + np.count_nonzero(a[1:] != a[:-1]) < MIN_THRESHOLD_LEVELS:
        return np.zeros(0)
    q = distinct(sorted_quantiles(a, np.linspace(0.05, 0.95, 19)))
    return q[q > 0]


#: The thresholds of each signal of a data set (weakly held: an entry goes with its data).
_GRIDS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def signal_thresholds(data: IOData, name: str) -> np.ndarray:
    """:func:`threshold_grid` of the signal ``name`` of ``data``, found once per data set: a
    diagnosis asks for it when it lists its candidates and again when it scans, and a ladder
    diagnoses the same data again (each a sort of the record).

    Parameters
    ----------
    data : IOData
    name : str
        A signal of ``data`` (as :meth:`IOData.signal` reads it).

    Returns
    -------
    ndarray
        As :func:`threshold_grid` (a copy: the kept grid is not changed through it).
    """
    memo = _GRIDS.setdefault(data, {})
    if name not in memo:
        memo[name] = threshold_grid(np.asarray(data.signal(name), dtype=float))
    return memo[name].copy()


def auto_candidates(model: ArxModel, data: IOData, loop_signals: Sequence[str] = ()) -> list[str]:
    """Candidate effects and structure changes built from the signals of ``data``.

    Effects (grammar of :mod:`arxid.effects`, physics in :data:`CATALOGUE`): each extra signal as
    a new input; products of each input with every extra signal, every other input and the output;
    powers 2 and 3 of each input and of the output; ``abs`` of signals that change sign;
    ``sign(y)`` for an output that changes sign and is not integrated (friction on a speed);
    ``sign(dNAME)`` of the output and of each input; ``dz(u)`` / ``sat(u)`` (threshold scanned) and
    ``pos(u)`` of each input; ``const``; ``time``. Dynamics: ``na+1``, ``nb+1`` and ``nk±1`` (per
    input, written ``nb(name)+1`` when there are several inputs); for a polynomial model those of
    :func:`arxid.polynomial_diagnosis.structure_changes` (``nf+1`` instead of ``na+1`` for OE and
    BJ). Candidates already in the model are left out.

    Parameters
    ----------
    model : ArxModel
        The fitted model to extend (its effects and orders ``nb_``, ``nk_``).
    data : IOData
        The data whose input, output and extra signals the candidates are built from.
    loop_signals : sequence of str
        Extra signals that belong to a feedback loop (its reference, the controller's terms): never
        candidates, alone or in products, since they explain the output through the loop.

    Returns
    -------
    list of str
        The effect strings first, then the structure changes (``na+1``, ``nb+1``, ``nk-1``, ...).
        ``dz(u1)`` and ``sat(u1)`` without a threshold ask the diagnosis to scan it.
    """
    have = set(model.effects)
    ins = candidate_input_names(data)
    effects = auto_effects(data, lambda: output_integrates(model), loop_signals)
    return [e for e in effects if e not in have] + _dynamics_candidates(model, ins)


def auto_effects(data: IOData, integrates: Callable[[], bool], loop_signals: Sequence[str] = ()) -> list[str]:
    """The effects of :func:`auto_candidates`, for any model of ``data``'s output.

    Parameters
    ----------
    data : IOData
        The data of one output.
    integrates : callable
        Whether the model integrates the output (a position: ``sign(y)`` is then not offered);
        asked only when the output changes sign.
    loop_signals : sequence of str
        Extra signals of a feedback loop, never candidates.

    Returns
    -------
    list of str
    """
    # Effects are written in the grammar's words: a name that is not an identifier (``rpm[1/min]``)
    # is called u1, u2, ... for an input and left out for an extra signal.
    ins = candidate_input_names(data)
    skip = {*ins, "y", data.output_name, *loop_signals}
    extras = [k for k in data.extra if k.isidentifier() and k not in skip]
    out: list[str] = list(extras)
    for i, a in enumerate(ins):
        out += [f"{a}*{x}" for x in extras]
        out += [f"{a}*{b}" for b in ins[i + 1 :]]
        out.append(f"{a}*y")
    for a in ins:
        out += [f"{a}^2", f"{a}^3"]
    out += ["y^2", "y^3"]
    out += [f"abs({a})" for i, a in enumerate(ins) if changes_sign(data.u[:, i])]
    if changes_sign(data.y):
        out.append("abs(y)")
        if not integrates():
            out.append("sign(y)")
    out.append("sign(dy)")
    out += [f"sign(d{a})" for a in ins]
    for i, a in enumerate(ins):
        if signal_thresholds(data, a).size:
            out += [f"dz({a})", f"sat({a})"]
        if changes_sign(data.u[:, i]):
            out.append(f"pos({a})")
    return out + ["const", "time"]


def candidate_input_names(data: IOData) -> list[str]:
    """The inputs as candidates name them: their names, or u1, u2, ... for a name that is not an
    identifier (``rpm[1/min]``).

    Parameters
    ----------
    data : IOData

    Returns
    -------
    list of str
    """
    return [a if a.isidentifier() else f"u{i + 1}" for i, a in enumerate(data.input_names)]


def _dynamics_candidates(model: ArxModel, ins: list[str]) -> list[str]:
    if isinstance(model, PolynomialModel):
        from .polynomial import structure_changes

        return structure_changes(model, ins)
    dyn = ["na+1"]
    for i, a in enumerate(ins):
        tag = "" if len(ins) == 1 else f"({a})"
        if model.nb_[i] > 0:
            dyn.append(f"nb{tag}+1")
            if model.nk_[i] > 0:
                dyn.append(f"nk{tag}-1")
            dyn.append(f"nk{tag}+1")
    return dyn


_BY_WRITTEN = {e.written: e for e in CATALOGUE}
_DYNAMICS = re.compile(r"(?P<what>na|nb|nf|nk)(?:\([^)]*\))?(?P<sign>[+-])1")
_SCAN = re.compile(r"(?P<op>dz|sat)\((?P<signal>[A-Za-z_]\w*)\)")


def physics(label: str, data: IOData) -> str:
    """What a candidate stands for, in a control engineer's words (``""`` when it is not in the catalogue).

    Parameters
    ----------
    label : str
        A candidate as the diagnosis lists it: an effect (``"sign(y)"``, ``"dz(u1,0.3)"``), a pair
        (``"sign(dy)+const"``) or a structure change (``"na+1"``).
    data : IOData
        The data, to tell inputs, the output and logged signals apart.

    Returns
    -------
    str
        e.g. ``"Coulomb friction on a speed output"``.
    """
    label = label.replace(" ", "")
    dyn = _DYNAMICS.fullmatch(label)
    if dyn:
        key = "nk-1, nk+1" if dyn["what"] == "nk" else f"{dyn['what']}+1"
        text = _BY_WRITTEN[key].physics
        return text if dyn["what"] != "nk" else f"a delay one sample {'shorter' if dyn['sign'] == '-' else 'longer'}"
    parts = [p for p in label.split("+") if p]
    if len(parts) > 1:
        first = "+".join(parts[:-1]) if parts[-1] == "const" else None
        if first is not None:
            return f"{physics(first, data)}, with an offset"
        return "; ".join(physics(p, data) for p in parts)
    scan = _SCAN.fullmatch(label)
    if scan:
        return _entry_text(f"{scan['op']}(u,c)", scan["signal"], "c")
    return _effect_physics(label, data)


def _effect_physics(label: str, data: IOData) -> str:
    from ..exceptions import OrderError

    try:
        effect = parse_effect(label, data)
    except OrderError:
        return ""
    if effect.special is not None:
        return _BY_WRITTEN[effect.special].physics
    if effect.shape is not None:
        return effect.shape.physics()
    written = "*".join(_written(f, data) for f in effect.factors)
    if written in ("u*u", "u*u2"):
        written = "u1*u2"
    f = effect.factors[0]
    if f.op in ("dz", "sat"):
        return _entry_text(f"{f.op}(u,c)", f.signal, f"{f.threshold:.4g}")
    entry = _BY_WRITTEN.get(written.replace("neg(", "pos("))
    return entry.physics if entry is not None else ""


def _written(f: Factor, data: IOData) -> str:
    """A factor in the catalogue's letters: u for an input, y for the output, x for a logged signal."""
    if f.signal in ("y", data.output_name):
        role = "y"
    elif f.signal in data.input_names or (re.fullmatch(r"u\d+", f.signal) and f.signal not in data.extra):
        role = "u"
    else:
        role = "x"
    return {
        "pow": role if f.power == 1 else f"{role}^{f.power}",
        "abs": f"abs({role})",
        "sign": f"sign({role})",
        "signdiff": f"sign(d{role})",
        "diff": f"d{role}",
    }.get(f.op, f"{f.op}({role})")


def _entry_text(written: str, signal: str, c: str) -> str:
    """The dead-zone or saturation text with the signal's name and the threshold filled in."""
    text = _BY_WRITTEN[written].physics
    return text.replace("|u|", f"|{signal}|").replace("< c", f"< {c}").replace("> c", f"> {c}")


def scan_threshold(
    x: np.ndarray, scores: Callable[[np.ndarray], np.ndarray], grid: np.ndarray | None = None
) -> tuple[float, int]:
    """The threshold c of the best score: the grid of :func:`threshold_grid`, then a grid ten times
    finer between the best value's neighbours.

    Parameters
    ----------
    x : ndarray
        The signal the threshold applies to.
    scores : callable
        The scores of an array of thresholds, one call per grid (NaN where one cannot be tested);
        the added-variable score in the diagnosis.
    grid : ndarray, optional
        The coarse grid, when known (:func:`signal_thresholds`); default :func:`threshold_grid` of ``x``.

    Returns
    -------
    c : float
        The best threshold (NaN when none could be scored).
    n_tried : int
        Number of values on the coarse grid (0 when |x| takes too few values): the Bonferroni factor
        for the chosen threshold's p-value.
    """
    grid = threshold_grid(x) if grid is None else grid
    coarse = np.asarray(scores(grid), dtype=float) if grid.size else np.zeros(0)
    if not grid.size or np.isnan(coarse).all():
        return float("nan"), int(grid.size)
    i = int(np.nanargmax(coarse))
    fine = np.linspace(grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)], 21)
    near = np.asarray(scores(fine), dtype=float)
    if np.isnan(near).all() or np.nanmax(near) <= coarse[i]:
        return float(grid[i]), int(grid.size)
    return float(fine[int(np.nanargmax(near))]), int(grid.size)
