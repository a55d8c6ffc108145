"""Inputs of a polynomial model that are computed from the data: effect terms added by the diagnosis.

When :func:`arxid.diagnose` adds an effect such as ``u1*vbat`` or ``y^3`` to an output-error, ARMAX
or Box–Jenkins model, the effect enters as one more input with its own B/F. The model records how
that input is computed (a :class:`DerivedInput`), so it predicts from the measured signals alone:
``model.predict(validation)`` completes the data first.

A term of the output is computed from the *simulated* output of the model it was added to (its
``source``: the free run from the inputs, without noise), never from the measured output. An
output-error model takes only known inputs: feeding the measured, noisy output back as an input
would correlate the regressor with the noise and bias every parameter (the reason ARX is biased
under output noise), while the simulated output is a function of the inputs, as in a
Hammerstein–Wiener view of the plant.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError
from .effects import effect_series, parse_effect

__all__ = ["DerivedInput", "uses_output", "derived_series", "complete_inputs"]


@record
class DerivedInput:
    """How one input of a polynomial model is computed from the data.

    Attributes
    ----------
    effect : str
        The effect string, e.g. ``"u1*vbat"`` or ``"y^3"`` (unlagged; the model's nk applies).
    source : PolynomialModel or None
        For a term of the output: the model whose free-run simulation stands for the output.
    """

    effect: str
    source: Any = None


def uses_output(effect: str, data: IOData) -> bool:
    """True when ``effect`` has a factor of the output (``y^3``, ``sign(dy)``, ``u1*y``).

    Parameters
    ----------
    effect : str
    data : IOData

    Returns
    -------
    bool
    """
    return any(f.signal in ("y", data.output_name) for f in parse_effect(effect, data).factors)


def derived_series(effect: str, data: IOData, source: Any = None) -> np.ndarray:
    """The effect's signal on ``data``; a term of the output uses ``source``'s free-run simulation.

    Parameters
    ----------
    effect : str
    data : IOData
        Measured data (the source's inputs).
    source : model, optional
        Required when ``effect`` involves the output.

    Returns
    -------
    ndarray of shape (n_samples,)
        NaN where the simulation has no value yet (its initial conditions).
    """
    if not uses_output(effect, data):
        return effect_series(effect, data)
    if source is None:
        raise DataError(f"{effect!r} involves the output: give the model whose simulated output it uses")
    with np.errstate(all="ignore"):
        simulated = np.asarray(source.predict(data, None), dtype=float)
    return effect_series(effect, replace(data, y=simulated))


def complete_inputs(data: IOData, input_names: Sequence[str], derived: Sequence[DerivedInput]) -> IOData:
    """``data`` with the derived inputs appended, when it has only the measured ones.

    Parameters
    ----------
    data : IOData
        Measured data, possibly with some of the derived inputs already (the first ones, in order).
    input_names : sequence of str
        The model's inputs: the measured ones, then one per derived input.
    derived : sequence of DerivedInput

    Returns
    -------
    IOData
    """
    names = tuple(input_names)
    k = data.n_inputs
    first = len(names) - len(derived)
    if data.input_names == names or not derived:
        return data
    if not first <= k < len(names) or data.input_names != names[:k]:
        raise DataError(
            f"the model's measured inputs are {list(names[:first])} (then {[d.effect for d in derived]}, computed "
            f"from them) but the data have {list(data.input_names)}"
        )
    cols = [data.u]
    for i in range(k, len(names)):
        base = data.with_signals(u=np.hstack(cols), input_names=names[:i])
        d = derived[i - first]
        cols.append(derived_series(d.effect, base, d.source).reshape(-1, 1))
    return data.with_signals(
        u=np.hstack(cols), input_names=names, input_units=(*data.input_units, *("",) * (len(names) - k))
    )
