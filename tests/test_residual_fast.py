"""The residual tests' correlations of zero-filled series against direct sums (numpy)."""

import numpy as np
import pytest

import arxid
from arxid.checks.correlation import centered, correlation, zeroed_correlation


@pytest.mark.parametrize("seed", [0, 1])
def test_zeroed_correlation_is_the_direct_sum_inside_each_experiment(seed):
    rng = np.random.default_rng(seed)
    n = 70000  # long enough for the blocked sums
    a, b = rng.standard_normal(n), rng.standard_normal(n)
    b[3:] += 0.4 * a[:-3]
    a[[10, 500, 40000]] = np.nan
    segs = [(0, 30000), (30000, n)]
    ac, bc = centered(a), centered(b)
    az, bz = np.nan_to_num(ac), np.nan_to_num(bc)
    lags = np.arange(-25, 26)
    got = zeroed_correlation(az, bz, lags, segs)
    want = np.zeros(len(lags))
    for lo, hi in segs:
        for i, k in enumerate(lags):
            if k >= 0:
                want[i] += np.dot(az[lo + k : hi], bz[lo : hi - k])
            else:
                want[i] += np.dot(az[lo : hi + k], bz[lo - k : hi])
    want /= np.sqrt(np.dot(az, az) * np.dot(bz, bz))
    assert np.allclose(got, want, rtol=1e-12, atol=1e-15)
    assert np.array_equal(got, correlation(ac, bc, lags, segs))
    assert got[lags == -3][0] > 0.3  # b follows a three samples later


def test_residual_tests_see_a_missing_input_and_not_an_unrelated_signal():
    rng = np.random.default_rng(4)
    n = 20000
    u, w, z = rng.standard_normal(n), rng.standard_normal(n), rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.7 * y[t - 1] + u[t - 1] + 0.5 * w[t - 1] + 0.1 * rng.standard_normal()
    y[[100, 9000]] = np.nan
    data = arxid.IOData(y, u, 0.01, extra={"w": w, "z": z})
    r = arxid.residuals(arxid.arx(data, 1, 1, 1), data)
    assert r.cross_p_values["w"] < 1e-6
    assert r.cross_p_values["z"] > 1e-3
