"""The missing-effect diagnosis of a state-space model, per output: a linear plant names nothing, a
battery-voltage gain on one output of a 2×2 plant is named on that output only and takes its
validation error down to the noise, one output agrees with the output-error diagnosis, and bad
input gets a typed error."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.checks import PerOutput
from arxid.diagnosis.state_space_output import StateSpaceOutput

NOISE = 0.02  # output noise, standard deviation
V_NOMINAL = 15.0  # battery voltage about which it sags and recovers, V


def two_by_two(seed: int, n: int = 1200, battery: float = 0.0, level: float = 0.0) -> arxid.IOData:
    """Two second-order channels, p (poles 0.75 ± 0.37j) and q (poles 0.6 ± 0.37j), both driven by
    u1 and u2; white output noise of ``NOISE``. The battery voltage (15 V ± 1 V, slow) scales u1's
    gain into q by ``battery`` per volt; inputs are ±1 steps of random height about ``level``."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.5, 1.5, size=(n // 10 + 1, 2)).repeat(10, axis=0)[:n]
    u = level + rng.choice([-1.0, 1.0], size=(n, 2)) * steps
    t = np.arange(n)
    vbat = V_NOMINAL + np.sin(2 * np.pi * t / (n / 2.7) + rng.uniform(0, 6)) + 0.02 * rng.standard_normal(n)
    a = np.array([[1.5, -0.7, 0, 0], [1, 0, 0, 0], [0, 0, 1.2, -0.5], [0, 0, 1, 0]])
    b = np.array([[1.0, 0.5], [0, 0], [0.8, -0.6], [0, 0]])
    c = np.array([[0.1, 0.05, 0, 0], [0, 0, 0.2, 0.1]])
    x, y = np.zeros(4), np.zeros((n, 2))
    for k in range(n):
        y[k] = c @ x
        x = a @ x + b @ u[k]
        x[2] += battery * 0.8 * u[k, 0] * (vbat[k] - V_NOMINAL)
    y += NOISE * rng.standard_normal((n, 2))
    return arxid.IOData(y, u, ts=0.01, output_name=["p", "q"], input_names=["u1", "u2"], extra={"vbat": vbat})


def diagnosed(seed: int, **plant) -> PerOutput:
    est, val = two_by_two(seed, **plant), two_by_two(1000 + seed, **plant)
    return arxid.diagnose(arxid.ssest(est, order=4), est, val)


def test_a_linear_plant_with_white_noise_names_nothing():
    for seed in range(10):
        found = diagnosed(seed, level=float(seed % 2))  # every other record about an operating point
        assert list(found) == ["p", "q"]
        for name, d in found.items():
            assert not d.significant, (seed, name, d.top)
            assert d.suspects and d.n_tested >= 15  # the candidates were scored and judged
            assert d.rms_sim_val == pytest.approx(NOISE, rel=0.15)


def test_a_battery_gain_is_named_on_its_output_and_not_the_other():
    """The term is ±12 % of u1's gain into q (inputs about zero); naming it takes q's error down to
    the noise."""
    for seed in range(5):
        found = diagnosed(seed, battery=0.15)
        q, p = found["q"], found["p"]
        assert q.top is not None and q.top.effect == "u1*vbat", (seed, q.top)
        assert q.rms_sim_val > 2 * NOISE  # what the linear model misses
        assert q.top.rms_sim_val_after == pytest.approx(NOISE, rel=0.12)
        assert not p.significant, (seed, p.top)
        assert p.rms_sim_val == pytest.approx(NOISE, rel=0.2)


def test_about_an_operating_point_the_gain_is_named_though_the_held_modes_recover_part():
    """Inputs about 1: the battery term's slow part biases the model's A and C, and the refit that
    holds them takes q's error about half way to the noise (see arxid.diagnosis.state_space_output)."""
    for seed in range(2):
        found = diagnosed(seed, battery=0.15, level=1.0)
        q, p = found["q"], found["p"]
        assert q.top is not None and q.top.effect == "u1*vbat", (seed, q.top)
        assert q.top.improvement > 0.4 and q.top.rms_sim_val_after > 2 * NOISE
        assert not p.significant, (seed, p.top)


def test_de_meaned_data_of_two_experiments_with_a_gap_name_the_same_effect():
    est = arxid.IOData.merge([two_by_two(7, battery=0.15), two_by_two(8, battery=0.15)])
    y = est.outputs.copy()
    y[700:705, 0] = np.nan  # a few samples of p lost: three stretches, each with its initial state
    est, val = est.with_outputs(y, ["p", "q"]).detrend(), two_by_two(1007, battery=0.15).detrend()
    model = arxid.ssest(est, order=4)
    assert len(model.initial_states) == 3
    found = arxid.diagnose(model, est, val)
    assert found["q"].top.effect == "u1*vbat"
    assert found["q"].top.rms_sim_val_after == pytest.approx(NOISE, rel=0.12)
    assert not found["p"].significant


def test_one_output_agrees_with_the_output_error_diagnosis():
    est, val = two_by_two(3, battery=0.15).output("q"), two_by_two(1003, battery=0.15).output("q")
    cands = ["u1*vbat", "u1^2", "vbat", "y^3"]
    ss = arxid.diagnose(arxid.ssest(est, order=2), est, val, candidates=cands)
    oe = arxid.diagnose(arxid.oe(est, [2, 2], [2, 2], [1, 1]), est, val, candidates=cands)
    assert isinstance(ss, arxid.Diagnosis)  # one output: the usual result
    assert [s.effect for s in ss.significant] == [s.effect for s in oe.significant] == ["u1*vbat"]
    assert ss.top.improvement == pytest.approx(oe.top.improvement, abs=0.02)
    assert ss.suspect("vbat").p_value > 0.01 and oe.suspect("vbat").p_value > 0.01


def test_apply_gives_the_refitted_model_of_every_output():
    est, val = two_by_two(4, battery=0.15), two_by_two(1004, battery=0.15)
    found = arxid.diagnose(arxid.ssest(est, order=4), est, val)
    best = found["q"].apply(0)
    assert isinstance(best, StateSpaceOutput) and best.effects == ("u1*vbat",)
    assert best.model.input_names == ("u1", "u2", "u1*vbat") and best.model.n_outputs == 2
    assert best.validation_rms(val, None, "zero") == pytest.approx(found["q"].top.rms_sim_val_after)
    unrefitted = next(s for s in found["p"].suspects if not s.refitted and s.kind == "effect")
    assert found["p"].apply(unrefitted.effect).effects == (unrefitted.effect,)
    report = json.loads(found.to_json())
    assert report["q"]["suspects"][0]["effect"] == "u1*vbat" and report["q"]["suspects"][0]["significant"]
    assert "output q" in str(found)


def test_a_term_that_does_not_act_barely_moves_the_refit():
    """The refit nests the model (A, C and K held): white noise as an input, or a term of an output
    the term does not drive, moves that output's validation error by about what one more input costs."""
    rng = np.random.default_rng(9)
    est, val = (two_by_two(s, battery=0.15) for s in (9, 1009))
    est, val = (d.with_signals(extra={**d.extra, "noise": rng.standard_normal(d.n_samples)}) for d in (est, val))
    view = StateSpaceOutput(arxid.ssest(est, order=4), "p")
    before = view.validation_rms(val, None, "zero")
    for effect in ("noise", "y^3", "u1*y"):
        after = view.extended(est, [effect]).validation_rms(val, None, "zero")
        assert after == pytest.approx(before, rel=0.01), effect


def test_bad_input_gets_a_typed_error():
    est = two_by_two(5, n=600)
    model = arxid.ssest(est, order=4)
    with pytest.raises(arxid.ArxidError, match="does not keep its data"):
        arxid.diagnose(model)
    with pytest.raises(arxid.DataError, match=r"lack the model's output\(s\) \['q'\]"):
        arxid.diagnose(model, est.output("p"))
    with pytest.raises(arxid.OrderError, match="not a candidate for a state-space model"):
        arxid.diagnose(model, est, candidates=["na+1"])
    with pytest.raises(arxid.OrderError, match="not a candidate for a state-space model"):
        arxid.diagnose(model, est, candidates=["dz(u1)"])
    with pytest.raises(arxid.OrderError):
        arxid.diagnose(model, est, candidates=["volts^2"])
    with pytest.raises(arxid.ArxidError, match="alpha"):
        arxid.diagnose(model, est, alpha=2.0)
    with pytest.raises(arxid.ArxidError, match="'auto' or a list"):
        arxid.diagnose(model, est, candidates="all")


def test_ssest_cli_searches_each_output(tmp_path, capsys):
    from arxid.analysis.cli import main

    d = two_by_two(6, n=2400, battery=0.15, level=1.0)
    path = tmp_path / "rates.csv"
    columns = np.column_stack([d.outputs, d.u, d.extra["vbat"]])
    np.savetxt(path, columns, delimiter=",", header="p,q,u1,u2,vbat", comments="")
    args = ["ssest", str(path), "--output", "p,q", "--inputs", "u1,u2", "--extra", "vbat", "--ts", "0.01"]
    assert main([*args, "--order", "4", "--diagnose", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    q, p = out["diagnosis"]["q"]["suspects"], out["diagnosis"]["p"]["suspects"]
    assert q[0]["effect"] == "u1*vbat" and q[0]["significant"] and not any(s["significant"] for s in p)
    assert not any("No search for a missing effect" in note for note in out["notes"])
