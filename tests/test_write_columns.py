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


@pytest.mark.parametrize("n", [301, 40_000])  # the core writes a long matrix on all cores
@pytest.mark.parametrize("signs", [True, False])
def test_regressors_written_by_the_core_equal_numpys_columns(n, signs):
    """The regressor matrix the core writes row by row (lags, input effects, output terms with and
    without a carrier; missing samples) is, to the bit, the one numpy's columns give, with the same
    rows left out."""
    import arxid
    from arxid.models import regressors
    from arxid.models.effects import compile_effects

    rng = np.random.default_rng(7)
    u, y = rng.standard_normal(n), 2.0 * rng.standard_normal(n)
    u[50] = np.nan
    y[120:123] = np.nan
    y[200] = 0.0  # sign(0) is 0, as numpy's
    data = arxid.IOData(y, u, ts=0.1, extra={"vbat": 11 + rng.standard_normal(n)})
    effects = ("u1*vbat", "y^2", "y^5", "sign(dy)", "abs(y)", "sign(y)*u1", "y^3*vbat")
    layout = compile_effects(effects, data, (2,), (1,))
    phi, yy, rows = regressors.regressor_matrix(data, 2, layout, 3, signs=signs)
    every = regressors.regression_rows(data, 3)
    expected = regressors.regressor_columns(data, 2, layout, every, list(range(phi.shape[1])))
    if not signs:
        expected[:, :2] *= -1.0
    ok = np.isfinite(expected).all(axis=1) & np.isfinite(y[every])
    assert phi.tobytes() == expected[ok].tobytes()
    np.testing.assert_array_equal(rows, every[ok])
    assert yy.tobytes() == y[every[ok]].tobytes()
    assert 0 < len(every) - len(rows) < 20  # rows near the gaps left out


def test_regressors_written_into_the_first_columns_leave_the_others():
    import arxid
    from arxid.models import regressors
    from arxid.models.effects import compile_effects

    rng = np.random.default_rng(3)
    data = arxid.IOData(rng.standard_normal(50), rng.standard_normal(50), ts=0.1)
    layout = compile_effects(("y^3",), data, (1,), (0,))
    rows = np.arange(2, 50)
    out = np.full((48, 6), np.nan)
    finite = regressors.write_regressors(out, data, 1, layout, rows)
    assert finite.all() and np.isnan(out[:, 3:]).all()
    np.testing.assert_array_equal(out[:, :3], regressors.regressor_columns(data, 1, layout, rows, [0, 1, 2]))
