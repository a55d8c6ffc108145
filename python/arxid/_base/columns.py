"""Columns written into a row-major matrix a block of rows at a time.

The Rust core reads its inputs row-major (sample by sample). A column written alone into such a
matrix touches every row, so each column is one more pass over the whole matrix; a block of rows
with all its columns stays in cache while they are written, so the matrix is written once.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

__all__ = ["write_columns"]

#: Rows per block: the block of every column stays in the processor's cache.
ROWS_AT_ONCE = 1 << 14


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
    for lo in range(0, len(out), ROWS_AT_ONCE):
        block = out[lo : lo + ROWS_AT_ONCE]
        for j, c in placed:
            block[:, j : j + c.shape[1]] = c[lo : lo + ROWS_AT_ONCE]
