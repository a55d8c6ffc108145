"""Initial conditions of prediction-error fits: ``initial="zero"`` and ``initial="estimate"`` (issue 11).

Known answers: records cut out of a longer simulation, so each starts mid-transient with a known
initial state. For an output-error model the output's free response from that state is
``x - lfilter(B, F, u)`` (the record simulated from rest), and its numerator over F is the state
arxid estimates.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import signal

import arxid

B_TRUE, F_TRUE = [0, 0.5, 0.3], [1, -1.8, 0.85]  # poles of modulus 0.92: a slow transient
C_TRUE, D_TRUE = [1, 0.5], [1, -0.9]
PRE = 300  # samples of a large step (amplitude 20) before the record starts


def mid_transient(seed: int, n: int = 2000, noise: float = 0.3, coloured: bool = False):
    """A record that starts PRE samples into a run that began with a large step.

    Returns the data, the noise-free output, the true initial-state numerator over F, and the
    innovations variance.
    """
    rng = np.random.default_rng(seed)
    u = np.r_[20 * np.ones(PRE), np.sign(rng.standard_normal(n))]
    e = noise * rng.standard_normal(n + PRE)
    x = signal.lfilter(B_TRUE, F_TRUE, u)[PRE:]
    v = (signal.lfilter(C_TRUE, D_TRUE, e) if coloured else e)[PRE:]
    u = u[PRE:]
    transient = x - signal.lfilter(B_TRUE, F_TRUE, u)
    state = np.convolve(F_TRUE, transient)[:2]
    return arxid.IOData(x + v, u, ts=1.0), x, state, noise**2


def test_estimated_initial_state_reproduces_the_noise_free_output():
    data, x, state, _ = mid_transient(0, noise=0.0)
    model = arxid.oe(data, 2, 2, 1, initial="estimate")
    assert model.converged_ and model.initial_ == "estimate" and model.first_lag_ == 0
    np.testing.assert_allclose(model.parameters_, [0.5, 0.3, -1.8, 0.85], atol=1e-10)
    # One run, its state: the numerator of the output's free response over F.
    assert list(model.initial_states_) == [(0, 2000)]
    np.testing.assert_allclose(model.initial_states_[(0, 2000)], state, rtol=1e-8)
    assert model.n_rows_ == 2000  # every sample scored
    for horizon in (1, 3, None):
        np.testing.assert_allclose(model.predict(data, horizon, initial="estimate"), x, atol=1e-8)
    # From rest the same parameters miss the transient at the start of the record.
    assert np.nanmax(np.abs(model.predict(data, None) - x)) > 100


@pytest.mark.parametrize("seed", range(2))
def test_mid_transient_output_error_estimate_reaches_the_noise_floor_where_zero_does_not(seed):
    data, _, _, variance = mid_transient(seed)
    model = arxid.oe(data, 2, 2, 1, initial="estimate")
    assert model.converged_
    assert model.loss_ == pytest.approx(variance, rel=0.05)
    assert np.all(np.abs(model.parameters_ - [0.5, 0.3, -1.8, 0.85]) <= 3 * model.standard_errors_)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", arxid.ArxidWarning)
        at_rest = arxid.oe(data, 2, 2, 1)  # initial="zero", the default
    assert at_rest.initial_ == "zero" and at_rest.initial_states_ == {}
    assert at_rest.loss_ > 100 * variance  # measured: about 1700 σ²


@pytest.mark.parametrize("seed", range(2))
def test_mid_transient_box_jenkins_estimates_plant_and_noise_model(seed):
    data, _, _, variance = mid_transient(seed, coloured=True)
    model = arxid.bj(data, 2, 1, 1, 2, 1, initial="estimate")
    truth = np.r_[B_TRUE[1:], C_TRUE[1:], D_TRUE[1:], F_TRUE[1:]]
    assert model.loss_ == pytest.approx(variance, rel=0.05)
    assert np.all(np.abs(model.parameters_ - truth) <= 3 * model.standard_errors_)
    # One state per run; for BJ the free response of the noise filter is part of it.
    assert len(model.initial_states_[(0, 2000)]) == 3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", arxid.ArxidWarning)
        assert arxid.bj(data, 2, 1, 1, 2, 1).loss_ > 10 * variance  # measured: about 37 σ²


def test_one_initial_state_per_experiment_and_per_run_between_missing_samples():
    (d1, x1, s1, _), (d2, x2, s2, _) = mid_transient(3, 1500, noise=0.0), mid_transient(4, 1000, noise=0.0)
    y = np.r_[d1.y, d2.y]
    data = arxid.IOData(y, np.r_[d1.u, d2.u], ts=1.0, experiment_starts=(0, 1500))
    model = arxid.oe(data, 2, 2, 1, initial="estimate")
    assert list(model.initial_states_) == [(0, 1500), (1500, 2500)]
    np.testing.assert_allclose(model.initial_states_[(0, 1500)], s1, rtol=1e-7)
    np.testing.assert_allclose(model.initial_states_[(1500, 2500)], s2, rtol=1e-7)
    np.testing.assert_allclose(model.predict(data, None, initial="estimate"), np.r_[x1, x2], atol=1e-7)
    # A missing sample splits the first experiment into two runs, each with its own state; a run
    # too short to say more than its own state (here 2 samples) is left out, as arx leaves it out.
    holed = y.copy()
    holed[[700, 703]] = np.nan
    model = arxid.oe(arxid.IOData(holed, data.u, ts=1.0, experiment_starts=(0, 1500)), 2, 2, 1, initial="estimate")
    assert list(model.initial_states_) == [(0, 700), (704, 1500), (1500, 2500)]
    assert model.n_rows_ == 2500 - 4 and model.n_skipped_ == 4
    np.testing.assert_allclose(model.parameters_, [0.5, 0.3, -1.8, 0.85], atol=1e-9)


def test_initial_option_round_trips_and_is_checked():
    data, _, _, _ = mid_transient(5)
    model = arxid.oe(data, 2, 2, 1, initial="estimate")
    loaded = arxid.PolynomialModel.from_json(model.to_json())
    assert loaded.initial_ == "estimate"
    np.testing.assert_array_equal(loaded.initial_states_[(0, 2000)], model.initial_states_[(0, 2000)])
    np.testing.assert_array_equal(
        loaded.predict(data, 1, initial="estimate"), model.predict(data, 1, initial="estimate")
    )
    # On the estimation data the one-step predictor with estimated states is the fit's.
    e = data.y - model.predict(data, 1, initial="estimate")
    assert np.mean(e**2) == pytest.approx(model.loss_, rel=1e-9)
    with pytest.raises(arxid.ArxidError, match="'zero' or 'estimate'"):
        arxid.oe(data, 2, 2, 1, initial="auto")
    with pytest.raises(arxid.ArxidError, match="'zero' or 'estimate'"):
        model.predict(data, None, initial=True)


def test_compare_estimates_initial_states_of_every_linear_model():
    est, _, _, _ = mid_transient(6, noise=0.05)
    val, x, _, _ = mid_transient(7, noise=0.05)
    oe = arxid.oe(est, 2, 2, 1, initial="estimate")
    arx = arxid.arx(est, 2, 2, 1)
    at_rest = arxid.compare({"oe": oe, "arx": arx}, val)
    estimated = arxid.compare({"oe": oe, "arx": arx}, val, initial="estimate")
    # The validation record starts mid-transient: from rest the OE model misses it.
    assert at_rest.fit_percent[0] < 90 < 99 < estimated.fit_percent[0]
    assert estimated.fit_percent[1] > at_rest.fit_percent[1]
    # The ARX model's polynomial form has the same parameters and the same one-step predictions.
    poly = arxid.PolynomialModel.from_arx(arx)
    np.testing.assert_array_equal(poly.parameters_, arx.parameters_)
    np.testing.assert_allclose(poly.predict(val, 1), arx.predict(val, 1), atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(estimated.predictions[0], oe.predict(val, None, initial="estimate"))
    # An ARX model with effect terms is compared from fitted initial outputs too (issue 27, point 7:
    # the ladder's models carry effects); it used to be refused.
    const = arxid.arx(est, 2, 2, 1, effects=["const"])
    assert arxid.compare(const, val, initial="estimate").rms[0] < arxid.compare(const, val).rms[0]


@pytest.mark.parametrize("fit", ["oe_two_inputs", "polyest"])
def test_estimated_state_of_two_inputs_and_of_a_shared_pole_reproduces_the_output(fit):
    """The state count covers each input's delay and poles (OE with two inputs) and A with F."""
    rng = np.random.default_rng(1)
    u1 = np.r_[10 * np.ones(PRE), np.sign(rng.standard_normal(3000))]
    u2 = np.r_[-5 * np.ones(PRE), rng.standard_normal(3000)]
    if fit == "oe_two_inputs":
        x = signal.lfilter([0, 0, 0.5, 0.3], [1, -1.5, 0.7], u1) + signal.lfilter([0.2, 0.4], [1, -0.9], u2)
        data = arxid.IOData(x[PRE:], np.c_[u1, u2][PRE:], ts=1.0)
        model = arxid.oe(data, [2, 2], [2, 1], [2, 0], initial="estimate")
        truth = [0.5, 0.3, 0.2, 0.4, -1.5, 0.7, -0.9]
    else:
        x = signal.lfilter([0, 1.0, 0.5], np.convolve([1, -0.8], [1, -1.2, 0.5]), u1)
        data = arxid.IOData(x[PRE:], u1[PRE:], ts=1.0)
        model = arxid.polyest(data, 1, 2, 0, 0, 2, 1, initial="estimate")
        truth = [-0.8, 1.0, 0.5, -1.2, 0.5]
    np.testing.assert_allclose(model.parameters_, truth, atol=1e-9)
    np.testing.assert_allclose(model.predict(data, None, initial="estimate"), x[PRE:], atol=1e-8)
    np.testing.assert_allclose(model.predict(data, 1, initial="estimate"), x[PRE:], atol=1e-8)
