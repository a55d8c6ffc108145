"""Output-error, ARMAX and Box–Jenkins models by prediction-error minimisation (issue 11).

Known answers: seeded plants with exact parameters, the frequency response of the true plant,
coverage of 3-standard-error intervals, and scipy's ``least_squares`` on the same prediction error.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import signal

import arxid
from arxid.exceptions import ConvergenceError, IdentifiabilityError, OrderError

# The issue's plant: G = (0.5 z^-3 + 0.3 z^-4) / (1 - 1.5 z^-1 + 0.7 z^-2).
B_TRUE = [0, 0, 0, 0.5, 0.3]
F_TRUE = [1, -1.5, 0.7]


def issue_plant(seed: int, noise: float = 0.2, n: int = 10_000) -> arxid.IOData:
    """Binary input, output noise at ``noise`` times the output's std."""
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n))
    x = signal.lfilter(B_TRUE, F_TRUE, u)
    return arxid.IOData(x + noise * np.std(x) * rng.standard_normal(n), u, ts=1.0)


def frequency_error(num, den) -> float:
    """max|H − G| / max|G| over (0, π]."""
    w = np.linspace(1e-4, np.pi, 4000)
    _, g = signal.freqz(B_TRUE, F_TRUE, w)
    _, h = signal.freqz(num, den, w)
    return float(np.max(np.abs(h - g)) / np.max(np.abs(g)))


def model_frequency_error(model) -> float:
    num, den = arxid.convert.tf_coefficients(model)
    return frequency_error(num[0], den)


# ----------------------------------------------------------------------------- output error
@pytest.mark.parametrize("seed", range(3))
def test_oe_with_the_right_orders_recovers_the_plant_where_arx_does_not(seed):
    est, _ = issue_plant(seed).split(0.5)
    model = arxid.oe(est, 2, 2, 3)
    assert model.kind == "OE" and model.converged_
    assert model_frequency_error(model) < 0.03
    assert model_frequency_error(arxid.arx(est, 2, 2, 3)) > 0.2  # the issue measured 44 %
    assert model.dc_gain()[0] == pytest.approx(4.0, rel=0.03)
    # getpvec order: B then F, with the delay's zeros and F's leading one left out.
    np.testing.assert_allclose(model.parameters_, [0.5, 0.3, -1.5, 0.7], atol=4 * model.standard_errors_.max())


def test_oe_reaches_the_minimum_scipy_least_squares_finds():
    from scipy.optimize import least_squares

    est, _ = issue_plant(7).split(0.5)
    model = arxid.oe(est, 2, 2, 3)
    y, u, lag = est.y, est.u[:, 0], model.first_lag_

    def errors(th):
        return (y - signal.lfilter(np.r_[0, 0, 0, th[:2]], np.r_[1, th[2:]], u))[lag:]

    ref = least_squares(errors, np.array([0.1, 0.1, -1.0, 0.5]), method="lm")
    assert model.rss_ <= float(np.sum(ref.fun**2)) * (1 + 1e-9)
    np.testing.assert_allclose(model.parameters_, ref.x, atol=1e-5)


def lightly_damped(ts: float, noise: float, n: int, seed: int = 0):
    """ω0/2π = 20 Hz, ζ = 0.02, zero-order-hold sampled; white input; output noise variance."""
    w0 = 2 * np.pi * 20.0
    num, den, _ = signal.cont2discrete(([w0**2], [1, 2 * 0.02 * w0, w0**2]), ts, method="zoh")
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    x = signal.lfilter(np.ravel(num), den, u)
    sigma = noise * np.std(x)
    return arxid.IOData(x + sigma * rng.standard_normal(n), u, ts=ts), sigma**2


@pytest.mark.parametrize(("ts", "noise", "n"), [(1e-3, 0.02, 10_000), (1e-3, 0.17, 10_000), (1e-4, 0.02, 20_000)])
def test_lightly_damped_mode_reaches_the_noise_floor(ts, noise, n):
    data, variance = lightly_damped(ts, noise, n)
    model = arxid.oe(data, 2, 2, 1)
    assert model.loss_ == pytest.approx(variance, rel=0.05)
    # Least squares alone (the ARX estimate used as the OE parameters) is far from it.
    arx = arxid.arx(data, 2, 2, 1)
    ls_start = np.r_[arx.parameters_[2:], arx.parameters_[:2]]
    e = data.y - signal.lfilter(np.r_[0, ls_start[:2]], np.r_[1, ls_start[2:]], data.u[:, 0])
    if noise < 0.1:
        assert np.mean(e[model.first_lag_ :] ** 2) > 1.5 * variance


def test_delayest_recovers_the_delay_under_output_noise():
    est, _ = issue_plant(3).split(0.5)
    assert arxid.delayest(est, nkmax=10) == 3


def test_refined_sweep_ranks_a_small_model_with_the_right_response_first():
    data = issue_plant(1)
    grid = dict(na=range(1, 9), nb=range(1, 11), nk=range(0, 6), validation=0.5, progress=False)
    refined = arxid.sweep(data, **grid, refine="oe", refine_top=3)
    assert isinstance(refined, arxid.RefinedSweep)
    assert refined.sweep.n_params[0] > 6  # the plain ARX sweep compensates with many parameters
    best = refined.rows[0]
    assert best.n_params <= 6 and best.model_class == "OE"
    assert model_frequency_error(best.model) < 0.03
    assert {r.model_class for r in refined.rows} == {"ARX", "OE"}
    assert "class" in refined.table()
    with pytest.raises(arxid.ArxidError, match="refine"):
        arxid.sweep(data, na=2, nb=2, nk=3, refine="bj", progress=False)


# ----------------------------------------------------------------------------- ARMAX and BJ coverage
A_TRUE, B2, C_TRUE = [1, -1.5, 0.7], [0, 1.0, 0.5], [1, -0.8, 0.2]
D_BJ, C_BJ = [1, -0.9], [1, 0.5]


def _coverage(fit, truth, make, runs: int = 40) -> np.ndarray:
    inside = []
    for seed in range(runs):
        model = fit(make(np.random.default_rng(1000 + seed)))
        inside.append(np.abs(model.parameters_ - truth) <= 3 * model.standard_errors_)
    return np.mean(inside, axis=0)


def test_armax_parameters_and_noise_model_within_three_standard_errors():
    def make(rng):
        u, e = np.sign(rng.standard_normal(1000)), 0.5 * rng.standard_normal(1000)
        y = signal.lfilter(B2, A_TRUE, u) + signal.lfilter(C_TRUE, A_TRUE, e)
        return arxid.IOData(y, u, ts=1.0)

    truth = np.r_[A_TRUE[1:], B2[1:], C_TRUE[1:]]
    cover = _coverage(lambda d: arxid.armax(d, 2, 2, 2, 1), truth, make)
    assert np.all(cover >= 0.95), cover


def test_bj_parameters_and_noise_model_within_three_standard_errors():
    def make(rng):
        u, e = np.sign(rng.standard_normal(1000)), 0.5 * rng.standard_normal(1000)
        y = signal.lfilter(B2, A_TRUE, u) + signal.lfilter(C_BJ, D_BJ, e)
        return arxid.IOData(y, u, ts=1.0)

    truth = np.r_[B2[1:], C_BJ[1:], D_BJ[1:], A_TRUE[1:]]
    cover = _coverage(lambda d: arxid.bj(d, 2, 1, 1, 2, 1), truth, make)
    assert np.all(cover >= 0.95), cover


# ----------------------------------------------------------------------------- the model surface
def test_predictors_use_the_noise_model():
    rng = np.random.default_rng(5)
    u, e = np.sign(rng.standard_normal(3000)), 0.5 * rng.standard_normal(3000)
    y = signal.lfilter(B2, A_TRUE, u) + signal.lfilter(C_TRUE, A_TRUE, e)
    data = arxid.IOData(y, u, ts=1.0)
    model = arxid.armax(data, 2, 2, 2, 1)
    one, free = model.predict(data, 1), model.predict(data, None)
    ok = np.isfinite(one)
    # One-step errors are the innovations, e (up to the start-up transient and estimation error).
    assert np.std((y - one)[ok][100:] - e[ok][100:]) < 0.1
    assert np.std((y - free)[ok]) > 1.3 * np.std((y - one)[ok])
    # k-step predictions lie between (they converge to the free run as k grows).
    mid = model.rms(data, 3)
    assert model.rms(data, 1) < mid < model.rms(data, None)
    # Free run equals simulate from rest.
    np.testing.assert_allclose(free[ok], model.simulate(u)[ok], atol=1e-9)


def test_model_surface_round_trip_and_converters():
    est, val = issue_plant(2).split(0.5)
    model = arxid.bj(est, 2, 1, 1, 2, 3)
    text = str(model)
    assert text.startswith("Discrete-time BJ model: y(t) = [B(z)/F(z)]u(t) + [C(z)/D(z)]e(t)")
    assert "F(z) = 1 - 1.5" in text
    loaded = arxid.PolynomialModel.from_json(model.to_json())
    np.testing.assert_array_equal(loaded.parameters_, model.parameters_)
    np.testing.assert_allclose(loaded.predict(val, 2), model.predict(val, 2), equal_nan=True)
    dlti = model.to_scipy()
    _, h = signal.dfreqz(dlti, worN=[0.5]) if hasattr(signal, "dfreqz") else dlti.freqresp(w=[0.5])
    _, g = signal.freqz(*model.input_transfer(0), worN=[0.5])
    np.testing.assert_allclose(h, g, rtol=1e-9)
    assert np.sort(np.abs(model.poles())) == pytest.approx(np.sqrt([0.7, 0.7]), rel=0.02)
    assert model.fpe_ > model.loss_ and np.isfinite(model.aic_) and np.isfinite(model.bic_)
    cmp = arxid.compare({"oe": arxid.oe(est, 2, 2, 3), "arx": arxid.arx(est, 2, 2, 3)}, val)
    assert cmp.fit_percent[0] > cmp.fit_percent[1]
    white = arxid.residuals(model, val)  # the noise model whitens the one-step residual
    assert white.n_samples > 4900 and white.ljung_box_p_value > 0.001
    fails = arxid.where_it_fails(model, val)
    assert fails.rms == pytest.approx(model.rms(val, None), rel=1e-9)


def test_to_control_matches_the_polynomials():
    control = pytest.importorskip("control")
    est, _ = issue_plant(4).split(0.5)
    model = arxid.oe(est, 2, 2, 3)
    tf = model.to_control()
    assert isinstance(tf, control.TransferFunction)
    assert control.dcgain(tf) == pytest.approx(model.dc_gain()[0], rel=1e-9)
    assert control.dcgain(model.to_control(continuous=True)) == pytest.approx(model.dc_gain()[0], rel=1e-6)


def test_missing_samples_and_experiments_split_the_runs():
    data = issue_plant(6, n=6000)
    y = data.y.copy()
    y[2000:2010] = np.nan
    holed = arxid.IOData(y, data.u, ts=1.0, experiment_starts=(0, 4000))
    model = arxid.oe(holed, 2, 2, 3)
    assert model.n_rows_ == 6000 - 10 - 3 * model.first_lag_
    assert model_frequency_error(model) < 0.03
    assert np.isnan(model.predict(holed, 1)[2000 : 2010 + model.first_lag_]).all()


# ----------------------------------------------------------------------------- typed errors
def test_typed_errors():
    data = issue_plant(0, n=2000)
    with pytest.raises(IdentifiabilityError, match="constant"):
        arxid.oe(arxid.IOData(data.y, np.ones(2000), ts=1.0), 2, 2, 3)
    with pytest.raises(OrderError, match="nb = 0"):
        arxid.oe(data, 0, 2, 3)
    with pytest.raises(OrderError):
        arxid.oe(data, -1, 2, 3)
    with pytest.raises(arxid.DataError, match="too few samples"):
        arxid.oe(arxid.IOData(data.y[:8], data.u[:8], ts=1.0), 2, 2, 3)
    with pytest.raises(IdentifiabilityError):
        # A sine excites two parameters only: OE(3,3) is not identifiable from it.
        t = np.arange(2000)
        arxid.oe(arxid.IOData(np.sin(0.3 * t + 0.4), np.sin(0.3 * t), ts=1.0), 3, 3, 1)
    # Orders above the plant's: the extra pole and zero cancel, so they are not determined.
    noise_free = arxid.IOData(signal.lfilter(B_TRUE, F_TRUE, data.u[:, 0]), data.u, ts=1.0)
    with pytest.raises(IdentifiabilityError, match=r"OE\(3,3,3\).*orders may be too high"):
        arxid.oe(noise_free, 3, 3, 3)
    # A noise model asked of noise-free data.
    with pytest.raises(IdentifiabilityError, match="noise-free"):
        arxid.armax(noise_free, 2, 2, 1, 3)
    with pytest.raises(ConvergenceError, match="not finite"):
        arxid.oe(data, 2, 2, 3, start=[np.nan, 0.0, -1.0, 0.5])
    with pytest.raises(arxid.NotFittedError):
        _ = arxid.PolynomialModel(nb=2, nf=2, nk=3).parameters_


def test_non_convergence_warns_with_the_reason():
    data = issue_plant(0, n=2000)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = arxid.oe(data, 2, 2, 3, start=[0.1, 0.1, -0.5, 0.1], max_iterations=1)
    assert not model.converged_ and "iteration limit" in model.termination_
    assert any(issubclass(w.category, arxid.ArxidWarning) and "iteration limit" in str(w.message) for w in caught)


def test_warn_false_keeps_the_outcome_and_drops_only_the_warning():
    data = issue_plant(0, n=2000)
    start = [0.1, 0.1, -0.5, 0.1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning fails the fit
        quiet = arxid.oe(data, 2, 2, 3, start=start, max_iterations=1, warn=False)
    with pytest.warns(arxid.ArxidWarning, match="iteration limit"):
        loud = arxid.oe(data, 2, 2, 3, start=start, max_iterations=1)
    assert not quiet.converged_ and quiet.termination_ == loud.termination_
    np.testing.assert_array_equal(quiet.parameters_, loud.parameters_)


# ----------------------------------------------------------------------------- real data
def _scipy_oe_loss(data: arxid.IOData, model, start) -> float:
    """Loss a plain ``scipy.optimize.least_squares`` OE fit reaches on the samples arxid scores."""
    from scipy.optimize import least_squares

    nb, nk, lag = model.nb_[0], model.nk_[0], model.first_lag_

    def errors(th):
        return (data.y - signal.lfilter(np.r_[np.zeros(nk), th[:nb]], np.r_[1, th[nb:]], data.u[:, 0]))[lag:]

    return float(np.mean(least_squares(errors, start).fun ** 2))


@pytest.mark.realdata
def test_real_data_oe_loss_no_higher_than_scipy_least_squares(shared_data):
    """Silverbox (estimation part) and the DaISy heating system: SIPPY is not installed here, so the
    reference is scipy's least_squares from the same ARX-refined start and from a plain one."""
    raw = np.genfromtxt(shared_data / "silverbox" / "SNLS80mV.csv", delimiter=",", skip_header=1, usecols=(0, 1))
    u, y = raw[40650:60650, 0], raw[40650:60650, 1]
    silver = arxid.IOData(y - y.mean(), u - u.mean(), 1 / 610.35)
    heat = np.loadtxt(shared_data / "daisy-heating" / "heating_system.dat")
    heating = arxid.IOData(heat[:, 2] - heat[:, 2].mean(), heat[:, 1] - heat[:, 1].mean(), 2.0)
    for data, orders in [(silver, (2, 2, 1)), (heating, (2, 2, 1))]:
        model = arxid.oe(data, *orders)
        for start in (model.start_parameters_, np.r_[np.zeros(orders[0]), -0.5, 0.1][: model.n_params]):
            assert model.loss_ <= _scipy_oe_loss(data, model, start) * (1 + 1e-6)


# ----------------------------------------------------------------------------- general structure
def test_polyest_with_both_a_and_f_recovers_every_polynomial():
    """A y = B/F u + C e (MATLAB polyest [1 2 1 0 2 1]): A's pole is shared by input and noise."""
    a, b, f, c = [1, -0.8], [0, 1.0, 0.5], [1, -1.2, 0.5], [1, 0.4]

    def make(rng):
        u, e = np.sign(rng.standard_normal(1000)), 0.3 * rng.standard_normal(1000)
        y = signal.lfilter(b, np.convolve(a, f), u) + signal.lfilter(c, a, e)
        return arxid.IOData(y, u, ts=1.0)

    truth = np.r_[a[1:], b[1:], c[1:], f[1:]]
    cover = _coverage(lambda d: arxid.polyest(d, 1, 2, 1, 0, 2, 1), truth, make)
    assert np.all(cover >= 0.95), cover
    data = make(np.random.default_rng(0))
    model = arxid.polyest(data, 1, 2, 1, 0, 2, 1)
    assert model.kind == "polynomial" and model.structure_name() == "poly(1,2,1,0,2,1)"
    assert str(model).startswith("Discrete-time polynomial model: A(z)y(t) = [B(z)/F(z)]u(t) + [C(z)/D(z)]e(t)")
    # The input path is B/(A F): free run and simulate agree, the poles are A's and F's.
    free = model.predict(data, None)
    ok = np.isfinite(free)
    np.testing.assert_allclose(free[ok], model.simulate(data.u)[ok], atol=1e-9)
    assert np.sort(np.abs(model.poles())) == pytest.approx(np.sort(np.abs(np.r_[np.roots(a), np.roots(f)])), abs=0.03)
