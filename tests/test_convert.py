"""Export: python-control (discrete and continuous), scipy, JSON; printing."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from conftest import simulate_arx


def fitted(na, nb, nk, a, b, n=3000, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = simulate_arx(a, [b], [nk], u, noise=noise * rng.standard_normal(n))
    return arxid.arx(arxid.IOData(y, u, ts=0.01, output_name="roll", input_names=["torque"]), na, nb, nk)


@pytest.mark.parametrize(
    "na,nb,nk,a,b",
    [
        (2, 1, 8, [-1.5, 0.7], [0.5]),
        (1, 3, 0, [-0.6], [1.0, 0.5, 0.25]),  # nb > na, direct feedthrough
        (2, 2, 3, [-1.2, 0.5], [0.3, 0.2]),
    ],
)
def test_to_control_matches_the_difference_equation(na, nb, nk, a, b):
    control = pytest.importorskip("control")
    model = fitted(na, nb, nk, a, b)
    tf = model.to_control()
    assert tf.dt == 0.01 and tf.input_labels == ["torque"] and tf.output_labels == ["roll"]
    num, den = np.squeeze(tf.num_array[0, 0]), np.squeeze(tf.den_array[0, 0])  # noqa: F841
    n = max(na, nk + nb - 1)
    assert len(den) == n + 1 and den[0] == 1.0
    # Evaluate B(z⁻¹)/A(z⁻¹) and the TF at a few points on the unit circle.
    for w in (0.1, 0.7, 2.0):
        z = np.exp(1j * w)
        direct = sum(model.b[0][k] * z**-k for k in range(len(model.b[0]))) / sum(
            model.a[k] * z**-k for k in range(na + 1)
        )
        assert complex(tf(z)) == pytest.approx(direct, rel=1e-10)
    np.testing.assert_allclose(
        np.sort_complex(tf.poles()[np.abs(tf.poles()) > 1e-9]), np.sort_complex(model.poles()), atol=1e-9
    )
    assert np.squeeze(control.dcgain(tf)) == pytest.approx(model.dc_gain()[0], rel=1e-10)


@pytest.mark.parametrize(
    "na,nb,nk,a,b",
    [
        (2, 1, 1, [-1.5, 0.7], [0.5]),
        (2, 2, 3, [-1.2, 0.5], [0.3, 0.2]),
        (1, 1, 0, [-0.6], [1.0]),
    ],
)
def test_continuous_model_resamples_to_the_discrete_one(na, nb, nk, a, b):
    control = pytest.importorskip("control")
    model = fitted(na, nb, nk, a, b)
    cont = model.to_control(continuous=True)
    assert cont.dt == 0 and cont.dead_time == pytest.approx(max(nk - 1, 0) * 0.01)
    back = control.c2d(cont, 0.01, method="zoh")
    shift = max(nk - 1, 0)
    disc = model.to_control()
    for w in (0.05, 0.5, 1.5, 3.0):
        z = np.exp(1j * w)
        assert complex(back(z)) * z**-shift == pytest.approx(complex(disc(z)), rel=1e-9, abs=1e-12)


def test_to_scipy_agrees_with_simulate():
    from scipy import signal

    model = fitted(2, 2, 1, [-1.2, 0.5], [0.3, 0.2], noise=0.01)
    u = np.random.default_rng(3).standard_normal(200)
    _, yout = signal.dlsim(model.to_scipy(), u)
    np.testing.assert_allclose(np.squeeze(yout), model.simulate(u), atol=1e-10)


def test_to_scipy_miso_state_space_agrees_with_simulate():
    from scipy import signal

    rng = np.random.default_rng(4)
    u = rng.standard_normal((2000, 2))
    y = simulate_arx([-0.9, 0.2], [[1.0, 0.5], [0.3]], [1, 0], u, noise=0.01 * rng.standard_normal(2000))
    model = arxid.arx(arxid.IOData(y, u, ts=0.1), 2, [2, 1], [1, 0])
    _, yout, *_ = signal.dlsim(model.to_scipy(), u[:300])
    np.testing.assert_allclose(np.squeeze(yout), model.simulate(u[:300]), atol=1e-10)


def test_json_round_trip_is_exact(tmp_path):
    model = fitted(2, 2, 3, [-1.2, 0.5], [0.3, 0.2], noise=0.1)
    path = tmp_path / "m.json"
    text = model.to_json(path)
    json.loads(text)  # plain JSON
    back = arxid.ArxModel.from_json(path)
    assert np.array_equal(back.parameters_, model.parameters_)
    assert np.array_equal(back.covariance_, model.covariance_)
    assert back.to_json() == text
    assert str(back).splitlines()[:4] == str(model).splitlines()[:4]
    data = model.data_
    np.testing.assert_array_equal(back.predict(data), model.predict(data))


def test_json_round_trip_with_effects():
    rng = np.random.default_rng(5)
    u = rng.standard_normal(2000)
    vbat = 4 + 0.1 * rng.standard_normal(2000)
    y = simulate_arx([-0.5], [[1.0]], [1], u * vbat, noise=0.01 * rng.standard_normal(2000))
    data = arxid.IOData(y, u, ts=1.0, extra={"vbat": vbat})
    model = arxid.arx(data, 1, 1, 1, effects=["u1*vbat", "y^3", "sign(dy)"])
    back = arxid.ArxModel.from_json(model.to_json())
    np.testing.assert_array_equal(back.predict(data), model.predict(data))


def test_str_prints_equation_29_of_seed_004():
    from test_arx import roll_axis_closed_loop

    model = arxid.arx(roll_axis_closed_loop(n=20000), 2, 1, 8)
    text = str(model)
    assert "ARX(2,1,8)" in text
    assert "4.22" in text and "e-08" in text
    assert "1 - 1.959 z^-1 + 0.9567 z^-2" in text
    assert "roll_torque(z) z^-8" in text
