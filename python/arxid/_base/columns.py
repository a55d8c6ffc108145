"""Columns written into a row-major matrix a block of rows at a time.

The Rust core reads its inputs row-major (sample by sample). A column written alone into such a
matrix touches every row, so each column is one more pass over the whole matrix; a block of rows
with all its columns stays in cache while they are written, so the matrix is written once.

A long matrix is written in two halves of its rows on two threads
(:func:`arxid._base.background.in_row_halves`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from .background import in_row_halves

__all__ = ["rows_per_block", "write_columns"]

#: Rows per block at most (and the fewest a long matrix needs to be split between two threads).
ROWS_AT_ONCE = 1 << 14

#: Bytes of a block of rows: it stays in a core's L2 cache while its columns are written (a block
#: of 16,384 rows of 12 columns, 1.5 MiB, did not: the matrix was written 1.7x slower).
BLOCK_BYTES = 1 << 19


def rows_per_block(n_columns: int) -> int:
    """Rows of a block of ``n_columns`` columns that fit :data:`BLOCK_BYTES` (1,024 at least).

    Parameters
    ----------
    n_columns : int

    Returns
    -------
    int

    Examples
    --------
    >>> rows_per_block(4), rows_per_block(12), rows_per_block(100)
    (16384, 4096, 1024)
    """
    rows = ROWS_AT_ONCE
    while rows > 1024 and rows * n_columns * 8 > BLOCK_BYTES:
        rows //= 2
    return rows


def write_columns(out: np.ndarray, columns: Mapping[int, np.ndarray]) -> None:
    """``out[:, j:j + w] = c`` for each ``j: c`` (``c`` of shape (n,) or (n, w)), a block of rows at
    a time.

    Parameters
    ----------
    out : ndarray of shape (n, m)
    columns : mapping of int to ndarray
        The first column each array goes to, and the array.

    Examples
    --------
    >>> out = np.zeros((3, 3))
    >>> write_columns(out, {0: np.arange(3.0), 1: np.ones((3, 2))})
    >>> out.tolist()
    [[0.0, 1.0, 1.0], [1.0, 1.0, 1.0], [2.0, 1.0, 1.0]]
    """
    placed = [(j, c if c.ndim == 2 else c[:, None]) for j, c in columns.items()]
    step = rows_per_block(out.shape[1])

    def rows(span: tuple[int, int]) -> None:
        for lo in range(span[0], span[1], step):
            hi = min(lo + step, span[1])
            block = out[lo:hi]
            for j, c in placed:
                block[:, j : j + c.shape[1]] = c[lo:hi]

    in_row_halves(rows, len(out), ROWS_AT_ONCE)
