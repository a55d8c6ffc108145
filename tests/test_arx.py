"""ARX fitting: exact recovery, agreement with numpy.linalg.lstsq, statistics, simulation."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.models.effects import compile_effects
from arxid.models.regressors import regressor_matrix
from conftest import simulate_arx


def lstsq_reference(data, na, nb, nk, effects=(), first_lag=0):
    m = data.n_inputs
    nb = [nb] * m if np.isscalar(nb) else list(nb)
    nk = [nk] * m if np.isscalar(nk) else list(nk)
    layout = compile_effects(effects, data, nb, nk)
    phi, y, _ = regressor_matrix(data, na, layout, first_lag)
    theta, *_ = np.linalg.lstsq(phi, y, rcond=None)
    return theta, phi, y


@pytest.mark.parametrize("nk", range(0, 11))
def test_noise_free_siso_recovered_exactly_for_every_delay(nk):
    rng = np.random.default_rng(nk)
    u = rng.standard_normal(1500)
    a, b = [-1.3, 0.45], [0.8, -0.3]
    y = simulate_arx(a, [b], [nk], u)
    model = arxid.arx(arxid.IOData(y, u, ts=0.01), na=2, nb=2, nk=nk)
    np.testing.assert_allclose(model.parameters_, a + b, rtol=0, atol=1e-11)
    np.testing.assert_allclose(model.a, [1.0] + a, atol=1e-11)
    np.testing.assert_allclose(model.b[0], [0.0] * nk + b, atol=1e-11)
    assert model.rss_ < 1e-18


def test_noise_free_miso_recovered_exactly_with_different_orders():
    rng = np.random.default_rng(1)
    u = rng.standard_normal((3000, 3))
    a = [-0.9, 0.2, 0.05]
    bs = [[1.0], [0.5, 0.25, -0.1], [-2.0, 0.7]]
    nks = [0, 4, 10]
    y = simulate_arx(a, bs, nks, u)
    model = arxid.arx(arxid.IOData(y, u, ts=1.0), na=3, nb=[1, 3, 2], nk=nks)
    np.testing.assert_allclose(model.parameters_, a + sum(bs, []), atol=1e-11)
    assert model.regressor_names_[3] == "u1(t)"
    assert model.regressor_names_[-1] == "u3(t-11)"


def test_matches_lstsq_on_well_conditioned_noisy_data():
    rng = np.random.default_rng(2)
    u = rng.standard_normal((20000, 2))
    y = simulate_arx([-1.2, 0.5], [[1.0, 0.5], [0.3]], [1, 3], u, noise=0.3 * rng.standard_normal(20000))
    data = arxid.IOData(y, u, ts=0.1)
    model = arxid.arx(data, na=2, nb=[2, 1], nk=[1, 3])
    ref, phi, yr = lstsq_reference(data, 2, [2, 1], [1, 3])
    np.testing.assert_allclose(model.parameters_, ref, rtol=1e-10)
    rss = np.sum((yr - phi @ ref) ** 2)
    assert model.rss_ == pytest.approx(rss, rel=1e-10)
    assert model.n_rows_ == len(yr)
    # Covariance: σ² (ΦᵀΦ)⁻¹ with σ² = RSS / (N − p).
    cov = rss / (len(yr) - 5) * np.linalg.inv(phi.T @ phi)
    np.testing.assert_allclose(model.covariance_, cov, rtol=1e-8)
    np.testing.assert_allclose(model.standard_errors_, np.sqrt(np.diag(cov)), rtol=1e-8)
    n, p, loss = len(yr), 5, rss / len(yr)
    assert model.loss_ == pytest.approx(loss, rel=1e-10)
    assert model.fpe_ == pytest.approx(loss * (1 + p / n) / (1 - p / n), rel=1e-10)
    assert model.aic_ == pytest.approx(n * np.log(loss) + 2 * p + n * (np.log(2 * np.pi) + 1), rel=1e-10)
    assert model.bic_ == pytest.approx(n * np.log(loss) + p * np.log(n) + n * (np.log(2 * np.pi) + 1), rel=1e-10)
    pred = phi @ ref
    fit = 100 * (1 - np.linalg.norm(yr - pred) / np.linalg.norm(yr - yr.mean()))
    assert model.fit_percent_ == pytest.approx(fit, rel=1e-9)


def roll_axis_closed_loop(n=50_000, seed=4):
    """Seed 004's roll axis, 1 − 1.959 z⁻¹ + 0.9567 z⁻² (one pole outside the unit circle), nk = 8,
    ts = 2 ms, stabilised by a PD attitude loop so the data stay bounded, excited by a pilot signal."""
    rng = np.random.default_rng(seed)
    b = 4.222e-8
    kp, kd = 0.006, 0.075
    r = np.repeat(rng.standard_normal(n // 50 + 1), 50)[:n] * 2e5 + rng.standard_normal(n) * 2e4
    y = np.zeros(n)
    u = np.zeros(n)
    e = 1e-5 * rng.standard_normal(n)
    for t in range(n):
        acc = e[t]
        if t >= 1:
            acc += 1.959 * y[t - 1]
        if t >= 2:
            acc -= 0.9567 * y[t - 2]
        if t >= 8:
            acc += b * u[t - 8]
        y[t] = acc
        u[t] = r[t] - (kp * y[t] + kd * (y[t] - (y[t - 1] if t else 0.0))) / b
    return arxid.IOData(y, u, ts=0.002, output_name="roll", input_names=["roll_torque"])


def test_matches_lstsq_on_ill_conditioned_near_integrator_roll_axis():
    data = roll_axis_closed_loop()
    model = arxid.arx(data, na=2, nb=1, nk=8)
    ref, phi, _ = lstsq_reference(data, 2, 1, 8)
    assert np.linalg.cond(phi) > 1e6  # normal equations would square this
    np.testing.assert_allclose(model.parameters_, ref, rtol=1e-7)
    np.testing.assert_allclose(model.parameters_, [-1.959, 0.9567, 4.222e-8], rtol=2e-3)
    assert "4.222e-08" in str(model) and "1 - 1.959 z^-1 + 0.9567 z^-2" in str(model)
    assert not model.is_stable


def test_free_run_simulation_equals_python_control_forced_response():
    control = pytest.importorskip("control")
    rng = np.random.default_rng(5)
    u = rng.standard_normal((400, 2))
    y = simulate_arx([-1.5, 0.7], [[0.5, 0.2], [0.1]], [2, 0], u, noise=0.05 * rng.standard_normal(400))
    model = arxid.arx(arxid.IOData(y, u, ts=0.05), na=2, nb=[2, 1], nk=[2, 0])
    sim = model.simulate(u)
    tfs = model.to_control()
    assert [tf.dt for tf in tfs] == [0.05, 0.05]
    t = np.arange(400) * 0.05
    ref = sum(np.squeeze(control.forced_response(tf, T=t, U=u[:, i]).outputs) for i, tf in enumerate(tfs))
    np.testing.assert_allclose(sim, ref, rtol=0, atol=1e-9 * np.abs(sim).max())
    step = model.step(50)
    resp = control.step_response(tfs[0], T=np.arange(50) * 0.05)
    np.testing.assert_allclose(step, np.squeeze(resp.outputs), atol=1e-12)


def test_predict_horizons_are_consistent():
    rng = np.random.default_rng(6)
    u = rng.standard_normal(2000)
    y = simulate_arx([-1.6, 0.64], [[0.2]], [3], u, noise=0.1 * rng.standard_normal(2000))
    data = arxid.IOData(y, u, ts=1.0)
    model = arxid.arx(data, na=2, nb=1, nk=3)
    one = model.predict(data, horizon=1)
    theta, phi, yr = lstsq_reference(data, 2, 1, 3)
    np.testing.assert_allclose(one[3:], phi @ model.parameters_, atol=1e-12)
    # k-step prediction by brute force at one sample.
    k, t = 7, 1500
    yh = list(y[: t - k + 1])
    for tau in range(t - k + 1, t + 1):
        yh.append(-model.a[1] * yh[tau - 1] - model.a[2] * yh[tau - 2] + model.b[0][3] * u[tau - 3])
    assert model.predict(data, horizon=k)[t] == pytest.approx(yh[t], rel=1e-12)
    free = model.predict(data)
    assert np.isnan(free[:3]).all() and np.isfinite(free[3:]).all()
    assert model.rms(data, 1) < model.rms(data, k) < model.rms(data) * 1.01


def test_effect_terms_are_simulated_on_the_simulated_output():
    # Cubic spring: y(t) = 1.6 y1 - 0.8 y2 - 0.5 y1^3 + 0.1 u(t-1)
    rng = np.random.default_rng(7)
    n = 3000
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.6 * y[t - 1] - 0.8 * y[t - 2] - 0.5 * y[t - 1] ** 3 + 0.1 * u[t - 1]
    data = arxid.IOData(y, u, ts=1.0)
    model = arxid.arx(data, 2, 1, 1, effects=["y^3"])
    np.testing.assert_allclose(model.parameters_, [-1.6, 0.8, 0.1, -0.5], atol=1e-10)
    free = model.predict(data)
    np.testing.assert_allclose(free[2:], y[2:], atol=1e-8)
    assert "y^3" in model.to_json()
    assert model.effect_parameters["y^3"][0] == pytest.approx(-0.5, abs=1e-10)


def test_input_effect_uses_lags_of_its_input_and_matches_lstsq():
    rng = np.random.default_rng(8)
    n = 4000
    u = rng.uniform(0.5, 2.0, n)
    vbat = 4.0 - np.linspace(0, 0.6, n) + 0.01 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(3, n):
        y[t] = 0.7 * y[t - 1] + 0.3 * u[t - 2] * vbat[t - 2] + 0.2 * u[t - 2] ** 2 + 0.01 * rng.standard_normal()
    data = arxid.IOData(y, u, ts=1.0, input_names=["w"], extra={"vbat": vbat})
    model = arxid.arx(data, 1, 1, 2, effects=["w*vbat", "w^2"])
    ref, *_ = lstsq_reference(data, 1, 1, 2, effects=["w*vbat", "w^2"])
    np.testing.assert_allclose(model.parameters_, ref, rtol=1e-10)
    np.testing.assert_allclose(model.parameters_[1:], [0.0, 0.3, 0.2], atol=0.02)
    assert "w*vbat(t-2)" in model.regressor_names_


def test_nan_rows_are_left_out_and_counted():
    rng = np.random.default_rng(9)
    u = rng.standard_normal(1000)
    y = simulate_arx([-0.5], [[1.0]], [1], u)
    y[500] = np.nan
    u[700] = np.nan
    data = arxid.IOData(y, u, ts=1.0)
    model = arxid.arx(data, 1, 1, 1)
    np.testing.assert_allclose(model.parameters_, [-0.5, 1.0], atol=1e-12)
    # y[500] touches rows 500 (output) and 501 (lag 1); u[700] touches row 701.
    assert model.n_skipped_ == 3
    assert model.n_rows_ == 999 - 3
    assert "3 rows skipped" in str(model)


def test_merged_experiments_never_straddle_a_boundary():
    rng = np.random.default_rng(10)
    parts = []
    for k in range(3):
        u = rng.standard_normal(500)
        y = simulate_arx([-0.8, 0.15], [[1.0, 0.5]], [2], u) + 100.0 * k  # offsets break cross-boundary rows
        y -= 100.0 * k
        parts.append(arxid.IOData(y, u, ts=0.5))
    merged = arxid.IOData.merge(parts)
    assert merged.experiment_starts == (0, 500, 1000)
    model = arxid.arx(merged, 2, 2, 2)
    np.testing.assert_allclose(model.parameters_, [-0.8, 0.15, 1.0, 0.5], atol=1e-11)
    assert model.n_rows_ == 3 * (500 - 3)
    # Concatenating without merge mixes experiments: the fit is no longer exact.
    glued = arxid.IOData(np.concatenate([p.y for p in parts]), np.concatenate([p.u for p in parts]), ts=0.5)
    assert arxid.arx(glued, 2, 2, 2).rss_ > 1e-6


def test_n_threads_do_not_change_the_answer():
    rng = np.random.default_rng(11)
    u = rng.standard_normal(30000)
    y = simulate_arx([-0.9], [[1.0, 0.3]], [1], u, noise=rng.standard_normal(30000))
    data = arxid.IOData(y, u, ts=1.0)
    a = arxid.arx(data, 1, 2, 1, n_threads=1).parameters_
    b = arxid.arx(data, 1, 2, 1, n_threads=0).parameters_
    assert np.array_equal(a, b)


def test_free_run_restarts_after_missing_initial_outputs():
    # The first outputs of the second experiment are missing: the simulation must start once
    # measured outputs are available again, not stay NaN for the whole experiment.
    rng = np.random.default_rng(12)
    parts = []
    for _ in range(2):
        u = rng.standard_normal(400)
        parts.append(arxid.IOData(simulate_arx([-0.7], [[1.0]], [1], u), u, ts=1.0))
    y = parts[1].y.copy()
    y[:3] = np.nan
    parts[1] = arxid.IOData(y, parts[1].u, ts=1.0)
    data = arxid.IOData.merge(parts)
    model = arxid.arx(data, 1, 1, 1)
    free = model.predict(data)
    second = free[400:]
    assert np.isnan(second[:4]).all()
    np.testing.assert_allclose(second[4:], y[4:], atol=1e-9)


def test_compiled_effects_are_kept_per_data_and_equal_a_fresh_compile():
    """The input matrix of the last effect set compiled on a record is kept (read-only) and served
    again; lags still follow each call's nb, nk, and another record gets its own."""
    from arxid.models import effects as fx

    rng = np.random.default_rng(3)
    n = 500
    data = arxid.IOData(rng.standard_normal(n), rng.standard_normal((n, 2)), 0.01, extra={"vbat": 4 + rng.random(n)})
    first = fx.compile_effects(("u1*vbat", "y^2"), data, (2, 1), (1, 3))
    again = fx.compile_effects(("u1*vbat", "y^2"), data, (3, 2), (0, 1))
    assert again.u is first.u and not first.u.flags.writeable
    assert again.nb == (3, 2, 3) and again.nk == (0, 1, 0) and first.nb == (2, 1, 2)
    fx._COMPILED.clear()
    fresh = fx.compile_effects(("u1*vbat", "y^2"), data, (3, 2), (0, 1))
    np.testing.assert_array_equal(fresh.u, again.u)
    assert fresh.output_terms == again.output_terms and fresh.column_labels == again.column_labels
    np.testing.assert_array_equal(fresh.u[:, 2], data.u[:, 0] * data.extra["vbat"])
    other = arxid.IOData(data.y.copy(), data.u * 2.0, 0.01, extra={"vbat": data.extra["vbat"]})
    np.testing.assert_allclose(fx.compile_effects(("u1*vbat", "y^2"), other, (3, 2), (0, 1)).u, 2.0 * fresh.u)
    for effects in [(), ("const",), ("time",), ("u1^2",)]:  # a short record's sets stay (the inputs need none)
        fx.compile_effects(effects, data, (1, 1), (1, 1))
    kept = [("u1*vbat", "y^2"), ("const",), ("time",), ("u1^2",)]
    assert list(fx._COMPILED[data]) == kept
    bare = fx.compile_effects(("u1*vbat", "y^2"), data, (3, 2), (0, 1), samples=False)
    assert bare.u.shape == (0, 3) and bare.nb == fresh.nb and list(fx._COMPILED[data]) == kept


def test_a_long_records_input_matrices_are_kept_one_at_a_time(monkeypatch):
    """Beyond the bytes kept per record only the last matrix stays: a long record's never pile up."""
    from arxid.models import effects as fx

    rng = np.random.default_rng(4)
    data = arxid.IOData(rng.standard_normal(400), rng.standard_normal((400, 1)), 0.01)
    monkeypatch.setattr(fx, "_KEEP_BYTES", 2 * 400 * 8)  # room for the inputs and one column, not two matrices
    for effects in [("const",), ("u1^2",), ("time",)]:
        fx.compile_effects(effects, data, (1,), (1,))
    assert list(fx._COMPILED[data]) == [("time",)]
