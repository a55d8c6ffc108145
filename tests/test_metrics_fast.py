"""Rolling RMS, mean square, peaks and the divergence rule against direct references (numpy, window
by window)."""

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
    # one pass in eight lanes in the core: numpy's pairwise sum to rounding
    assert metrics.mean_square(x) == pytest.approx(np.mean(x * x), rel=1e-14)
    x[[3, 70]] = np.nan
    x[5] = np.inf
    assert metrics.mean_square(x) == pytest.approx(np.mean(x[np.isfinite(x)] ** 2), rel=1e-14)
    assert math.isnan(metrics.mean_square(np.array([np.nan])))
    assert math.isnan(metrics.mean_square(np.zeros(0)))
    assert metrics.mean_square(np.array([1e200, 1.0])) == math.inf  # the square overflows, as in numpy


def test_mean_square_and_peaks_read_any_layout():
    """Strided, two-dimensional, integer and misaligned inputs give what their values give."""
    rng = np.random.default_rng(3)
    m = rng.standard_normal((300, 3))
    m[7, 1] = np.nan
    col = m[:, 1]  # strided view
    finite = col[np.isfinite(col)]
    assert metrics.mean_square(col) == pytest.approx(np.mean(finite**2), rel=1e-14)
    assert metrics.mean_square(m) == pytest.approx(np.mean(m[np.isfinite(m)] ** 2), rel=1e-14)
    assert metrics.mean_square([1, 2, 3]) == pytest.approx(14 / 3)
    raw = np.zeros(8 * 300 + 1, dtype=np.uint8)[1:].view(np.float64)  # misaligned buffer
    raw[:] = col
    assert metrics.mean_square(raw) == metrics.mean_square(col)
    assert metrics.finite_peak(col) == np.max(np.abs(finite))
    col[9] = -np.inf
    assert metrics.finite_peak(col) == np.max(np.abs(col[np.isfinite(col)]))
    assert metrics.finite_peak(np.array([np.nan, np.inf])) == 0.0


def test_divergence_rule_on_missing_and_infinite_predictions():
    y = np.array([1.0, -2.0, np.nan, 0.5])
    limit = metrics.divergence_limit(y)
    assert limit == metrics.DIVERGENCE_FACTOR * 2.0
    assert not metrics.diverged(y, np.array([np.nan, 1.0, -limit, 0.0]))
    assert metrics.diverged(y, np.array([np.nan, 1.0, -limit * 1.001, 0.0]))
    assert metrics.diverged(y, np.array([np.nan, np.inf, 0.0, 0.0]))
    assert not metrics.diverged(y, np.full(4, np.nan))  # no prediction at all: nothing diverged
    # the limit comes from the largest |y| anywhere, not only from the first samples
    long = np.full(10000, 0.1)
    long[-1] = 100.0
    near = np.zeros(10000)
    near[5] = 50.0 * metrics.DIVERGENCE_FACTOR
    assert not metrics.diverged(long, near)
    near[5] = 100.0 * metrics.DIVERGENCE_FACTOR * 1.001
    assert metrics.diverged(long, near)


def test_prediction_rms_is_the_rms_of_the_differences_to_the_bit():
    """The core sums (y - pred)² without forming the differences, in the lanes of ``rms``: the same
    number as the RMS of the array of differences, for any length, missing samples on either side,
    strided inputs, and a difference that overflows."""
    rng = np.random.default_rng(11)
    for n in (0, 1, 7, 8, 9, 63, 1000, 100_003):
        y, pred = rng.standard_normal(2 * n)[::2], 0.5 * rng.standard_normal(n)  # y strided
        if n > 4:
            y[rng.integers(0, n, 3)] = np.nan
            pred[rng.integers(0, n, 3)] = np.nan
        with np.errstate(invalid="ignore"):
            expected = metrics.rms(y - pred)
        got = metrics.prediction_rms(y, pred)
        assert got == expected or (np.isnan(got) and np.isnan(expected)), n
    big = np.array([1e300, 0.0])
    assert metrics.prediction_rms(big, -big) == metrics.rms(big + big)  # (2e300)² overflows: inf
    assert metrics.prediction_rms(np.array([1.0, 2.0]), np.array([np.inf, 0.0])) == np.inf  # diverged


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_percent_is_the_nrmse_fit_over_the_samples_where_both_exist(seed):
    """The core's two passes give 100 (1 − ‖y − ŷ‖ / ‖y − ȳ‖) over the samples where both exist,
    at any scale of the output, with missing samples, and for a scalar prediction."""
    rng = np.random.default_rng(seed)
    for n, scale in [(5, 1.0), (1001, 1e-200), (100_003, 1e150)]:
        y = rng.standard_normal(n) * scale
        pred = y + 0.3 * scale * rng.standard_normal(n)
        pred[0] = np.nan
        y[-1] = np.nan
        both = np.isfinite(y) & np.isfinite(pred)
        yo, po = y[both] / scale, pred[both] / scale
        want = 100 * (1 - np.linalg.norm(yo - po) / np.linalg.norm(yo - yo.mean()))
        assert metrics.fit_percent(y, pred) == pytest.approx(want, rel=1e-12, abs=1e-10)
        finite = y[np.isfinite(y)] / scale
        want = 100 * (1 - np.linalg.norm(finite - 0.5) / np.linalg.norm(finite - finite.mean()))
        assert metrics.fit_percent(y, 0.5 * scale) == pytest.approx(want, rel=1e-12, abs=1e-10)
    y = np.array([1.0, 2.0, 3.0, 4.0])
    assert metrics.fit_percent(y, np.array([1.0, 2.0, np.inf, 4.0])) == -math.inf  # a diverged prediction
    assert metrics.fit_percent(y, y) == 100.0
    assert math.isnan(metrics.fit_percent(y, np.full(4, np.nan)))
