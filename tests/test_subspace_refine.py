"""The prediction-error refinement of subspace estimates (arxid.ssest(..., refine=True)): coloured
noise fitted down to the true predictor, exact models kept exact, several experiments and gaps,
and typed errors."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
from scipy import signal

import arxid
from arxid._base import _core
from arxid.exceptions import ConvergenceError, DataError
from arxid.models.state_space import StateSpaceModel
from subspace_systems import System, as_data, binary_inputs, random_system

TRUE = System(
    a=np.array([[0.8, 0.3, 0.0], [-0.3, 0.8, 0.0], [0.0, 0.0, 0.5]]),
    b=np.array([[1.0, 0.0], [0.0, 0.5], [0.7, -1.0]]),
    c=np.array([[1.0, 0.0, 1.0], [0.0, 2.0, -0.5]]),
    d=np.array([[0.1, 0.0], [0.0, -0.2]]),
)


def innovation_system(seed: int):
    """A random 4-state, 2-input, 2-output plant and its steady-state Kalman gain (scipy's DARE for
    unit process noise and output noise of variance 0.1): coloured output noise, K far from zero."""
    rng = np.random.default_rng(seed)
    plant = random_system(rng, 4, 2, 2)
    p = scipy.linalg.solve_discrete_are(plant.a.T, plant.c.T, np.eye(4), 0.1 * np.eye(2))
    gain = plant.a @ p @ plant.c.T @ np.linalg.inv(plant.c @ p @ plant.c.T + 0.1 * np.eye(2))
    return rng, plant, gain


def innovation_data(rng, plant: System, gain: np.ndarray, n: int, sigma: float = 0.5):
    u = binary_inputs(rng, n, 2)
    e = sigma * rng.normal(size=(n, 2))
    x, y = np.zeros(4), np.empty((n, 2))
    for t in range(n):
        y[t] = plant.c @ x + plant.d @ u[t] + e[t]
        x = plant.a @ x + plant.b @ u[t] + gain @ e[t]
    return u, y


def one_step_mse(model: StateSpaceModel, data, y: np.ndarray) -> float:
    return float(np.mean((y - model.predict(data, k=1)) ** 2))


def test_coloured_noise_is_refined_towards_the_true_predictor():
    rng, plant, gain = innovation_system(5)
    assert np.max(np.abs(np.linalg.eigvals(plant.a - gain @ plant.c))) < 1.0
    u, y = innovation_data(rng, plant, gain, 1500)
    uv, yv = innovation_data(rng, plant, gain, 4000)
    est, val = as_data(y, u), as_data(yv, uv)
    subspace = arxid.ssest(est, order=4, horizon=4)
    refined = arxid.ssest(est, order=4, horizon=4, refine=True)
    truth = StateSpaceModel(
        a=plant.a,
        b=plant.b,
        c=plant.c,
        d=plant.d,
        k=gain,
        initial_states=np.zeros((1, 4)),
        ts=0.01,
        input_names=("u1", "u2"),
        output_names=("y1", "y2"),
    )
    report = refined.refinement
    assert report is not None and report.converged and report.iterations >= 1
    assert report.loss < report.start_loss and "refinement" in str(refined)
    best, before, after = (one_step_mse(m, val, yv) for m in (truth, subspace, refined))
    # On fresh data: better than the subspace estimate, within 2 % of the true predictor's error.
    assert after < before and after < 1.02 * best, (best, before, after)
    assert np.max(np.abs(np.linalg.eigvals(refined.a - refined.k @ refined.c))) < 1.0


def test_noise_free_data_keep_the_exact_model_markov_parameters_as_scipy_computes_them():
    rng = np.random.default_rng(1)
    u = binary_inputs(rng, 1500, 2)
    y = TRUE.simulate(u, x0=[2.0, -1.0, 0.5])
    model = arxid.ssest(as_data(y, u), refine=True)
    assert model.order == 3 and model.refinement is not None
    # The reference: scipy's impulse responses of the true system, input by input.
    for j in range(2):
        _, (want,) = signal.dimpulse((TRUE.a, TRUE.b[:, [j]], TRUE.c, TRUE.d[:, [j]], 0.01), n=10)
        _, (got,) = signal.dimpulse((model.a, model.b[:, [j]], model.c, model.d[:, [j]], 0.01), n=10)
        np.testing.assert_allclose(got, want, atol=1e-8)
    np.testing.assert_allclose(model.simulate(u, model.x0), y, atol=1e-8)


def test_several_experiments_and_gaps_each_get_their_initial_state():
    rng, plant, gain = innovation_system(7)
    runs = [innovation_data(rng, plant, gain, 700) for _ in range(2)]
    u, y = np.vstack([r[0] for r in runs]), np.vstack([r[1] for r in runs])
    y[1000, 1] = np.nan  # splits the second experiment
    data = as_data(y, u, experiment_starts=(0, 700))
    refined = arxid.ssest(data, order=4, refine=True)
    assert refined.initial_states.shape == (3, 4)
    assert refined.refinement is not None and refined.refinement.loss <= refined.refinement.start_loss
    zero = arxid.ssest(data, order=4, refine=True, initial="zero")
    np.testing.assert_array_equal(zero.initial_states, np.zeros((3, 4)))


def test_an_unstable_predictor_and_mismatched_shapes_are_typed_errors():
    rng = np.random.default_rng(2)
    u = binary_inputs(rng, 300, 2)
    y = TRUE.simulate(u)
    k = np.array([[-3.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    x0 = np.zeros((1, 3))
    with pytest.raises(ConvergenceError, match="unstable"):
        _core.subspace_refine(TRUE.a, TRUE.b, TRUE.c, TRUE.d, k, x0, u, y, [(0, 300)])
    with pytest.raises(DataError, match="initial states"):
        _core.subspace_refine(TRUE.a, TRUE.b, TRUE.c, TRUE.d, np.zeros((3, 2)), x0, u, y, [(0, 100), (100, 300)])
    with pytest.raises(DataError):
        _core.subspace_refine(TRUE.a, TRUE.b, TRUE.c, TRUE.d, np.zeros((3, 2)), x0, u, y, [(0, 4)])
