"""An orthonormal basis of a tall matrix's few columns, and the factor of new columns projected off
it: the projections of the diagnosis's encompassing and added-variable tests and of its shape scans,
at millions of rows, without the copies of the rows numpy's QR makes beside its Q."""

from __future__ import annotations

import math

import numpy as np

from . import _core
from .nested import blocked_r, core_readable

__all__ = ["RANK_FACTOR", "Projector", "orthonormal_basis", "projected_r"]

#: The core's rank rule: a column is dependent when the sine of its angle to the columns before it
#: is at most (rows · machine epsilon · 10).
RANK_FACTOR = 10.0 * np.finfo(float).eps


def orthonormal_basis(columns: np.ndarray, overwrite: bool = False, r: np.ndarray | None = None) -> np.ndarray | None:
    """Q of the columns' QR, or None when one depends on those before it by the core's rank rule.

    A tall matrix (from :data:`_LEAN_ROWS` rows) gets Q as ``columns`` R⁻¹, twice (the second pass
    restores orthogonality to rounding), block of rows by block, R from the core's blocked QR
    (:func:`~arxid._base.nested.blocked_r`) or ``r`` when given (an upper triangular R with RᵀR the
    columns' cross products, a fit's own: one pass less): no copy of the rows beside Q, and with
    ``overwrite`` Q is written over ``columns`` (a shorter one: numpy's QR)."""
    lean = columns.shape[0] >= _LEAN_ROWS and columns.shape[1] > 0
    if lean and r is not None:
        q, norms = None, np.sqrt(np.einsum("ij,ij->j", r, r))  # R's column norms are the columns'
    else:
        q, r = (None, blocked_r(columns)) if lean else np.linalg.qr(columns)
        norms = np.sqrt(np.einsum("ij,ij->j", columns, columns))
    tol = RANK_FACTOR * max(columns.shape)
    if columns.shape[1] and not (np.abs(np.diag(r)) > tol * norms).all():
        return None
    if q is None:
        q = columns if overwrite else columns.copy()
        _divide_rows(q, r)
        _divide_rows(q, blocked_r(q))
    return q


def _divide_rows(q: np.ndarray, r: np.ndarray) -> None:
    """q ← q R⁻¹ in place, a block of rows at a time."""
    inverse = np.linalg.inv(r)
    for a in range(0, q.shape[0], _LEAN_ROWS):
        q[a : a + _LEAN_ROWS] = q[a : a + _LEAN_ROWS] @ inverse


#: Rows from which :func:`orthonormal_basis` divides by R in place (numpy's QR copies what it
#: factors), and rows per block of that division.
_LEAN_ROWS = 131_072


def projected_r(basis: np.ndarray, y_perp: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R of [Z − Q(QᵀZ) | y⊥] (no Q formed), whose last diagonal entry is the residual's norm, and
    per column of ``z`` whether it depends on the basis or on those before it (the core's rule).

    One call of the core (two passes over the rows, no tall temporary): a shape scan asks for it
    once per value it tries, on a few thousand rows or on millions (through a :class:`Projector`,
    which readies the basis once).

    Parameters
    ----------
    basis : ndarray of shape (n, p)
        Orthonormal columns Q.
    y_perp : ndarray of shape (n,)
        A residual orthogonal to them.
    z : ndarray of shape (n, k)

    Returns
    -------
    r : ndarray of shape (k + 1, k + 1)
        Upper triangular, up to the signs of its rows.
    dependent : ndarray of bool, shape (k,)

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> q = np.linalg.qr(rng.standard_normal((500, 2)))[0]
    >>> y = rng.standard_normal(500); y -= q @ (q.T @ y)
    >>> z = np.column_stack([rng.standard_normal(500), q[:, 0]])
    >>> r, dependent = projected_r(q, y, z)
    >>> dependent.tolist()
    [False, True]
    """
    r, dependent = Projector(basis, y_perp).r(z)
    return r, np.array(dependent, dtype=bool)


class Projector:
    """:func:`projected_r` against one basis and residual for many ``z``: the two are readied for
    the core once, and the rank rule is read from the few diagonal entries as Python numbers (a
    scan's value costs the core's call and little beside it).

    Parameters
    ----------
    basis, y_perp : ndarray
        The orthonormal columns Q, shape (n, p), and a residual orthogonal to them, shape (n,).
    """

    def __init__(self, basis: np.ndarray, y_perp: np.ndarray):
        self.basis, self.y_perp = core_readable(basis), core_readable(y_perp)
        self._y: np.ndarray | None = None  # y_perp contiguous, for the gathered scans

    def r(self, z: np.ndarray) -> tuple[np.ndarray, list[bool]]:
        """R of [Z − Q(QᵀZ) | y⊥] and whether each column of ``z`` is dependent (as :func:`projected_r`).

        Parameters
        ----------
        z : ndarray of shape (n, k)

        Returns
        -------
        (ndarray of shape (k + 1, k + 1), list of bool)
        """
        r, squares = _core.projected_r(self.basis, self.y_perp, core_readable(z))
        scale = RANK_FACTOR * z.shape[0]  # the core's rule, in the order numpy would evaluate it
        return r, [not abs(r[c, c]) > scale * math.sqrt(s) for c, s in enumerate(squares.tolist())]

    def rss(self, z: np.ndarray) -> float:
        """The residual sum of squares of y on the basis and ``z``; +inf when a column of ``z``
        depends on the basis or on those before it.

        Parameters
        ----------
        z : ndarray of shape (n, k)

        Returns
        -------
        float
        """
        r, dependent = self.r(z)
        return math.inf if any(dependent) else float(r[-1, -1] ** 2)

    def shaped_rss(self, series: np.ndarray, index: np.ndarray) -> list[float | None]:
        """:meth:`rss` for each row of ``series`` with ``z[t, c] = series[v, index[t, c]]`` (the same
        numbers), the lags gathered by the core, one call for all rows; None where a gathered lag is
        not finite.

        Parameters
        ----------
        series : ndarray of shape (n_values, n_samples)
        index : ndarray of int64, shape (n, k)

        Returns
        -------
        list of float or None
        """
        if self._y is None:
            self._y = np.ascontiguousarray(self.y_perp)
        r, squares, finite = _core.shaped_projected_r(self.basis, self._y, np.ascontiguousarray(series), index)
        scale = RANK_FACTOR * index.shape[0]  # the core's rule, as :meth:`r` reads it
        out: list[float | None] = []
        for rv, sv, ok in zip(r.tolist(), squares.tolist(), finite.tolist()):  # Python floats: the same bits
            dependent = any(not abs(rv[c][c]) > scale * math.sqrt(s) for c, s in enumerate(sv))
            out.append(None if not ok else math.inf if dependent else rv[-1][-1] ** 2)
        return out
