"""Triangular and Cholesky solves with numpy alone.

:func:`scipy.linalg.solve_triangular` and ``cho_solve`` are the usual tools, but importing
:mod:`scipy.linalg` takes a fifth of a second or more, a large share of a short diagnosis. An upper
triangular matrix is its own LU factorisation (partial pivoting finds nothing below the diagonal
to swap, the multipliers are zero), so :func:`numpy.linalg.solve` runs the same back substitution;
a lower triangular one is upper triangular with its rows and columns reversed.
"""

from __future__ import annotations

import numpy as np

__all__ = ["solve_upper", "solve_upper_transposed", "cholesky_solve"]


def solve_upper(r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with R x = b for an upper triangular R (``scipy.linalg.solve_triangular(r, b)``).

    Parameters
    ----------
    r : ndarray of shape (p, p)
        Upper triangular; what lies below its diagonal is not read.
    b : ndarray of shape (p,) or (p, k)

    Returns
    -------
    ndarray like ``b``
    """
    return np.linalg.solve(np.triu(r), b)


def solve_upper_transposed(r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with Rᵀ x = b for an upper triangular R (``solve_triangular(r, b, trans="T")``): the reversed
    rows and columns of Rᵀ are upper triangular."""
    flipped = np.triu(r)[::-1, ::-1].T
    return np.linalg.solve(flipped, b[::-1])[::-1]


def cholesky_solve(factor: np.ndarray, b: np.ndarray, lower: bool = False) -> np.ndarray:
    """x with RᵀR x = b from the Cholesky factor R (upper), or L Lᵀ x = b from L with ``lower=True``
    (``scipy.linalg.cho_solve((factor, lower), b)``)."""
    r = factor.T if lower else factor
    return solve_upper(r, solve_upper_transposed(r, b))
