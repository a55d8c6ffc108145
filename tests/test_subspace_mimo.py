"""The acceptance test of issue 44: 20 random stable MIMO systems (2–4 inputs and outputs, orders
2–8, white output noise at 20 dB, random binary inputs, fixed seeds). The chosen order must be right
in at least 18 of 20, and every output's validation fit within 1 point of the true system's."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid._base.metrics import fit_percent
from subspace_systems import add_noise, as_data, binary_inputs, random_system

N_EST, N_VAL = 4000, 2000


def one_case(seed: int):
    rng = np.random.default_rng(1000 + seed)
    n, nu, ny = int(rng.integers(2, 9)), int(rng.integers(2, 5)), int(rng.integers(2, 5))
    true = random_system(rng, n, nu, ny)
    u = binary_inputs(rng, N_EST + N_VAL, nu)
    clean = true.simulate(u)
    y = add_noise(rng, clean, 20)
    model = arxid.ssest(as_data(y[:N_EST], u[:N_EST]))
    val = as_data(y[N_EST:], u[N_EST:])
    # The true system starts the validation part in its true state, so its fit is the noise's alone.
    true_fit = np.array([fit_percent(y[N_EST:, i], clean[N_EST:, i]) for i in range(ny)])
    return n, model, model.fit_percent(val), true_fit


@pytest.fixture(scope="module")
def cases():
    return [one_case(seed) for seed in range(20)]


def test_the_order_is_right_in_at_least_90_percent(cases):
    right = [model.order == n for n, model, _, _ in cases]
    assert sum(right) >= 18, [(n, model.order) for n, model, _, _ in cases]


def test_every_outputs_validation_fit_is_within_one_point_of_the_true_systems(cases):
    for n, model, fit, true_fit in cases:
        assert np.all(fit > true_fit - 1.0), (n, model.order, fit, true_fit)
