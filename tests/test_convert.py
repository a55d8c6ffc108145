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


def _zoh_with_delay(num, den, dead_time, ts):
    """Reference ZOH sampling of num/den · e^{-s·dead_time} (modified z-transform, Åström &
    Wittenmark ch. 2.3), the integrals by Van Loan's block exponential: H(z) as a function."""
    from scipy.linalg import expm

    control = pytest.importorskip("control")
    ss = control.tf2ss(control.tf(num, den))
    a, b, c, d = (np.asarray(x, dtype=float) for x in (ss.A, ss.B, ss.C, ss.D))
    whole = int(np.floor(dead_time / ts + 1e-9))
    frac = max(dead_time - whole * ts, 0.0)
    n = a.shape[0]

    def integral(t):  # ∫_0^t e^{As} ds B
        block = np.zeros((n + 1, n + 1))
        block[:n, :n], block[:n, n:] = a, b
        return expm(block * t)[:n, n:]

    g0, g1 = integral(ts - frac), expm(a * (ts - frac)) @ integral(frac)
    phi = expm(a * ts)

    def h(z):
        out = (c @ np.linalg.solve(z * np.eye(n) - phi, g0 + g1 / z))[0, 0] + d[0, 0] / (z if frac > 0 else 1)
        return out * z**-whole

    return h


def _discrete(a, b, z):
    return np.polyval(np.asarray(b)[::-1], 1 / z) / np.polyval(np.asarray(a)[::-1], 1 / z)


def _random_poles(rng, na):
    poles = rng.uniform(0.3, 0.97, na).astype(complex)
    if na >= 2:
        r, th = rng.uniform(0.5, 0.97), rng.uniform(0.05, 1.2)
        poles[:2] = [r * np.exp(1j * th), r * np.exp(-1j * th)]
    return np.real(np.poly(poles))


FREQS = (0.03, 0.4, 1.3, 2.9)


def test_zoh_round_trip_over_the_grid_or_a_typed_refusal():
    """Every structure with nb <= na + 1 and nk 0..8: the continuous model (with its dead time)
    sampled again equals the discrete one to 1e-9, or the conversion refuses with a ConversionError.
    A numerator one longer than the poles (nb = na + 1 with a delay) comes from a fractional delay:
    sampled from a known continuous system, it is recovered, not refused."""
    from arxid.models.continuous import d2c

    ts = 0.01
    rng = np.random.default_rng(0)
    returned = refused = 0
    for na in range(1, 5):
        for nb in range(1, na + 2):
            for nk in range(0, 9):
                a = _random_poles(rng, na)
                b = np.concatenate([np.zeros(nk), rng.standard_normal(nb)])
                try:
                    cont = d2c(a, b, ts)
                except arxid.exceptions.ConversionError as err:
                    assert nb == na + 1 and nk >= 1 and "fractional" in str(err)
                    refused += 1
                    continue
                returned += 1
                back = _zoh_with_delay(cont.num, cont.den, cont.dead_time, ts)
                for w in FREQS:
                    z = np.exp(1j * w)
                    assert abs(back(z) - _discrete(a, b, z)) <= 1e-9 * abs(_discrete(a, b, z))
    assert returned + refused == 126 and returned >= 100


@pytest.mark.parametrize("na", [1, 2, 3])
@pytest.mark.parametrize("delay", [0.3, 2.75, 7.5])
@pytest.mark.parametrize("relative_degree", ["one", "na"])
def test_zoh_recovers_a_fractional_input_delay(na, delay, relative_degree):
    """Sample a continuous system with a delay of a fraction of a sample: the discrete model has
    nb = na + 1; d2c gives back the same delay and the same continuous model. With relative degree
    >= 2 the delay is determined only to second order (a small delay change is, to first order, a
    change of the numerator), so it is checked to 1e-4 there; the round trip stays exact."""
    control = pytest.importorskip("control")
    from arxid.models.continuous import d2c

    ts = 0.01
    den = np.real(np.poly({1: [-20.0], 2: [-35.0 + 30j, -35.0 - 30j], 3: [-20.0, -35.0 + 30j, -35.0 - 30j]}[na]))
    num = np.array([den[-1] * 1.7])  # DC gain 1.7
    if relative_degree == "one":  # zeros at s = -60, -80: numerator of degree na - 1
        zeros = np.atleast_1d(np.poly([-60.0, -80.0][: na - 1]))
        num = zeros * 1.7 * den[-1] / zeros[-1]
    h = _zoh_with_delay(num, den, delay * ts, ts)
    # The discrete model from its frequency response: fit A and B on the unit circle exactly.
    sys_d = control.sample_system(control.tf(num, den), ts, "zoh")
    a = np.squeeze(sys_d.den[0][0]) / np.squeeze(sys_d.den[0][0])[0]
    ws = np.linspace(0.1, 3.0, 3 * na + 3)
    z = np.exp(1j * ws)
    whole = int(np.floor(delay))
    cols = np.array([[zi ** -(whole + 1 + k) for k in range(na + 1)] for zi in z])
    rhs = np.array([h(zi) * np.polyval(a[::-1], 1 / zi) for zi in z])
    beta = np.linalg.lstsq(np.vstack([cols.real, cols.imag]), np.concatenate([rhs.real, rhs.imag]), rcond=None)[0]
    b = np.concatenate([np.zeros(whole + 1), beta])
    cont = d2c(a, b, ts)
    exact = relative_degree == "one" or na == 1
    assert cont.dead_time == pytest.approx(delay * ts, rel=1e-8 if exact else 1e-4)
    np.testing.assert_allclose(cont.den, den, rtol=1e-8)
    for s in (0.0, 10j, 100j, 1000j):
        assert np.polyval(cont.num, s) == pytest.approx(np.polyval(num, s), rel=1e-7 if exact else 1e-3)
    back = _zoh_with_delay(cont.num, cont.den, cont.dead_time, ts)
    for w in FREQS:
        z = np.exp(1j * w)
        assert back(z) == pytest.approx(_discrete(a, b, z), rel=1e-9)


def test_nb_greater_than_na_keeps_every_numerator_term():
    """y = 0.5 y(t-1) + u(t-1) + 0.8 u(t-2): DC gain 3.6 in both times (it used to return 2.0)."""
    pytest.importorskip("control")
    rng = np.random.default_rng(1)
    u = rng.standard_normal(500)
    y = simulate_arx([-0.5], [[1.0, 0.8]], [1], u)
    model = arxid.arx(arxid.IOData(y, u, ts=0.01), 1, 2, 1)
    cont = model.to_control(continuous=True)
    assert float(np.squeeze(cont.dcgain())) == pytest.approx(3.6, rel=1e-9)
    assert 0 < cont.dead_time < 0.01  # a fraction of a sample
    back = _zoh_with_delay(np.squeeze(cont.num_array[0, 0]), np.squeeze(cont.den_array[0, 0]), cont.dead_time, 0.01)
    for w in FREQS:
        z = np.exp(1j * w)
        assert back(z) == pytest.approx(_discrete([1, -0.5], [0, 1, 0.8], z), rel=1e-9)


def test_longer_numerator_is_refused_with_a_reason():
    from arxid.models.continuous import d2c

    with pytest.raises(arxid.exceptions.ConversionError, match="poles at z = 0.*nb <= na \\+ 1.*tustin"):
        d2c([1, -0.5], [0, 1, 0.8, 0.3], 0.01)
    with pytest.raises(arxid.exceptions.ConversionError, match="poles at z = 0"):
        d2c([1, -0.5], [1, 0.8, 0.3], 0.01)  # feedthrough: at most na + 1 coefficients


def _negative_pole_model():
    """ARX(3,2,8) with a pole at z = -0.4, as the sweep picks for the simulated roll axis."""
    a = np.real(np.poly([0.95, 0.8, -0.4]))
    b = np.concatenate([np.zeros(8), [0.5, 0.3]])
    return a, b


def test_negative_real_pole_refuses_zoh_and_names_the_alternatives():
    from arxid.models.continuous import d2c

    a, b = _negative_pole_model()
    with pytest.raises(arxid.exceptions.ConversionError, match="negative real axis.*tustin.*matched"):
        d2c(a, b, 0.01)


@pytest.mark.parametrize("method", ["tustin", "matched"])
def test_tustin_and_matched_invert_python_control_sample_system(method):
    """``sample_system(G, ts, method)`` of the result, times its dead time, is the discrete model."""
    control = pytest.importorskip("control")
    from arxid.models.continuous import d2c

    ts = 0.01
    cases = [(np.real(np.poly([0.95, 0.8 + 0.1j, 0.8 - 0.1j])), np.concatenate([np.zeros(4), [0.5, -0.3]]))]
    if method == "tustin":
        cases += [_negative_pole_model(), ([1, -0.6], [0.4, 0.2]), ([1, -1.2, 0.5], [0, 0.3, 0.2, 0.1])]
    else:
        cases += [([1, -0.6], [0, 0, 0.4, -0.2]), ([1, -1.2, 0.5], [0, 0, 0.3, -0.2])]
    for a, b in cases:
        cont = d2c(a, b, ts, method)
        back = control.sample_system(control.tf(cont.num, cont.den), ts, method=method)
        shift = round(cont.dead_time / ts)
        assert cont.dead_time == pytest.approx(shift * ts)
        for w in FREQS:
            z = np.exp(1j * w)
            assert complex(back(z)) * z**-shift == pytest.approx(_discrete(a, b, z), rel=1e-9)


def test_matched_refuses_zeros_at_the_origin_and_negative_poles():
    from arxid.models.continuous import d2c

    with pytest.raises(arxid.exceptions.ConversionError, match="zero\\(s\\) at z = 0"):
        d2c([1, -1.5, 0.7], [0, 0.5], 0.01, "matched")  # ARX(2,1,1): b z / (z^2 + ...)
    a, b = _negative_pole_model()
    with pytest.raises(arxid.exceptions.ConversionError, match="negative real axis.*tustin"):
        d2c(a, b, 0.01, "matched")
    with pytest.raises(arxid.exceptions.ConversionError, match="method must be one of"):
        d2c(a, b, 0.01, "bilinear")


@pytest.mark.parametrize(
    "na,nb,nk,a,b",
    [
        (2, 1, 1, [-1.5, 0.7], [0.5]),
        (2, 2, 3, [-1.2, 0.5], [0.3, 0.2]),
        (1, 1, 0, [-0.6], [1.0]),
        (1, 2, 0, [-0.6], [1.0, 0.4]),
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
    assert float(np.squeeze(cont.dcgain())) == pytest.approx(model.dc_gain()[0], rel=1e-9)


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
