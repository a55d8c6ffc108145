"""The added-variable F-test: does a block of extra regressor columns explain part of a residual?

One definition, shared by the missing-effect diagnosis (:mod:`arxid.missing`, one test per candidate)
and the residual nonlinearity test (:mod:`arxid.nonlinearity`, one test per signal and lag).

Given the model's regressors Φ (n × p) and its output y on the same rows, the residual is
e = y − Φθ̂. A block of columns z is first stripped of what Φ already explains (z̃ = z − Φ(Φ⁺z));
the share of the residual energy the block removes is ΔRSS / RSS₀, its square root the *score*
(the partial correlation for one column), and

    F = (ΔRSS / q) / ((RSS₀ − ΔRSS) / (n − p − q)),   p-value = P(F_{q, n−p−q} > F).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from .._base import _core
from .._base.nested import blocked_r, column_norms
from .._base.orthonormal import orthonormal_basis
from .._base.probabilities import f_sf
from .._base.records import record
from .._base.triangular import cholesky_solve, solve_upper, solve_upper_transposed

__all__ = [
    "all_finite",
    "AddedVariableTest",
    "AddedVariableResult",
    "held_columns",
    "holm",
    "lagged_view",
    "stripped_test",
]


@record
class AddedVariableResult:
    """Outcome of one added-variable test.

    Attributes
    ----------
    score : float
        sqrt(ΔRSS / RSS₀) in [0, 1]: its square is the share of residual energy the block removes.
    f_statistic : float
    p_value : float
        Uncorrected F-test p-value.
    n_columns : int
        Independent columns the block adds beyond the model's regressors.
    """

    score: float
    f_statistic: float
    p_value: float
    n_columns: int


def _gram_with(phi: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """[Φ | y]'[Φ | y] (by BLAS: a blocked product beats dot products for a wide Φ); None when Φ
    has no column, no more rows than columns, or a product that is not finite."""
    n, p = phi.shape
    if p == 0 or n <= p:
        return None
    gram = np.empty((p + 1, p + 1))
    gram[:p, :p] = phi.T @ phi
    gram[p, :p] = gram[:p, p] = phi.T @ y
    gram[p, p] = float(y @ y)
    return gram if np.isfinite(gram).all() else None


def _cholesky(g: np.ndarray, scale: np.ndarray) -> np.ndarray | None:
    """R with R'R = the Gram matrix ``g`` scaled by ``scale`` on both sides; None when it is
    (nearly) singular."""
    g = g / np.outer(scale, scale)
    w = np.linalg.eigvalsh(g)
    if w.min() <= 1e-10 * w.max():
        return None
    return np.linalg.cholesky(g).T


class AddedVariableTest:
    """Added-variable statistics against fixed regressors on fixed rows.

    Parameters
    ----------
    phi : ndarray of shape (n_rows, n_params)
        The model's regressors.
    y : ndarray of shape (n_rows,)
        The output on the same rows.
    """

    def __init__(self, phi: np.ndarray, y: np.ndarray):
        self.n, self.p = phi.shape
        self._phi = np.ascontiguousarray(phi, dtype=float)
        y = np.ascontiguousarray(y, dtype=float)
        self._q: np.ndarray | None = None
        self._sums: tuple[np.ndarray, float] | None = None  # Φ'1 and e'1, for blocks tested with an offset
        self._keep: np.ndarray | None = None  # the independent columns (None: all)
        self._theta: np.ndarray | None = None
        #: [Φ | y]'[Φ | y] (None when the regressors are ill-conditioned or not finite).
        self.gram = _gram_with(self._phi, y)
        # Well-conditioned regressors (the usual case): the Cholesky factor R of the scaled Gram
        # matrix stands for Q = Φ R⁻¹, which is never formed (no n × p copies); the residual is
        # refined once, each step one pass over Φ (Rust core). Otherwise Householder QR, as
        # accurate as it gets.
        p = self.p
        self._scale = np.sqrt(np.diag(self.gram)[:p]) if self.gram is not None else column_norms(phi)
        self._scale[self._scale == 0] = 1.0
        self._r = None if self.gram is None else _cholesky(self.gram[:p, :p], self._scale)
        if self.gram is not None and self._r is not None:
            first = self._solve(self.gram[:p, p])
            self.e, products = _core.fit_residual(self._phi, y, first)
            refined = self._solve(products)
            self.rss0 = _core.refine_fit_residual(self._phi, self.e, refined)
            self._theta = first + refined
            energy = float(self.gram[p, p])
        else:  # ill-conditioned: R of [Φ | y] by Householder QR in blocks of rows (no n × p copy)
            self.gram = None
            self._keep, self._r, theta = _independent(blocked_r(phi, y, self._scale), phi.shape[1])
            if self._r is not None:
                self.e = y - phi @ (theta / self._scale)
            else:
                self.e = y - self.q @ (self.q.T @ y)
            self.rss0 = float(self.e @ self.e)
            energy = float(y @ y)
        # Noise-free data a model fits exactly leave a residual at rounding level: testing columns
        # against it would find effects in rounding noise (and its F-ratio can divide by zero).
        self.exact = self.rss0 <= _ROUNDING**2 * energy

    def _solve(self, v: np.ndarray) -> np.ndarray:
        """θ with R'R (θ scale) = v / scale: least-squares coefficients from Φ'v (a column of
        coefficients for each column of a 2-D ``v``)."""
        assert self._r is not None
        scale = self._scale if v.ndim == 1 else self._scale[:, None]
        return cholesky_solve(self._r, v / scale) / scale

    @property
    def q(self) -> np.ndarray:
        """Orthonormal basis of the regressors' span (n × p; formed only when they are ill-conditioned and a
        test needs it)."""
        if self._q is None:  # on a tall Φ written over its scaled copy: no second n × p beside it
            q = orthonormal_basis(self._phi / self._scale, overwrite=True)
            self._q = np.linalg.qr(self._phi / self._scale)[0] if q is None else q
        return self._q

    def share(self, z: np.ndarray) -> float:
        """ΔRSS / RSS₀ of the columns ``z`` alone, without the F-test: a fast score for scans.

        The small block's normal equations (q × q) are solved instead of a QR of n × q, which is
        accurate enough to rank thresholds; :meth:`test` gives the reported statistics.

        Parameters
        ----------
        z : ndarray of shape (n_rows, q)

        Returns
        -------
        float
            In [0, 1]; NaN when the block is zero or already explained by the model.
        """
        if self.exact:
            return math.nan
        b, zz, ze = self._cross(z)
        got = self._share_from(b, zz, ze)
        if got is not None:
            return got
        norms = np.sqrt(np.maximum(np.diag(zz), 0.0))
        k = norms > 0
        return self._exact_share(z[:, k] / norms[k], ze[k] / norms[k])

    def shares(
        self, products: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]], n_blocks: int, width: int
    ) -> np.ndarray | None:
        """:meth:`share` of many blocks of ``width`` columns at once, from their products with the
        regressors formed in one pass (a threshold scan tries some forty blocks; one product per
        block would read Φ forty times).

        Parameters
        ----------
        products : callable
            ``products(phi, e)`` gives ``(cross, zz)``: ``cross`` of shape ``(n_params + 1,
            n_blocks * width)``, the products of ``[Φ | e]`` with every column (block i in columns
            ``i * width`` to ``(i + 1) * width``), and ``zz`` of shape ``(n_blocks, width, width)``,
            each block's own products.
        n_blocks, width : int

        Returns
        -------
        ndarray of shape (n_blocks,) or None
            The shares (NaN where :meth:`share` gives NaN); None when the regressors are
            ill-conditioned or a block needs the exact residual: then ask :meth:`share` one by one.
        """
        if self.exact:
            return np.full(n_blocks, math.nan)
        if self._r is None:
            return None
        cross, zz = products(self._phi, self.e)
        k = self._phi.shape[1]  # the regressors' columns (p may count more, for the degrees of freedom)
        b, ze = self._projected(cross[:k]), cross[k]
        out = np.empty(n_blocks)
        for i in range(n_blocks):
            sl = slice(i * width, (i + 1) * width)
            got = self._share_from(b[:, sl], zz[i], ze[sl])
            if got is None:
                return None
            out[i] = got
        return out

    def _share_from(self, b: np.ndarray, zz: np.ndarray, ze: np.ndarray) -> float | None:
        """The share from the cross-products (None: the block is nearly explained by the model, and
        the exact residual of its columns decides)."""
        norms = np.sqrt(np.maximum(np.diag(zz), 0.0))
        if not (norms > 0).any() or self.rss0 <= 0:
            return math.nan
        k = norms > 0
        g = (zz - b.T @ b)[np.ix_(k, k)] / np.outer(norms[k], norms[k])
        if np.trace(g) < 1e-10:
            return None
        return self._solved_share(g, ze[k] / norms[k])

    def _exact_share(self, zn: np.ndarray, v: np.ndarray) -> float:
        """The share of a block (nearly) explained by the model, from its exactly stripped columns
        (``zn``: the nonzero columns normalised, a new array, ``v``: their products with the residual)."""
        zr = self._strip(zn)
        if np.linalg.norm(zr) < 1e-7:
            return math.nan
        return self._solved_share(zr.T @ zr, v)

    def _solved_share(self, g: np.ndarray, v: np.ndarray) -> float:
        coef = np.linalg.lstsq(g, v, rcond=1e-10)[0]
        return float(min(max(v @ coef, 0.0), self.rss0) / self.rss0)

    def _cross(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Q'z, z'z and z'e: all a test needs of the n rows (z'e = z̃'e, as Q'e = 0)."""
        if self._r is None:
            return self.q.T @ z, z.T @ z, z.T @ self.e
        pz, zz, ze = self._products([z])[0]
        return self._projected(pz), zz, ze

    def test(self, z: np.ndarray) -> tuple[AddedVariableResult | None, str]:
        """Test the columns ``z`` (rows aligned with ``phi``).

        Parameters
        ----------
        z : ndarray of shape (n_rows, q)

        Returns
        -------
        result : AddedVariableResult or None
            None when the block cannot be tested.
        why : str
            The reason it cannot ("" when it can).
        """

        if self.exact:
            return None, _EXACT
        return self._tested(z, *self._cross(z))

    def tests(self, blocks: list[np.ndarray], offset: bool = False) -> list[tuple[AddedVariableResult | None, str]]:
        """:meth:`test` of several blocks, reading Φ once per block of rows for all of them (one
        product per block would read the regressors once per candidate).

        Parameters
        ----------
        blocks : list of ndarray of shape (n_rows, q_i)
        offset : bool
            Test each block with a column of ones beside it, ``[z | 1]``. The ones' products are
            sums (Φ's columns, z's, the residual's), so the block is never copied to add the column.

        Returns
        -------
        list of (AddedVariableResult or None, str)
            As :meth:`test`, in the order of ``blocks``.
        """
        if self.exact:
            return [(None, _EXACT) for _ in blocks]
        if self._r is None:
            return [self.test(_with_ones(z) if offset else z) for z in blocks]
        products = self._products(blocks)
        if not offset:
            return [self._tested(z, self._projected(pz), zz, ze) for z, (pz, zz, ze) in zip(blocks, products)]
        out = []
        for z, (pz, zz, ze) in zip(blocks, products):
            pz1, zz1, ze1 = self._products_with_ones(z, pz, zz, ze)
            out.append(self._tested(functools.partial(_with_ones, z), self._projected(pz1), zz1, ze1))
        return out

    def _products_with_ones(
        self, z: np.ndarray, pz: np.ndarray, zz: np.ndarray, ze: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Φ'[z | 1], [z | 1]'[z | 1] and [z | 1]'e from z's products and sums."""
        if self._sums is None:
            self._sums = (self._phi.sum(axis=0), float(self.e.sum()))
        phi_ones, e_sum = self._sums
        zs = np.array([float(z[:, j].sum()) for j in range(z.shape[1])])  # a lagged view's columns are slices
        q = z.shape[1]
        zz1 = np.empty((q + 1, q + 1))
        zz1[:q, :q], zz1[:q, q], zz1[q, :q], zz1[q, q] = zz, zs, zs, float(self.n)
        return np.column_stack([pz, phi_ones]), zz1, np.append(ze, e_sum)

    def _products(self, blocks: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Φ'z, z'z and z'e of every block, in one pass over the rows (Rust core): a z that is a
        strided view of one signal's lags (see :func:`lagged_view`) is read off the signal, never
        copied."""
        k = self._phi.shape[1]
        some = [z for z in blocks if z.shape[1]]
        got = iter(_core.tested_products(self._phi, self.e, [_as_block(z) for z in some]) if some else ())
        out = []
        for z in blocks:
            cross, zz = next(got) if z.shape[1] else (np.zeros((k + 1, 0)), np.zeros((0, 0)))
            out.append((cross[:k], zz, cross[k]))
        return out

    def coefficients(self, z: np.ndarray) -> np.ndarray | None:
        """Least-squares coefficients of y on ``[Φ | z]`` (Φ's first) from the cross-products, by
        the partitioned normal equations: one pass over the rows, no n × (p + q) copy.

        Parameters
        ----------
        z : ndarray of shape (n_rows, q)

        Returns
        -------
        ndarray of shape (n_params + q,) or None
            None when Φ or the stripped block is ill-conditioned (then fit ``[Φ | z]`` itself).
        """
        if self._theta is None or self._keep is not None or self._r is None:
            return None
        b, zz, ze = self._cross(z)
        g = zz - b.T @ b  # z̃'z̃, with z̃ = z stripped of Φ
        d = np.sqrt(np.maximum(np.diag(g), 0.0))
        if d.min() <= 1e-4 * max(float(np.sqrt(np.max(np.diag(zz)))), 1e-300):
            return None
        if np.linalg.eigvalsh(g / np.outer(d, d)).min() <= 1e-8:
            return None
        gamma = np.linalg.solve(g, ze)
        fitted_z = solve_upper(self._r, b) / self._scale[:, None]  # Φ⁺z
        return np.concatenate([self._theta - fitted_z @ gamma, gamma])

    def _projected(self, phi_z: np.ndarray) -> np.ndarray:
        """Q'z from Φ'z (R⁻ᵀ of the scaled products, on the independent columns)."""
        assert self._r is not None
        pz = phi_z / self._scale[:, None]
        return solve_upper_transposed(self._r, pz if self._keep is None else pz[self._keep])

    def _tested(
        self, z: np.ndarray | Callable[[], np.ndarray], b: np.ndarray, zz: np.ndarray, ze: np.ndarray
    ) -> tuple[AddedVariableResult | None, str]:
        """The test of ``z`` from its cross-products Q'z, z'z and z'e (``z`` itself, or a function
        that forms it, is read only when the block is ill-conditioned beside Φ)."""
        norms = np.sqrt(np.maximum(np.diag(zz), 0.0))
        keep = norms > 0
        if not keep.any():
            return None, "the candidate is zero on these data"
        fast = self._from_cross(b, zz, ze, keep, norms)
        if fast is not None:
            return fast, ""
        return self._stripped(z() if callable(z) else z, keep, norms)

    def _stripped(self, z: np.ndarray, keep: np.ndarray, norms: np.ndarray) -> tuple[AddedVariableResult | None, str]:
        """Ill-conditioned beside Φ: the QR of the stripped, normalised block decides which columns count."""
        zn = np.empty((z.shape[0], int(keep.sum())))
        for j, col in enumerate(np.flatnonzero(keep)):  # column by column: a lagged view's columns are slices
            np.divide(z[:, col], norms[col], out=zn[:, j])
        return stripped_test(self._strip(zn), self.e, self.n - self.p, self.rss0)

    def _strip(self, zn: np.ndarray) -> np.ndarray:
        """``zn`` minus its projection on the regressors (``zn`` a new array: overwritten).

        Well-conditioned regressors: Φ⁺z from the Cholesky factor, subtracted in place a block of
        rows at a time, twice (the second pass removes what the first solve's rounding left in Φ's
        span, as accurate as an orthonormal basis of Φ, which would be an n × p copy beside Φ).
        Otherwise that basis."""
        if self.gram is None:
            return zn - self.q @ (self.q.T @ zn)
        for _ in range(2):
            fitted = self._solve(self._phi.T @ zn)
            for lo in range(0, self.n, _STRIP_ROWS):
                zn[lo : lo + _STRIP_ROWS] -= self._phi[lo : lo + _STRIP_ROWS] @ fitted
        return zn

    def _from_cross(
        self, b: np.ndarray, zz: np.ndarray, ze: np.ndarray, keep: np.ndarray, norms: np.ndarray
    ) -> AddedVariableResult | None:
        """The test from the cross-products when the block is well conditioned beside the model's
        regressors (None otherwise: the QR of the stripped block decides which columns count)."""
        nk = norms[keep]
        g = (zz - b.T @ b)[np.ix_(keep, keep)] / np.outer(nk, nk)
        rn = np.sqrt(np.maximum(np.diag(g), 0.0))
        if rn.min() <= 1e-4:
            return None
        gs = g / np.outer(rn, rn)
        if np.linalg.eigvalsh(gs).min() <= 1e-8:
            return None
        q = g.shape[0]
        dof = self.n - self.p - q
        if dof < 1 or self.rss0 <= 0:
            return None
        v = ze[keep] / nk
        drss = min(float(v @ np.linalg.solve(g, v)), self.rss0)
        drss = max(drss, 0.0)
        rss1 = max(self.rss0 - drss, 1e-300 * self.rss0)
        f = (drss / q) / (rss1 / dof)
        return AddedVariableResult(math.sqrt(drss / self.rss0), float(f), float(f_sf(f, q, dof)), q)


def stripped_test(zr: np.ndarray, e: np.ndarray, dof0: int, rss0: float) -> tuple[AddedVariableResult | None, str]:
    """The F-test of a block already stripped of the model's regressors, ``zr`` (z̃ of normalised
    columns), against the model's residual ``e``: the QR of z̃ decides which columns count.

    Parameters
    ----------
    zr : ndarray of shape (n_rows, q)
        The block minus its projection on the model's regressors (in any orthonormal basis of the
        rows, as long as ``e`` is in the same one).
    e : ndarray of shape (n_rows,)
        The model's residual.
    dof0 : int
        Rows minus the model's parameters.
    rss0 : float
        The model's residual sum of squares.

    Returns
    -------
    (AddedVariableResult or None, str)
        The result, or None with the reason the block cannot be tested.
    """
    rn = column_norms(zr)
    ok = rn > 1e-7
    if not ok.any():
        return None, "already explained by the model's regressors (collinear)"
    # R of [z̃ (normalised) | e] by blocks of rows, read in place: its last column above the diagonal
    # is Q'e, so the Q of z̃ (an n × q copy, with numpy's copy of z̃ beside it) is never formed.
    k = int(ok.sum())
    r = np.zeros((k + 1, k + 1))
    got = blocked_r(zr if ok.all() else zr[:, ok], e, rn[ok])
    r[: got.shape[0]] = got
    kept = _independent_columns(r[:, :k])
    if len(kept) < k:  # the R of the independent columns and e, from this small R (the same products)
        r = np.asarray(np.linalg.qr(r[:, [*kept, k]], mode="r"))
    q = len(kept)
    dof = dof0 - q
    if dof < 1 or rss0 <= 0:
        return None, "too few rows to test it"
    drss = min(float(np.sum(r[:q, q] ** 2)), rss0)
    rss1 = max(rss0 - drss, 1e-300 * rss0)
    f = (drss / q) / (rss1 / dof)
    return AddedVariableResult(math.sqrt(drss / rss0), float(f), float(f_sf(f, q, dof)), q), ""


def _independent_columns(r: np.ndarray) -> list[int]:
    """The columns of unit norm whose R is ``r`` that count, in order: each whose distance to the
    span of those kept before it is above 1e-7. (The diagonal of ``r`` itself measures a column's
    distance to all columns before it: after a dependent one, its Q column points wherever rounding
    left it, and the columns after would be measured against that direction too.)"""
    kept: list[int] = []
    for j in range(r.shape[1]):
        if abs(np.asarray(np.linalg.qr(r[:, [*kept, j]], mode="r"))[-1, -1]) > 1e-7:
            kept.append(j)
    return kept


def all_finite(z: np.ndarray) -> bool:
    """Whether every entry of ``z`` is finite. A lagged view (:func:`lagged_view`: strides
    ``(s, -s)``) is read as the samples it spans, each once: its entries are those samples repeated
    ``width`` times, and numpy's check of the strided view is ten times slower.

    Parameters
    ----------
    z : ndarray

    Returns
    -------
    bool

    Examples
    --------
    >>> x = np.arange(6.0)
    >>> all_finite(lagged_view(x, 2, 2, 3)), all_finite(np.array([[1.0, np.inf]]))
    (True, False)
    """
    if z.ndim == 2 and z.shape[0] and z.shape[1] > 1 and z.strides[0] == z.itemsize == -z.strides[1]:
        n, w = z.shape
        # Column w - 1 starts at the lowest sample; the span runs on to the last row of column 0.
        span = np.lib.stride_tricks.as_strided(z[:, -1], shape=(n + w - 1,), strides=(z.itemsize,), writeable=False)
        return bool(np.isfinite(span).all())
    return bool(np.isfinite(z).all())


def lagged_view(x: np.ndarray, first: int, width: int, n_rows: int) -> np.ndarray:
    """``(n_rows, width)`` with column j holding ``x[first - j + r]`` for row r: a read-only strided
    view of ``x``, nothing copied (the columns of a lagged candidate on consecutive rows).

    Parameters
    ----------
    x : ndarray of shape (n_samples,)
    first : int
        The sample of row 0, column 0 (at least ``width - 1``).
    width, n_rows : int

    Returns
    -------
    ndarray

    Examples
    --------
    >>> lagged_view(np.arange(6.0), 2, 2, 3).tolist()
    [[2.0, 1.0], [3.0, 2.0], [4.0, 3.0]]
    """
    x = np.ascontiguousarray(x, dtype=float)
    if first < width - 1 or first + n_rows > len(x):
        raise ValueError(f"rows {first - width + 1} to {first + n_rows - 1} are outside the {len(x)} samples")
    step = x.strides[0]
    return np.lib.stride_tricks.as_strided(x[first:], shape=(n_rows, width), strides=(step, -step), writeable=False)


def _with_ones(z: np.ndarray) -> np.ndarray:
    """``[z | 1]``, written column by column (a lagged view's columns are slices: fast to copy)."""
    out = np.empty((z.shape[0], z.shape[1] + 1))
    for j in range(z.shape[1]):
        out[:, j] = z[:, j]
    out[:, -1] = 1.0
    return out


def _is_lagged(z: np.ndarray) -> bool:
    """``z`` is a :func:`lagged_view` of one signal (or a contiguous single column)."""
    step, w = z.itemsize, z.shape[1]
    return z.dtype == np.float64 and w > 0 and z.strides[0] == step and (w == 1 or z.strides[1] == -step)


def held_columns(z: np.ndarray) -> int:
    """Columns of the record's length that the block ``z`` holds in memory: one for a
    :func:`lagged_view` (its columns are one signal read at other lags), else its width."""
    return min(1, z.shape[1]) if _is_lagged(z) else z.shape[1]


def _as_block(z: np.ndarray) -> tuple[np.ndarray, int, bool]:
    """A block as the core reads it: the signal behind a :func:`lagged_view` (or a contiguous single
    column), else the C-ordered values."""
    n, w = z.shape
    step = z.itemsize
    if _is_lagged(z):
        series = np.lib.stride_tricks.as_strided(z[:, w - 1 :], shape=(n + w - 1,), strides=(step,), writeable=False)
        return series, w, True
    return np.ascontiguousarray(z, dtype=float).ravel(), w, False


#: Rows of the block stripped of the regressors at a time (:meth:`AddedVariableTest._strip`).
_STRIP_ROWS = 16384

_EXACT = "the model reproduces the output to rounding: nothing is left to explain"

#: Residual RMS, relative to the output's, below which a fit is exact (rounding, not noise).
_ROUNDING = 1e-10


def _independent(r: np.ndarray, p: int) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray]:
    """From R of [Φ | y] (p + 1 columns): the independent columns of Φ (None: all), the R of those
    columns and the least-squares coefficients of y on them (zero on the others); R None when Φ has
    no independent column or too few rows."""
    theta = np.zeros(p)
    if p == 0 or r.shape[0] <= p:
        return None, None, theta
    d = np.abs(np.diag(r)[:p])
    if d.min() > 1e-12 * d.max():
        theta[:] = solve_upper(r[:p, :p], r[:p, p])
        return None, r[:p, :p], theta
    # Exactly dependent columns (a lag listed twice, ...): keep a largest independent set, the
    # span of Φ unchanged; R of the kept columns and y from the small factor.
    piv, dp = _pivoted_diagonal(r[:p, :p])
    k = int(np.sum(dp > 1e-12 * dp.max())) if dp.max() > 0 else 0
    if k == 0:
        return None, None, theta
    keep = np.sort(piv[:k])
    r2 = np.asarray(np.linalg.qr(r[:, np.append(keep, p)], mode="r"))
    theta[keep] = solve_upper(r2[:k, :k], r2[:k, k])
    return keep, r2[:k, :k], theta


def _pivoted_diagonal(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The column order and |diagonal| of a QR factorisation with column pivoting (the column of
    largest remaining norm first, LAPACK's geqp3 rule), by Householder steps on a small matrix."""
    a = np.array(a, dtype=float)
    n, p = a.shape
    piv = np.arange(p)
    diag = np.zeros(min(n, p))
    for j in range(min(n, p)):
        m = j + int(np.argmax(np.einsum("ij,ij->j", a[j:, j:], a[j:, j:])))
        a[:, [j, m]], piv[[j, m]] = a[:, [m, j]], piv[[m, j]]
        x = a[j:, j]
        alpha = -math.copysign(float(np.linalg.norm(x)), x[0])
        v = x.copy()
        v[0] -= alpha
        vv = float(v @ v)
        if vv > 0:
            a[j:, j:] -= np.outer(v, (2.0 / vv) * (v @ a[j:, j:]))
        diag[j] = abs(alpha)
    return piv, diag


def holm(p: np.ndarray) -> np.ndarray:
    """Holm's step-down correction of the p-values ``p`` (same order).

    Parameters
    ----------
    p : ndarray of shape (m,)

    Returns
    -------
    ndarray of shape (m,)
        Adjusted p-values, each at most 1.
    """
    m = len(p)
    if m == 0:
        return p
    order = np.argsort(p)
    adj = np.empty(m)
    running = 0.0
    for i, j in enumerate(order):
        running = max(running, min(1.0, (m - i) * p[j]))
        adj[j] = running
    return adj


#: The same share under a public name, for tests built from other statistics than the regressors.
ROUNDING = _ROUNDING
