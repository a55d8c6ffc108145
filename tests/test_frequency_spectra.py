"""The Welch cross-spectral matrix of the frequency check against scipy.signal.csd."""

import numpy as np
import pytest
from scipy.signal import csd, get_window

from arxid.checks.frequency import spectra
from arxid.frequency_domain._spectra import hann_window


@pytest.mark.parametrize("nseg", [32, 64, 256, 33])
@pytest.mark.parametrize("seed", [0, 1])
def test_spectra_are_scipys_csd_averaged_over_the_runs(nseg, seed):
    rng = np.random.default_rng(seed)
    n = 24000
    x = np.vstack([rng.standard_normal(n), np.cumsum(rng.standard_normal(n)) * 0.1 + 3.0, rng.standard_normal(n)])
    x[2] += 0.5 * x[0]
    runs = [(0, 5000), (5200, 5200 + 70 * nseg + 5)]  # the first run is longer than a chunk of segments
    f, s, count = spectra(x, runs, 0.01, nseg)
    step = nseg // 2
    want, total = 0.0, 0
    for a, b in runs:
        k = 1 + (b - a - nseg) // step
        seg = x[:, a : a + (k - 1) * step + nseg]
        if nseg % 2 == 0:  # scipy's segments of the run: the same k
            ff, sc = csd(seg[:, None, :], seg[None, :, :], fs=100.0, nperseg=nseg, noverlap=step, axis=-1)
            want = want + sc * k
        total += k
    assert count == total
    if nseg % 2 == 0:
        assert np.allclose(f, ff, rtol=0, atol=0)
        want = np.moveaxis(want / total, -1, 0)
        assert np.allclose(s, want, rtol=1e-12, atol=1e-14 * np.abs(want).max())
    assert np.allclose(s, np.conj(np.swapaxes(s, 1, 2)))


@pytest.mark.parametrize("n", [0, 1, 2, 3, 32, 100, 257, 4096])
def test_the_hann_window_is_scipys_to_the_last_bit(n):
    """The spectra's window, computed without importing scipy.signal: scipy's numbers exactly."""
    assert np.array_equal(hann_window(n), get_window("hann", n)) if n else hann_window(0).size == 0
