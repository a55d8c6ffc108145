"""write_columns: the blocks of rows (and, for a long matrix, its two halves on two threads) give the
matrix the plain column assignments give."""

from __future__ import annotations

import numpy as np
import pytest

from arxid._base import background, columns


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 40, 41, 100])
def test_blocks_and_halves_write_what_the_column_assignments_write(monkeypatch, n):
    monkeypatch.setattr(columns, "ROWS_AT_ONCE", 4)
    monkeypatch.setattr(background, "ROWS_IN_HALVES", 9)  # small: the two-thread path at these sizes
    rng = np.random.default_rng(n)
    parts = {0: rng.standard_normal(n), 1: rng.standard_normal((n, 3)), 5: rng.standard_normal((n, 2))[:, ::-1]}
    expected = np.full((n, 8), np.nan)
    for j, c in parts.items():
        expected[:, j : j + (c.shape[1] if c.ndim == 2 else 1)] = c if c.ndim == 2 else c[:, None]
    out = np.full((n, 8), np.nan)
    columns.write_columns(out, parts)
    np.testing.assert_array_equal(out, expected)  # column 4 and 7 untouched (NaN) in both


@pytest.mark.parametrize("block_bytes", [1, 64 * 1024, 2**30])
def test_blocks_sized_by_bytes_write_what_the_column_assignments_write(monkeypatch, block_bytes):
    # 1,024 rows a block (the fewest), 1,024 again (64 KiB of 8 columns), or one block of 4,096
    monkeypatch.setattr(columns, "ROWS_AT_ONCE", 4096)
    monkeypatch.setattr(columns, "BLOCK_BYTES", block_bytes)
    assert columns.rows_per_block(8) == (4096 if block_bytes == 2**30 else 1024)
    rng = np.random.default_rng(block_bytes)
    n = 5000
    parts = {0: rng.standard_normal(n), 2: rng.standard_normal((n, 6))}
    out = np.full((n, 8), np.nan)
    columns.write_columns(out, parts)
    np.testing.assert_array_equal(out[:, 0], parts[0])
    np.testing.assert_array_equal(out[:, 2:], parts[2])
    assert np.isnan(out[:, 1]).all()


def test_regressors_written_in_halves_equal_those_written_in_one_pass(monkeypatch):
    """The regressor matrix (lags, input effects, output terms; with missing samples) is the same
    to the bit whether its rows are written in one pass or in two halves on two threads."""
    import arxid
    from arxid.models import regressors
    from arxid.models.effects import compile_effects

    rng = np.random.default_rng(7)
    n = 301
    u, y = rng.standard_normal(n), rng.standard_normal(n)
    u[50] = np.nan
    data = arxid.IOData(y, u, ts=0.1, extra={"vbat": 11 + rng.standard_normal(n)})
    layout = compile_effects(("u1*vbat", "y^2", "sign(dy)"), data, (2,), (1,))
    monkeypatch.setattr(regressors, "_BLOCK_ROWS", 8)
    monkeypatch.setattr(background, "ROWS_IN_HALVES", 10**9)
    whole = regressors.regressor_matrix(data, 2, layout, 3)
    monkeypatch.setattr(background, "ROWS_IN_HALVES", 16)
    halves = regressors.regressor_matrix(data, 2, layout, 3)
    for a, b in zip(whole, halves, strict=True):
        np.testing.assert_array_equal(a, b)
    assert whole[0].shape[1] == 2 + 2 + 2 + 2 and len(whole[2]) < n - 3  # rows near the gap left out
