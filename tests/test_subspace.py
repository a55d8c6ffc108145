"""Subspace identification (arxid.ssest): exact recovery, the three weightings, prediction,
conversion, and the complaints of SIPPY and nfoursid users as regression tests."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.exceptions import DataError, IdentifiabilityError, OrderError
from subspace_systems import System, add_noise, as_data, binary_inputs, random_system

TRUE = System(
    a=np.array([[0.8, 0.3, 0.0], [-0.3, 0.8, 0.0], [0.0, 0.0, 0.5]]),
    b=np.array([[1.0, 0.0], [0.0, 0.5], [0.7, -1.0]]),
    c=np.array([[1.0, 0.0, 1.0], [0.0, 2.0, -0.5]]),
    d=np.array([[0.1, 0.0], [0.0, -0.2]]),
)


def markov(a, b, c, d, k):
    return d if k == 0 else c @ np.linalg.matrix_power(a, k - 1) @ b


@pytest.fixture(scope="module")
def exact():
    rng = np.random.default_rng(1)
    u = binary_inputs(rng, 1500, 2)
    return u, TRUE.simulate(u, x0=[2.0, -1.0, 0.5])


@pytest.mark.parametrize("method", ["n4sid", "moesp", "cva"])
def test_noise_free_data_give_the_true_markov_parameters_order_and_initial_response(exact, method):
    u, y = exact
    model = arxid.ssest(as_data(y, u), method=method)
    assert model.order == 3 and not model.order_fixed
    for k in range(8):
        np.testing.assert_allclose(
            markov(model.a, model.b, model.c, model.d, k), markov(*vars(TRUE).values(), k), atol=1e-8
        )
    # The record starts mid-transient: the estimated x0 reproduces the data exactly.
    np.testing.assert_allclose(model.simulate(u, model.x0), y, atol=1e-8)
    assert model.canonical_correlations[2] > 0.999 and model.canonical_correlations[3] < 1e-3


def test_the_transfer_function_agrees_with_python_control(exact):
    control = pytest.importorskip("control")
    u, y = exact
    model = arxid.ssest(as_data(y, u), method="moesp")
    sys_true = control.ss(TRUE.a, TRUE.b, TRUE.c, TRUE.d, dt=0.01)
    freqs = np.array([0.5, 3.0, 12.0, 40.0])
    want = sys_true.frequency_response(2 * np.pi * freqs).complex  # (ny, nu, nf)
    got = model.to_control().frequency_response(2 * np.pi * freqs).complex
    np.testing.assert_allclose(got, want, atol=1e-8)
    np.testing.assert_allclose(np.moveaxis(model.frequency_response(freqs), 0, -1), want, atol=1e-8)
    scipy_model = model.to_scipy()
    np.testing.assert_allclose(scipy_model.A, model.a)
    assert scipy_model.dt == 0.01


def test_a_fixed_order_is_kept_sippy_64(exact):
    u, y = exact
    model = arxid.ssest(as_data(y, u), order=5)
    assert model.order == 5 and model.order_fixed and "fixed by the caller" in str(model)


def test_the_callers_arrays_are_unchanged_sippy_67(exact):
    u, y = exact
    u_before, y_before = u.copy(), y.copy()
    y_col = np.ascontiguousarray(y[:, 0])
    data = [arxid.IOData(y_col, u, ts=0.01, output_name="a"), arxid.IOData(y[:, 1].copy(), u, ts=0.01, output_name="b")]
    model = arxid.ssest(data, stable=True)
    model.predict(data, k=3)
    model.simulate(u)
    np.testing.assert_array_equal(u, u_before)
    np.testing.assert_array_equal(y, y_before)
    np.testing.assert_array_equal(y_col, y_before[:, 0])


def test_siso_is_a_special_case_nfoursid_pr10():
    rng = np.random.default_rng(3)
    sys1 = System(
        np.array([[1.5, -0.7], [1.0, 0.0]]), np.array([[1.0], [0.0]]), np.array([[0.5, 0.3]]), np.zeros((1, 1))
    )
    u = binary_inputs(rng, 2000, 1)
    y = sys1.simulate(u)
    model = arxid.ssest(arxid.IOData(y[:, 0], u[:, 0], ts=0.1))
    assert model.order == 2 and model.n_inputs == 1 and model.n_outputs == 1
    np.testing.assert_allclose(np.sort_complex(model.poles), np.sort_complex(np.linalg.eigvals(sys1.a)), atol=1e-8)


def test_several_experiments_and_nan_gaps_nfoursid_5():
    rng = np.random.default_rng(4)
    runs = []
    for x0 in ([1.0, 0.0, 0.0], [0.0, 3.0, -1.0], [-2.0, 0.0, 1.0]):
        u = binary_inputs(rng, 600, 2)
        runs.append((u, TRUE.simulate(u, x0)))
    u = np.vstack([r[0] for r in runs])
    y = np.vstack([r[1] for r in runs])
    y[1500, 0] = np.nan  # a gap splits the third experiment into two stretches
    data = as_data(y, u, experiment_starts=(0, 600, 1200))
    model = arxid.ssest(data, method="cva")
    assert model.order == 3 and model.initial_states.shape == (4, 3)
    for k in range(6):
        np.testing.assert_allclose(
            markov(model.a, model.b, model.c, model.d, k), markov(*vars(TRUE).values(), k), atol=1e-7
        )
    fits = model.fit_percent(data)
    assert fits.shape == (2,) and np.all(fits > 99.999)


def multisine(n: int, freqs: np.ndarray, phase_seed: int) -> np.ndarray:
    phases = np.random.default_rng(phase_seed).uniform(0, 2 * np.pi, len(freqs))
    t = np.arange(n)
    return np.sum(np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None]), axis=0)


def test_a_sine_rich_input_sippy_8():
    # Each input a sum of 25 sines at its own frequencies: rich enough for the horizons.
    n = 4000
    u = np.column_stack([multisine(n, np.linspace(0.01, 0.45, 25) + 0.003 * i, i) for i in range(2)])
    y = TRUE.simulate(u)
    model = arxid.ssest(as_data(y, u))
    assert model.order == 3
    np.testing.assert_allclose(np.sort_complex(model.poles), np.sort_complex(np.linalg.eigvals(TRUE.a)), atol=1e-8)
    assert np.all(model.fit_percent(as_data(y, u)) > 99.99)


def test_a_few_sines_are_refused_with_a_reason_not_returned_as_nan():
    # Six sines shared by both inputs: the future inputs span all the data, nothing is left to
    # identify the state from (a likely cause of SIPPY #8's "very far off" results).
    n = 3000
    u = np.column_stack([multisine(n, np.array([0.013, 0.041, 0.077, 0.12, 0.19, 0.31]), i) for i in range(2)])
    with pytest.raises(IdentifiabilityError, match="not rich enough"):
        arxid.ssest(as_data(TRUE.simulate(u), u), order=3)


def test_a_non_minimum_phase_zero_does_not_make_the_model_unstable_sippy_16():
    # G(z) = (z − 1.5) / ((z − 0.8)(z − 0.6)): a zero outside the unit circle, stable poles.
    rng = np.random.default_rng(16)
    sys1 = System(
        np.array([[1.4, -0.48], [1.0, 0.0]]), np.array([[1.0], [0.0]]), np.array([[1.0, -1.5]]), np.zeros((1, 1))
    )
    u = binary_inputs(rng, 4000, 1)
    y = add_noise(rng, sys1.simulate(u), 20)
    for method in ("n4sid", "moesp", "cva"):
        model = arxid.ssest(arxid.IOData(y[:, 0], u[:, 0], ts=1.0), order=2, method=method)
        assert model.is_stable
        zeros = np.roots(np.poly(model.a - model.b @ model.c / model.d[0, 0])) if model.d[0, 0] else None
        g = model.to_scipy()
        num, _den = __import__("scipy").signal.ss2tf(g.A, g.B, g.C, g.D)
        z = np.roots(np.trim_zeros(num[0], "f"))
        assert np.min(np.abs(z - 1.5)) < 0.1, (method, z, zeros)


def test_stable_true_reflects_unstable_poles_and_refits():
    rng = np.random.default_rng(8)
    u = binary_inputs(rng, 400, 1)
    # An unstable plant (pole 1.02) identified with stability enforced comes out stable.
    sys1 = System(np.array([[1.02]]), np.array([[0.1]]), np.array([[1.0]]), np.zeros((1, 1)))
    y = sys1.simulate(u) + rng.normal(size=(400, 1)) * 0.01
    free = arxid.ssest(arxid.IOData(y[:, 0], u[:, 0], ts=1.0), order=1)
    forced = arxid.ssest(arxid.IOData(y[:, 0], u[:, 0], ts=1.0), order=1, stable=True)
    assert not free.is_stable and forced.is_stable
    assert abs(forced.poles[0] - 0.995 / free.poles[0]) < 1e-12


def test_k_step_prediction_of_a_noisy_system_improves_on_simulation():
    # Noise through the plant's own dynamics (ARMAX-like): the Kalman gain helps prediction.
    rng = np.random.default_rng(5)
    n = 4000
    u = binary_inputs(rng, n, 1)
    e = rng.normal(size=n) * 0.3
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + u[t - 1, 0] + 0.5 * u[t - 2, 0] + e[t] - 0.2 * e[t - 1]
    data = arxid.IOData(y, u[:, 0], ts=1.0)
    model = arxid.ssest(data, order=2)
    one, five, sim = (model.fit_percent(data, k=k)[0] for k in (1, 5, np.inf))
    assert one > five > sim
    # One-step predictions against the ideal predictor's error e(t).
    resid = y - model.predict(data, k=1)[:, 0]
    assert np.std(resid[50:]) < 1.05 * np.std(e[50:])
    # k = 1 prediction equals the predictor recursion written out in numpy (from a zero state).
    ak, bk = model.a - model.k @ model.c, np.hstack([model.b - model.k @ model.d, model.k])
    x = np.zeros(2)
    manual = np.empty(n)
    for t in range(n):
        manual[t] = (model.c @ x + model.d @ u[t])[0]
        x = ak @ x + bk @ np.concatenate([u[t], [y[t]]])
    np.testing.assert_allclose(model.predict(data, k=1, initial="zero")[:, 0], manual, atol=1e-9)


def test_bad_arguments_are_typed_errors(exact):
    u, y = exact
    data = as_data(y, u)
    with pytest.raises(OrderError, match="method"):
        arxid.ssest(data, method="pca")
    with pytest.raises(OrderError, match="order"):
        arxid.ssest(data, order=0)
    with pytest.raises(OrderError, match="order 30"):
        arxid.ssest(data, order=30)
    with pytest.raises(OrderError, match="horizon"):
        arxid.ssest(data, horizon=(3, 1))
    with pytest.raises(DataError, match="longer than"):
        arxid.ssest(as_data(y[:30], u[:30]))
    with pytest.raises(DataError, match="other input samples"):
        arxid.ssest([data[0], arxid.IOData(y[:, 1], -u, ts=0.01, output_name="b")])
    with pytest.raises(DataError, match="IOData"):
        arxid.ssest(np.zeros(10))
    model = arxid.ssest(data)
    with pytest.raises(DataError, match="shape"):
        model.simulate(np.zeros((10, 3)))
    with pytest.raises(DataError, match="horizon"):
        model.predict(data, k=0)


def test_noisy_random_mimo_system_fits_like_the_true_one():
    rng = np.random.default_rng(11)
    true = random_system(rng, 4, 2, 3)
    u = binary_inputs(rng, 4000, 2)
    y = add_noise(rng, true.simulate(u), 20)
    model = arxid.ssest(as_data(y[:3000], u[:3000]))
    assert model.order == 4
    val = as_data(y[3000:], u[3000:])
    true_fit = [arxid._base.metrics.fit_percent(y[3000:, i], true.simulate(u)[3000:, i]) for i in range(3)]
    assert np.all(model.fit_percent(val) > np.array(true_fit) - 1.0)


def test_a_time_series_without_inputs_gives_its_innovation_model():
    # ARMA(1,1): y(t) = 0.9 y(t-1) + e(t) + 0.5 e(t-1), so A = 0.9 and C K = 0.9 + 0.5 in any coordinates.
    rng = np.random.default_rng(5)
    e = rng.normal(size=20_000)
    y = np.zeros(20_000)
    for t in range(1, 20_000):
        y[t] = 0.9 * y[t - 1] + e[t] + 0.5 * e[t - 1]
    model = arxid.ssest(arxid.IOData(y, np.zeros((20_000, 0)), ts=1.0), order=1)
    assert model.b.shape == (1, 0) and abs(model.a[0, 0] - 0.9) < 0.02
    assert abs((model.c @ model.k)[0, 0] - 1.4) < 0.05
