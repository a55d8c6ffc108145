"""Effects: physical terms a user adds to an ARX model, written as short strings.

================  ===================================  ==========================================
effect            meaning                              typical physics
================  ===================================  ==========================================
``vbat``          a logged signal used as an input     battery voltage, temperature
``u1*vbat``       product of two signals               command scaled by battery
``u1^2``          power of a signal                    propeller thrust ∝ ω²
``y^3``           power of the output                  cubic spring
``abs(u1)``       absolute value                       direction-independent losses
``sign(y)``       sign of the output                   Coulomb friction when y is a speed
``sign(dy)``      sign of a signal's first difference  Coulomb friction when y is a position
``dz(u1,0.2)``    dead zone of width c                 no response while |u1| < 0.2
``sat(u1,0.8)``   saturation at c                      response flattens above |u1| > 0.8
``pos(u1)``       positive part max(u1, 0)             different gains for u1 > 0 and u1 < 0
``neg(u1)``       negative part min(u1, 0)             (the same, written for the negative side)
``const``         offset                               bias
``time``          drift                                slow drift
================  ===================================  ==========================================

``dz(x,c) = sign(x)·max(|x| − c, 0)`` and ``sat(x,c) = sign(x)·min(|x|, c)``; the threshold c > 0
is in the signal's units (:func:`arxid.diagnose` finds it by a grid scan, see
:mod:`arxid.candidates`). With x itself in the model, ``dz``, ``sat`` and ``x`` span the same
space as any two of them, and so do ``pos``, ``neg`` and ``x``.

Lags: an input-derived term uses the lags (nb, nk) of the input it is built from (for a product,
of its first input factor); a signal that is not an input enters as a new input with nb = 1 and the
smallest nk of the model's inputs; ``const`` and ``time`` enter with nb = 1, nk = 0. Terms that
involve the output use lag 1 (``y^3`` means y(t-1)³, ``sign(y)`` means sign(y(t-1)), ``sign(dy)``
means sign(y(t-1) − y(t-2))) and are re-evaluated on the simulated output in free run. Thresholds
and positive/negative parts apply to inputs and logged signals only.
"""

from __future__ import annotations

import re
import threading
import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base import _core
from .._base.columns import write_columns
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError, OrderError
from .input_shapes import InputShape, parse_shape
from .term_values import format_threshold, integer_power, thresholded, thresholded_products

__all__ = [
    "Effect",
    "parse_effect",
    "EffectLayout",
    "compile_effects",
    "layout_column",
    "format_threshold",
    "factor_series",
    "thresholded",
    "thresholded_products",
    "effect_names",
    "effect_series",
]

_NUMBER = r"(?:\d+\.?\d*|\.\d+)(?:[eE]-?\d+)?"
_FACTOR = re.compile(
    r"^(?:(?P<abs>abs)\((?P<absarg>[A-Za-z_]\w*)\)"
    rf"|(?P<thr>dz|sat)\((?P<targ>[A-Za-z_]\w*),(?P<c>{_NUMBER})\)"
    r"|(?P<part>pos|neg)\((?P<parg>[A-Za-z_]\w*)\)"
    r"|sign\(d(?P<sdarg>[A-Za-z_]\w*)\)"
    r"|sign\((?P<sarg>[A-Za-z_]\w*)\)"
    r"|(?P<name>[A-Za-z_]\w*)(?:\^(?P<pow>\d+))?)$"
)


@record
class Factor:
    """One factor of an effect: ``op`` in {"pow", "abs", "sign", "signdiff", "diff", "dz", "sat", "pos",
    "neg"} applied to a signal (``threshold`` is the c of ``dz`` and ``sat``)."""

    signal: str
    op: str = "pow"
    power: int = 1
    threshold: float = 0.0


@record
class Effect:
    """A parsed effect string: a product of factors, or ``const`` / ``time``."""

    text: str
    factors: tuple[Factor, ...]
    shape: InputShape | None = None  # through(SHAPE): the shape replaces its input

    @property
    def special(self) -> str | None:
        """``"const"`` or ``"time"`` for those two effects, else None."""
        return self.text if self.text in ("const", "time") else None


def effect_names(effects: Any) -> tuple[str, ...]:
    """``effects`` as a tuple of effect strings, refusing what is not a sequence of strings.

    A single string is refused rather than split into characters: ``effects="const"`` most likely
    meant ``effects=["const"]``.

    Parameters
    ----------
    effects : sequence of str

    Returns
    -------
    tuple of str
    """
    if isinstance(effects, str):
        raise OrderError(f"effects must be a list of effect strings, e.g. [{effects!r}], not the string {effects!r}")
    try:
        names = tuple(effects)
    except TypeError:
        raise OrderError(
            f"effects must be a list of effect strings such as ['u1^2', 'const'], got {effects!r}"
        ) from None
    bad = [e for e in names if not isinstance(e, str)]
    if bad:
        raise OrderError(f"effects must be strings such as 'u1^2' or 'const', got {bad[0]!r}")
    return names


#: What a parsed effect or a layout's lags and labels depend on in the data: the signals' names
#: (never their samples). A diagnosis parses and compiles the same effects hundreds of times, on
#: the record and on the slices and samples cut from it, which share these names.
_SignalsKey = tuple[Any, tuple[str, ...], tuple[str, ...], tuple[str, ...], int]

#: Entries kept in each cache below (the oldest go first): more than a diagnosis of many signals uses.
_CACHE_SIZE = 4096


def _signals_key(data: IOData) -> _SignalsKey:
    key = _KEYS.get(data)  # read once per data set: a diagnosis asks for it a thousand times
    if key is None:
        key = (data.output_name, data.output_names, data.input_names, tuple(data.extra), data.n_inputs)
        with _CACHE_LOCK:
            _KEYS[data] = key
    return key


#: The signal names of each data set (they never change).
_KEYS: weakref.WeakKeyDictionary[IOData, _SignalsKey] = weakref.WeakKeyDictionary()


def _remember(cache: dict, key: Any, value: Any) -> Any:
    """``value`` kept under ``key`` (immutable values only: callers share them)."""
    with _CACHE_LOCK:
        cache[key] = value
        while len(cache) > _CACHE_SIZE:
            cache.pop(next(iter(cache)))
    return value


#: Parsed effects by (text, the data's signal names).
_PARSED: dict[tuple[str, _SignalsKey], Effect] = {}

#: Stages of an analysis may parse and compile on two threads (:mod:`arxid._base.background`).
_CACHE_LOCK = threading.Lock()


def _split_product(text: str) -> list[str]:
    return [f for f in text.split("*") if f]


def parse_effect(text: str, data: IOData) -> Effect:
    """Parse ``text`` against the signals of ``data``.

    Parameters
    ----------
    text : str
        An effect such as ``"u1^2"``, ``"u1*vbat"``, ``"y^3"`` or ``"sign(dy)"`` (see the grammar in
        :mod:`arxid.effects`).
    data : IOData
        The data whose signals the effect may name.

    Returns
    -------
    Effect

    Raises
    ------
    OrderError
        For an effect the grammar does not know or a signal the data do not have.
    """
    if not isinstance(text, str) or not text.strip():
        raise OrderError(f"an effect must be a non-empty string such as 'u1^2' or 'y^3', got {text!r}")
    key = (text, _signals_key(data))
    parsed = _PARSED.get(key)
    if parsed is None:  # an error is raised again each time, never kept
        parsed = _remember(_PARSED, key, _parse(text, data))
    return parsed


def _parse(text: str, data: IOData) -> Effect:
    clean = re.sub(r"\s+", "", text)
    if clean in ("const", "time"):
        return Effect(clean, ())
    names = set(data.signal_names) | {"y"} | {f"u{i + 1}" for i in range(data.n_inputs)}
    if clean.startswith("through(") and clean.endswith(")"):
        return _through(clean, names, data)
    factors = []
    for part in _split_product(clean):
        m = _FACTOR.match(part)
        if not m:
            raise OrderError(
                f"cannot read effect {text!r}: factor {part!r} is not one of NAME, NAME^p, abs(NAME), "
                f"sign(dNAME), sign(NAME), dNAME, dz(NAME,c), sat(NAME,c), pos(NAME), neg(NAME)"
            )
        if m["absarg"]:
            f = Factor(m["absarg"], "abs")
        elif m["thr"]:
            f = Factor(m["targ"], m["thr"], threshold=_threshold(text, m["c"]))
        elif m["part"]:
            f = Factor(m["parg"], m["part"])
        elif m["sdarg"]:
            f = Factor(m["sdarg"], "signdiff")
        elif m["sarg"]:
            f = Factor(m["sarg"], "sign")
        else:
            name, p = m["name"], int(m["pow"] or 1)
            if name not in names and name.startswith("d") and name[1:] in names:
                f = Factor(name[1:], "diff")
            else:
                if p < 1:
                    raise OrderError(f"effect {text!r}: powers must be >= 1")
                f = Factor(name, "pow", p)
        if f.signal not in names:
            raise OrderError(
                f"effect {text!r} uses signal {f.signal!r}, which the data do not have; signals: {sorted(names)}"
            )
        factors.append(f)
    if not factors:
        raise OrderError(f"cannot read effect {text!r}")
    return Effect(clean, tuple(factors))


def _through(clean: str, names: set[str], data: IOData) -> Effect:
    """A replacing shape (:mod:`arxid.models.input_shapes`): its factors are the signals it reads."""
    shape = parse_shape(clean[len("through(") : -1], names, clean)
    if _input_index(shape.signal, data) is None:
        raise OrderError(f"effect {clean!r}: through( ) shapes an input, and {shape.signal!r} is not one")
    signals = (shape.signal, shape.other) if shape.other else (shape.signal,)
    return Effect(f"through({shape.text})", tuple(Factor(s) for s in signals), shape)


def shape_series(e: Effect, data: IOData) -> np.ndarray:
    """The samples of a replacing shape's input f(u) on ``data``."""
    assert e.shape is not None
    other = data.signal(e.shape.other) if e.shape.other else None
    with np.errstate(over="ignore", invalid="ignore"):
        value = e.shape.evaluate(data.signal(e.shape.signal), other)
    _check_range(e.text, value)
    return value


def _threshold(text: str, c: str) -> float:
    value = float(c)
    if not 0 < value < float("inf"):
        raise OrderError(f"effect {text!r}: the threshold c must be a positive number, got {c}")
    return value


def _is_output(name: str, data: IOData) -> bool:
    return name in ("y", data.output_name)


def _input_index(name: str, data: IOData) -> int | None:
    if name in data.input_names:
        return data.input_names.index(name)
    if re.fullmatch(r"u\d+", name) and name not in data.extra:
        i = int(name[1:]) - 1
        if 0 <= i < data.n_inputs:
            return i
    return None


def factor_series(f: Factor, data: IOData) -> np.ndarray:
    """The samples of one factor of an effect on ``data`` (``dz(u1,0.3)`` of ``u1``), without the
    range checks and the layout of :func:`compile_effects` (a threshold scan evaluates dozens).

    Parameters
    ----------
    f : Factor
        A factor of a parsed effect (:func:`parse_effect`).
    data : IOData

    Returns
    -------
    ndarray of shape (n_samples,)
        The same numbers as the effect's column in the layout when it has this one factor.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        return _apply(f, np.asarray(data.signal(f.signal), dtype=float), data)


def _apply(f: Factor, x: np.ndarray, data: IOData) -> np.ndarray:
    if f.op == "pow":
        return integer_power(x, f.power)
    if f.op == "abs":
        return np.abs(x)
    if f.op == "sign":
        return np.sign(x)
    if f.op in ("dz", "sat"):
        magnitude = np.abs(x)
        return thresholded(f.op, magnitude, np.sign(x), f.threshold, out=magnitude)  # |x| is ours: written over
    if f.op in ("pos", "neg"):
        return np.maximum(x, 0.0) if f.op == "pos" else np.minimum(x, 0.0)
    d = np.zeros_like(x)
    for a, b in data.segments:  # np.diff's differences, written in place (no temporary per segment)
        np.subtract(x[a + 1 : b], x[a : b - 1], out=d[a + 1 : b])
    return np.sign(d, out=d) if f.op == "signdiff" else d


@record
class EffectLayout:
    """What the Rust core sees for a model with effects.

    ``u`` holds the model's inputs followed by one column per input-derived effect and one carrier
    column per output term with a multiplier. ``tie[j]`` says where column j takes its lags from: an
    input index, or None for fixed lags ``nb[j], nk[j]``.
    """

    u: np.ndarray
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    tie: tuple[int | None, ...]
    output_terms: tuple[tuple[str, int, int], ...]
    column_labels: tuple[str, ...]
    effect_of_column: tuple[str | None, ...]
    effect_of_term: tuple[str, ...]


def _output_term(f: Factor, text: str) -> tuple[str, int]:
    if f.op == "pow":
        return "pow", f.power
    if f.op in ("abs", "sign", "signdiff"):
        return f.op, 1
    raise OrderError(
        f"effect {text!r}: {f.op}(y) is not supported for the output (thresholds and positive/negative parts "
        f"apply to inputs); use y^p, abs(y), sign(y) or sign(dy)"
    )


def _check_range(text: str, value: np.ndarray) -> None:
    """Refuse an effect that leaves the float range (IOData holds no inf, so any inf is an overflow):
    the core would drop those rows as if they were missing samples."""
    if value.ndim == 1 and value.dtype == np.float64 and value.flags.c_contiguous:
        # One pass, no temporary (the largest |x|: inf when one is infinite); the sample found the long way.
        if not np.isinf(_core.peak_magnitude(value)):
            return
    bad = np.isinf(value)
    if bad.any():
        i = int(np.argmax(bad))
        raise DataError(
            f"effect {text!r} overflows the float range at sample {i} (its signals are finite there but too large for "
            f"the term); scale the signals (other units, or divide by a typical value) or use a lower power"
        )


def compile_effects(
    effects: Sequence[str], data: IOData, nb: Sequence[int], nk: Sequence[int], *, samples: bool = True
) -> EffectLayout:
    """Turn effect strings into extra regressor columns and output terms for ``data``.

    The input matrix depends only on the effects and the data (not on nb, nk): the last few built
    on each data set are kept (read-only), as a diagnosis compiles the same effects on the same
    record for every refit, free run and band.

    Parameters
    ----------
    effects : sequence of str
        Effect strings (each at most once).
    data : IOData
        The data the model is fitted on.
    nb, nk : sequence of int
        Orders and delays of the model's inputs, one per input.
    samples : bool
        False: the layout's lags, labels and output terms only (``u`` has no rows, and an effect
        that overflows is not found here).

    Returns
    -------
    EffectLayout
        The inputs followed by the effect columns, with their lags and the output terms.
    """
    texts = tuple(effects)
    with _COMPILED_LOCK:
        kept = _COMPILED.get(data)
        u = kept.get(texts) if kept is not None else None
    build = u is None and samples
    key = (texts, _signals_key(data), tuple(nb), tuple(nk))
    lags = _LAYOUTS.get(key)
    if lags is None or build:  # the columns are built (and checked) whenever they are not kept
        plan = _Plan(data, nb, nk, build=build)
        seen = set()
        for text in texts:
            e = parse_effect(text, data)
            if e.text in seen:
                raise OrderError(f"effect {e.text!r} is listed twice")
            seen.add(e.text)
            plan.effect(e, text)
        lags = _remember(_LAYOUTS, key, plan.lags())
        if build:
            u = _stacked(plan.cols, data.n_samples)
            if len(plan.cols) > 1 or plan.replaced:  # the inputs themselves need no keeping
                u = _keep(data, texts, u)
    if u is None or not samples:
        u = np.empty((0, len(lags[0])))
    return EffectLayout(u, *lags)


#: A layout's lags, ties, labels and output terms (:class:`EffectLayout` but its ``u``), by effects,
#: signal names and orders: they do not depend on the samples.
_LAYOUTS: dict[tuple, tuple] = {}

#: The input matrices of the last effect sets compiled on each data set (by effect tuple).
_COMPILED: weakref.WeakKeyDictionary[IOData, dict[tuple[str, ...], np.ndarray]] = weakref.WeakKeyDictionary()

#: The input matrices kept per data set: the last always (a model is simulated again and again),
#: and earlier ones, up to this many, while they all fit in :data:`_KEEP_BYTES` (a diagnosis of a
#: short record predicts with a dozen effect sets in turn; a long record's each fill it alone).
_KEEP_PER_DATA = 32
_KEEP_BYTES = 16 * 2**20


#: Stages of an analysis may compile on two threads (:mod:`arxid._base.background`).
_COMPILED_LOCK = threading.Lock()


def _keep(data: IOData, texts: tuple[str, ...], u: np.ndarray) -> np.ndarray:
    u.setflags(write=False)
    with _COMPILED_LOCK:
        kept = _COMPILED.setdefault(data, {})
        kept.pop(texts, None)
        kept[texts] = u
        while len(kept) > 1 and (len(kept) > _KEEP_PER_DATA or sum(a.nbytes for a in kept.values()) > _KEEP_BYTES):
            kept.pop(next(iter(kept)))
    return u


class _Plan:
    """The layout of :func:`compile_effects` as its effects are added: lags, ties, labels and output
    terms always; the columns only when ``build`` (else the kept input matrix serves)."""

    def __init__(self, data: IOData, nb: Sequence[int], nk: Sequence[int], build: bool):
        m = data.n_inputs
        self.data, self.build = data, build
        self.cols: list[np.ndarray] = [data.u]
        self.nb, self.nk = list(nb), list(nk)
        self.tie: list[int | None] = list(range(m))
        self.labels = list(data.input_names)
        self.eff_col: list[str | None] = [None] * m
        self.terms: list[tuple[str, int, int]] = []
        self.eff_term: list[str] = []
        used_nk = [k for b, k in zip(nb, nk, strict=False) if b > 0]
        self.min_nk = min(used_nk) if used_nk else 0
        self.replaced = False

    def lags(self) -> tuple:
        """The fields of :class:`EffectLayout` after ``u``."""
        return (
            tuple(self.nb),
            tuple(self.nk),
            tuple(self.tie),
            tuple(self.terms),
            tuple(self.labels),
            tuple(self.eff_col),
            tuple(self.eff_term),
        )

    def add(self, col: np.ndarray | None, b: int, k: int, source: int | None, label: str, effect: str | None) -> None:
        if col is not None:
            self.cols.append(col.reshape(-1, 1))
        self.nb.append(b)
        self.nk.append(k)
        self.tie.append(source)
        self.labels.append(label)
        self.eff_col.append(effect)

    def replace(self, e: Effect) -> None:
        """A replacing shape takes its input's column, lags and label (the input is not kept beside it)."""
        i = _input_index(e.shape.signal if e.shape else "", self.data)
        assert i is not None  # parse_effect checked it
        if self.eff_col[i] is not None:
            raise OrderError(f"effects {self.eff_col[i]!r} and {e.text!r} both replace the input {self.labels[i]!r}")
        if self.build:
            col = layout_column(e.text, self.data)  # shape_series, kept per data set (read-only)
            if self.cols[0].shape[1] == 1:  # the only input: the shape's column itself, not a copy
                self.cols[0] = col.reshape(-1, 1)
            else:
                if self.cols[0] is self.data.u:
                    self.cols[0] = self.data.u.copy()
                self.cols[0][:, i] = col
        self.labels[i], self.eff_col[i] = e.text, e.text
        self.replaced = True

    def effect(self, e: Effect, text: str) -> None:
        data = self.data
        if e.special is not None:
            col = _special_column(e.special, data, stacked=True) if self.build else None
            self.add(col, 1, 0, None, e.special, e.text)
            return
        if e.shape is not None:
            self.replace(e)
            return
        y_factors = [f for f in e.factors if _is_output(f.signal, data)]
        others = [f for f in e.factors if not _is_output(f.signal, data)]
        if len(y_factors) > 1:
            raise OrderError(f"effect {text!r}: at most one factor may involve the output")
        prod = None
        if self.build and others and text == e.text:  # kept per data set (an error names the text as given)
            prod = layout_column(f"carrier:{e.text}" if y_factors else e.text, data)
        elif self.build:
            prod = _input_product(text, others, data)
        if y_factors:
            kind, power = _output_term(y_factors[0], text)
            if self.build:
                _check_output_term(text, kind, power, prod, data)
            mult = -1
            if others:
                mult = len(self.nb)
                self.add(prod, 0, 0, None, f"carrier:{e.text}", None)
            self.terms.append((kind, power, mult))
            self.eff_term.append(e.text)
            return
        src = next((_input_index(f.signal, data) for f in others if _input_index(f.signal, data) is not None), None)
        if src is not None:
            self.add(prod, self.nb[src], self.nk[src], src, e.text, e.text)
        else:
            self.add(prod, 1, self.min_nk, None, e.text, e.text)


def _stacked(cols: list[np.ndarray], n: int) -> np.ndarray:
    """The columns side by side as one C-ordered float64 array: the inputs themselves (already
    C-ordered float64, read-only) when there is no effect column, else one array filled a block of
    rows at a time (no intermediate copies)."""
    if len(cols) == 1:
        return np.ascontiguousarray(cols[0], dtype=float)
    out = np.empty((n, sum(c.shape[1] for c in cols)))
    starts = np.cumsum([0] + [c.shape[1] for c in cols[:-1]])
    write_columns(out, dict(zip(starts.tolist(), cols)))
    return out


def effect_series(text: str, data: IOData) -> np.ndarray:
    """The effect's signal at each sample, without lags: ``y^3`` is y(t)³, ``sign(dy)`` is
    sign(y(t) − y(t−1)), ``u1*vbat`` is u1(t)·vbat(t) (the model applies the lags).

    Parameters
    ----------
    text : str
        An effect string (see the grammar above).
    data : IOData

    Returns
    -------
    ndarray of shape (n_samples,)
    """
    e = parse_effect(text, data)
    if e.special is not None:
        return _special_column(e.special, data)
    if e.shape is not None:
        return shape_series(e, data)
    prod = np.ones(data.n_samples)
    with np.errstate(over="ignore", invalid="ignore"):
        for f in e.factors:
            prod = prod * _apply(f, np.asarray(data.signal(f.signal), dtype=float), data)
    _check_range(e.text, prod)
    return prod


def _special_column(special: str, data: IOData, stacked: bool = False) -> np.ndarray:
    """The column of ``const`` (ones) or ``time`` (the sample times); ``stacked``: only copied into
    an input matrix, so ``const`` is a read-only broadcast 1 (no array of ones formed and dropped)."""
    if special == "const":
        return np.broadcast_to(1.0, (data.n_samples,)) if stacked else np.ones(data.n_samples)
    return np.asarray(data.time, dtype=float)


def _input_product(text: str, factors: list[Factor], data: IOData) -> np.ndarray | None:
    """Product of the factors that do not involve the output (None when there are none), refusing
    overflow."""
    prod, formed = None, False  # formed: prod is an array made here, so multiplied in place
    with np.errstate(over="ignore", invalid="ignore"):
        for f in factors:
            x = np.asarray(data.signal(f.signal), dtype=float)
            own = f.op != "pow" or f.power != 1  # else the signal as it is (no inf in an IOData), not a copy
            if own:
                x = _apply(f, x, data)
                _check_range(text, x)
            if prod is not None:
                prod = np.multiply(prod, x, out=prod) if formed else prod * x
                _check_range(text, prod)
            prod, formed = (x, own) if prod is None else (prod, True)
    return prod


#: Output terms whose values on a data set were found finite (a data set never changes).
_TERMS_CHECKED: weakref.WeakKeyDictionary[IOData, set[str]] = weakref.WeakKeyDictionary()


def _check_output_term(text: str, kind: str, power: int, prod: np.ndarray | None, data: IOData) -> None:
    """The core evaluates an output term on y(t-1); refuse overflow on the measured output here
    (once per term and data set: the diagnosis compiles the same term for every refit)."""
    with _COMPILED_LOCK:
        if text in _TERMS_CHECKED.get(data, ()):
            return
    _check_output_term_once(text, kind, power, prod, data)
    with _COMPILED_LOCK:
        _TERMS_CHECKED.setdefault(data, set()).add(text)


def _check_output_term_once(text: str, kind: str, power: int, prod: np.ndarray | None, data: IOData) -> None:
    with np.errstate(over="ignore", invalid="ignore"):
        g = _apply(Factor("y", kind, power), data.y, data)
        _check_range(text, g)
        if prod is not None:
            _check_range(text, np.multiply(g, prod, out=g))  # g is a new array


def layout_column(label: str, data: IOData) -> np.ndarray:
    """The samples of one column of a compiled layout, by its label (``EffectLayout.column_labels``):
    an input, an input-derived effect or an output term's carrier, the values :func:`compile_effects`
    puts in that column, without building the other columns.

    Parameters
    ----------
    label : str
        An input's name, an effect's text (``u1^2``, ``const``) or ``carrier:`` and an output term's
        text (``carrier:y*u1``).
    data : IOData

    Returns
    -------
    ndarray of shape (n_samples,)
        Read-only (it may be the data's own samples).

    Raises
    ------
    DataError
        When the column overflows the float range.

    Examples
    --------
    >>> data = IOData(np.zeros(3), np.array([1.0, -2.0, 3.0]), 0.1)
    >>> layout_column("u1^2", data).tolist(), layout_column("carrier:sign(y)*u1", data).tolist()
    ([1.0, 4.0, 9.0], [1.0, -2.0, 3.0])
    """
    i = _input_index(label, data)
    if i is not None:
        return data.u[:, i]
    with _COLUMNS_LOCK:
        out = _COLUMNS.get(data, {}).get(label)
    if out is not None:
        return out
    text = label.removeprefix("carrier:")
    e = parse_effect(text, data)
    if e.special is not None:
        out = _special_column(e.special, data)
    elif e.shape is not None:
        out = shape_series(e, data)
    else:
        out = _input_product(e.text, [f for f in e.factors if not _is_output(f.signal, data)], data)
    # A read-only view, not a copy (16 MB at 2M samples, for each of dozens of candidates): it may
    # be the data's own samples (a logged signal as it is).
    out = np.asarray(out, dtype=float).view()
    out.flags.writeable = False
    return _keep_column(data, label, out)


#: The columns :func:`layout_column` formed on each data set, by label, while they fit in :data:`_KEEP_BYTES`
#: (the last always): a diagnosis forms one effect's column for every refit's envelope and validation's lanes.
_COLUMNS: weakref.WeakKeyDictionary[IOData, dict[str, np.ndarray]] = weakref.WeakKeyDictionary()
_COLUMNS_LOCK = threading.Lock()


def _keep_column(data: IOData, label: str, column: np.ndarray) -> np.ndarray:
    with _COLUMNS_LOCK:
        kept = _COLUMNS.setdefault(data, {})
        kept.pop(label, None)
        kept[label] = column
        while len(kept) > 1 and sum(a.nbytes for a in kept.values()) > _KEEP_BYTES:
            kept.pop(next(iter(kept)))
    return column
