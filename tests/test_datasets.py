"""Known-answer tests of the simulators in arxid.datasets."""

import time

import numpy as np
import pytest

from arxid.data.iodata import IOData
from arxid.exceptions import DataError
from arxid.quadrotor.datasets import (
    DEFAULT_EFFECTS,
    QuadrotorParameters,
    quadrotor_axis,
    quadrotor_flight,
    thrust_stand,
    thrust_stand_static,
)

TRUTH = QuadrotorParameters()


@pytest.fixture(scope="module")
def flight():
    return quadrotor_flight(seed=3, duration=10.0)


def test_flight_is_deterministic_for_a_seed(flight):
    again = quadrotor_flight(seed=3, duration=10.0)
    other = quadrotor_flight(seed=4, duration=10.0)
    assert np.array_equal(flight.y, again.y) and np.array_equal(flight.u, again.u)
    for name in flight.extra:
        assert np.array_equal(flight.extra[name], again.extra[name]), name
    assert not np.allclose(flight.y, other.y)


def test_flight_shape_names_and_hover(flight):
    assert isinstance(flight, IOData)
    assert flight.n_samples == 5000 and flight.ts == 0.002
    assert flight.input_names == ("d1", "d2", "d3", "d4")
    for name in ("pitch", "yaw", "w1", "w4", "vbat", "thrust", "az", "p", "q", "r", "tau_x"):
        assert flight.signal(name).shape == (5000,)
    # the altitude loop holds the weight on average (vertical component of the thrust)
    vertical = flight.signal("thrust") * np.cos(flight.signal("pitch")) * np.cos(flight.y)
    assert vertical.mean() == pytest.approx(TRUTH.mass * 9.81, rel=0.01)
    # excitation is attitude-sized: tenths of a radian, not saturated
    assert 0.03 < flight.y.std() < 0.3
    assert 0.0 < flight.u.min() and flight.u.max() < 1.0


@pytest.mark.timed  # a duration bound: run alone (make test runs these after the parallel run)
def test_flight_runs_fast():
    t0 = time.perf_counter()
    quadrotor_flight(seed=0, duration=20.0, ts=0.002)
    assert time.perf_counter() - t0 < 2.0


def _diff(a, b, name):
    return float(np.sqrt(np.mean((a.signal(name) - b.signal(name)) ** 2)))


@pytest.mark.parametrize(
    "effect, signal, at_least",
    [
        ("battery_sag", "vbat", 0.05),  # volts of sag and drain
        ("gyroscopic", "roll", 2e-4),  # rad of roll changed by the coupling
        ("delay", "roll", 1e-3),  # rad: the log lags by 7 samples more
        ("motor_mismatch", "w1", 10.0),  # rad/s of motor-speed difference
        ("noise", "roll", 5e-5),  # rad: the attitude estimate's error is small and slow
        ("turbulence", "roll", 2e-3),  # rad: gusts move the vehicle about half a degree
    ],
)
def test_each_hidden_effect_is_switchable(effect, signal, at_least):
    on = quadrotor_flight(seed=5, duration=4.0, effects={effect: True})
    off = quadrotor_flight(seed=5, duration=4.0, effects={effect: False})
    assert _diff(on, off, signal) > at_least


def test_battery_sag_off_gives_nominal_voltage():
    d = quadrotor_flight(seed=1, duration=2.0, effects={"battery_sag": False, "noise": False})
    assert np.all(d.signal("vbat") == TRUTH.nominal_voltage)


def test_battery_drains_and_sags_with_load(flight):
    vb = flight.signal("vbat")
    assert vb[:500].mean() - vb[-500:].mean() > 0.05
    # at a given time, more current means lower voltage: detrended correlation is negative
    t = np.arange(vb.size)
    res_v = vb - np.polyval(np.polyfit(t, vb, 2), t)
    cur = flight.signal("current")
    res_i = cur - np.polyval(np.polyfit(t, cur, 2), t)
    assert np.corrcoef(res_v, res_i)[0, 1] < -0.5


def test_delay_shows_in_the_log():
    """The logged roll responds to the roll torque delay_samples samples later."""
    d = quadrotor_flight(seed=2, duration=6.0, effects={"noise": False, "turbulence": False, "gyroscopic": False})
    ax = quadrotor_axis(d, "roll")
    y, u = ax.y, ax.u[:, 0]
    t = np.arange(20, y.size)
    dd = y[t] - 2 * y[t - 1] + y[t - 2]  # second difference ~ c ts^2 u(t - nk)
    rss = [np.linalg.lstsq(u[t - nk, None], dd, rcond=None)[1][0] for nk in range(0, 15)]
    assert int(np.argmin(rss)) == TRUTH.delay_samples
    # the gyro rate is one integration closer: p(t) - p(t-1) ~ c ts u(t - nk)
    p = d.signal("p")
    rss_p = [np.linalg.lstsq(u[t - nk, None], p[t] - p[t - 1], rcond=None)[1][0] for nk in range(0, 15)]
    assert int(np.argmin(rss_p)) == TRUTH.delay_samples


def test_unknown_effect_and_output_are_refused():
    with pytest.raises(DataError, match="unknown effects"):
        quadrotor_flight(duration=1.0, effects={"wind": True})
    with pytest.raises(DataError, match="unknown output"):
        quadrotor_flight(duration=1.0, output="altitude")
    with pytest.raises(DataError, match="at least 100"):
        quadrotor_flight(duration=0.01)
    with pytest.raises(DataError, match="duration"):
        quadrotor_flight(duration=float("nan"))
    with pytest.raises(DataError, match="at most"):
        quadrotor_flight(duration=1e9)  # would need terabytes: refused before allocating
    with pytest.raises(DataError, match="seed"):
        quadrotor_flight(seed=-1, duration=1.0)
    with pytest.raises(DataError, match="seed"):
        thrust_stand(seed=-1, duration=2.0)
    assert set(DEFAULT_EFFECTS) == {"battery_sag", "motor_mismatch", "gyroscopic", "delay", "noise", "turbulence"}


def test_quadrotor_axis_mixes_the_logged_speeds(flight):
    ax = quadrotor_axis(flight, "pitch")
    assert ax.output_name == "pitch" and ax.input_names == ("pitch_torque",)
    expect = flight.signal("w3") ** 2 - flight.signal("w1") ** 2
    np.testing.assert_allclose(ax.u[:, 0], expect)
    assert "vbat" in ax.extra and "pitch" not in ax.extra
    with pytest.raises(DataError, match="axis"):
        quadrotor_axis(flight, "heave")


def test_thrust_stand_follows_the_w2_law_and_drains():
    s = thrust_stand(seed=0, duration=30.0, effects={"noise": False})
    w2 = sum(s.signal(f"w{i}") ** 2 for i in range(1, 5))
    np.testing.assert_allclose(s.y, TRUTH.thrust_coefficient * w2, rtol=1e-12)
    vb = s.signal("vbat")
    assert vb[0] > vb[-1] + 0.3
    np.testing.assert_allclose(s.signal("rpm1"), s.signal("w1") * 60 / (2 * np.pi))
    fixed = thrust_stand(seed=0, duration=5.0, supply=3.7, profile="steps", effects={"noise": False})
    assert np.all(fixed.signal("vbat") == 3.7)


def test_thrust_stand_static_is_settled():
    s = thrust_stand_static(seed=0, thrust_noise=0.0)
    assert s.n_samples == 48
    np.testing.assert_allclose(s.y, 4 * TRUTH.thrust_coefficient * s.signal("w") ** 2)
    # more supply voltage, more thrust at the same PWM
    hi = s.y[s.signal("vbat") == 4.1]
    lo = s.y[s.signal("vbat") == 3.5]
    assert np.all(hi > lo)
