"""The cross products of one series' lags from its lagged products (the AR prewhitening's Gram
matrix) against the matrix of lags formed and multiplied block by block."""

import numpy as np
import pytest

from arxid.models import lagged


def _formed(columns, segments, back, ahead):
    count = [0]
    gram = np.zeros((len(columns), len(columns)))
    for mat in lagged._blocks(columns, segments, back, ahead, count):
        gram += mat.T @ mat
    return gram, count[0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_lags_of_one_series_match_the_formed_matrix(seed):
    rng = np.random.default_rng(seed)
    for _ in range(60):
        n = int(rng.integers(30, 400))
        x = np.cumsum(rng.standard_normal(n)) * 0.1 + rng.standard_normal(n) + 5.0  # raw: not centred
        cuts = sorted(set(rng.integers(1, n, size=int(rng.integers(0, 3))).tolist()))
        bounds = [0, *cuts, n]
        segments = list(zip(bounds[:-1], bounds[1:]))
        back, ahead = int(rng.integers(1, 9)), int(rng.integers(0, 3))
        lags = [int(v) for v in rng.integers(-ahead, back + 1, size=int(rng.integers(1, 6)))]
        columns = [(x, lag) for lag in lags]
        gram, n_rows = lagged.lagged_gram(columns, segments, back, ahead)
        want, want_rows = _formed(columns, segments, back, ahead)
        assert n_rows == want_rows
        np.testing.assert_allclose(gram, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
        assert lagged._lags_of_one_series(columns, segments, back, ahead) is not None


def test_missing_samples_split_the_rows_into_stretches():
    """The rows that read a missing sample drop out, as in the formed matrix: a residual's missing
    first samples, gaps inside, and more gaps than the shortcut takes (the general path)."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal(3000)
    x[:7] = np.nan  # a residual before its first prediction
    x[[77, 78, 500, 2999]] = np.nan
    segments = [(0, 1200), (1200, 3000)]
    for back, ahead, lags in [(2, 0, [1, 2, 0]), (3, 2, [3, -2, 0, 1, -1, 2]), (1, 1, [1]), (3, 2, [3, -2, 0])]:
        columns = [(x, lag) for lag in lags]
        got = lagged._lags_of_one_series(columns, segments, back, ahead)
        # lags with a hole: a row may skip a missing sample between two it reads (the general path)
        assert (got is None) == (len(lags) == 3 and -2 in lags)
        gram, n_rows = lagged.lagged_gram(columns, segments, back, ahead)
        want, want_rows = _formed(columns, segments, back, ahead)
        assert n_rows == want_rows
        np.testing.assert_allclose(gram, want, rtol=1e-12)
    scattered = x.copy()
    scattered[10::40] = np.nan  # 75 gaps: the general path
    columns = [(scattered, 1), (scattered, 0)]
    assert lagged._lags_of_one_series(columns, [(0, 3000)], 1, 0) is None
    gram, n_rows = lagged.lagged_gram(columns, [(0, 3000)], 1)
    want, want_rows = _formed(columns, [(0, 3000)], 1, 0)
    assert n_rows == want_rows
    np.testing.assert_allclose(gram, want, rtol=1e-13)


def test_other_series_or_reads_outside_the_experiment_take_the_general_path():
    rng = np.random.default_rng(4)
    x, z = rng.standard_normal(200), rng.standard_normal(200)
    assert lagged._lags_of_one_series([(z, 1), (x, 0)], [(0, 200)], 1, 0) is None
    assert lagged._lags_of_one_series([(x, 3), (x, 0)], [(0, 200)], 1, 0) is None  # lag 3 > back 1
