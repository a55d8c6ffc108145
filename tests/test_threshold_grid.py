"""The thresholds of a scan are computed once per read-only signal and follow the data."""

import gc

import numpy as np

import arxid
from arxid.diagnosis import candidates
from arxid.diagnosis.candidates import threshold_grid


def _quantile_grid(x):
    a = np.abs(x[np.isfinite(x)])
    q = np.unique(np.quantile(a, np.linspace(0.05, 0.95, 19)))
    return q[q > 0]


def test_the_grid_of_each_signal_is_its_quantiles_and_kept_while_its_data_live():
    rng = np.random.default_rng(0)
    data = arxid.IOData(rng.standard_normal(5000), rng.standard_normal((5000, 2)), 0.01)
    first, second = threshold_grid(data.u[:, 0]), threshold_grid(data.u[:, 1])
    np.testing.assert_array_equal(first, _quantile_grid(data.u[:, 0]))
    np.testing.assert_array_equal(second, _quantile_grid(data.u[:, 1]))
    first[:] = 0.0  # a caller's copy: the kept grid is not changed through it
    np.testing.assert_array_equal(threshold_grid(data.u[:, 0]), _quantile_grid(data.u[:, 0]))
    assert id(data.u) in candidates._GRIDS
    key = id(data.u)
    del data
    gc.collect()
    assert key not in candidates._GRIDS


def test_a_writable_signal_is_read_each_time():
    x = np.random.default_rng(1).uniform(-2, 2, 3000)
    before = threshold_grid(x)
    x *= 2.0
    np.testing.assert_allclose(threshold_grid(x), 2.0 * before)
    x[:] = 1.0  # a single level: no threshold to scan
    assert threshold_grid(x).size == 0
