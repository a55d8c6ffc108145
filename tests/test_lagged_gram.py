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


def test_a_missing_sample_or_a_second_series_takes_the_general_path():
    rng = np.random.default_rng(3)
    x, z = rng.standard_normal(200), rng.standard_normal(200)
    x[77] = np.nan
    columns = [(x, 1), (x, 2), (x, 0)]
    assert lagged._lags_of_one_series(columns, [(0, 200)], 2, 0) is None
    gram, n_rows = lagged.lagged_gram(columns, [(0, 200)], 2)
    want, want_rows = _formed(columns, [(0, 200)], 2, 0)
    assert n_rows == want_rows == 198 - 3  # the rows reading sample 77 drop out
    np.testing.assert_allclose(gram, want, rtol=1e-13)
    assert lagged._lags_of_one_series([(z, 1), (x, 0)], [(0, 200)], 1, 0) is None
