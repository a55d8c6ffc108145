"""The low-frequency share of the remaining disturbance against a direct periodogram (numpy rfft).

The share's low bins are summed without a length-n DFT when n is a slow FFT length (a large prime
factor); these tests hold it to the definition: the one-sided periodogram of each experiment's
finite run, bins at or below the split over all bins.
"""

import numpy as np
import pytest

from arxid.diagnosis.disturbance import _low_power, _low_share


def _reference(error, segments, ts, split):
    low = total = 0.0
    for lo, hi in segments:
        e = error[lo:hi]
        ok = np.isfinite(e)
        first, last = int(np.argmax(ok)), len(e) - int(np.argmax(ok[::-1]))
        e = np.where(ok[first:last], e[first:last], 0.0)
        weight = np.ones(len(e) // 2 + 1)
        weight[1 : (len(e) + 1) // 2] = 2.0
        spec = np.abs(np.fft.rfft(e)) ** 2 * weight
        low += spec[np.fft.rfftfreq(len(e), ts) <= split].sum()
        total += spec.sum()
    return low / total


@pytest.mark.parametrize("n", [7, 1000, 1001, 4099, 19 * 5003, 2 * 3 * 5 * 7 * 11 * 13])
@pytest.mark.parametrize("seed", [0, 1])
def test_low_power_is_the_sum_of_the_dft_bins(n, seed):
    rng = np.random.default_rng(seed)
    e = rng.standard_normal(n) + np.cumsum(rng.standard_normal(n)) * 0.05 + 0.3
    x = np.abs(np.fft.fft(e)) ** 2
    for k in sorted({0, 1, 2, n // 7, (n - 1) // 2 - 1, (n - 2) // 2}):
        if 2 * k + 1 >= n:
            continue
        want = x[0] + 2.0 * x[1 : k + 1].sum()
        assert _low_power(e, k) == pytest.approx(want, rel=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_low_share_matches_the_periodogram(seed):
    rng = np.random.default_rng(seed)
    n = 30011  # prime: the slow length the share avoids
    drift = np.cumsum(rng.standard_normal(n)) * 0.01
    e = 0.2 * rng.standard_normal(n) + drift
    e[:3] = np.nan  # leading gap: the run starts at the first finite sample
    e[500:520] = np.nan  # a gap inside counts as 0
    e[-2:] = np.nan
    segments = [(0, 12007), (12007, n)]  # two experiments, one odd and one even run
    for split in [0.0, 0.01, 0.5, 3.0, 49.0, 50.0, 80.0]:
        assert _low_share(e, segments, 0.01, split) == pytest.approx(_reference(e, segments, 0.01, split), rel=1e-11)


def test_low_share_of_a_slow_error_is_near_one_and_of_white_noise_near_the_bandwidth():
    rng = np.random.default_rng(3)
    n = 20011
    white = rng.standard_normal(n)
    assert _low_share(white, [(0, n)], 0.01, 5.0) == pytest.approx(0.1, abs=0.01)
    slow = np.sin(2 * np.pi * 0.2 * 0.01 * np.arange(n)) + 0.01 * white
    assert _low_share(slow, [(0, n)], 0.01, 1.0) > 0.999


def test_largest_prime_factor():
    from arxid.diagnosis.disturbance import _largest_prime_factor

    assert [_largest_prime_factor(n) for n in [1, 2, 9, 12, 97, 1999997, 1999998, 2000000]] == [
        1,
        2,
        3,
        3,
        97,
        105263,
        37,
        5,
    ]
