"""The closed-loop chain of arxid.analyse: the feedback verdict steers the method (IV with a logged
reference and validation on the two-stage input; the direct Box-Jenkins method without one), loop
signals are never proposed as extra inputs, and the plant comes out right where ARX and OE do not."""

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.closed_loop import loop_signal_names, reference_candidates
from arxid.analysis.verdicts import delay_notes
from arxid.datasets import PiLoopPlant, RateLoopPlant, pi_loop, pid_rate_loop


def _gain_and_pole_error(a, b, plant) -> tuple[float, float]:
    """Relative static-gain error and the largest distance of a true pole to the model's nearest."""
    poles = np.roots(a)
    return float(b.sum() / a.sum() / plant.gain - 1), float(max(min(abs(poles - q)) for q in plant.poles))


def _loop_effects(analysis) -> set[str]:
    """Every effect any diagnosis of the ladder listed, and those the ladder added."""
    listed = {s.effect for d in analysis.ladder.diagnoses for s in d.suspects}
    return listed | set(analysis.ladder.final_model.effects)


@pytest.mark.parametrize("seed", range(5))
def test_pid_rate_loop_plant_within_3_percent_and_poles_within_0_01(seed):
    plant = RateLoopPlant()
    data = pid_rate_loop(seed=seed, n_samples=20000)
    a = arxid.analyse(data, reference="rate_sp")
    assert a.feedback.feedback and a.closed_loop.key == "iv-reference"
    gain, pole = _gain_and_pole_error(a.model.a, a.model.b[0], plant)
    assert abs(gain) < 0.03 and pole < 0.01, (a.model.structure_name(), gain, pole)
    assert min(a.model.nk_) >= 1
    est = data.split(0.7)[0]
    arx = arxid.arx(est, 2, 1, plant.nk)  # the true structure, by least squares: poles far off
    assert _gain_and_pole_error(arx.a, arx.b[0], plant)[1] > 5 * max(pole, 0.002)
    oe = arxid.oe(est, 1, 2, plant.nk)  # output error: the feedback leaks into the plant
    oe_gain, oe_pole = _gain_and_pole_error(oe.f[0], oe.b[0], plant)
    assert abs(oe_gain) > abs(gain) or oe_pole > pole
    assert not {"rate_sp", "pid_d"} & {f for e in _loop_effects(a) for f in e.replace("*", " ").split()}


@pytest.mark.parametrize("seed", range(8))
def test_pi_loop_plant_recovered_where_arx_and_oe_are_biased(seed):
    plant = PiLoopPlant()
    data = pi_loop(seed=seed, n_samples=30000, band=0.5)
    a = arxid.analyse(data, reference="r")
    gain, pole = _gain_and_pole_error(a.model.a, a.model.b[0], plant)
    assert abs(gain) < 0.03 and pole < 0.01, (a.model.structure_name(), gain, pole)
    est = data.split(0.7)[0]
    arx = arxid.arx(est, 2, 2, 1)
    assert _gain_and_pole_error(arx.a, arx.b[0], plant)[1] > 0.05
    oe = arxid.oe(est, 2, 2, 1)
    assert abs(_gain_and_pole_error(oe.f[0], oe.b[0], plant)[0]) > 0.2
    assert "r" not in {e for e in _loop_effects(a)}


def test_method_json_and_notes_name_the_method_and_the_criterion():
    a = arxid.analyse(pid_rate_loop(seed=7, n_samples=12000), reference="rate_sp", max_steps=1)
    out = json.loads(a.to_json())
    assert out["closed_loop"]["key"] == "iv-reference"
    assert out["closed_loop"]["references"] == ["rate_sp"]
    assert set(out["closed_loop"]["loop_signals"]) == {"rate_sp", "pid_d"}
    notes = " ".join(a.notes)
    assert "instrumental variables with the reference rate_sp" in notes
    assert "reference-driven part of the validation input" in notes
    assert "operating point" in notes


def test_the_reference_is_recognised_by_its_name():
    d = pid_rate_loop(seed=3, n_samples=12000)
    a = arxid.analyse(d, max_steps=1)  # rate_sp is found without reference=
    assert a.closed_loop.key == "iv-reference" and a.closed_loop.references == ("rate_sp",)


def test_without_a_reference_the_direct_method_says_the_plant_may_be_biased():
    d = pid_rate_loop(seed=4, n_samples=8000)
    d = d.with_signals(extra={})  # the setpoint was not logged
    a = arxid.analyse(d, max_steps=1, grid={"na": [2], "nb": [1], "nk": [2, 3, 4]})
    assert a.closed_loop.key == "direct"
    assert a.model.structure_name().startswith("BJ(")
    assert "may be biased" in " ".join(a.notes) or "biases the plant estimate" in " ".join(a.notes)


def test_open_loop_data_keep_the_open_loop_chain():
    a = arxid.analyse(pi_loop(seed=1, n_samples=6000, closed=False), max_steps=1)
    assert not a.feedback.feedback and a.closed_loop.key == "open-loop"
    assert not any("Closed-loop method" in n for n in a.notes)


def test_reference_and_controller_signals_are_recognised_but_not_the_battery():
    names = {
        "setpoint_0": 0,
        "RATE_RDes": 0,
        "vehicle_rates_setpoint_roll": 0,
        "roll_sp": 0,
        "axisP_0": 0,
        "motor_2": 0,
        "vbatLatest": 0,
        "BAT_Volt": 0,
        "battery_status_voltage_v": 0,
    }
    d = arxid.IOData(np.zeros(300), np.zeros(300), 0.001, extra={k: np.zeros(300) for k in names})
    assert set(reference_candidates(d)) == {"setpoint_0", "RATE_RDes", "vehicle_rates_setpoint_roll", "roll_sp"}
    loop = set(loop_signal_names(d, ["setpoint_0"]))
    assert {"axisP_0", "motor_2", "setpoint_0", "roll_sp"} <= loop
    assert not {"vbatLatest", "BAT_Volt", "battery_status_voltage_v"} & loop


def test_a_named_reference_that_is_not_logged_is_a_clear_error():
    with pytest.raises(arxid.DataError, match="no signal 'roll_sp'"):
        arxid.analyse(pid_rate_loop(seed=0, n_samples=2000), reference="roll_sp")


def test_zero_delay_at_kilohertz_rates_is_reported():
    rng = np.random.default_rng(0)
    u = rng.standard_normal(3000)
    y = np.convolve(u, [0.5, 0.2])[:3000] + 0.01 * rng.standard_normal(3000)
    d = arxid.IOData(y, u, ts=0.001)
    m = arxid.arx(d, 1, 2, 0)
    assert "no delay from u1 to y" in delay_notes(m, d)[0]
    assert delay_notes(m, arxid.IOData(y, u, ts=0.1)) == ()
    assert delay_notes(arxid.arx(d, 1, 2, 1), d) == ()
    slow = arxid.IOData(y, u, ts=0.1)
    assert "the controller reacting to the output" in delay_notes(arxid.arx(slow, 1, 2, 0), slow, closed=True)[0]


def test_cli_reference_names_the_method(tmp_path, capsys):
    from arxid.analysis.cli import main

    d = pid_rate_loop(seed=5, n_samples=8000)
    path = tmp_path / "loop.csv"
    cols = {"rate": d.y, "command": d.u[:, 0], "rate_sp": d.extra["rate_sp"]}
    np.savetxt(path, np.column_stack(list(cols.values())), delimiter=",", header=",".join(cols), comments="")
    argv = ["diagnose", str(path), "--output", "rate", "--inputs", "command", "--reference", "rate_sp"]
    assert main([*argv, "--ts", "0.002", "--json", "--no-progress", "--max-steps", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["closed_loop"]["key"] == "iv-reference"


def test_quadrotor_simulator_under_its_attitude_and_rate_controller():
    # The simulator flies a roll setpoint under its PID; a noisier gyro (0.05 rad/s) makes the loop
    # visible to the feedback test at this length. Roll command d4 - d2 to the gyro's roll rate p:
    # torque to rate integrates.
    from dataclasses import replace

    from arxid.inputs import prbs
    from arxid.quadrotor.flight_sim import QuadrotorParameters

    ref = prbs(9, band=0.2, levels=(-0.15, 0.15), ts=0.002, periods=6)
    par = replace(QuadrotorParameters(), gyro_noise=0.05)
    f = arxid.datasets.quadrotor_flight(seed=1, duration=16.0, roll_reference=ref.values, parameters=par)
    d = arxid.IOData(f.extra["p"], f.u[:, 3] - f.u[:, 1], f.ts, output_name="p", input_names=("roll_cmd",))
    d = d.with_signals(extra={k: f.extra[k] for k in ("roll_ref", "vbat")})
    a = arxid.analyse(d, reference="roll_ref", max_steps=1)
    assert a.closed_loop.key == "iv-reference" and "roll_ref" in a.closed_loop.loop_signals
    assert "roll_ref" not in {f for e in _loop_effects(a) for f in e.replace("*", " ").split()}
    assert min(a.model.nk_) >= 1
    assert min(abs(np.abs(a.model.poles()) - 1.0)) < 0.01  # the integrator from torque to rate


@pytest.mark.realdata
def test_real_px4_log_names_its_method_and_never_proposes_the_setpoint(shared_data):
    pytest.importorskip("pyulog", reason="needs the px4 extra: pip install 'arxid[px4]'")
    path = shared_data / "px4-ulog" / "sample_log_small.ulg"
    if not path.is_file():
        pytest.skip("px4-ulog/sample_log_small.ulg is absent from the shared data")
    d = arxid.IOData.from_ulog(
        path,
        output="vehicle_angular_velocity.xyz[0]",
        inputs=["actuator_controls_0.control[0]"],
        extra=["vehicle_rates_setpoint.roll", "battery_status.voltage_v"],
    )
    a = arxid.analyse(d)
    assert a.closed_loop.key == "iv-reference"
    assert "vehicle_rates_setpoint_roll" not in {f for e in _loop_effects(a) for f in e.replace("*", " ").split()}
    assert min(a.model.nk_) >= 1
    assert a.diagnosis.fit_val > 0


def test_readme_closed_loop_walkthrough_runs_and_says_what_it_claims():
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    example = re.search(r"## Flight data in closed loop\n.*?```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {"arxid": arxid}
    exec(compile(example, "README closed-loop example", "exec"), namespace)
    a = namespace["a"]
    assert a.closed_loop.method.startswith("instrumental variables with the reference rate_sp")
    gain, pole = _gain_and_pole_error(a.model.a, a.model.b[0], RateLoopPlant())
    assert abs(gain) < 0.03 and pole < 0.01


def test_bode_view_is_the_plant_from_the_reference_and_the_report_shows_it():
    from arxid.analysis.report.html import render_html

    plant = RateLoopPlant()
    a = arxid.analyse(pid_rate_loop(seed=6, n_samples=16000), reference="rate_sp", max_steps=1)
    fr = a.bode
    assert "reference" in fr.method_text
    zinv = np.exp(-2j * np.pi * fr.frequency * a.validation.ts)
    true = plant.rate_gain * (1 - plant.motor_pole) * zinv ** (plant.delay + 1)
    true = true / ((1 - plant.rate_pole * zinv) * (1 - plant.motor_pole * zinv))
    good = fr.coherence > 0.9
    assert good.sum() > 10
    assert np.max(np.abs(20 * np.log10(np.abs(fr.response[good, 0] / true[good])))) < 1.0
    html = render_html(a)
    assert 'id="bode"' in html and "Bode view" in html
    assert all(lo <= hi for lo, hi in a.bode_misses)  # the report states these bands, computed by the API
    said = ", ".join(f"{lo:.3g} Hz" if lo == hi else f"{lo:.3g}–{hi:.3g} Hz" for lo, hi in a.bode_misses)
    assert (said and said in html) or (not said and "stays inside the measured response" in html)


@pytest.mark.parametrize("seed", range(2))
def test_a_battery_sag_the_controller_hides_is_still_named_in_closed_loop(seed):
    # The refits are instrumental variables from the setpoint too: the effect is found on the
    # two-stage criterion, and the linear loops above add nothing.
    a = arxid.analyse(pid_rate_loop(seed=seed, n_samples=20000, battery_sag=3.0), reference="rate_sp")
    assert a.closed_loop.key == "iv-reference"
    assert a.ladder.final_model.effects == ("command*vbat",)
    assert a.ladder.final_model.structure_name().startswith("IV(")
    assert a.error_fall > 0.05


def test_iv_with_effects_reduces_to_the_cores_basic_iv_and_matches_the_normal_equations():
    from arxid.models.iv import instrument_signals
    from arxid.models.iv_effects import iv_with_effects

    d = pid_rate_loop(seed=9, n_samples=6000, battery_sag=2.0)
    plain = iv_with_effects(d, 2, [1], [3], [], ["rate_sp"])
    core = arxid.iv(d, 2, 1, 3, instruments="rate_sp", iterations=0)
    np.testing.assert_allclose(plain.parameters_, core.parameters_, rtol=1e-9, atol=1e-12)
    m = iv_with_effects(d, 2, [1], [3], ["command*vbat"], ["rate_sp"])
    # the normal equations written out: phi(t) = [-y(t-1), -y(t-2), u(t-3), u(t-3) vbat(t-3)]
    xy, xu = instrument_signals(d, ["rate_sp"])
    y, u, v, t = d.y, d.u[:, 0], d.extra["vbat"], np.arange(3, d.n_samples)
    phi = np.column_stack([-y[t - 1], -y[t - 2], u[t - 3], u[t - 3] * v[t - 3]])
    z = np.column_stack([-xy[t - 1], -xy[t - 2], xu[t - 3, 0], xu[t - 3, 0] * v[t - 3]])
    want = np.linalg.solve(z.T @ phi, z.T @ y[t])
    np.testing.assert_allclose(m.parameters_, want, rtol=1e-8)
