"""compare, residuals and where_it_fails of a StateSpaceModel, per output, against known answers:
the exact model of a seeded system, its innovations, python-control's simulation."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.checks.state_space import PerOutput
from arxid.exceptions import DataError
from subspace_systems import binary_inputs, random_system

NAMES = ["p", "q", "r"]


def exact_model(system, k=None, **kwargs) -> arxid.StateSpaceModel:
    n, ny = system.a.shape[0], system.c.shape[0]
    return arxid.StateSpaceModel(
        a=system.a,
        b=system.b,
        c=system.c,
        d=system.d,
        k=np.zeros((n, ny)) if k is None else k,
        initial_states=np.zeros((1, n)),
        ts=0.01,
        input_names=("m1", "m2"),
        output_names=tuple(NAMES[:ny]),
        **kwargs,
    )


@pytest.fixture(scope="module")
def innovation_case():
    """A 4-state, 2-input, 3-output system in innovation form with white innovations e."""
    rng = np.random.default_rng(44)
    system = random_system(rng, 4, 2, 3)
    k = 0.2 * rng.normal(size=(4, 3))
    assert np.all(np.abs(np.linalg.eigvals(system.a - k @ system.c)) < 1)
    n = 4000
    u = binary_inputs(rng, n, 2)
    e = 0.05 * rng.normal(size=(n, 3))
    x = np.zeros(4)
    y = np.empty((n, 3))
    for t in range(n):
        y[t] = system.c @ x + e[t]
        x = system.a @ x + system.b @ u[t] + k @ e[t]
    data = arxid.IOData(y, u, ts=0.01, output_name=NAMES, input_names=["m1", "m2"])
    return system, k, e, data


def test_compare_gives_each_outputs_fit_of_the_exact_model_as_python_control_simulates_it():
    control = pytest.importorskip("control")
    rng = np.random.default_rng(7)
    system = random_system(rng, 3, 2, 3)
    u = binary_inputs(rng, 600, 2)
    model = exact_model(system)
    reference = control.forced_response(model.to_control(), U=u.T).outputs.T
    data = arxid.IOData(reference, u, ts=0.01, output_name=NAMES, input_names=["m1", "m2"])
    result = arxid.compare(model, data)
    assert isinstance(result, PerOutput) and list(result) == NAMES
    for i, name in enumerate(NAMES):
        c = result[name]
        assert c.output_name == name and c.names == ("N4SID, 3 states",)
        np.testing.assert_allclose(c.predictions[0], reference[:, i], rtol=1e-10, atol=1e-10)
        assert c.fit_percent[0] == pytest.approx(100.0, abs=1e-6)
    assert set(result.to_dict()) == set(NAMES)
    assert "output q:" in str(result)


def test_compare_puts_an_arx_model_of_one_output_beside_the_state_space_model(innovation_case):
    _, _, _, data = innovation_case
    ss = arxid.ssest(data, order=4)
    arx_q = arxid.arx(data.output("q"), 4, [4, 4], [1, 1])
    result = arxid.compare({"subspace": ss, "arx": arx_q}, data, horizon=1)
    assert result["p"].names == ("subspace",) and result["q"].names == ("subspace", "arx")
    np.testing.assert_allclose(result["q"].fit_percent[1], arxid.compare(arx_q, data.output("q"), 1).fit_percent[0])
    assert result["q"].fit_percent[0] == pytest.approx(ss.fit_percent(data, k=1, initial="zero")[1], abs=1e-9)


def test_a_state_space_model_of_one_output_compares_as_any_single_output_model():
    rng = np.random.default_rng(5)
    u = rng.choice([-1.0, 1.0], size=1500)
    y = np.zeros(1500)
    for t in range(1, 1500):
        y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 1]
    data = arxid.IOData(y, u, ts=0.01)
    ss = arxid.ssest(data, order=1)
    c = arxid.compare([ss, arxid.arx(data, 1, 1, 1)], data)
    assert isinstance(c, arxid.checks.Comparison)
    np.testing.assert_allclose(c.fit_percent, [100.0, 100.0], atol=1e-6)


def test_the_residual_of_the_exact_innovation_form_is_the_innovation_and_passes(innovation_case):
    system, k, e, data = innovation_case
    result = arxid.residuals(exact_model(system, k), data)
    assert list(result) == NAMES
    for i, name in enumerate(NAMES):
        r = result[name]
        np.testing.assert_allclose(r.residual[200:], e[200:, i], atol=1e-8)
        assert r.ljung_box_dof == 25 - 4 and r.whiteness_expected
        assert r.is_white and all(r.independent.values()), str(r)


def test_a_model_missing_an_input_path_fails_the_independence_test_of_that_input(innovation_case):
    system, k, _, data = innovation_case
    b = system.b.copy()
    b[:, 1] = 0.0  # the model ignores m2
    wrong = exact_model(type(system)(system.a, b, system.c, system.d), k)
    result = arxid.residuals(wrong, data)
    for name in NAMES:
        assert result[name].independent["m2"] is False
        assert result[name].independent["m1"] is True


def test_where_it_fails_finds_the_burst_in_the_output_that_has_it(innovation_case):
    system, k, _, data = innovation_case
    y = data.outputs.copy()
    y[2500:2700, 1] += np.random.default_rng(0).normal(size=200)  # a disturbance on q only
    burst = arxid.IOData(y, data.u, ts=0.01, output_name=NAMES, input_names=["m1", "m2"])
    result = arxid.where_it_fails(exact_model(system, k), burst, window=200)
    worst_q = result["q"].worst_segments[0]
    assert 2400 <= worst_q.start <= 2600 and worst_q.significant
    assert not result["p"].worst_segments[0].significant
    assert result["q"].model_name == "N4SID, 4 states, output q"


def test_the_data_must_hold_every_output_of_the_model(innovation_case):
    system, k, _, data = innovation_case
    model = exact_model(system, k)
    for check in (arxid.compare, arxid.residuals, arxid.where_it_fails):
        with pytest.raises(DataError, match=r"lack the model's output\(s\) \['p', 'r'\].*all of them"):
            check(model, data.output("q"))
    other = arxid.IOData(data.outputs, data.u, ts=0.02, output_name=NAMES, input_names=["m1", "m2"])
    with pytest.raises(DataError, match="ts = 0.02 s"):
        arxid.compare(model, other)


def test_outputs_in_another_order_are_matched_by_name(innovation_case):
    system, k, _, data = innovation_case
    model = exact_model(system, k)
    shuffled = arxid.IOData(
        data.outputs[:, [2, 0, 1]], data.u, ts=0.01, output_name=["r", "p", "q"], input_names=["m1", "m2"]
    )
    a, b = arxid.compare(model, data, horizon=1), arxid.compare(model, shuffled, horizon=1)
    assert list(b) == ["r", "p", "q"]
    for name in NAMES:
        np.testing.assert_allclose(a[name].predictions[0], b[name].predictions[0], rtol=1e-12)
