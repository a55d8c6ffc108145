"""Where the model fails in frequency, and the confidence bands of its curves.

Known answers: a plant with a 25 Hz resonance the model does not have (the band named must hold
25 Hz and stay near it); the true structure (no band); bands against a Monte Carlo reference that
simulates with ``scipy.signal.lfilter`` (not arxid), to 10 %.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.checks.bands import free_run_band, frequency_response, normal_quantile, step_band
from arxid.checks.frequency import frequency_check
from arxid.exceptions import ArxidError, DataError

TS = 0.002
F_RES = 25.0


def _resonance(f0: float = F_RES, zeta: float = 0.03) -> np.ndarray:
    w = 2 * np.pi * f0
    r, th = np.exp(-zeta * w * TS), w * np.sqrt(1 - zeta**2) * TS
    return np.array([1.0, -2 * r * np.cos(th), r * r])


def _plant(seed: int, resonance: bool, n: int = 20000) -> arxid.IOData:
    """A first-order lag 0.05 z⁻¹/(1 − 0.95 z⁻¹) with equation noise (an ARX(1,1,1) plant), plus
    (optionally) a lightly damped 25 Hz mode 0.002 (1 − z⁻²)/A_res (a band-pass: no gain at 0 Hz
    and at the Nyquist frequency)."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter([0, 0.05], [1, -0.95], u) + lfilter([1], [1, -0.95], 0.01 * rng.standard_normal(n))
    if resonance:
        y += lfilter([0.002, 0, -0.002], _resonance(), u)
    return arxid.IOData(y, u, TS, output_name="y", input_names=("u",), output_unit="m", input_units=("V",))


def test_a_resonance_the_model_misses_is_named():
    """The model of the plant without its 25 Hz mode, checked on the plant with it."""
    model = arxid.arx(_plant(1, resonance=False), 1, 1, 1)
    fc = frequency_check(model, _plant(2, resonance=True))
    assert fc.bands, fc.summary
    hit = [b for b in fc.bands if b.low <= F_RES <= b.high]
    assert hit, fc.summary
    assert 5 < hit[0].low and hit[0].high < 100  # around the mode, not over the whole 0.5-250 Hz range
    assert abs(hit[0].worst - F_RES) < 2
    assert fc.summary.startswith("the model misses the data between ")
    assert f"{hit[0].low:.3g} and {hit[0].high:.3g} Hz" in fc.summary


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_the_true_structure_misses_nothing(seed):
    """An ARX plant with the resonance fitted with its own structure: no band."""
    rng = np.random.default_rng(seed)
    n = 20000
    a = np.convolve([1, -0.95], _resonance())
    b = np.convolve([0, 0.05], _resonance()) + np.r_[np.convolve([0, 0.02], [1, -0.95]), 0]
    u = rng.standard_normal(n)
    y = lfilter(b, a, u) + lfilter([1], a, 0.02 * rng.standard_normal(n))
    data = arxid.IOData(y, u, TS)
    fc = frequency_check(arxid.arx(data, 3, 3, 1), data)
    assert fc.bands == ()
    assert fc.summary.startswith("the model matches the data within the uncertainty")
    # and the data's estimate agrees with the model where the input explains the output
    good = fc.coherence > 0.9
    assert good.sum() > 100
    rel = np.abs(fc.data_response[good, 0] - fc.model_response[good, 0]) / np.abs(fc.model_response[good, 0])
    assert np.median(rel) < 0.05


def test_h1_estimate_against_scipy_and_the_true_response():
    """One input: the estimate is scipy's csd/welch ratio, and close to the plant's own B/A."""
    from scipy.signal import csd, freqz, welch

    data = _plant(6, resonance=True)
    model = arxid.arx(data, 1, 1, 1)
    fc = frequency_check(model, data, segment_length=512)
    u, y = data.u[1:, 0], data.y[1:]  # the free run (whose error is tested) starts at sample 1
    f, puy = csd(u, y, fs=1 / TS, nperseg=512)
    _, puu = welch(u, fs=1 / TS, nperseg=512)
    _, pyy = welch(y, fs=1 / TS, nperseg=512)
    np.testing.assert_allclose(fc.frequency, f[1:])
    np.testing.assert_allclose(fc.data_response[:, 0], (puy / puu)[1:], rtol=1e-9)
    np.testing.assert_allclose(fc.coherence, (np.abs(puy) ** 2 / (puu * pyy))[1:], rtol=1e-9)
    _, g1 = freqz([0, 0.05], [1, -0.95], worN=f[1:], fs=1 / TS)
    _, g2 = freqz([0.002, 0, -0.002], _resonance(), worN=f[1:], fs=1 / TS)
    _, gm = freqz(model.b[0], model.a, worN=f[1:], fs=1 / TS)
    np.testing.assert_allclose(fc.model_response[:, 0], gm, rtol=1e-9)
    far = np.abs(fc.frequency - F_RES) > 5  # away from the peak the window's smoothing is small
    assert np.median(np.abs(fc.data_response[far, 0] - (g1 + g2)[far]) / np.abs((g1 + g2)[far])) < 0.05


def test_frequency_check_json_and_errors():
    data = _plant(7, resonance=True, n=4000)
    fc = frequency_check(arxid.arx(data, 1, 1, 1), data)
    d = json.loads(fc.to_json())
    assert set(d) == {"summary", "bands", "frequency_range_hz", "segment_length", "n_averages", "alpha"}
    assert d["bands"] and set(d["bands"][0]) == {"input", "low_hz", "high_hz", "worst_hz", "p_value"}
    assert "misses the data" in str(fc)
    with pytest.raises(DataError, match="gap-free stretch"):
        frequency_check(arxid.arx(data, 1, 1, 1), data[:100], segment_length=256)
    with pytest.raises(ArxidError, match="level"):
        frequency_check(arxid.arx(data, 1, 1, 1), data, alpha=1.5)


# ----------------------------------------------------------------------------------------- bands
@pytest.fixture(scope="module")
def arx221():
    """ARX(2,2,1) with equation noise, fitted on 1500 samples (parameters known to ~1 %)."""
    rng = np.random.default_rng(11)
    n = 1500
    u = rng.standard_normal(n)
    a = [1, -1.5, 0.7]
    y = lfilter([0, 0.5, 0.3], a, u) + lfilter([1], a, 0.3 * rng.standard_normal(n))
    data = arxid.IOData(y, u, 0.01)
    return arxid.arx(data, 2, 2, 1), data


def _reference_draws(model, n_draws=4000, seed=0):
    rng = np.random.default_rng(seed)
    return rng.multivariate_normal(model.parameters_, model.covariance_, n_draws)


def test_step_band_matches_a_monte_carlo_reference(arx221):
    model, _ = arx221
    n = 80
    ref = np.array([lfilter(np.r_[0, th[2:4]], np.r_[1, th[:2]], np.ones(n)) for th in _reference_draws(model)])
    band = step_band(model, n)
    np.testing.assert_allclose(band.response, lfilter(model.b[0], model.a, np.ones(n)), rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(band.sd[1:] / ref.std(axis=0)[1:] - 1)) < 0.10
    z = normal_quantile(0.99)
    np.testing.assert_allclose(band.upper - band.response, z * band.sd)
    mc = step_band(model, n, method="monte-carlo", n_draws=400, seed=1)
    assert np.max(np.abs(mc.sd[1:] / ref.std(axis=0)[1:] - 1)) < 0.10
    lo, hi = np.percentile(ref, [0.5, 99.5], axis=0)
    assert np.max(np.abs(mc.upper[1:] - hi[1:]) / (hi[1:] - lo[1:])) < 0.10


def test_free_run_band_matches_a_monte_carlo_reference(arx221):
    model, data = arx221
    u = data.u[:, 0]
    ref = np.array([lfilter(np.r_[0, th[2:4]], np.r_[1, th[:2]], u) for th in _reference_draws(model, 2000)])
    band = free_run_band(model, data)
    # arxid's free run starts from the measured first outputs; compare once that start has died out
    late = slice(200, None)
    assert np.max(np.abs(band.sd[late] / ref.std(axis=0)[late] - 1)) < 0.10
    assert band.to_dict()["method"] == "first-order" and band.to_dict()["level"] == 0.99


def test_frequency_response_band_matches_a_monte_carlo_reference(arx221):
    model, _ = arx221
    f = np.linspace(0.1, 50, 40)
    g, sd = frequency_response(model, f)
    zinv = np.exp(-2j * np.pi * f * 0.01)
    draws = _reference_draws(model)
    G = np.array([(th[2] * zinv + th[3] * zinv**2) / (1 + th[0] * zinv + th[1] * zinv**2) for th in draws])
    ref = np.sqrt(np.mean(np.abs(G - G.mean(axis=0)) ** 2, axis=0))
    assert np.max(np.abs(sd / ref - 1)) < 0.10


def test_band_arguments_are_checked(arx221):
    model, _ = arx221
    with pytest.raises(ArxidError, match="method"):
        step_band(model, 10, method="bootstrap")
    with pytest.raises(ArxidError, match="level"):
        step_band(model, 10, level=99)
    with pytest.raises(ArxidError, match="n_draws"):
        step_band(model, 10, method="monte-carlo", n_draws=2)


def _polynomial_models():
    """OE (two inputs), BJ and ARMAX fits of a plant with input denominators."""
    rng = np.random.default_rng(3)
    u = rng.standard_normal((4000, 2))
    y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.5], u[:, 0]) + lfilter([0, 0, 0.3], [1, -0.6], u[:, 1])
    y += 0.05 * lfilter([1, 0.4], [1, -0.5], rng.standard_normal(4000))
    d2 = arxid.IOData(y, u, ts=0.02)
    d1 = arxid.IOData(y, u[:, 0], ts=0.02)
    return [
        arxid.oe(d2, [2, 1], [2, 1], [1, 2]),
        arxid.bj(d1, 2, 1, 1, 2, 1),
        arxid.armax(d1, 2, 2, 1, 1),
    ]


@pytest.mark.parametrize("index", range(3))
def test_frequency_response_of_polynomial_models_is_b_over_a_f(index):
    """The response is B_i/(A F_i) of the model's own polynomials (scipy's freqz), and its standard
    deviation is the first-order one from a finite-difference Jacobian over all of θ."""
    from scipy.signal import freqz

    model = _polynomial_models()[index]
    freq = np.array([0.05, 0.5, 2.0, 7.0, 20.0])
    w = 2 * np.pi * freq * model.ts
    for i in range(len(model.nb_)):
        g, sd = frequency_response(model, freq, i)
        num, den = model.input_transfer(i)
        np.testing.assert_allclose(g, freqz(num, den, worN=w)[1], rtol=1e-12, atol=1e-14)
        theta, jac = model.parameters_.copy(), np.empty((len(freq), model.n_params), dtype=complex)
        for k in range(model.n_params):
            h = 1e-7 * max(1.0, abs(theta[k]))
            model.parameters_ = theta.copy()
            model.parameters_[k] += h
            up = freqz(*model.input_transfer(i), worN=w)[1]
            model.parameters_[k] -= 2 * h
            down = freqz(*model.input_transfer(i), worN=w)[1]
            jac[:, k] = (up - down) / (2 * h)
        model.parameters_ = theta
        cov = model.covariance_
        var = np.einsum("fi,ij,fj->f", jac.real, cov, jac.real) + np.einsum("fi,ij,fj->f", jac.imag, cov, jac.imag)
        ref = np.sqrt(var)
        np.testing.assert_allclose(sd, ref, rtol=1e-5)


@pytest.mark.parametrize("effects", [[], ["u1*v"], ["y^2"]])
@pytest.mark.parametrize("gap", [False, True])
def test_a_free_run_band_summed_in_the_core_is_the_band_of_each_pair_of_runs(effects, gap):
    """The core sums the central differences of each pair of free runs: the band of the generic
    path to the bit; a model with an output term, or inputs with a missing sample, take that path."""
    from arxid.checks.bands import _free_run_first_order, response_band

    rng = np.random.default_rng(12)
    n = 2000
    u, v = rng.standard_normal(n), 1.0 + 0.1 * rng.standard_normal(n)
    y = lfilter([0, 0.5, 0.3], [1, -1.5, 0.7], u * v) + 0.05 * rng.standard_normal(n)
    if gap:
        u[1500] = np.nan  # in the validation half
    data = arxid.IOData(y, u, 0.01, extra={"v": v})
    est, val = data.split(0.5)
    model = arxid.arx(est, 2, 2, 1, effects=effects)
    band = free_run_band(model, val)
    generic = response_band(model, lambda m: m.predict(val, None), val.time)
    for got, want in ((band.sd, generic.sd), (band.response, generic.response), (band.upper, generic.upper)):
        assert np.array_equal(got, want, equal_nan=True)
    assert band.n_draws == generic.n_draws and np.isfinite(band.sd[10:]).any()
    in_core = _free_run_first_order(model, val) is not None
    assert in_core == (not gap and "y^2" not in effects)
