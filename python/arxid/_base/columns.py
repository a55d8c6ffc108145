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

    def rows(span: tuple[int, int]) -> None:
        for lo in range(span[0], span[1], ROWS_AT_ONCE):
            hi = min(lo + ROWS_AT_ONCE, span[1])
            block = out[lo:hi]
            for j, c in placed:
                block[:, j : j + c.shape[1]] = c[lo:hi]

    in_row_halves(rows, len(out), ROWS_AT_ONCE)
