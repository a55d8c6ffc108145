"""arxid.frf: the frequency response from data, against known discrete plants simulated with
scipy.signal.lfilter (not arxid), against scipy's own Welch spectra, and against a loop-form
reimplementation of MATLAB spa's formula.

Known answers: within 0.5 dB and 3° of the true plant where the coherence exceeds 0.9, in open loop
and in closed loop with a reference (a PI loop with coloured output noise, where the naive u→y
estimate is shown biased); the band holds the true response about as often as it says.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.signal import coherence, csd, freqz, lfilter, welch

import arxid
from arxid.exceptions import ArxidError, DataError, IdentifiabilityError

TS = 0.01
B = np.array([0.0, 0.2, 0.1])  # plant: a sample of delay, poles 0.8 ± 0.3j
A = np.array([1.0, -1.6, 0.73])


def _true(freq: np.ndarray, b: np.ndarray = B, a: np.ndarray = A) -> np.ndarray:
    return freqz(b, a, worN=freq, fs=1.0 / TS)[1]


def _errors(fr: arxid.FrequencyResponse, g: np.ndarray, i: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gain error [dB], phase error [deg] and the frequencies with coherence > 0.9."""
    h = fr.response[:, i]
    good = fr.coherence > 0.9
    return np.abs(20 * np.log10(np.abs(h / g))), np.abs(np.degrees(np.angle(h / g))), good


def _open_loop(seed: int, n: int = 2**15, noise: float = 0.05) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    v = lfilter([1.0], [1.0, -0.9], rng.standard_normal(n)) * noise
    return arxid.IOData(lfilter(B, A, u) + v, u, ts=TS)


def _pi_loop(seed: int, n: int = 2**15, noise: float = 1.0, pole: float = 0.99, gains=(0.3, 0.1)) -> arxid.IOData:
    """y = G u + v (v coloured), u = PI(r − y); r white. Returns y, u and r (extra 'r')."""
    rng = np.random.default_rng(seed)
    r = 10.0 * rng.standard_normal(n)
    v = lfilter([1.0], [1.0, -pole], rng.standard_normal(n)) * noise
    kp, ki = gains
    x = np.zeros(n)  # plant output without noise
    y, u = np.zeros(n), np.zeros(n)
    e_prev = 0.0
    for t in range(n):
        if t >= 2:
            x[t] = 1.6 * x[t - 1] - 0.73 * x[t - 2] + 0.2 * u[t - 1] + 0.1 * u[t - 2]
        elif t == 1:
            x[t] = 1.6 * x[0] + 0.2 * u[0]
        y[t] = x[t] + v[t]
        e = r[t] - y[t]
        u[t] = (u[t - 1] if t else 0.0) + kp * (e - e_prev) + ki * e
        e_prev = e
    return arxid.IOData(y, u, ts=TS, extra={"r": r})


@pytest.fixture(scope="module")
def closed_loops() -> list[arxid.IOData]:
    return [_pi_loop(seed, noise=0.3) for seed in range(6)]


@pytest.mark.parametrize("seed", range(8))
def test_welch_within_half_a_db_and_3_degrees_where_coherent(seed):
    fr = arxid.frf(_open_loop(seed), segment_length=256)
    db, deg, good = _errors(fr, _true(fr.frequency))
    assert good.sum() > 0.5 * good.size
    assert db[good].max() < 0.5
    assert deg[good].max() < 3.0


@pytest.mark.parametrize("seed", range(4))
def test_blackman_tukey_within_half_a_db_and_3_degrees_where_coherent(seed):
    fr = arxid.frf(_open_loop(seed), method="blackman-tukey", lag_width=100)
    db, deg, good = _errors(fr, _true(fr.frequency))
    assert fr.frequency.size == 128 and fr.resolution == 100
    assert good.sum() > 0.5 * good.size
    assert db[good].max() < 0.5
    assert deg[good].max() < 3.0


def test_blackman_tukey_default_width_is_spas_rule():
    assert arxid.frf(_open_loop(0, n=2000), method="blackman-tukey").resolution == 30
    assert arxid.frf(_open_loop(0, n=250), method="blackman-tukey").resolution == 25


def test_blackman_tukey_is_spas_formula_in_loop_form():
    """R(τ) = 1/N Σ x(t) y(t+τ) with each mean removed, Φ(ω) = Σ_{|τ|≤M} W(τ) R(τ) e^{−iωτ}, W the Hann lag window."""
    data = _open_loop(3, n=600)
    m = 20
    fr = arxid.frf(data, method="blackman-tukey", lag_width=m, n_frequencies=16)
    y, u = data.y - data.y.mean(), data.u[:, 0] - data.u[:, 0].mean()
    n = len(y)

    def cov(x, z, tau):  # 1/N Σ_t x(t) z(t + τ)
        if tau >= 0:
            return sum(x[t] * z[t + tau] for t in range(n - tau)) / n
        return sum(x[t] * z[t + tau] for t in range(-tau, n)) / n

    for k, f in enumerate(fr.frequency):
        w = 2 * np.pi * f * TS
        phi_uu = phi_uy = 0.0
        for tau in range(-m, m + 1):
            lag = 0.5 * (1 + np.cos(np.pi * tau / m))
            phi_uu += lag * cov(u, u, tau) * np.exp(-1j * w * tau)
            phi_uy += lag * cov(u, y, tau) * np.exp(-1j * w * tau)
        assert fr.response[k, 0] == pytest.approx(phi_uy / phi_uu, rel=1e-10)


@pytest.mark.parametrize("nseg", [64, 256])
def test_h1_and_coherence_are_scipys_on_the_same_segments(nseg):
    data = _open_loop(1, n=10000)
    fr = arxid.frf(data, segment_length=nseg)
    y, u = data.y, data.u[:, 0]
    f, s_uy = csd(u, y, fs=1 / TS, nperseg=nseg, noverlap=nseg // 2)
    _, s_uu = welch(u, fs=1 / TS, nperseg=nseg, noverlap=nseg // 2)
    _, coh = coherence(u, y, fs=1 / TS, nperseg=nseg, noverlap=nseg // 2)
    np.testing.assert_array_equal(fr.frequency, f[1:])
    np.testing.assert_allclose(fr.response[:, 0], (s_uy / s_uu)[1:], rtol=1e-12)
    np.testing.assert_allclose(fr.coherence, coh[1:], rtol=1e-12)


def test_nan_gaps_and_experiments_drop_the_segments_they_touch():
    """A NaN gap and an experiment start: H1 is the segment-weighted average of scipy's spectra of each
    gap-free run (a segment never holds a NaN nor crosses a start)."""
    data = _open_loop(2, n=12000)
    y = data.y.copy()
    y[3000:3010] = np.nan
    gapped = arxid.IOData(y, data.u, ts=TS, experiment_starts=[0, 8000])
    nseg = 128
    fr = arxid.frf(gapped, segment_length=nseg)
    s_uy = s_uu = 0.0
    for a, b in [(0, 3000), (3010, 8000), (8000, 12000)]:
        k = 1 + (b - a - nseg) // (nseg // 2)
        stop = a + (k - 1) * nseg // 2 + nseg
        s_uy = s_uy + k * csd(data.u[a:stop, 0], y[a:stop], nperseg=nseg, noverlap=nseg // 2)[1]
        s_uu = s_uu + k * welch(data.u[a:stop, 0], nperseg=nseg, noverlap=nseg // 2)[1]
    np.testing.assert_allclose(fr.response[:, 0], (s_uy / s_uu)[1:], rtol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_closed_loop_reference_estimate_is_right_where_the_naive_one_is_biased(closed_loops, seed):
    """Where the coherence exceeds 0.9, S_ry / S_ru is within 0.5 dB and 3°. Below 1 Hz the feedback of
    the coloured noise dominates u, and S_uy / S_uu tends to −1/C: off by more than 6 dB, while the
    true response stays inside the reference-based estimate's 99 % band."""
    data = closed_loops[seed]
    fr = arxid.frf(data, reference="r", segment_length=256)
    naive = arxid.frf(data, segment_length=256)
    g = _true(fr.frequency)
    db, deg, good = _errors(fr, g)
    assert fr.reference == ("r",) and good.sum() > 0.3 * good.size
    assert db[good].max() < 0.5
    assert deg[good].max() < 3.0
    low = fr.frequency < 1.0
    naive_db, _, _ = _errors(naive, g)
    assert naive_db[low].max() > 6.0
    assert np.all(np.abs(fr.response[low, 0] - g[low]) <= fr.band_radius[low, 0])


def test_the_band_holds_the_true_response_as_often_as_it_says(closed_loops):
    """Open and closed loop: the 90 % disc holds the true response at 80–97 % of the frequencies."""
    inside, total = 0, 0
    for seed in range(4):
        for fr in (
            arxid.frf(_open_loop(seed, noise=2.0), segment_length=256, confidence=0.9),
            arxid.frf(closed_loops[seed], reference="r", segment_length=256, confidence=0.9),
        ):
            err = np.abs(fr.response[:, 0] - _true(fr.frequency))
            inside += int(np.sum(err <= fr.band_radius[:, 0]))
            total += fr.frequency.size
    assert 0.80 < inside / total < 0.97


def test_relative_error_is_bendat_and_piersols_in_open_loop():
    fr = arxid.frf(_open_loop(0, noise=1.0), segment_length=256)
    g2 = fr.coherence
    np.testing.assert_allclose(fr.relative_error[:, 0], np.sqrt((1 - g2) / (2 * fr.n_averages * g2)), rtol=1e-9)
    lo, hi = fr.magnitude_band_db
    assert np.all(lo[:, 0] <= fr.magnitude_db[:, 0]) and np.all(hi[:, 0] >= fr.magnitude_db[:, 0])
    assert np.all((fr.phase_band_deg > 0) & (fr.phase_band_deg <= 180))


def test_two_inputs_give_each_plant():
    """Each response is the partial one (the other input held), within 0.5 dB and 3° where its error is small."""
    rng = np.random.default_rng(5)
    n = 2**15
    u = rng.standard_normal((n, 2))
    b2, a2 = np.array([0.0, 0.5]), np.array([1.0, -0.5])
    y = lfilter(B, A, u[:, 0]) + lfilter(b2, a2, u[:, 1]) + 0.05 * rng.standard_normal(n)
    fr = arxid.frf(arxid.IOData(y, u, ts=TS), segment_length=256)
    for i, (b, a) in enumerate([(B, A), (b2, a2)]):
        db, deg, _ = _errors(fr, _true(fr.frequency, b, a), i)
        good = fr.relative_error[:, i] < 0.02  # the multiple coherence speaks for both inputs together
        assert good.sum() > 0.5 * good.size
        assert db[good].max() < 0.5 and deg[good].max() < 3.0
    assert fr.response.shape == (fr.frequency.size, 2)


def test_text_and_json():
    fr = arxid.frf(_open_loop(0), segment_length=256)
    text = str(fr)
    assert "Welch H1, 256-sample Hann segments" in text and "coherence above 0.9" in text
    d = json.loads(fr.to_json())
    assert d["method"] == "welch" and len(d["inputs"]["u1"]["magnitude_db"]) == fr.frequency.size
    assert d["frequency_hz"][0] == pytest.approx(fr.frequency[0])


def test_bad_input_gives_typed_errors():
    data = _open_loop(0, n=2000)
    with pytest.raises(DataError, match="IOData"):
        arxid.frf(np.zeros(100))
    with pytest.raises(ArxidError, match="method must be"):
        arxid.frf(data, method="etfe")
    with pytest.raises(ArxidError, match="confidence"):
        arxid.frf(data, confidence=99)
    with pytest.raises(DataError, match="no signal named"):
        arxid.frf(data, reference="setpoint")
    with pytest.raises(DataError, match="output or an input"):
        arxid.frf(data, reference="u1")
    two = arxid.IOData(data.y, np.column_stack([data.u, data.u[::-1]]), ts=TS, extra={"r": data.y})
    with pytest.raises(DataError, match="one reference per input"):
        arxid.frf(two, reference="r")
    with pytest.raises(DataError, match="gap-free stretch"):
        arxid.frf(data, segment_length=4096)
    with pytest.raises(IdentifiabilityError, match="constant"):
        arxid.frf(arxid.IOData(data.y, np.ones(2000), ts=TS))
    with pytest.raises(DataError, match="width M"):
        arxid.frf(arxid.IOData(data.y[:15], data.u[:15], ts=TS), method="blackman-tukey")
