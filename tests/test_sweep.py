"""arxid.sweep: every structure equals lstsq on the same rows, thread-independent results,
integrating plants, a delayed double-integrator roll axis, MISO grids, size guard, divergence."""

from __future__ import annotations

import json
import sys
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.exceptions import DataError, OrderError
from arxid.models.effects import compile_effects
from arxid.models.regressors import regressor_matrix
from arxid.selection.sanity import SanityLimits


def _arx_data(n, seed, noise=0.02):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = noise * rng.standard_normal(n)
    y = lfilter([0, 0, 0.5, 0.25], [1, -1.5, 0.7], u) + lfilter([1], [1, -1.5, 0.7], e)
    return arxid.IOData(y, u, ts=0.01)


@pytest.fixture(scope="module")
def small():
    est, val = _arx_data(3000, 1), _arx_data(2000, 2)
    res = arxid.sweep(est, na=range(1, 4), nb=range(1, 4), nk=range(0, 4), validation=val, progress=False)
    return est, val, res


def test_every_structure_equals_lstsq_and_arx_on_the_same_rows(small):
    est, val, res = small
    assert len(res) == 3 * 3 * 4
    assert res.first_lag == 5  # nb 3 + nk 3 - 1
    for i in range(len(res)):
        na, nb, nk = int(res.na[i]), int(res.nb[i, 0]), int(res.nk[i, 0])
        layout = compile_effects((), est, [nb], [nk])
        phi, y, _ = regressor_matrix(est, na, layout, first_lag=res.first_lag)
        assert len(y) == res.n_est
        ref, *_ = np.linalg.lstsq(phi, y, rcond=None)
        np.testing.assert_allclose(res.parameters[i], ref, rtol=1e-9, atol=1e-11)
        rss = np.sum((y - phi @ ref) ** 2)
        assert res.rms_est_one_step[i] == pytest.approx(np.sqrt(rss / len(y)), rel=1e-9)
        # validation one-step loss from the validation R equals the explicit residual
        phv, yv, _ = regressor_matrix(val, na, compile_effects((), val, [nb], [nk]), first_lag=res.first_lag)
        assert res.rms_val_one_step[i] == pytest.approx(np.sqrt(np.mean((yv - phv @ ref) ** 2)), rel=1e-8)
    m = res.model(0)
    fresh = arxid.ArxModel(na=m.na, nb=m.nb, nk=m.nk).fit(est, first_lag=res.first_lag)
    np.testing.assert_allclose(res.parameters[0], fresh.parameters_, rtol=1e-9, atol=1e-12)
    assert res.fpe[0] == pytest.approx(fresh.fpe_, rel=1e-9)
    assert res.aic[0] == pytest.approx(fresh.aic_, rel=1e-9)
    assert res.bic[0] == pytest.approx(fresh.bic_, rel=1e-9)


def test_with_missing_samples_every_structure_and_its_model_use_the_sweeps_rows():
    # NaN in output and input: the sweep leaves out every row where the grid's largest regressor
    # touches a NaN; model(i) must refit on those same rows (it used its own, larger row set).
    d = _arx_data(3000, 4)
    y, u = d.y.copy(), d.u.copy()
    y[[100, 500, 901, 1700]] = np.nan
    u[[300, 1200, 2222], 0] = np.nan
    d = arxid.IOData(y, u, ts=d.ts)
    res = arxid.sweep(d, na=range(1, 4), nb=range(1, 3), nk=range(0, 4), progress=False)
    env = compile_effects((), d, [5], [0])  # lags 0..4 of u: nb 1..2 with nk 0..3
    _, _, rows = regressor_matrix(d, 3, env, first_lag=res.first_lag)
    assert res.n_est == len(rows) < d.n_samples - res.first_lag
    for i in range(len(res)):
        na, nb, nk = int(res.na[i]), int(res.nb[i, 0]), int(res.nk[i, 0])
        phi, _, own = regressor_matrix(d, na, compile_effects((), d, [nb], [nk]), first_lag=res.first_lag)
        keep = np.isin(own, rows)
        ref, *_ = np.linalg.lstsq(phi[keep], d.y[own[keep]], rcond=None)
        np.testing.assert_allclose(res.parameters[i], ref, rtol=1e-9, atol=1e-11)
        m = res.model(i)
        np.testing.assert_allclose(m.parameters_, res.parameters[i], rtol=1e-9, atol=1e-11)
        assert m.n_rows_ == res.n_est
        assert m.n_skipped_ == d.n_samples - res.first_lag - res.n_est


def test_free_run_errors_match_an_explicit_simulation(small):
    est, val, res = small
    for i in (0, 5, len(res) - 1):
        if res.diverged_val[i]:
            continue
        na, nb, nk = int(res.na[i]), int(res.nb[i, 0]), int(res.nk[i, 0])
        th = res.parameters[i]
        lag = res.first_lag
        sim = np.zeros(val.n_samples)
        sim[:lag] = val.y[:lag]
        for t in range(lag, val.n_samples):
            sim[t] = -th[:na] @ sim[t - na : t][::-1] + th[na:] @ val.u[t - nk - np.arange(nb), 0]
        rms = np.sqrt(np.mean((val.y[lag:] - sim[lag:]) ** 2))
        assert res.rms_val[i] == pytest.approx(rms, rel=1e-9)
        fit = 100 * (1 - np.linalg.norm(val.y[lag:] - sim[lag:]) / np.linalg.norm(val.y[lag:] - val.y[lag:].mean()))
        assert res.fit_val[i] == pytest.approx(fit, rel=1e-9)


def test_ranked_by_validation_and_best_is_the_true_structure(small):
    _, _, res = small
    finite = res.rms_val[np.isfinite(res.rms_val)]
    assert np.all(np.diff(finite) >= 0)
    best = res.best()
    assert best.na_ == 2 and best.nk_[0] + best.nb_[0] - 1 >= 3 and best.nk_[0] <= 2
    assert np.max(np.abs(res.parameters[0][:2] - [-1.5, 0.7])) < 0.01


def test_one_thread_and_all_threads_give_identical_results():
    est, val = _arx_data(20000, 3), _arx_data(20000, 4)
    kw = dict(na=range(1, 5), nb=range(1, 4), nk=range(0, 4), validation=val, progress=False)
    a = arxid.sweep(est, n_threads=1, **kw)
    b = arxid.sweep(est, n_threads=0, **kw)
    for field in ("rms_est", "rms_val", "rms_est_one_step", "rms_val_one_step", "fpe"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
    for x, y in zip(a.parameters, b.parameters):
        np.testing.assert_array_equal(x, y)


def test_table_json_and_pandas(small):
    _, _, res = small
    text = str(res)
    assert "structure" in text and "RMS val" in text and res.structure_name(0) in text
    assert "free-run" in text
    d = json.loads(res.to_json())
    assert len(d["structures"]) == len(res) and d["structures"][0]["structure"] == res.structure_name(0)
    df = res.to_pandas()
    assert list(df["structure"])[:3] == [res.structure_name(i) for i in range(3)]
    assert {"rms_est", "rms_val", "fit_val", "fpe", "aic", "bic", "n_params", "stable", "step_sanity"} <= set(
        df.columns
    )


def test_plot_returns_a_figure(small):
    from matplotlib.figure import Figure

    _, _, res = small
    fig = res.plot()
    assert isinstance(fig, Figure)
    assert len([ax for ax in fig.axes if ax.get_visible() and ax.images]) == 3  # one panel per nb


def test_integrating_plant_is_detected_and_ranked_by_k_step_error():
    rng = np.random.default_rng(5)
    n = 6000
    u = rng.standard_normal(n)
    y = lfilter([0, 0, 0.2], [1, -1.0], u) + 0.002 * rng.standard_normal(n)
    est, val = arxid.IOData(y, u, ts=0.01).split(0.6)
    res = arxid.sweep(est, na=range(1, 3), nb=range(1, 3), nk=range(0, 4), validation=val, progress=False)
    assert res.integrating and "pole at z = 1" in res.integrating_reason
    assert res.horizon == max(10, 2 * res.first_lag)
    assert f"k={res.horizon}" in str(res)
    best = res.best()
    assert best.nk_[0] == 2
    # the k-step RMS equals the model's own k-step prediction error on the same samples
    i = 0
    pred = best.predict(val, horizon=res.horizon)
    lag = res.first_lag
    ok = np.isfinite(pred)
    ok[:lag] = False
    # (the sweep starts every prediction at the grid's lag, the model at its own: the first k
    # predictions have shorter horizons, hence the tolerance)
    assert res.rms_val[i] == pytest.approx(np.sqrt(np.mean((val.y[ok] - pred[ok]) ** 2)), rel=1e-3)
    # an explicit horizon is used as given (stable plant too)
    short = arxid.sweep(est, na=range(1, 3), nb=1, nk=range(1, 3), validation=val, progress=False, horizon=3)
    assert short.horizon == 3 and "3-step" in short.measure


def _roll_axis(seed, n=12000, delay=8, ts=0.002):
    """Double-integrator roll axis (phi'' = c u) with an 8-sample sensor delay, under a PD
    controller acting on the delayed measurement plus an excitation signal."""
    rng = np.random.default_rng(seed)
    c = 40.0
    kp, kd = 0.9, 0.12
    phi = omega = 0.0
    meas = np.zeros(n)
    u = np.zeros(n)
    hist = np.zeros(n + delay)
    excitation = np.repeat(rng.standard_normal(n // 25 + 1), 25)[:n] * 1.5
    prev = 0.0
    for t in range(n):
        hist[t] = phi
        y = hist[t - delay] if t >= delay else 0.0
        meas[t] = y
        dy = (y - prev) / ts
        prev = y
        u[t] = -kp * y - kd * dy + excitation[t]
        # exact ZOH discretisation of the double integrator
        phi += ts * omega + 0.5 * c * ts**2 * u[t]
        omega += c * ts * u[t]
    meas = meas + 2e-5 * rng.standard_normal(n)
    return arxid.IOData(meas, u, ts=ts, output_name="roll", input_names=["torque"])


def test_delayed_double_integrator_best_sane_structure_has_the_delay_and_grows(capsys):
    est, val = _roll_axis(11), _roll_axis(12)
    res = arxid.sweep(
        est,
        na=range(1, 5),
        nb=range(1, 3),
        nk=range(0, 13),
        validation=val,
        progress=False,
        expect="double-integrating",
    )
    assert res.integrating and res.horizon is not None
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        best = res.best(sane=True)
    if best.selection_.skipped:
        assert any(issubclass(w.category, arxid.ArxidWarning) and "skipped" in str(w.message) for w in seen)
    assert abs(best.nk_[0] - 8) <= 1
    verdict = res.sanity(best.selection_.rank)
    assert verdict.ok
    step = best.step(2000, amplitude=1.0)
    assert step[-1] > 0 and step[-1] > 3 * step[1000] > 0  # grows, with the sign of the torque
    # nothing flagged (for example implausibly small amplitude) is ever returned
    for rank, _, reasons in best.selection_.skipped:  # noqa: B007
        assert not res.sanity(rank).ok
    flagged_small = [i for i in range(len(res)) if "too-small" in res.sanity(i).flags]
    assert best.selection_.rank not in flagged_small


def test_best_sane_refuses_when_everything_is_flagged_and_says_why(small):
    est, val, _ = small
    # expect an integrator on a stable plant: every structure is flagged "not-growing"
    res = arxid.sweep(est, na=range(1, 3), nb=1, nk=range(1, 4), validation=val, progress=False, expect="integrating")
    with pytest.raises(arxid.ArxidError, match="not growing"):
        res.best(sane=True)
    assert res.best(sane=False).na >= 1
    strict = arxid.sweep(
        est, na=range(1, 3), nb=1, nk=range(1, 4), validation=val, progress=False, limits=SanityLimits(small=1e3)
    )
    with pytest.raises(arxid.ArxidError, match="implausibly small"):
        strict.best(sane=True)


def test_miso_grid_recovers_both_delays():
    rng = np.random.default_rng(7)
    n = 5000
    u = rng.standard_normal((n, 2))
    y = lfilter([1], [1, -0.6], np.concatenate([[0, 0], u[:-2, 0]]) * 0.8 + np.concatenate([[0] * 4, u[:-4, 1]]) * -0.5)
    y = y + 0.01 * rng.standard_normal(n)
    d = arxid.IOData(y, u, ts=0.01)
    res = arxid.sweep(
        d,
        na=range(1, 3),
        nb=[range(1, 3), range(1, 2)],
        nk=[range(0, 4), range(2, 6)],
        validation=0.3,
        progress=False,
        sort_by="bic",
    )
    assert len(res) == 2 * 2 * 1 * 4 * 4
    best = res.best()
    assert best.na_ == 1 and tuple(best.nk_) == (2, 4) and tuple(best.nb_) == (1, 1)
    est, _ = d.split(0.7)
    i = 0
    layout = compile_effects((), est, list(best.nb_), list(best.nk_))
    phi, yy, _ = regressor_matrix(est, best.na_, layout, first_lag=res.first_lag)
    ref, *_ = np.linalg.lstsq(phi, yy, rcond=None)
    np.testing.assert_allclose(res.parameters[i], ref, rtol=1e-9, atol=1e-12)


def test_effects_are_tied_to_their_input(small):
    est, val, _ = small
    res = arxid.sweep(
        est, na=range(1, 3), nb=range(1, 3), nk=range(1, 3), validation=val, progress=False, effects=["u1^2", "const"]
    )
    for i in range(len(res)):
        m = res.model(i)
        np.testing.assert_allclose(res.parameters[i], m.parameters_, rtol=1e-9, atol=1e-12)
        assert len(res.parameters[i]) == m.na + 2 * m.nb[0] + 1


def test_grid_too_large_is_refused_with_its_size():
    d = _arx_data(2000, 1)
    with pytest.raises(DataError, match=r"too large: 4,000,000 structures.*GiB|too large: 4,000,000 structures.*MiB"):
        arxid.sweep(d, na=range(1, 201), nb=range(1, 201), nk=range(0, 100), progress=False)
    with pytest.raises(DataError, match="max_memory"):
        arxid.sweep(d, na=range(1, 3), nb=range(1, 3), nk=range(0, 3), progress=False, max_memory=1000)


def test_divergence_is_reported_not_a_number():
    rng = np.random.default_rng(9)
    n = 3000
    u = rng.standard_normal(n)
    # Nearly unstable plant measured with strong noise: some short models fit unstable poles.
    y = lfilter([0, 1.0], [1, -1.9, 0.905], u) + 5 * rng.standard_normal(n)
    d = arxid.IOData(y, u, ts=0.01)
    val = arxid.IOData(lfilter([0, 1.0], [1, -1.9, 0.905], u[::-1]), u[::-1].copy(), ts=0.01)
    res = arxid.sweep(
        d, na=range(1, 3), nb=range(1, 3), nk=range(0, 3), validation=val, progress=False, expect="stable"
    )
    # force one diverging structure through the core to check reporting end to end
    from arxid._base import _core

    grid = np.array([[1, 1, 1]], dtype=np.int64)
    # validation output scaled down: the same simulation now leaves DIVERGENCE_FACTOR x its peak
    out = _core.sweep(np.ascontiguousarray(d.y), d.u, [0], grid, [], yv=1e-6 * val.y, uv=val.u, starts_v=[0])
    assert out.diverged_val[0] and np.isnan(out.rms_sim_val[0])
    for i in range(len(res)):
        if res.diverged_val[i]:
            assert np.isnan(res.rms_val[i]) and "diverged" in res.table(n=len(res), sanity=False)
    assert np.all(np.isfinite(res.rms_val) | res.diverged_val | res.diverged_est)


def test_bad_arguments_say_what_to_do():
    d = _arx_data(500, 1)
    with pytest.raises(OrderError, match="non-negative"):
        arxid.sweep(d, na=[-1, 2], progress=False)
    with pytest.raises(OrderError, match="2 ranges but the data have 1 inputs"):
        arxid.sweep(d, nb=[range(1, 2), range(1, 3)], progress=False)
    with pytest.raises(arxid.ArxidError, match="sort_by"):
        arxid.sweep(d, sort_by="speed", progress=False)
    with pytest.raises(DataError, match="fraction"):
        arxid.sweep(d, validation=1.5, progress=False)


def test_progress_is_reported_from_the_core_and_drives_a_bar(monkeypatch, capsys):
    from arxid._base import _core

    est, val = _arx_data(5000, 1), _arx_data(5000, 2)
    grid = np.array([(a, b, k) for a in range(1, 5) for b in range(1, 5) for k in range(0, 5)], dtype=np.int64)
    calls = []
    _core.sweep(est.y, est.u, [0], grid, [], yv=val.y, uv=val.u, starts_v=[0], chunk=16, progress=calls.append)
    assert calls[-1] == len(grid) and all(0 < c <= len(grid) for c in calls) and len(calls) > 2
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    res = arxid.sweep(est, na=range(1, 5), nb=range(1, 5), nk=range(0, 5), validation=val, progress=True)
    assert len(res) == len(grid)
    assert "arxid.sweep" in capsys.readouterr().err


def test_validation_shorter_than_the_grid_lag_is_a_data_error():
    d = _arx_data(1000, 1)
    with pytest.raises(DataError, match="validation data.*3 samples.*largest lag 6.*longer validation"):
        arxid.sweep(d, na=range(1, 3), nb=range(1, 3), nk=range(0, 6), validation=d[:3], progress=False)


def test_all_nan_output_is_a_data_error_without_warnings():
    d = _arx_data(500, 1)
    bad = arxid.IOData(np.full(500, np.nan), d.u, ts=d.ts)
    with pytest.raises(DataError, match="too few usable samples"):
        arxid.sweep(bad, na=range(1, 3), nb=1, nk=1, progress=False)  # warnings are errors here
    with pytest.raises(DataError, match="validation.*no finite output"):
        arxid.sweep(d, na=range(1, 3), nb=1, nk=1, validation=bad, progress=False)


def test_when_no_structure_can_be_fitted_best_says_why():
    d = _arx_data(1000, 1)
    d = arxid.IOData(d.y, d.u, ts=d.ts, extra={"vbat": np.full(1000, 12.0)})
    res = arxid.sweep(d, na=range(1, 3), nb=1, nk=range(1, 3), effects=["u1*vbat"], progress=False)
    assert all(e is not None for e in res.errors)
    with pytest.raises(arxid.ArxidError, match="could not be fitted.*linear combination"):
        res.best()


def test_fit_percent_with_missing_validation_inputs_is_that_of_the_scored_samples():
    # The fit percent must normalise by the output samples the simulation scored, not by every
    # validation sample from the first lag on (they differ when inputs are missing).
    from arxid._base import _core

    est, val = _arx_data(2000, 5), _arx_data(1500, 6)
    uv = val.u.copy()
    uv[[100, 400, 401, 700, 1100], 0] = np.nan
    val = arxid.IOData(val.y, uv, ts=val.ts)
    res = arxid.sweep(est, na=range(1, 3), nb=range(1, 3), nk=range(1, 4), validation=val, progress=False)
    for i in range(len(res)):
        m = res.model(i)
        pred = _core.predict(val.y, val.u, [0], m.na, list(m.nb), list(m.nk), [], m.parameters_, None, res.first_lag)
        ok = np.isfinite(pred) & np.isfinite(val.y)
        e = val.y[ok] - pred[ok]
        assert res.rms_val[i] == pytest.approx(np.sqrt(np.mean(e**2)), rel=1e-9)
        fit = 100 * (1 - np.linalg.norm(e) / np.linalg.norm(val.y[ok] - val.y[ok].mean()))
        assert res.fit_val[i] == pytest.approx(fit, rel=1e-9)


def test_any_structure_follows_from_the_estimation_factor_as_a_refit_gives_it(small):
    """The integrator test reads parameters and covariances from the sweep's factor, not the data."""
    from arxid._base import _core

    est, _, res = small
    env = (res.row_orders[0], list(res.row_orders[1]), list(res.row_orders[2]))
    for i in (0, 5, len(res) - 1):
        orders = (int(res.na[i]), [int(res.nb[i, 0])], [int(res.nk[i, 0])])
        fit = _core.fit_from_factor(res.estimation_factor, res.n_est, env, orders, [])
        m = res.model(i)
        np.testing.assert_allclose(fit.theta, m.parameters_, rtol=1e-10, atol=1e-13)
        cov = arxid._base.metrics.parameter_covariance(fit.inv_gram, fit.rss, fit.n_rows)
        np.testing.assert_allclose(cov, m.covariance_, rtol=1e-9, atol=1e-18)
    outside = (4, [1], [0])  # na 4 is beyond the grid's largest na 3
    with pytest.raises(OrderError, match="outside the envelope"):
        _core.fit_from_factor(res.estimation_factor, res.n_est, env, outside, [])
