"""Export a fitted ARX model to control design: python-control, scipy, and continuous time (d2c)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ._optional import require
from .exceptions import ArxidError

if TYPE_CHECKING:
    from .model import ArxModel

__all__ = ["to_control", "to_scipy", "tf_coefficients"]


def _control() -> Any:
    return require("control", "to_control")


def tf_coefficients(model: ArxModel) -> tuple[list[np.ndarray], np.ndarray]:
    """Numerators (one per layout column) and the denominator, in descending powers of z, all of
    one length.

    Parameters
    ----------
    model : ArxModel
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
    num_z1 = model.layout_numerators()
    n = max([model.na_] + [len(x) - 1 for x in num_z1])
    den = np.zeros(n + 1)
    den[: model.na_ + 1] = model.a
    nums = []
    for x in num_z1:
        v = np.zeros(n + 1)
        v[: len(x)] = x
        nums.append(v)
    return nums, den


def to_control(model: ArxModel, continuous: bool = False, input: int | None = None) -> Any:
    """python-control transfer function with ``dt = ts`` (descending powers of z).

    Parameters
    ----------
    model : ArxModel
        A fitted linear model.
    continuous : bool
        Invert the zero-order-hold sampling (matrix logarithm). The input delay of ``(nk − 1)·ts``
        that ZOH sampling of a strictly proper system does not explain is returned in the
        attribute ``dead_time`` of the result (seconds).
    input : int, optional
        Only this column's transfer function.

    Returns
    -------
    control.TransferFunction or list of control.TransferFunction
        One input gives a ``TransferFunction``; several inputs (including input-derived effect
        columns) a list with one SISO ``TransferFunction`` per input (MIMO conversions in
        python-control need slycot), or the one picked with ``input``.
    """
    model.check_fitted()
    control = _control()
    nums, den = tf_coefficients(model)
    labels = model.input_labels()
    idx = range(len(nums)) if input is None else [input]
    if continuous:
        return _d2c(model, [nums[i] for i in idx], den, [model.layout_.nk[i] for i in idx], [labels[i] for i in idx])
    tfs = [
        control.TransferFunction(nums[i], den, model.ts, inputs=[labels[i]], outputs=[model.output_name]) for i in idx
    ]
    return tfs[0] if len(tfs) == 1 else tfs


def to_scipy(model: ArxModel) -> Any:
    """``scipy.signal.dlti``: a transfer function for one input, a state-space model for several.

    Parameters
    ----------
    model : ArxModel
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


def _d2c(
    model: ArxModel, nums: Sequence[np.ndarray], den: np.ndarray, nks: Sequence[int], labels: Sequence[str]
) -> Any:
    """Continuous-time model whose ZOH sampling is the discrete model (input delays split off)."""
    import control
    from scipy.linalg import logm

    results = []
    for num, nk, label in zip(nums, nks, labels):
        # Pure delay beyond the one sample ZOH sampling of a strictly proper system implies.
        shift = max(nk - 1, 0)
        n = np.trim_zeros(num, "f")
        n = np.concatenate([np.zeros(len(num) - len(n) - shift), n]) if shift else num
        n = np.concatenate([n, np.zeros(len(num) - len(n))])[: len(num)]
        dd = np.trim_zeros(den, "b")
        trimmed = len(den) - len(dd)
        n = n[: len(n) - trimmed] if trimmed else n
        # Remove common trailing zeros (poles and zeros at the origin) from both.
        while len(dd) > 1 and dd[-1] == 0 and n[-1] == 0:
            dd, n = dd[:-1], n[:-1]
        if len(dd) > 1 and dd[-1] == 0:
            raise ArxidError(
                "the model has a pole at z = 0 that cannot be a zero-order-hold sample of a continuous system"
            )
        sys_d = control.tf2ss(control.TransferFunction(n, dd, model.ts))
        a, b, c, d = (np.asarray(x) for x in (sys_d.A, sys_d.B, sys_d.C, sys_d.D))
        k = a.shape[0]
        big = np.zeros((k + 1, k + 1))
        big[:k, :k], big[:k, k:] = a, b
        big[k, k] = 1.0
        with np.errstate(all="ignore"):
            lg = logm(big)
        if np.iscomplexobj(lg):
            if np.max(np.abs(lg.imag)) > 1e-8 * max(1.0, np.max(np.abs(lg.real))):
                raise ArxidError(
                    "the model has poles on the negative real axis: it is not the zero-order-hold sample of a real continuous system"  # noqa: E501
                )
            lg = lg.real
        lg = lg / model.ts
        sys_c = control.ss(lg[:k, :k], lg[:k, k:], c, d)
        tf_c = control.ss2tf(sys_c)
        tf_c = control.TransferFunction(tf_c.num[0][0], tf_c.den[0][0], inputs=[label], outputs=[model.output_name])
        tf_c.dead_time = shift * model.ts
        results.append(tf_c)
    return results[0] if len(results) == 1 else results
