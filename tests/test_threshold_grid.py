"""The thresholds of a scan are found once per signal of a data set and follow the data."""

import gc
import weakref

import numpy as np

import arxid
from arxid.diagnosis import candidates
from arxid.diagnosis.candidates import signal_thresholds, threshold_grid


def _quantile_grid(x):
    a = np.abs(x[np.isfinite(x)])
    q = np.unique(np.quantile(a, np.linspace(0.05, 0.95, 19)))
    return q[q > 0]


def test_the_grid_of_each_signal_is_its_quantiles_and_kept_while_its_data_live():
    rng = np.random.default_rng(0)
    data = arxid.IOData(
        rng.standard_normal(5000), rng.standard_normal((5000, 2)), 0.01, extra={"v": rng.uniform(0, 3, 5000)}
    )
    first, second = signal_thresholds(data, "u1"), signal_thresholds(data, "u2")
    np.testing.assert_array_equal(first, _quantile_grid(data.u[:, 0]))
    np.testing.assert_array_equal(second, _quantile_grid(data.u[:, 1]))
    np.testing.assert_array_equal(signal_thresholds(data, "v"), threshold_grid(data.extra["v"]))
    first[:] = 0.0  # a caller's copy: the kept grid is not changed through it
    np.testing.assert_array_equal(signal_thresholds(data, "u1"), _quantile_grid(data.u[:, 0]))
    assert set(candidates._GRIDS[data]) == {"u1", "u2", "v"}
    held = weakref.ref(data)
    del data
    gc.collect()
    assert held() is None  # the kept grids do not keep their data alive (their entry goes with them)


def test_a_signal_with_a_single_level_has_no_threshold_to_scan():
    x = np.random.default_rng(1).uniform(-2, 2, 3000)
    np.testing.assert_array_equal(threshold_grid(x), _quantile_grid(x))
    assert threshold_grid(np.ones(3000)).size == 0
