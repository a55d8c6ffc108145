"""Missing terms and structure changes of a polynomial (OE, ARMAX, BJ) model: score tests and refits.

A candidate term z(t) enters the model as an extra input (a :class:`~arxid.derived_inputs.DerivedInput`):

* a term of the inputs and logged signals (``u1*vbat``, ``u1^2``, ``dz(u1,0.3)``) with the orders and
  delay of the input it is built from (a gain that scales u1 passes through u1's dynamics), or as a
  static input (``nb = 1, nf = 0, nk = 0``) when it involves no input (``vbat``, ``const``);
* a term of the output (``y^3``, ``sign(y)``, ``sign(dy)``, ``u1*y``) computed on the model's
  *simulated* output ŷ (the free run from the inputs, noise-free), one sample back (nb = 1, nk = 1)
  and through the denominator of the first input (the term acts inside the plant, before its
  poles). The measured output is never fed back: it carries the output noise, which an output-error
  model keeps out of its regressors (see :mod:`arxid.derived_inputs`).

Its score test regresses the model's prediction error on the prediction-error gradient ψ of the
model extended by that input, evaluated at the fitted parameters with the new numerator at zero:
the model's own gradient columns are projected out, the candidate's columns are (D/(C F)) z at its
lags, the directions in which adding the term would move the prediction error (a
Lagrange-multiplier test). Structure changes (one more pole ``nf+1`` or ``na+1``, one more zero
``nb+1``, a delay ``nk-1`` / ``nk+1``) are tested the same way: the model is written in the larger
structure that contains it and the new coefficients' gradient columns are tested; ``nk+1`` (not a
larger structure) is scored by the coefficient one lag beyond B, which it would add, and refitted as
stated.
"""

from __future__ import annotations

import re
from collections.abc import Sequence

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from ..exceptions import OrderError
from ..models.derived_inputs import DerivedInput, complete_inputs, derived_series, uses_output
from ..models.effects import compile_effects
from ..models.polynomial import PolynomialModel, finite_segments
from .added_variable import AddedVariableResult, AddedVariableTest

__all__ = [
    "effect_columns",
    "with_effects",
    "appended_inputs",
    "score_effects",
    "refit_with_effects",
    "structure_changes",
    "score_structure",
    "refit_structure",
    "OUTPUT_TERM_NOTE",
    "whitened_test",
    "WhitenedTest",
]

#: Refits of a model with a term of the output, each computing the term on the previous refit's
#: simulated output (a fixed-point iteration towards the term acting inside the plant).
OUTPUT_TERM_PASSES = 4
#: A pass that lowers the estimation loss by less than this share ends the iteration.
OUTPUT_TERM_GAIN = 0.01

#: Largest AR order used to whiten the prediction error before a score test.
MAX_WHITENING_ORDER = 10

#: Why a term of the output is not tested without a model to simulate it.
OUTPUT_TERM_NOTE = (
    "involves the output: a polynomial model takes only known inputs, so this term is built from "
    "the model's simulated (noise-free) output, which needs the model"
)


def effect_columns(effects: Sequence[str], data: IOData, source: PolynomialModel | None = None) -> np.ndarray | None:
    """The signals of ``effects`` on ``data``, unlagged, shape (n_samples, len(effects)).

    Parameters
    ----------
    effects : sequence of str
        Effect strings (``"u1*vbat"``, ``"u1^2"``, ``"const"``, ``"y^3"``).
    data : IOData
        Measured data.
    source : PolynomialModel, optional
        The model whose simulated output stands for the output in terms of the output.

    Returns
    -------
    ndarray or None
        None when an effect involves the output and no ``source`` is given.
    """
    if source is None and any(uses_output(e, data) for e in effects):
        return None
    base = data if source is None else complete_inputs(data, source.input_names_, source.derived_inputs)
    cols = [derived_series(e, base, source) for e in effects]
    return np.column_stack(cols) if cols else np.zeros((data.n_samples, 0))


def with_effects(data: IOData, effects: Sequence[str], source: PolynomialModel | None = None) -> IOData:
    """``data`` (completed with ``source``'s derived inputs) with the effects' signals appended as
    inputs named by the effects (``vbat`` as an input next to the measured signal ``vbat`` is named
    ``vbat_input``).

    Parameters
    ----------
    data : IOData
    effects : sequence of str
    source : PolynomialModel, optional
        The model the effects are added to (needed for terms of the output).

    Returns
    -------
    IOData

    Raises
    ------
    OrderError
        When an effect involves the output and no ``source`` is given.
    """
    z = effect_columns(effects, data, source)
    if z is None:
        raise OrderError(f"{'+'.join(effects)} {OUTPUT_TERM_NOTE}")
    if source is not None:
        data = complete_inputs(data, source.input_names_, source.derived_inputs)
    return appended_inputs(data, effects, z)


def appended_inputs(data: IOData, effects: Sequence[str], z: np.ndarray) -> IOData:
    """``data`` with the columns ``z`` of ``effects`` appended as inputs named by the effects (one
    named like a signal of ``data`` gets ``_input``: ``vbat_input``).

    Parameters
    ----------
    data : IOData
    effects : sequence of str
    z : ndarray of shape (n_samples, len(effects))

    Returns
    -------
    IOData
    """
    taken = set(data.signal_names)
    return data.with_signals(
        u=np.hstack([data.u, z]),
        input_names=(*data.input_names, *(e if e not in taken else f"{e}_input" for e in effects)),
        input_units=(*data.input_units, *("",) * len(effects)),
    )


def _new_input_orders(model: PolynomialModel, data: IOData, effects: Sequence[str]) -> list[tuple]:
    """Per effect: (nb, nf, nk, start of its F) of the input it becomes."""
    m = data.n_inputs
    out = []
    for e in effects:
        if uses_output(e, data):
            i: int | None = 0 if model.nf_[0] else None
            out.append((1, model.nf_[0], 1, model.f[0][1:]) if i is not None else (1, 0, 1, np.zeros(0)))
            continue
        tie = compile_effects((e,), data, (1,) * m, (0,) * m).tie[m]
        if tie is None:
            out.append((1, 0, 0, np.zeros(0)))
        else:
            out.append((model.nb_[tie], model.nf_[tie], model.nk_[tie], model.f[tie][1:]))
    return out


def _extended(model: PolynomialModel, data: IOData, effects: Sequence[str]):
    """Data, orders and parameters of ``model`` extended by ``effects`` with zero numerators (so
    the extended model predicts as ``model`` does), the first new-numerator index and their count."""
    aug = with_effects(data, effects, model)
    new = _new_input_orders(model, data, effects)
    na, nb, nc, nd, nf, nk = model.na_, list(model.nb_), model.nc_, model.nd_, list(model.nf_), list(model.nk_)
    orders = (na, nb + [o[0] for o in new], nc, nd, nf + [o[1] for o in new], nk + [o[2] for o in new])
    at_b, th = model.na_ + sum(model.nb_), model.parameters_
    q = sum(o[0] for o in new)
    theta = np.concatenate([th[:at_b], np.zeros(q), th[at_b:], *[o[3] for o in new]])
    return aug, orders, theta, at_b, q


def score_effects(
    model: PolynomialModel, data: IOData, effects: Sequence[str]
) -> tuple[AddedVariableResult | None, str]:
    """Score test of adding ``effects`` as inputs to the fitted ``model``.

    Parameters
    ----------
    model : PolynomialModel
        A fitted model.
    data : IOData
        Estimation data (the model's measured inputs).
    effects : sequence of str
        Effects tested together (terms of the output use the model's simulated output).

    Returns
    -------
    AddedVariableResult or None, str
        The partial F-test of the candidate's gradient columns against the model's own, or None and
        the reason it could not be tested.
    """
    aug, orders, theta, at_b, q = _extended(model, data, effects)
    n_new_f = sum(orders[4][len(model.nb_) :])
    eps, jac = _gradient(aug, orders, theta, model.first_lag_, n_new_f)
    if eps is None or len(eps) <= model.n_params + q + 2:
        return None, "too few samples where its signal exists"
    own = jac[:, np.r_[0:at_b, at_b + q : at_b + q + model.n_params - at_b]]
    return whitened_test(own, eps, jac[:, at_b : at_b + q])


def whitened_test(own: np.ndarray, eps: np.ndarray, new: np.ndarray) -> tuple[AddedVariableResult | None, str]:
    """The partial F-test of ``new`` beside ``own`` on the prediction error, after the prediction
    error and every gradient column are filtered by the AR model of the prediction error (order by
    AIC, at most ``MAX_WHITENING_ORDER``). An output-error model leaves coloured noise in its
    prediction error; untreated, it makes the F-test's p-values far too small (generalised least
    squares: the test of a model whose noise model is that AR)."""
    return WhitenedTest(own, eps).test(new)


class WhitenedTest:
    """:func:`whitened_test` of many candidates beside the same ``own`` columns and error: the AR
    model and the factor of ``own`` are found once.

    Parameters
    ----------
    own : ndarray of shape (n_rows, n_own)
    eps : ndarray of shape (n_rows,)
    """

    def __init__(self, own: np.ndarray, eps: np.ndarray):
        self.a = _ar_whitener(eps)
        self.added = AddedVariableTest(self.whiten(own), self.whiten(eps))

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """``x`` (rows in time order) filtered by the AR model of the error; its first rows are lost."""
        p = len(self.a)
        out = x[p:].copy()
        for i, ai in enumerate(self.a, start=1):
            out += ai * x[p - i : len(x) - i]
        return out

    def test(self, new: np.ndarray) -> tuple[AddedVariableResult | None, str]:
        """The partial F-test of the columns ``new`` (same rows as ``own``).

        Parameters
        ----------
        new : ndarray of shape (n_rows, q)

        Returns
        -------
        AddedVariableResult or None, str
        """
        return self.added.test(self.whiten(new))


def _ar_whitener(e: np.ndarray) -> np.ndarray:
    """Coefficients a of the AR model e(t) + a1 e(t-1) + ... = w(t) by Yule–Walker, order by AIC
    (empty: white)."""
    from scipy.linalg import solve_toeplitz

    n = len(e)
    top = min(MAX_WHITENING_ORDER, n // 10)
    ec = e - e.mean()
    r = np.array([float(ec[k:] @ ec[: n - k]) / n for k in range(top + 1)])
    best, best_aic = np.zeros(0), n * np.log(max(r[0], 1e-300))
    for p in range(1, top + 1):
        phi = solve_toeplitz(r[:p], r[1 : p + 1])
        aic = n * np.log(max(float(r[0] - phi @ r[1 : p + 1]), 1e-300)) + 2 * p
        if aic < best_aic:
            best, best_aic = -phi, aic
    return best


def _gradient(aug: IOData, orders: tuple, theta: np.ndarray, first_lag: int, n_dropped: int = 0):
    """Prediction errors and their Jacobian on the scored samples (None when there are none); the
    last ``n_dropped`` columns (new denominators, whose gradient vanishes while their numerators are
    zero) are left out."""
    lag = max(first_lag, _core.pem_max_lag(orders))
    segments = finite_segments(aug, lag)
    if not segments:
        return None, None
    u = np.ascontiguousarray(np.nan_to_num(aug.u), dtype=float)
    eps, jac = _core.pem_gradient(np.nan_to_num(aug.y), u, segments, orders, theta)
    rows = np.isfinite(eps)
    return eps[rows], jac[rows, : len(theta) - n_dropped]


def _fit(orders: tuple, data: IOData, start: np.ndarray | None, derived: Sequence[DerivedInput]) -> PolynomialModel:
    na, nb, nc, nd, nf, nk = orders
    # A candidate's refit that ends before converging is judged like any other, by its validation
    # error; the warning would only repeat per candidate. (Not catch_warnings: the judge refits in
    # two threads, and restoring the process's filters in one would unmute the other.)
    fitted = PolynomialModel(na=na, nb=nb, nc=nc, nd=nd, nf=nf, nk=nk).fit(
        data, start=None if start is None else start.tolist(), warn=False
    )
    fitted.derived_inputs_ = tuple(derived)
    return fitted


def refit_with_effects(model: PolynomialModel, data: IOData, effects: Sequence[str]) -> PolynomialModel:
    """``model``'s structure with ``effects`` as extra inputs, fitted from ``model`` itself.

    An effect built from an input takes that input's nb, nf and nk; a term of the output takes nb = 1,
    nk = 1 and the first input's nf (it is computed from ``model``'s simulated output); any other is
    a static input (nb = 1, nf = 0, nk = 0). The iterations start at ``model``'s parameters with
    zero new numerators (a new denominator equal to its input's), near ``model``'s loss; a fresh
    start would have to separate nearly collinear inputs (u1 and u1*vbat) on its own. One
    Gauss–Newton step (new denominators held) first moves the new numerators off zero, where their
    denominators' gradient vanishes.

    Parameters
    ----------
    model : PolynomialModel
    data : IOData
        Measured estimation data.
    effects : sequence of str

    Returns
    -------
    PolynomialModel
        Its inputs are ``model``'s followed by the effects; it computes them from measured data
        itself (``derived_inputs``).
    """
    aug, orders, theta, _, _ = _extended(model, data, effects)
    eps, jac = _gradient(aug, orders, theta, model.first_lag_, sum(orders[4][len(model.nb_) :]))
    if eps is not None:  # one Gauss-Newton step with the new denominators held: nonzero numerators
        theta[: jac.shape[1]] -= np.linalg.lstsq(jac, eps, rcond=None)[0]
    derived = [DerivedInput(e, model if uses_output(e, data) else None) for e in effects]
    fitted = _fit(orders, aug, theta, (*model.derived_inputs, *derived))
    if not any(d.source is not None for d in derived):
        return fitted
    for _ in range(OUTPUT_TERM_PASSES - 1):  # the term on the simulated output of the model with it
        again = [DerivedInput(d.effect, fitted if d.source is not None else None) for d in derived]
        names = fitted.input_names_
        aug = complete_inputs(data, names, (*model.derived_inputs, *again))
        better = _fit(orders, aug, fitted.parameters_, (*model.derived_inputs, *again))
        if better.loss_ > (1.0 - OUTPUT_TERM_GAIN) * fitted.loss_:
            return better if better.loss_ < fitted.loss_ else fitted
        fitted = better
    return fitted


# ------------------------------------------------------------------------------- structure changes
_CHANGE = re.compile(r"(?P<what>na|nb|nf|nk)(?:\((?P<name>[^)]+)\))?(?P<sign>[+-])1")


def structure_changes(model: PolynomialModel, input_names: Sequence[str]) -> list[str]:
    """The structure changes offered for ``model``: one more pole (``na+1`` for a model with A,
    ``nf+1`` per input with F), one more zero (``nb+1``), a delay one sample shorter or longer.

    Parameters
    ----------
    model : PolynomialModel
    input_names : sequence of str
        Names of the measured inputs as the candidates write them.

    Returns
    -------
    list of str
        e.g. ``["nf+1", "nb+1", "nk-1", "nk+1"]``; ``nf(u2)+1`` with several inputs.
    """
    out = ["na+1"] if model.na_ else []
    for i, name in enumerate(input_names):
        tag = "" if len(input_names) == 1 else f"({name})"
        if model.nb_[i] == 0:
            continue
        out += [f"nf{tag}+1"] if model.nf_[i] else []
        out.append(f"nb{tag}+1")
        out += [f"nk{tag}-1"] if model.nk_[i] else []
        out.append(f"nk{tag}+1")
    return out


def _changed_orders(model: PolynomialModel, label: str, names: Sequence[str], union: bool) -> tuple:
    """Orders after ``label``; with ``union`` the smallest structure that contains both the model
    and the change (``nk-1`` adds a leading coefficient, ``nk+1`` a trailing one)."""
    mt = _CHANGE.fullmatch(label.replace(" ", ""))
    if mt is None:
        raise OrderError(f"{label!r} is not a structure change of a polynomial model (na+1, nb+1, nf+1, nk-1, nk+1)")
    m = len(names)
    na, nb, nf, nk = model.na_, list(model.nb_[:m]), list(model.nf_[:m]), list(model.nk_[:m])
    if mt["name"] is not None and mt["name"] not in names:
        raise OrderError(f"structure change {label!r}: no input named {mt['name']!r}; inputs: {list(names)}")
    idx = [names.index(mt["name"])] if mt["name"] is not None else list(range(len(names)))
    what, step = mt["what"], 1 if mt["sign"] == "+" else -1
    if what == "na":
        na += 1
    for i in idx if what != "na" else []:
        if what == "nf":
            nf[i] += 1
        elif what == "nb" or union:
            nb[i] += 1
            nk[i] += min(step, 0) if what == "nk" else 0
        else:
            nk[i] += step
    if min(nk) < 0 or (na and any(nf)):
        raise OrderError(f"structure change {label!r} is not possible for {model.structure_name()}")
    return (na, nb, model.nc_, model.nd_, nf, nk)


def _embedded(model: PolynomialModel, orders: tuple) -> tuple[np.ndarray, np.ndarray]:
    """``model``'s parameters written in the larger structure ``orders``, and a mask of the
    coefficients the model does not have (zero there)."""
    p = model.polynomials()
    na, nb, nc, nd, nf, nk = orders
    theta: list[float] = []
    new: list[bool] = []

    def put(full: np.ndarray, first: int, n: int, old_first: int, old_n: int) -> None:
        for j in range(first, first + n):
            theta.append(float(full[j]) if j < len(full) else 0.0)
            new.append(not old_first <= j < old_first + old_n)

    put(p["a"], 1, na, 1, model.na_)
    for i in range(len(nb)):
        put(p["b"][i], nk[i], nb[i], model.nk_[i], model.nb_[i])
    put(p["c"], 1, nc, 1, model.nc_)
    put(p["d"], 1, nd, 1, model.nd_)
    for i in range(len(nf)):
        put(p["f"][i], 1, nf[i], 1, model.nf_[i])
    return np.array(theta), np.array(new)


def score_structure(
    model: PolynomialModel, data: IOData, label: str, input_names: Sequence[str]
) -> tuple[AddedVariableResult | None, str]:
    """Score test of a structure change (see :func:`structure_changes`) at the fitted parameters.

    Parameters
    ----------
    model : PolynomialModel
    data : IOData
        Measured estimation data.
    label : str
    input_names : sequence of str
        The names the label may use for the measured inputs.

    Returns
    -------
    AddedVariableResult or None, str
    """
    full = _pad(_changed_orders(model, label, list(input_names), union=True), model)
    theta, new = _embedded(model, full)
    aug = complete_inputs(data, model.input_names_, model.derived_inputs)
    eps, jac = _gradient(aug, full, theta, model.first_lag_)
    if eps is None or len(eps) <= len(theta) + 2:
        return None, "too few samples"
    return whitened_test(jac[:, ~new], eps, jac[:, new])


def _pad(orders: tuple, model: PolynomialModel) -> tuple:
    """Orders for the measured inputs completed with the derived inputs' own."""
    m = len(orders[1])
    na, nb, nc, nd, nf, nk = orders
    return (na, nb + list(model.nb_[m:]), nc, nd, nf + list(model.nf_[m:]), nk + list(model.nk_[m:]))


def refit_structure(model: PolynomialModel, data: IOData, label: str, input_names: Sequence[str]) -> PolynomialModel:
    """``model`` refitted with the structure change ``label``, from ``model``'s parameters.

    Parameters
    ----------
    model : PolynomialModel
    data : IOData
        Measured estimation data.
    label : str
    input_names : sequence of str

    Returns
    -------
    PolynomialModel
    """
    orders = _pad(_changed_orders(model, label, list(input_names), union=False), model)
    # Another delay keeps every coefficient (B moves by one lag); a larger structure starts at the
    # model with the new coefficient at zero.
    theta = model.parameters_.copy() if label.startswith("nk") else _embedded(model, orders)[0]
    aug = complete_inputs(data, model.input_names_, model.derived_inputs)
    return _fit(orders, aug, theta, model.derived_inputs)
