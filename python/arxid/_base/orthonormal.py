"""An orthonormal basis of a tall matrix's few columns, and its R factor, by blocks of rows: the
projections of the diagnosis's encompassing and added-variable tests at millions of rows, without
the copies of the rows numpy's QR makes beside its Q."""

from __future__ import annotations

import numpy as np

__all__ = ["RANK_FACTOR", "orthonormal_basis", "tall_r"]

#: The core's rank rule: a column is dependent when the sine of its angle to the columns before it
#: is at most (rows · machine epsilon · 10).
RANK_FACTOR = 10.0 * np.finfo(float).eps


def orthonormal_basis(columns: np.ndarray, overwrite: bool = False) -> np.ndarray | None:
    """Q of the columns' QR, or None when one depends on those before it by the core's rank rule.

    A tall matrix (from :data:`_LEAN_ROWS` rows) gets Q as ``columns`` R⁻¹, twice (the second pass
    restores orthogonality to rounding), block of rows by block: no copy of the rows beside Q,
    and with ``overwrite`` Q is written over ``columns`` (a shorter one: numpy's QR)."""
    lean = columns.shape[0] >= _LEAN_ROWS and columns.shape[1] > 0
    q, r = (None, tall_r(columns)) if lean else np.linalg.qr(columns)
    tol = RANK_FACTOR * max(columns.shape)
    norms = np.sqrt(np.einsum("ij,ij->j", columns, columns))
    if columns.shape[1] and not (np.abs(np.diag(r)) > tol * norms).all():
        return None
    if q is None:
        q = columns if overwrite else columns.copy()
        _divide_rows(q, r)
        _divide_rows(q, tall_r(q))
    return q


def _divide_rows(q: np.ndarray, r: np.ndarray) -> None:
    """q ← q R⁻¹ in place, a block of rows at a time."""
    inverse = np.linalg.inv(r)
    for a in range(0, q.shape[0], _LEAN_ROWS):
        q[a : a + _LEAN_ROWS] = q[a : a + _LEAN_ROWS] @ inverse


#: Rows of each block whose R factors :func:`tall_r` stacks.
_BLOCK_ROWS = 4096
#: Rows from which :func:`orthonormal_basis` divides by R in place, and rows per batched QR of
#: :func:`tall_r` (numpy's QR copies what it factors).
_LEAN_ROWS = 32 * _BLOCK_ROWS


def tall_r(a: np.ndarray) -> np.ndarray:
    """R of a tall matrix of a few columns, up to the signs of its rows: the R factors of blocks of
    rows (batched QRs of at most :data:`_LEAN_ROWS` rows), stacked and reduced again. Householder's
    accuracy in about half the time of one QR of the whole matrix (whose reflections each pass over
    every row)."""
    whole = a.shape[0] // _BLOCK_ROWS * _BLOCK_ROWS
    if whole <= _BLOCK_ROWS:
        return np.asarray(np.linalg.qr(a, mode="r"))
    k = a.shape[1]
    stacks = (a[lo : min(lo + _LEAN_ROWS, whole)].reshape(-1, _BLOCK_ROWS, k) for lo in range(0, whole, _LEAN_ROWS))
    blocks = [np.asarray(np.linalg.qr(stack, mode="r")).reshape(-1, k) for stack in stacks]
    return np.asarray(np.linalg.qr(np.vstack([*blocks, a[whole:]]), mode="r"))
