"""A block tested with an offset beside it gives the test of the block with a column of ones."""

import numpy as np
import pytest

from arxid.diagnosis.added_variable import AddedVariableTest, all_finite, held_columns, lagged_view


def _data(seed, n=20000):
    rng = np.random.default_rng(seed)
    phi = rng.standard_normal((n, 4))
    x = 0.3 + rng.standard_normal(n + 3)  # a signal with a mean: its lags carry an offset
    y = phi @ [0.5, -1.0, 0.2, 0.1] + 0.05 * np.abs(x[3:]) + 0.4 + 0.1 * rng.standard_normal(n)
    return phi, y, x


def _ones(z):
    return np.column_stack([z, np.ones(len(z))])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_offset_blocks_match_the_blocks_with_a_column_of_ones(seed):
    phi, y, x = _data(seed)
    n = len(y)
    test = AddedVariableTest(phi, y)
    blocks = [lagged_view(np.abs(x), 3, 3, n), np.abs(x[3:])[:, None], lagged_view(x**2, 3, 2, n)]
    got = test.tests(blocks, offset=True)
    want = test.tests([_ones(z) for z in blocks])
    for (g, gw), (w, ww) in zip(got, want, strict=True):
        assert gw == ww == ""
        assert g.n_columns == w.n_columns
        assert g.score == pytest.approx(w.score, rel=1e-9)
        assert g.f_statistic == pytest.approx(w.f_statistic, rel=1e-9)
        assert g.p_value == pytest.approx(w.p_value, rel=1e-6, abs=1e-300)
    # the offset matters here: without it the scores differ
    plain = test.tests(blocks)
    assert all(abs(p.score - g.score) > 1e-3 for (p, _), (g, _) in zip(plain, got, strict=True))


def test_an_offset_already_in_the_model_or_the_block_takes_the_exact_path():
    phi, y, x = _data(3)
    n = len(y)
    with_const = AddedVariableTest(np.column_stack([phi, np.ones(n)]), y)
    constant_block = np.full((n, 1), 2.0)
    for test, z in ((with_const, np.abs(x[3:])[:, None]), (AddedVariableTest(phi, y), constant_block)):
        (g, gw), (w, ww) = test.tests([z], offset=True)[0], test.test(_ones(z))
        assert gw == ww
        assert (g is None) == (w is None)
        if g is not None:
            assert g.n_columns == w.n_columns
            assert g.score == pytest.approx(w.score, rel=1e-9)


def test_a_lagged_view_holds_one_column_of_memory_a_matrix_its_width():
    """The scoring's groups are bounded by the memory their blocks hold: the lags of one signal are
    a view of it (one column), a formed matrix holds every column."""
    x = np.arange(100.0)
    assert held_columns(lagged_view(x, 5, 4, 90)) == 1
    assert held_columns(np.ones((90, 4))) == 4
    assert held_columns(np.ones((90, 1))) == 1
    assert held_columns(np.ones((90, 0))) == 0
    assert held_columns(np.ones((90, 4))[:, ::2]) == 2  # a strided matrix is copied when read


def test_all_finite_reads_a_lagged_view_as_the_samples_it_spans():
    """A missing or infinite sample anywhere a lagged view reads (its first and last samples, the
    corners only one column reaches) is found; samples just outside it are not read."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        n_rows, width = int(rng.integers(1, 40)), int(rng.integers(1, 6))
        first = int(rng.integers(width - 1, width + 5))
        x = rng.standard_normal(first + n_rows + int(rng.integers(0, 4)))
        x[int(rng.integers(0, len(x)))] = rng.choice([np.nan, np.inf, -np.inf])
        z = lagged_view(x, first, width, n_rows)
        assert all_finite(z) == bool(np.isfinite(z).all())
        assert all_finite(np.ascontiguousarray(z)) == bool(np.isfinite(z).all())
    x = np.arange(10.0)
    x[[0, 9]] = np.nan  # outside the view of samples 1..8
    assert all_finite(lagged_view(x, 3, 3, 6)) and not all_finite(lagged_view(x, 2, 3, 7))
    assert all_finite(np.zeros((0, 3))) and not all_finite(np.array([[1.0], [np.nan]]))
