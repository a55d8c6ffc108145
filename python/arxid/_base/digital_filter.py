"""``lfilter``: a digital filter of a signal from rest with scipy.signal.lfilter's numbers, without
importing scipy.signal (it imports scipy.stats and parses hundreds of docstrings: most of the time
of an analysis of a short record)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import _core

if TYPE_CHECKING:  # numpy.typing parses its docstrings on import
    from numpy.typing import ArrayLike

__all__ = ["lfilter"]


def lfilter(b: ArrayLike, a: ArrayLike, x: ArrayLike) -> np.ndarray:
    """``scipy.signal.lfilter(b, a, x)`` of a 1-D signal from rest.

    Parameters
    ----------
    b, a : array_like of shape (n_b,), (n_a,)
        Numerator and denominator in powers of ``q^-1``, ``a[0] != 0``.
    x : array_like of shape (n_samples,)

    Returns
    -------
    ndarray of shape (n_samples,)
        ``y`` with ``sum_i a[i] y(t - i) = sum_j b[j] x(t - j)``: scipy's numbers to the last bit
        (a convolution for ``len(a) == 1``, as scipy computes it; else the Rust core's direct form II
        transposed, scipy's own).
    """
    b, a = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (b, a))
    x = np.asarray(x, dtype=float)
    if a.size == 1:
        return np.convolve(b / a[0], x)[: x.size]
    return _core.lfilter(b, a, x)
