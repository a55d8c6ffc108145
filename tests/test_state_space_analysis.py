"""The analysis of a state-space model of several outputs: the coupling against python-control,
a decoupled plant's coupling, the report's sections and plots, and ``arxid ssest``."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.cli import main
from arxid.analysis.coupling import coupling
from arxid.analysis.report.state_space import render_state_space_html
from arxid.analysis.state_space import NO_EFFECT_SEARCH, analyse_state_space
from subspace_systems import add_noise, binary_inputs, random_system

NAMES = ["p", "q", "r"]


def decoupled_plant(n: int = 4000, seed: int = 2):
    """Three first-order channels, input j → output j only (poles 0.9, 0.8, 0.7; gains 1, 2, 3)."""
    rng = np.random.default_rng(seed)
    u = binary_inputs(rng, n, 3)
    a, b = np.array([0.9, 0.8, 0.7]), np.array([0.1, 0.4, 0.9])
    y = np.zeros((n, 3))
    for t in range(1, n):
        y[t] = a * y[t - 1] + b * u[t - 1]
    y = add_noise(rng, y, 30)
    return arxid.IOData(y, u, ts=0.01, output_name=NAMES, input_names=["m1", "m2", "m3"], output_unit="rad/s")


@pytest.fixture(scope="module")
def analysis():
    return analyse_state_space(decoupled_plant())


def test_the_coupling_of_a_decoupled_plant_is_its_diagonal(analysis):
    cp = analysis.coupling
    assert analysis.model.order == 3
    np.testing.assert_allclose(np.diag(cp.steady_state), [1.0, 2.0, 3.0], rtol=0.02)
    off = cp.share[~np.eye(3, dtype=bool)]
    assert np.all(off < 0.05), cp.share
    np.testing.assert_allclose(np.diag(cp.share), 1.0, atol=0.05)
    assert [cp.strongest_input(name) for name in NAMES] == ["m1", "m2", "m3"]
    assert all(f > 95 for f in analysis.fit_percent.values()), analysis.fit_percent


def test_the_coupling_is_python_controls_frequency_response():
    control = pytest.importorskip("control")
    rng = np.random.default_rng(9)
    s = random_system(rng, 4, 2, 3)
    model = arxid.StateSpaceModel(
        a=s.a, b=s.b, c=s.c, d=s.d, k=np.zeros((4, 3)), initial_states=np.zeros((1, 4)), ts=0.01,
        input_names=("m1", "m2"), output_names=tuple(NAMES),
    )  # fmt: skip
    cp = coupling(model)
    sys = model.to_control()
    np.testing.assert_allclose(cp.steady_state, control.dcgain(sys), rtol=1e-9, atol=1e-12)
    for i in range(3):
        for j in range(2):
            w = 2 * np.pi * cp.peak_frequency[i, j]
            at_peak = abs(complex(sys[i, j](np.exp(1j * w * 0.01))))
            assert cp.peak[i, j] == pytest.approx(at_peak, rel=1e-9)
            grid = np.geomspace(0.05, 50.0, 400) * 2 * np.pi
            assert cp.peak[i, j] >= np.max(np.abs(sys[i, j](np.exp(1j * grid * 0.01)))) * (1 - 1e-9)
    assert np.isnan(cp.share).all()


def test_the_analysis_checks_each_output_and_says_what_it_does_not_do(analysis):
    assert list(analysis.comparisons) == NAMES and list(analysis.residual_tests) == NAMES
    assert list(analysis.failures) == NAMES
    assert analysis.notes[0] == NO_EFFECT_SEARCH
    text = str(analysis)
    assert "driven most by" in text and "No search for a missing effect" in text
    d = json.loads(analysis.to_json())
    assert set(d["outputs"]) == set(NAMES) and d["model"]["order"] == 3
    assert d["coupling"]["steady_state"]["q"]["m2"] == pytest.approx(2.0, rel=0.02)


def test_the_report_holds_every_section_and_plot(analysis):
    page = render_state_space_html(analysis, source="decoupled.csv")
    for section in ("order", "fit", "coupling", "residuals", "fails", "effects", "not-run"):
        assert f'id="{section}"' in page
    # singular values, a comparison and a residual plot per output, the coupling heat map
    assert page.count("<img ") == 1 + 3 + 1 + 3
    assert "singular value criterion" in page and "Steady-state gains" in page
    assert "No search for a missing effect" in page
    assert "arxid ssest --json" in page


def test_diagnose_takes_a_state_space_model_and_names_nothing_on_a_linear_plant(analysis):
    found = arxid.diagnose(analysis.model, analysis.estimation, analysis.validation, candidates=["m1^2", "const"])
    assert list(found) == NAMES
    assert all(not d.significant and {s.effect for s in d.suspects} == {"m1^2", "const"} for d in found.values())


@pytest.fixture
def rates_csv(tmp_path):
    d = decoupled_plant(3000)
    path = tmp_path / "rates.csv"
    np.savetxt(path, np.column_stack([d.outputs, d.u]), delimiter=",", header="p,q,r,m1,m2,m3", comments="")
    return path


def test_cli_ssest_prints_each_outputs_fit_and_writes_the_report(rates_csv, tmp_path, capsys):
    report = tmp_path / "rates.html"
    args = ["ssest", str(rates_csv), "--output", "p,q,r", "--inputs", "m1,m2,m3", "--ts", "0.01"]
    assert main([*args, "--json", "-o", str(report)]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["outputs"]) == set(NAMES)
    assert all(o["fit_percent"] > 95 for o in out["outputs"].values())
    assert out["report"] == str(report) and report.stat().st_size > 10_000
    assert main([*args, "--order", "3", "--method", "moesp", "--detrend"]) == 0
    text = capsys.readouterr().out
    assert "MOESP" in text and "3 states (fixed by the caller)" in text and "fit %" in text


def test_cli_single_output_commands_refuse_several_outputs(rates_csv, capsys):
    assert main(["fit", str(rates_csv), "--output", "p,q", "--inputs", "m1", "--ts", "0.01", "--orders", "1,1,1"]) == 2
    assert "'arxid ssest'" in capsys.readouterr().err


def test_the_quadrotors_rate_model_shows_the_plus_frames_coupling():
    """docs/state-space.md: four motor commands to p, q, r of a simulated flight (seed 1, 20 s)."""
    from arxid.datasets import body_rates, quadrotor_flight

    rates = body_rates(quadrotor_flight(seed=1, duration=20.0, output="p")).detrend()
    a = analyse_state_space(rates, horizon=10, stable=True)
    fits = a.fit_percent
    assert fits["p"] > 95 and fits["q"] > 92 and fits["r"] > 55, fits
    share = a.coupling.share
    # roll on the side motors 2 and 4, pitch on front and back 1 and 3, yaw on all four
    assert min(share[0, 1], share[0, 3]) > 10 * max(share[0, 0], share[0, 2]), share
    assert min(share[1, 0], share[1, 2]) > 5 * max(share[1, 1], share[1, 3]), share
    assert share[2].min() > 1.0, share


def test_body_rates_from_the_mixers_torques():
    from arxid.datasets import body_rates, quadrotor_flight
    from arxid.exceptions import DataError

    flight = quadrotor_flight(seed=2, duration=1.0, output="p")
    rates = body_rates(flight, inputs="torques")
    w2 = np.column_stack([flight.signal(f"w{i}") ** 2 for i in range(1, 5)])
    assert rates.input_names == ("roll_torque", "pitch_torque", "yaw_torque")
    np.testing.assert_allclose(rates.u[:, 0], w2[:, 3] - w2[:, 1], rtol=1e-12)  # plus frame: left − right
    np.testing.assert_allclose(rates.u[:, 1], w2[:, 2] - w2[:, 0], rtol=1e-12)  # back − front
    np.testing.assert_array_equal(rates.outputs, np.column_stack([flight.signal(n) for n in ("p", "q", "r")]))
    with pytest.raises(DataError, match="inputs must be one of"):
        body_rates(flight, inputs="speeds")
