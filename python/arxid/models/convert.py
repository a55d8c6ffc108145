"""Export a fitted model to control design: python-control, scipy, and continuous time (d2c).

The converters read a model through :class:`ConvertibleModel`, the surface :class:`~arxid.ArxModel`
and :class:`~arxid.PolynomialModel` share, so that the model classes can use them without this
module knowing either."""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from .._base.optional import require
from ..exceptions import ArxidError, DataError

__all__ = ["ConvertibleModel", "to_control", "to_scipy", "tf_coefficients"]


class ConvertibleModel(Protocol):
    """What the converters read of a fitted model. A polynomial model (OE, ARMAX, BJ) also has
    ``common_denominator()``: its inputs' B_i / (A F_i) over one denominator."""

    @property
    def ts(self) -> float:
        """Sampling time in seconds."""

    @property
    def output_name(self) -> str:
        """Name of the output."""

    @property
    def effects(self) -> tuple[str, ...]:
        """Effect terms of the model."""

    @property
    def is_linear(self) -> bool:
        """False when a term of the output makes the model nonlinear."""

    @property
    def a(self) -> np.ndarray:
        """Denominator A(z⁻¹)."""

    def check_fitted(self) -> None:
        """Raise :class:`~arxid.NotFittedError` unless fitted.

        Returns
        -------
        None
        """

    def layout_numerators(self) -> list[np.ndarray]:
        """Numerators of every input column, delays as leading zeros.

        Returns
        -------
        list of ndarray
        """

    def input_labels(self) -> list[str]:
        """Names of the input columns.

        Returns
        -------
        list of str
        """


def _control() -> Any:
    return require("control", "to_control")


def _fractions(model: ConvertibleModel) -> tuple[list[np.ndarray], np.ndarray]:
    """Numerators (one per input column) and their denominator, in powers of z⁻¹."""
    common = getattr(model, "common_denominator", None)
    return common() if common is not None else (model.layout_numerators(), model.a)


def tf_coefficients(model: ConvertibleModel) -> tuple[list[np.ndarray], np.ndarray]:
    """Numerators (one per layout column) and the denominator, in descending powers of z, all of
    one length.

    Parameters
    ----------
    model : ArxModel or PolynomialModel
        A fitted linear model (no output-derived effects).

    Returns
    -------
    numerators : list of ndarray
    denominator : ndarray
    """
    if not model.is_linear:
        raise ArxidError(
            f"the effects {list(model.effects)} involve the output: the model is nonlinear and has no transfer function"
        )
    num_z1, den_z1 = _fractions(model)
    n = max([len(den_z1) - 1] + [len(x) - 1 for x in num_z1])
    den = np.zeros(n + 1)
    den[: len(den_z1)] = den_z1
    nums = []
    for x in num_z1:
        v = np.zeros(n + 1)
        v[: len(x)] = x
        nums.append(v)
    return nums, den


def to_control(model: ConvertibleModel, continuous: bool = False, input: int | None = None, method: str = "zoh") -> Any:
    """python-control transfer function with ``dt = ts`` (descending powers of z).

    Parameters
    ----------
    model : ArxModel or PolynomialModel
        A fitted linear model.
    continuous : bool
        Convert to continuous time (d2c, see :mod:`arxid.continuous`). The input delay is returned
        in the attribute ``dead_time`` of each result (seconds; with ``method="zoh"`` and
        nb = na + 1 it includes a fraction of a sample).
    input : int, optional
        Only this column's transfer function.
    method : {"zoh", "tustin", "matched"}
        d2c method (only with ``continuous``): ``"zoh"`` is the exact inverse of zero-order-hold
        sampling, ``"tustin"`` and ``"matched"`` the inverses of python-control's
        ``sample_system`` methods of those names.

    Returns
    -------
    control.TransferFunction or list of control.TransferFunction
        One input gives a ``TransferFunction``; several inputs (including input-derived effect
        columns) a list with one SISO ``TransferFunction`` per input (MIMO conversions in
        python-control need slycot), or the one picked with ``input``.

    Raises
    ------
    ConversionError
        When ``continuous`` and the model has no exact continuous counterpart by ``method`` (a pole
        on the negative real axis for ``"zoh"``, more numerator coefficients than ZOH sampling
        produces, ...); the message names the methods that work.
    """
    model.check_fitted()
    control = _control()
    nums, den = tf_coefficients(model)
    labels = model.input_labels()
    if input is not None and (
        isinstance(input, bool) or not isinstance(input, numbers.Integral) or not 0 <= input < len(nums)
    ):
        raise DataError(
            f"input {input!r} does not exist: the model has {len(nums)} input column(s) {labels}, "
            f"numbered 0 to {len(nums) - 1}"
        )
    idx = range(len(nums)) if input is None else [input]
    if continuous:
        return _d2c(model, list(idx), [labels[i] for i in idx], method)
    tfs = [
        control.TransferFunction(nums[i], den, model.ts, inputs=[labels[i]], outputs=[model.output_name]) for i in idx
    ]
    return tfs[0] if len(tfs) == 1 else tfs


def to_scipy(model: ConvertibleModel) -> Any:
    """``scipy.signal.dlti``: a transfer function for one input, a state-space model for several.

    Parameters
    ----------
    model : ArxModel or PolynomialModel
        A fitted linear model.

    Returns
    -------
    scipy.signal.dlti
    """
    from scipy import signal

    nums, den = tf_coefficients(model)
    if len(nums) == 1:
        # Leading zeros of the numerator are the delay; scipy warns about them, so drop them.
        num = np.trim_zeros(nums[0], "f")
        return signal.dlti(num if len(num) else [0.0], den, dt=model.ts)
    # Observable canonical form shares A and C across inputs.
    n = len(den) - 1
    a = np.zeros((n, n))
    a[:, 0] = -den[1:]
    a[: n - 1, 1:] = np.eye(n - 1)
    b = np.column_stack([num[1:] - num[0] * den[1:] for num in nums])
    c = np.zeros((1, n))
    c[0, 0] = 1.0
    dmat = np.array([[num[0] for num in nums]])
    return signal.dlti(a, b, c, dmat, dt=model.ts)


def _d2c(model: ConvertibleModel, columns: Sequence[int], labels: Sequence[str], method: str) -> Any:
    """Continuous transfer functions (one per layout column) whose sampling is the discrete model."""
    from .continuous import d2c  # continuous time when asked for: a model's import stays light

    control = _control()
    nums, den = _fractions(model)
    results = []
    for i, label in zip(columns, labels):
        cont = d2c(den, nums[i], model.ts, method)
        tf_c = control.TransferFunction(cont.num, cont.den, inputs=[label], outputs=[model.output_name])
        tf_c.dead_time = cont.dead_time
        tf_c.d2c_method = cont.method
        results.append(tf_c)
    return results[0] if len(results) == 1 else results
