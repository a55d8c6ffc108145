"""The values of effect terms that several modules compute: integer powers evaluated as the Rust
core evaluates them, and the dead zone and saturation of a signal (with the products a threshold
scan needs, in the core) and its threshold as the grammar writes it."""

from __future__ import annotations

import numpy as np

from .._base import _core

__all__ = ["format_threshold", "integer_power", "thresholded", "thresholded_products"]


def thresholded(
    op: str, magnitude: np.ndarray, sign: np.ndarray, c: float, out: np.ndarray | None = None
) -> np.ndarray:
    """A dead zone or a saturation of a signal given as |x| and sign(x): ``dz`` is
    sign(x)·max(|x| − c, 0), ``sat`` is sign(x)·min(|x|, c) (a threshold scan shapes the same
    samples with dozens of thresholds, so |x| and sign(x) are taken once).

    Parameters
    ----------
    op : {"dz", "sat"}
    magnitude, sign : ndarray
        |x| and sign(x).
    c : float
        The threshold.
    out : ndarray, optional
        Where to write (same shape as ``magnitude``).

    Returns
    -------
    ndarray

    Examples
    --------
    >>> x = np.array([-2.0, 0.5, 3.0])
    >>> thresholded("dz", np.abs(x), np.sign(x), 1.0).tolist(), thresholded("sat", np.abs(x), np.sign(x), 1.0).tolist()
    ([-1.0, 0.0, 2.0], [-1.0, 0.5, 1.0])
    """
    if op == "dz":
        out = np.subtract(magnitude, c, out=out)
        np.maximum(out, 0.0, out=out)
    else:
        out = np.minimum(magnitude, c, out=out)
    out *= sign
    return out


def thresholded_products(
    op: str, a: np.ndarray, e: np.ndarray, lagged: np.ndarray, thresholds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The products of a threshold scan, without forming its columns: for every threshold c the
    columns ``z_c = thresholded(op, |lagged|, sign(lagged), c)`` times ``[a | e]`` and times
    themselves, in one pass over the rows (Rust core, all cores).

    Parameters
    ----------
    op : {"dz", "sat"}
    a : ndarray of shape (n_rows, k)
        The columns each ``z_c`` is multiplied with (a model's regressors).
    e : ndarray of shape (n_rows,)
        One more such column (the model's residual).
    lagged : ndarray of shape (n_rows, width)
        The samples each of the ``width`` columns of ``z_c`` shapes, row by row.
    thresholds : ndarray of shape (m,)

    Returns
    -------
    cross : ndarray of shape (k + 1, m * width)
        ``[a | e]' z_c`` for threshold i in columns ``i * width`` to ``(i + 1) * width``.
    zz : ndarray of shape (m, width, width)
        ``z_c' z_c`` for every threshold.

    Examples
    --------
    >>> x = np.array([[-2.0], [0.5], [3.0]])
    >>> cross, zz = thresholded_products("dz", np.ones((3, 1)), np.zeros(3), x, np.array([1.0]))
    >>> cross.tolist(), zz.tolist()
    ([[1.0], [0.0]], [[[5.0]]])
    """
    a, e, lagged = (np.ascontiguousarray(v, dtype=float) for v in (a, e, lagged))
    cs = np.ascontiguousarray(thresholds, dtype=float)
    cross, zz = _core.threshold_products(a, e, lagged, cs, op == "dz")
    k, width, m = cross.shape
    return cross.transpose(0, 2, 1).reshape(k, m * width), zz.transpose(2, 0, 1)


def integer_power(x: np.ndarray, power: int) -> np.ndarray:
    """``x ** power`` for an integer ``power >= 1`` by squaring and multiplying, as the Rust core's
    ``powi`` evaluates an output term: the same bits in the regressors and in the simulation (numpy's
    ``pow`` rounds once, and is eight times slower for a cube).

    Parameters
    ----------
    x : ndarray
    power : int

    Returns
    -------
    ndarray
        A new array.

    Examples
    --------
    >>> integer_power(np.array([2.0, -1.5]), 3).tolist()
    [8.0, -3.375]
    """
    x = np.asarray(x, dtype=float)
    if power & (power - 1) == 0 or (power & 1 and bin(power).count("1") == 2):
        # x^(2^k), or x^(2^k)·x (3, 5, 9): one buffer squared in place, x multiplied in last; a
        # product of two factors has the same bits in either order.
        out = np.multiply(x, x) if power > 1 else x.copy()
        for _ in range((power >> 1).bit_length() - 1):
            np.multiply(out, out, out=out)
        return np.multiply(out, x, out=out) if power & 1 and power > 1 else out
    result, base = None, x  # the general case: the core's order of products
    while True:
        if power & 1:
            result = base.copy() if result is None else np.multiply(result, base, out=result)
        power >>= 1
        if power == 0:
            assert result is not None  # power >= 1 sets it
            return result
        base = base * base if base is x else np.multiply(base, base, out=base)


def format_threshold(c: float) -> str:
    """A threshold as the grammar writes it: four significant digits, no ``+`` in an exponent.

    Parameters
    ----------
    c : float
        A positive threshold.

    Returns
    -------
    str
        e.g. ``"0.3012"`` or ``"1.5e-05"``.
    """
    return f"{c:.4g}".replace("e+", "e")
