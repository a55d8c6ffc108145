"""Rolling RMS and mean square against direct references (numpy, window by window)."""

import math

import numpy as np
import pytest

from arxid._base import metrics


@pytest.mark.parametrize("seed", [0, 1])
def test_rolling_rms_is_the_rms_of_each_centred_window(seed):
    rng = np.random.default_rng(seed)
    for n in [1, 2, 7, 60, 301]:
        x = rng.standard_normal(n) * 3.0
        x[rng.random(n) < 0.15] = np.nan
        for w in sorted({1, 2, 3, 4, 9, n}):
            if w > n:
                continue
            got = metrics.rolling_rms(x, w)
            for i in range(n):
                part = x[max(0, i - w // 2) : min(n, i + (w - 1) // 2 + 1)]
                part = part[np.isfinite(part)]
                if len(part) < max(1, w // 2):
                    assert math.isnan(got[i])
                else:
                    # cumulative sums: rounding of the order of eps · Σx² in each window's sum
                    assert got[i] == pytest.approx(math.sqrt(np.mean(part**2)), rel=1e-9, abs=1e-6)


def test_mean_square_over_the_finite_samples():
    rng = np.random.default_rng(2)
    x = rng.standard_normal(1000)
    assert metrics.mean_square(x) == np.mean(x * x)
    x[[3, 70]] = np.nan
    x[5] = np.inf
    assert metrics.mean_square(x) == np.mean(x[np.isfinite(x)] ** 2)
    assert math.isnan(metrics.mean_square(np.array([np.nan])))
    assert math.isnan(metrics.mean_square(np.zeros(0)))
