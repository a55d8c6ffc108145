"""Nested least-squares fits from one factorization: the fits of y on the first p columns of X for
every p at once (AR orders chosen by an information criterion), in one pass over the data.

The triangular factor R of ``[X | y]`` (n × (P + 1)) gives, with
``r`` its last column, the residual sum of squares of the fit on the first p columns as
``Σ_{i ≥ p} r_i²`` and its coefficients by a p × p triangular solve. R is the Cholesky factor of
the cross-product matrix (one pass over the data) when that is well conditioned, else the R of a
Householder QR (as accurate as ``numpy.linalg.lstsq``). Linear in n; the P separate ``lstsq``
calls it replaces each read the whole matrix again.
"""

from __future__ import annotations

import numpy as np

from . import _core
from .triangular import cholesky_solve

__all__ = [
    "nested_fits",
    "nested_from_factor",
    "least_squares",
    "blocked_r",
    "column_norms",
    "cholesky_factor",
    "BLOCK_ROWS",
    "core_readable",
]

#: Rows per block of the cross products summed in numpy (:func:`arxid.models.lagged.lagged_gram`): a
#: block of a few dozen columns stays in the processor's cache (the QRs, :func:`blocked_r`, are
#: reduced in the Rust core in blocks of its own).
BLOCK_ROWS = 16384


def nested_fits(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Residual sums of squares and coefficients of y on the first p columns of ``x``, p = 0..P.

    Parameters
    ----------
    x : ndarray of shape (n, P)
    y : ndarray of shape (n,)

    Returns
    -------
    rss : ndarray of shape (P + 1,)
        ``rss[p]`` = min ‖y − x[:, :p] a‖².
    coef : list of ndarray
        ``coef[p]`` of shape (p,); a fit whose leading columns are (nearly) dependent is solved by
        ``numpy.linalg.lstsq`` instead.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> x = rng.standard_normal((200, 3)); y = x @ [1.0, 0.5, 0.0] + 0.1 * rng.standard_normal(200)
    >>> rss, coef = nested_fits(x, y)
    >>> bool(np.isclose(rss[2], np.sum((y - x[:, :2] @ coef[2]) ** 2)))
    True
    """
    n, big_p = x.shape
    if n <= big_p:  # fewer rows than columns: each fit on its own
        coef = [np.linalg.lstsq(x[:, :p], y, rcond=None)[0] for p in range(big_p + 1)]
        rss = np.array([float(np.sum((y - x[:, :p] @ c) ** 2)) for p, c in enumerate(coef)])
        return rss, coef
    return nested_from_factor(_triangular_factor(x, y))


def nested_from_factor(r: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """:func:`nested_fits` from the triangular factor R of ``[X | y]`` ((P + 1) × (P + 1)), for
    callers that reduce a long record to R block by block.

    Parameters
    ----------
    r : ndarray of shape (P + 1, P + 1)
        Upper triangular, R'R = [X y]'[X y].

    Returns
    -------
    rss : ndarray of shape (P + 1,)
    coef : list of ndarray
        As :func:`nested_fits`; fits on (nearly) dependent leading columns by least squares on R
        (the same residuals as on X).
    """
    big_p = r.shape[1] - 1
    last = r[:, big_p]
    tail = np.cumsum((last**2)[::-1])[::-1]  # tail[p] = Σ_{i ≥ p} r_i²
    rss = np.array([float(tail[p]) for p in range(big_p + 1)])
    diag = np.abs(np.diag(r)[:big_p])
    coef = [np.zeros(0)]
    for p in range(1, big_p + 1):
        if diag[:p].min() <= 1e-12 * max(diag[:p].max(), 1e-300):
            c = np.linalg.lstsq(r[:, :p], last, rcond=None)[0]
            rss[p] = float(np.sum((last - r[:, :p] @ c) ** 2))
        else:
            c = np.linalg.solve(np.triu(r[:p, :p]), last[:p])
        coef.append(c)
    return rss, coef


def _triangular_factor(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """R with R'R = [x y]'[x y]: Cholesky of the Gram matrix when its scaled condition number is
    below 1e8 (so R keeps at least eight digits), else Householder QR."""
    g = np.empty((x.shape[1] + 1, x.shape[1] + 1))
    g[:-1, :-1] = x.T @ x
    g[:-1, -1] = g[-1, :-1] = x.T @ y
    g[-1, -1] = y @ y
    d = np.sqrt(np.diag(g))
    if np.all(d > 0) and np.all(np.isfinite(g)):
        gs = g / np.outer(d, d)
        w = np.linalg.eigvalsh(gs)
        if w.min() > 1e-8 * w.max():
            return np.linalg.cholesky(gs).T * d
    return np.asarray(np.linalg.qr(np.column_stack([x, y]), mode="r"))


def cholesky_factor(gram: np.ndarray, min_ratio: float) -> np.ndarray | None:
    """R with R'R = ``gram`` from the Cholesky factor of the scaled matrix when that is well
    conditioned (smallest eigenvalue above ``min_ratio`` times the largest), else None (then a QR of
    the rows is the accurate way; rounding in this R grows with the condition number).

    Parameters
    ----------
    gram : ndarray of shape (k, k)
        A cross-product matrix X'X.
    min_ratio : float

    Returns
    -------
    ndarray of shape (k, k) or None
        Upper triangular.

    Examples
    --------
    >>> x = np.random.default_rng(4).standard_normal((500, 3))
    >>> r = cholesky_factor(x.T @ x, 1e-4)
    >>> bool(np.allclose(r.T @ r, x.T @ x))
    True
    """
    d = np.sqrt(np.diag(gram))
    if not (np.all(d > 0) and np.all(np.isfinite(gram))):
        return None
    scaled = gram / np.outer(d, d)
    w = np.linalg.eigvalsh(scaled)
    if w.min() <= min_ratio * w.max():
        return None
    return np.linalg.cholesky(scaled).T * d


def least_squares(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Coefficients of the least-squares fit of ``y`` on the columns of ``x``, with no copy of ``x``.

    From the Cholesky factor of the scaled Gram matrix when it is well conditioned (scaled
    condition number below 1e5; one refinement step from the residual), else from the R of a
    blocked Householder QR (:func:`blocked_r`; any rank, the minimum-norm solution as
    ``numpy.linalg.lstsq`` gives).

    Parameters
    ----------
    x : ndarray of shape (n, p)
    y : ndarray of shape (n,)

    Returns
    -------
    ndarray of shape (p,)

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(1)
    >>> x = rng.standard_normal((500, 2)); y = x @ [2.0, -1.0]
    >>> np.round(least_squares(x, y), 12).tolist()
    [2.0, -1.0]
    """
    n, p = x.shape
    if p and n > p:
        d = column_norms(x)
        if np.all(d > 0) and np.all(np.isfinite(d)):
            g = (x.T @ x) / np.outer(d, d)
            w = np.linalg.eigvalsh(g)
            if w.min() > 1e-10 * w.max():
                c = np.linalg.cholesky(g)
                coef = cholesky_solve(c, (x.T @ y) / d, lower=True) / d
                coef += cholesky_solve(c, (x.T @ (y - x @ coef)) / d, lower=True) / d
                return coef
    if n <= p:
        return np.linalg.lstsq(x, y, rcond=None)[0]
    # Ill-conditioned: the small system R θ = r of the blocked QR has the same least-squares
    # solutions as the tall one (X = QR with Q orthonormal), the minimum-norm one included.
    r = blocked_r(x, y)
    return np.linalg.lstsq(np.triu(r[:p, :p]), r[:p, p], rcond=None)[0]


def column_norms(x: np.ndarray) -> np.ndarray:
    """The 2-norm of each column of ``x`` without a squared copy of ``x`` (``numpy.linalg.norm``
    with ``axis=0`` makes one: as large as the regressors themselves).

    Parameters
    ----------
    x : ndarray of shape (n, p)

    Returns
    -------
    ndarray of shape (p,)

    Examples
    --------
    >>> column_norms(np.array([[3.0, 0.0], [4.0, 1.0]])).tolist()
    [5.0, 1.0]
    """
    return np.sqrt(np.einsum("ij,ij->j", x, x))


def blocked_r(x: np.ndarray, y: np.ndarray | None = None, scale: np.ndarray | None = None) -> np.ndarray:
    """R with R'R = [x/scale | y]'[x/scale | y]: Householder QR of blocks of rows, then of their R's
    stacked (as accurate as one QR of the whole matrix), in the Rust core on every core (the same R
    for any number); the columns are read where they are, never copied.

    Parameters
    ----------
    x : ndarray of shape (n, p)
    y : ndarray of shape (n,), optional
        A last column (left out when None).
    scale : ndarray of shape (p,), optional
        Column divisors of ``x`` (default 1).

    Returns
    -------
    ndarray of shape (min(n, k), k)
        Upper triangular; k = p + 1 with ``y``, else p.

    Examples
    --------
    >>> import numpy as np
    >>> x = np.random.default_rng(2).standard_normal((300_000, 3))
    >>> r = blocked_r(x)
    >>> bool(np.allclose(r.T @ r, x.T @ x))
    True
    """
    x = core_readable(x)
    sources, columns = [x], [(0, j, 0) for j in range(x.shape[1])]
    if y is not None:
        sources.append(core_readable(y)[:, None])
        columns.append((1, 0, 0))
    if not columns:
        return np.zeros((0, 0))
    r, n_rows = _core.lagged_r(sources, columns, [(0, x.shape[0])], 0, 0, skip_missing=False)
    r = np.asarray(r)[: min(n_rows, len(columns))]
    if scale is not None:  # the R of [x D | y] is R D: QR commutes with scaling columns
        r[:, : x.shape[1]] /= scale
    return r


def core_readable(a: np.ndarray) -> np.ndarray:
    """``a`` as float, read in place by the core unless a stride is negative."""
    a = np.asarray(a, dtype=float)
    return a if all(s >= 0 for s in a.strides) else np.ascontiguousarray(a)
