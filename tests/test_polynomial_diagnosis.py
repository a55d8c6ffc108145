"""diagnose on output-error models: score tests on the prediction-error gradient, refits as extra inputs."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import arxid
from arxid.polynomial_diagnosis import OUTPUT_TERM_NOTE, score_effects, with_effects


def _plant(battery: bool, seed: int = 1, n: int = 4000) -> tuple[arxid.IOData, arxid.IOData]:
    """Second-order plant under 10 % output noise; with ``battery`` the input is scaled by a slowly
    varying supply voltage vbat (10-12 V, recorded as an extra signal) before the dynamics."""
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n)) * rng.uniform(0.5, 1.5, n)
    vbat = 11 + np.sin(np.arange(n) / 300)
    drive = u * vbat / 11 if battery else u
    x = signal.lfilter([0, 0.5, 0.3], [1, -1.5, 0.7], drive)
    y = x + 0.1 * np.std(x) * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=0.01, extra={"vbat": vbat}).split(0.6)


def test_gradient_binding_matches_finite_differences():
    est, _ = _plant(False)
    model = arxid.oe(est, 2, 2, 1)
    orders = (0, [2], 0, 0, [2], [1])
    segs = [(0, est.n_samples)]
    u = np.ascontiguousarray(est.u)
    eps, jac = arxid._core.pem_gradient(est.y, u, segs, orders, model.parameters_)
    rows = np.isfinite(eps)
    assert rows.sum() == model.n_rows_ and np.mean(eps[rows] ** 2) == pytest.approx(model.loss_, rel=1e-9)
    for j in range(model.n_params):
        th = model.parameters_.copy()
        th[j] += 1e-7
        e2, _ = arxid._core.pem_gradient(est.y, u, segs, orders, th)
        assert np.allclose((e2[rows] - eps[rows]) / 1e-7, jac[rows, j], atol=1e-4 * np.abs(jac[rows, j]).max())


def test_diagnose_names_a_hidden_supply_gain_of_an_oe_model():
    est, val = _plant(True)
    model = arxid.oe(est, 2, 2, 1)
    d = arxid.diagnose(model, est, val)
    assert d.top is not None and d.top.effect == "u1*vbat"
    assert [s.effect for s in d.significant] == ["u1*vbat"]
    assert d.top.p_value < 1e-20 and d.top.improvement > 0.10
    # the refit is the OE model with u1*vbat as a second input through its own B/F
    fitted = d.apply(0)
    assert fitted.nb_ == (2, 2) and fitted.nf_ == (2, 2) and fitted.nk_ == (1, 1)
    assert fitted.rms(with_effects(val, ["u1*vbat"]), None) == pytest.approx(d.top.rms_sim_val_after, rel=1e-9)
    # terms of the measured output are listed with the reason, not tested
    y2 = d.suspect("y^2")
    assert np.isnan(y2.p_value) and y2.note == OUTPUT_TERM_NOTE


def test_diagnose_finds_nothing_missing_in_a_linear_oe_plant():
    est, val = _plant(False)
    model = arxid.oe(est, 2, 2, 1)
    d = arxid.diagnose(model, est, val)
    assert d.significant == ()
    res, _ = score_effects(model, est, ["u1*vbat"])
    assert res is not None and res.p_value > 0.01
