"""`arxid diagnose LOG --axis roll`: a flight log's rate loop through the closed-loop chain, on a
synthetic ArduCopter DataFlash log written here and on the real Betaflight and ArduPlane logs."""

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.cli import main
from test_dataflash import write_copter_log

LOOP_WORDS = ("setpoint", "rcCommand", "motor", "RDes", "axis")


def _diagnose_json(capsys, *argv: str) -> dict:
    assert main(["diagnose", *argv, "--no-progress", "--json", "--max-steps", "2"]) == 0
    return json.loads(capsys.readouterr().out)


def _named_effects(out: dict) -> list[str]:
    """Every suspect the diagnosis listed and every effect the ladder added."""
    return [s["effect"] for s in out["suspects"]] + [step.get("added") or "" for step in out["ladder"]]


def _axis_analysis(path):
    """The analysis the CLI's --axis runs, through the API (for the model's numbers)."""
    from arxid.analysis.flight_log import axis_signals

    output, inputs, extra, reference = axis_signals(path, "roll")
    data = arxid.IOData.from_dataflash(path, output=output, inputs=inputs, extra=extra)
    return arxid.analyse(data, reference=reference, max_steps=2)


def test_synthetic_copter_log_by_axis_finds_the_plant_behind_the_rate_loop(tmp_path, capsys):
    path = tmp_path / "copter.bin"
    write_copter_log(path, n=8000)  # r[k] = 0.95 r[k-1] + 8 out[k-1] + noise, under a PI controller
    out = _diagnose_json(capsys, str(path), "--axis", "roll")
    assert out["closed_loop"]["key"] == "iv-reference"
    assert out["closed_loop"]["references"] == ["RATE_RDes"]
    assert min(out["model"]["nk"]) >= 1
    a = _axis_analysis(path)
    assert a.model.structure_name() == out["model"]["structure"]
    poles, gain = np.roots(a.model.a), float(a.model.b[0].sum() / a.model.a.sum())
    assert min(abs(poles - 0.95)) < 0.01 and abs(gain / 160.0 - 1) < 0.03
    assert not [e for e in _named_effects(out) if "RDes" in e]
    assert out["ladder"][-1].get("added") in (None, "")  # a linear plant: nothing is added


def test_axis_and_output_together_is_a_usage_error(tmp_path, capsys):
    path = tmp_path / "copter.bin"
    write_copter_log(path, n=400)
    assert main(["diagnose", str(path), "--axis", "roll", "--output", "RATE.R", "--inputs", "RATE.ROut"]) == 2
    assert "either --axis or --output" in capsys.readouterr().err


def _shared_log(shared_data, *parts):
    path = shared_data.joinpath(*parts)
    if not path.is_file():
        pytest.skip(f"{'/'.join(parts)} is absent from the shared data")
    return path


@pytest.mark.realdata
def test_real_betaflight_log_by_axis_names_iv_and_never_the_setpoint(shared_data, capsys):
    path = _shared_log(shared_data, "betaflight-blackbox", "LOG00037.BFL")
    out = _diagnose_json(capsys, str(path), "--axis", "roll")
    assert out["feedback"]["feedback"] is True
    assert out["closed_loop"]["key"] == "iv-reference" and out["closed_loop"]["references"] == ["setpoint_0"]
    assert {"setpoint_0", "motor_0", "motor_3"} <= set(out["closed_loop"]["loop_signals"])
    assert not [e for e in _named_effects(out) if any(w in e for w in LOOP_WORDS)]
    assert min(out["model"]["nk"]) >= 1  # no motor answers within the 1 ms sample
    assert out["baseline"]["fit_val"] > 0


@pytest.mark.realdata
def test_real_betaflight_hover_with_a_still_setpoint_takes_the_direct_method(shared_data, capsys):
    path = _shared_log(shared_data, "betaflight-blackbox", "btfl_001.bbl")
    out = _diagnose_json(capsys, str(path), "--axis", "roll", "--log", "2")
    assert out["closed_loop"]["key"] == "direct"
    assert "does not move" in out["closed_loop"]["reason"] and "may be biased" in out["closed_loop"]["reason"]
    assert not [e for e in _named_effects(out) if any(w in e for w in LOOP_WORDS)]
    assert min(out["model"]["nk"]) >= 1
    assert out["baseline"]["fit_val"] > 0


@pytest.mark.realdata
def test_real_arduplane_log_says_what_the_axis_is_missing(shared_data, capsys):
    path = _shared_log(shared_data, "ardupilot-dataflash", "pilot_0004.BIN")
    assert main(["diagnose", str(path), "--axis", "roll", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "no roll rate" in err and "ArduPlane" in err


@pytest.mark.realdata
def test_real_px4_log_by_axis(shared_data, capsys):
    pytest.importorskip("pyulog", reason="needs the px4 extra: pip install 'arxid[px4]'")
    path = _shared_log(shared_data, "px4-ulog", "sample_log_small.ulg")
    out = _diagnose_json(capsys, str(path), "--axis", "roll")
    assert out["closed_loop"]["references"] == ["vehicle_rates_setpoint_roll"]
    assert not [e for e in _named_effects(out) if "setpoint" in e or "actuator_outputs" in e]
    assert min(out["model"]["nk"]) >= 1 and out["baseline"]["fit_val"] > 0
