"""Input design (arxid.inputs): PRBS, multisine, chirp, CSV, and the simulator flying a designed input."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.inputs import chirp, crest_factor, multisine, prbs
from arxid.inputs.multisine import schroeder_phases


def _periodic_autocorrelation(x: np.ndarray) -> np.ndarray:
    return np.fft.ifft(np.abs(np.fft.fft(x)) ** 2).real / x.shape[0]


@pytest.mark.parametrize("order", [2, 3, 5, 7, 8, 10, 12, 13, 16, 18])
def test_prbs_is_maximum_length_with_two_valued_autocorrelation(order):
    x = prbs(order, levels=(-2.0, 2.0))
    n = 2**order - 1
    assert x.period == n == x.n_samples
    r = _periodic_autocorrelation(x.values)
    assert r[0] == pytest.approx(4.0)
    np.testing.assert_allclose(r[1:], -4.0 / n, atol=1e-9)  # the two values: a^2 and -a^2/N
    assert int(np.sum(x.values > 0)) == 2 ** (order - 1)  # one more high bit than low
    # no shorter period: the sequence differs from every cyclic shift of itself
    assert all(not np.array_equal(x.values, np.roll(x.values, k)) for k in range(1, min(n, 300)))


def test_prbs_band_levels_and_periods():
    x = prbs(6, band=0.25, levels=(0.1, 0.3), periods=3, ts=0.002)
    assert x.period == 4 * 63 and x.n_samples == 3 * 4 * 63
    assert set(np.unique(x.values)) == {0.1, 0.3}
    np.testing.assert_array_equal(x.values[: x.period], x.values[x.period : 2 * x.period])
    held = x.values[: x.period].reshape(63, 4)
    assert np.all(held == held[:, :1])  # each bit held for 4 samples
    f, p = x.spectrum()
    # held bits: the power falls as sinc^2, zero at 1 / (4 ts) = 125 Hz
    assert p[np.argmin(np.abs(f - 125.0))] < 1e-20 + 1e-3 * p[1:10].max()
    assert p[1:].sum() == pytest.approx(np.var(x.values[: x.period]), rel=1e-9)


def test_prbs_refuses_bad_arguments():
    with pytest.raises(arxid.DataError, match="order must be"):
        prbs(40)
    with pytest.raises(arxid.DataError, match="band"):
        prbs(5, band=1.5)
    with pytest.raises(arxid.DataError, match="levels"):
        prbs(5, levels=(1.0, 1.0))


@pytest.mark.parametrize("period", [256, 500, 2048])
def test_twenty_line_multisine_crest_factor_is_at_most_1_6_and_beats_schroeder(period):
    x = multisine(period, 20, rms=0.5)
    schroeder = multisine(period, 20, rms=0.5, iterations=0)
    assert x.crest_factor <= 1.6
    assert x.crest_factor < schroeder.crest_factor - 0.1
    # Schroeder's phases are what iterations=0 gives (same as the textbook formula)
    k = np.arange(1, 21)
    t = np.arange(period)
    ref = np.sum(np.cos(2 * np.pi * np.outer(t, k) / period + schroeder_phases(20)), axis=1)
    assert schroeder.crest_factor == pytest.approx(crest_factor(ref), rel=1e-9)
    assert np.sqrt(np.mean(x.values**2)) == pytest.approx(0.5)


def test_multisine_power_is_on_the_chosen_lines_only():
    lines = [3, 7, 8, 20, 41]
    x = multisine(200, lines, amplitudes=[1, 1, 2, 1, 0.5], periods=2, ts=0.01)
    f, p = x.spectrum()
    assert sorted(np.flatnonzero(p > 1e-12 * p.max()).tolist()) == lines
    np.testing.assert_allclose(p[lines] / p[3], [1, 1, 4, 1, 0.25], rtol=1e-9)
    np.testing.assert_allclose(f[lines], np.array(lines) / 2.0)
    assert x.n_samples == 400
    with pytest.raises(arxid.DataError, match="lines must be"):
        multisine(200, [0, 5])
    with pytest.raises(arxid.DataError, match="lines must be"):
        multisine(200, [5, 100])


@pytest.mark.parametrize("method", ["linear", "log"])
def test_chirp_sweeps_its_band(method):
    ts, n, f0, f1 = 0.001, 20000, 2.0, 40.0
    x = chirp(n, f0, f1, ts=ts, method=method, amplitude=0.3)
    assert np.max(np.abs(x.values)) == pytest.approx(0.3, rel=1e-3)
    # instantaneous frequency from the zero crossings at a quarter and three quarters of the time
    up = np.flatnonzero((x.values[:-1] < 0) & (x.values[1:] >= 0)) * ts
    freq = 1.0 / np.diff(up)
    mid = up[:-1]
    T = n * ts
    expected = {"linear": lambda t: f0 + (f1 - f0) * t / T, "log": lambda t: f0 * (f1 / f0) ** (t / T)}[method]
    for frac in (0.25, 0.75):
        i = np.argmin(np.abs(mid - frac * T))
        assert freq[i] == pytest.approx(expected(mid[i]), rel=0.03)
    with pytest.raises(arxid.DataError, match="Nyquist"):
        chirp(100, 1.0, 600.0, ts=ts)


def test_csv_reads_back(tmp_path):
    x = multisine(100, [2, 5, 9], ts=0.01, periods=2)
    path = x.to_csv(tmp_path / "roll_sp.csv", name="roll_sp", unit="rad")
    text = path.read_text().splitlines()
    assert text[0] == "time[s],roll_sp[rad]" and len(text) == 201
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1], x.values)  # 17 significant digits: exact
    np.testing.assert_allclose(np.diff(table[:, 0]), 0.01, rtol=1e-9)


def test_simulator_flies_a_designed_roll_reference():
    ts, duration = 0.002, 6.0
    n = round(duration / ts)
    x = prbs(7, band=0.005, levels=(-0.1, 0.1), ts=ts, periods=2)  # bits of 0.4 s
    assert x.n_samples >= n
    d = arxid.datasets.quadrotor_flight(seed=3, duration=duration, roll_reference=x)
    np.testing.assert_array_equal(d.extra["roll_ref"], x.values[:n])
    # the attitude loop follows the designed setpoint, about 0.3 s behind
    r = x.values[:n]
    best = max(np.corrcoef(d.y[500 + lag :], r[500 : n - lag])[0, 1] for lag in range(0, 300, 25))
    assert best > 0.85
    with pytest.raises(arxid.DataError, match="roll_reference must hold"):
        arxid.datasets.quadrotor_flight(seed=3, duration=duration, roll_reference=x.values[:100])
