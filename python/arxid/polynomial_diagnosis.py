"""Missing input-derived terms of a polynomial (OE, ARMAX, BJ) model: score test and refit.

A candidate term z(t) (an effect of the inputs and measured signals, such as ``u1*vbat``) enters
the model as an extra input: with the orders and delay of the input it is built from (a gain
that scales u1 passes through u1's dynamics), or as a static input (``nb = 1, nf = 0, nk = 0``)
when it involves no input (``vbat``, ``const``). Its score test regresses the model's prediction
error on the prediction-error gradient ψ of the model extended by that input, evaluated at the
fitted parameters with the new numerator at zero and its denominator equal to its input's: the
model's own gradient columns are projected out, the candidate's columns are (D/(C F)) z at its
lags, the directions in which adding the term would move the prediction error (a
Lagrange-multiplier test). Terms that involve the measured
output are not offered: as inputs of an output-error model they would feed the noisy output back
as if it were a known input.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from . import _core
from .added_variable import AddedVariableResult, AddedVariableTest
from .data import IOData
from .effects import compile_effects
from .exceptions import OrderError
from .polynomial import PolynomialModel, finite_segments

__all__ = ["effect_columns", "with_effects", "score_effects", "refit_with_effects", "OUTPUT_TERM_NOTE"]

#: Why a term of the output is not tested on a polynomial model.
OUTPUT_TERM_NOTE = (
    "involves the measured output: an output-error or Box-Jenkins model takes only known inputs, "
    "so this term is tested on ARX models only"
)


def effect_columns(effects: Sequence[str], data: IOData) -> np.ndarray | None:
    """The signals of ``effects`` on ``data``, shape (n_samples, len(effects)).

    Parameters
    ----------
    effects : sequence of str
        Effect strings built from inputs and measured signals (``"u1*vbat"``, ``"u1^2"``, ``"const"``).
    data : IOData

    Returns
    -------
    ndarray or None
        None when an effect involves the output.
    """
    m = data.n_inputs
    layout = compile_effects(tuple(effects), data, (1,) * m, (0,) * m)
    if layout.output_terms:
        return None
    return layout.u[:, m:]


def with_effects(data: IOData, effects: Sequence[str]) -> IOData:
    """``data`` with the effects' signals appended as inputs named by the effects (``vbat`` as an
    input next to the measured signal ``vbat`` is named ``vbat_input``).

    Parameters
    ----------
    data : IOData
    effects : sequence of str

    Returns
    -------
    IOData

    Raises
    ------
    OrderError
        When an effect involves the output.
    """
    z = effect_columns(effects, data)
    if z is None:
        raise OrderError(f"{'+'.join(effects)} {OUTPUT_TERM_NOTE}")
    taken = set(data.signal_names)
    return data.with_signals(
        u=np.hstack([data.u, z]),
        input_names=(*data.input_names, *(e if e not in taken else f"{e}_input" for e in effects)),
        input_units=(*data.input_units, *("",) * len(effects)),
    )


def _new_inputs(model: PolynomialModel, data: IOData, effects: Sequence[str]) -> list[int | None]:
    """Per effect, the input whose orders and delay it takes (None: a static input)."""
    m = data.n_inputs
    return list(compile_effects(tuple(effects), data, (1,) * m, (0,) * m).tie[m:])


def _extended_orders(model: PolynomialModel, ties: list[int | None]) -> tuple:
    nb, nf, nk = list(model.nb_), list(model.nf_), list(model.nk_)
    for i in ties:
        nb.append(1 if i is None else model.nb_[i])
        nf.append(0 if i is None else model.nf_[i])
        nk.append(0 if i is None else model.nk_[i])
    return (model.na_, nb, model.nc_, model.nd_, nf, nk)


def _extended(model: PolynomialModel, data: IOData, effects: Sequence[str]):
    """Data, orders and parameters of ``model`` extended by ``effects`` with zero numerators (so
    the extended model predicts as ``model`` does), the first new-numerator index and their count."""
    aug = with_effects(data, effects)
    ties = _new_inputs(model, data, effects)
    orders = _extended_orders(model, ties)
    at_b, th = model.na_ + sum(model.nb_), model.parameters_
    q = sum(orders[1][data.n_inputs :])
    f_new = [model.f[i][1:] for i in ties if i is not None]
    return aug, orders, np.concatenate([th[:at_b], np.zeros(q), th[at_b:], *f_new]), at_b, q


def score_effects(
    model: PolynomialModel, data: IOData, effects: Sequence[str]
) -> tuple[AddedVariableResult | None, str]:
    """Score test of adding ``effects`` as inputs to the fitted ``model``.

    Parameters
    ----------
    model : PolynomialModel
        A fitted model.
    data : IOData
        Estimation data (the model's inputs).
    effects : sequence of str
        Input-derived effects tested together.

    Returns
    -------
    AddedVariableResult or None, str
        The partial F-test of the candidate's gradient columns against the model's own, or None and
        the reason it could not be tested.
    """
    aug, orders, theta, at_b, q = _extended(model, data, effects)
    eps, jac = _gradient(aug, orders, theta, model.first_lag_, len(effects))
    if eps is None or len(eps) <= model.n_params + q + 2:
        return None, "too few samples where its signal exists"
    own = jac[:, np.r_[0:at_b, at_b + q : at_b + q + model.n_params - at_b]]
    return AddedVariableTest(own, eps).test(jac[:, at_b : at_b + q])


def _gradient(aug: IOData, orders: tuple, theta: np.ndarray, first_lag: int, n_new: int):
    """Prediction errors and their Jacobian on the scored samples (None when there are none); the
    new denominators' columns are left out (they vanish while the new numerators are zero)."""
    lag = max(first_lag, _core.pem_max_lag(orders))
    segments = finite_segments(aug, lag)
    if not segments:
        return None, None
    u = np.ascontiguousarray(np.nan_to_num(aug.u), dtype=float)
    eps, jac = _core.pem_gradient(np.nan_to_num(aug.y), u, segments, orders, theta)
    rows = np.isfinite(eps)
    return eps[rows], jac[rows, : len(theta) - sum(orders[4][aug.n_inputs - n_new :])]


def refit_with_effects(model: PolynomialModel, data: IOData, effects: Sequence[str]) -> PolynomialModel:
    """``model``'s structure with ``effects`` as extra inputs, fitted from ``model`` itself.

    An effect built from an input takes that input's nb, nf and nk; any other is a static input
    (nb = 1, nf = 0, nk = 0). The iterations start at ``model``'s parameters with zero new
    numerators (a new denominator equal to its input's), near ``model``'s loss; a fresh start
    would have to separate nearly collinear inputs (u1 and u1*vbat) on its own. One Gauss–Newton
    step (new denominators held) first moves the new numerators off zero, where
    their denominators' gradient vanishes.

    Parameters
    ----------
    model : PolynomialModel
    data : IOData
    effects : sequence of str

    Returns
    -------
    PolynomialModel
        Its inputs are ``data``'s followed by the effects (see :func:`with_effects`).
    """
    aug, orders, theta, _, q = _extended(model, data, effects)
    eps, jac = _gradient(aug, orders, theta, model.first_lag_, len(effects))
    if eps is not None:  # one Gauss-Newton step with the new denominators held: nonzero numerators
        theta[: jac.shape[1]] -= np.linalg.lstsq(jac, eps, rcond=None)[0]
    na, nb, nc, nd, nf, nk = orders
    return PolynomialModel(na=na, nb=nb, nc=nc, nd=nd, nf=nf, nk=nk).fit(aug, start=theta)
