"""Continuous-time models in the pipeline: analyse(model="tf:..."/"proc:..."), compare,
where_it_fails, the CLI's --model and the HTML report."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.cli import main
from arxid.analysis.report import render_html
from arxid.models.spec import parse_model_spec
from test_tfest import record

NUM, DEN, TAU = [4.0], [1.0, 0.8, 4.0], 0.12


@pytest.fixture(scope="module")
def records():
    est, _ = record(NUM, DEN, 0.05, 2500, 10, tau=TAU, seed=0)
    val, _ = record(NUM, DEN, 0.05, 1500, 10, tau=TAU, seed=1)
    return est, val


def test_specs_read_tf_and_process_forms():
    tf = parse_model_spec("tf:2,1")
    assert (tf.kind, tf.orders, tf.name) == ("tf", (2, 1), "tf(2,1)")
    proc = parse_model_spec("proc: p2du")
    assert (proc.kind, proc.orders, proc.process, proc.name) == ("proc", (), "P2DU", "P2DU")
    assert "SRIVC" in tf.method and "refinement" in proc.method


def test_analyse_a_continuous_model_scores_suspects_on_its_residuals(records):
    """The plant is exactly tf(2,0) with a dead time: its validation error is the noise (10 % of the
    output's std, fit near 90 %), no suspect is significant, and the comparison, the failure
    analysis and the diagnosis all see the continuous model's own free run."""
    est, val = records
    a = arxid.analyse(est, val, model="tf:2,0", max_steps=1)
    m = a.model
    assert isinstance(m, arxid.models.ContinuousTransferFunction)
    assert m.dead_time_ == pytest.approx(TAU, abs=0.005)
    assert a.comparison.names[0] == "tf(2,0)"
    rms = m.rms(val, None)
    assert a.comparison.rms[0] == pytest.approx(rms, rel=1e-12)
    assert a.diagnosis.rms_sim_val == pytest.approx(rms, rel=1e-12)
    assert a.failures[0].rms == pytest.approx(rms, rel=1e-12)
    assert 85 < a.comparison.fit_percent[0] < 95
    assert a.missing_effect is None and len(a.diagnosis.suspects) > 3
    assert "SRIVC" in a.choice.reason


def test_analyse_a_process_model_finds_a_missing_input_nonlinearity():
    """The plant driven by u + 0.4 u² (u uniform on 0..2, held 10 samples): the diagnosis of the
    P2DU model, fitted linear, scores the candidates on its residuals and names u1^2."""
    from test_tfest import simulate

    recs = []
    for seed in (0, 1):
        rng = np.random.default_rng(seed)
        u = rng.uniform(0, 2, 250).repeat(10)
        y0 = simulate(NUM, DEN, 0.05, TAU, u + 0.4 * u**2)
        recs.append(arxid.IOData(y0 + 0.05 * np.std(y0) * rng.standard_normal(len(u)), u, ts=0.05))
    a = arxid.analyse(recs[0], recs[1], model="proc:P2DU", max_steps=1)
    assert a.model.structure_name() == "P2DU"
    assert a.missing_effect == "u1^2"


def test_cli_and_report_accept_continuous_models(records, tmp_path, capsys):
    est, val = records
    paths = []
    for name, d in (("est", est), ("val", val)):
        p = tmp_path / f"{name}.csv"
        np.savetxt(p, np.column_stack([d.u[:, 0], d.y]), delimiter=",", header="u,y", comments="")
        paths.append(str(p))
    base = [paths[0], "--output", "y", "--inputs", "u", "--ts", "0.05", "--validation", paths[1], "--max-steps", "1"]
    assert main(["diagnose", *base, "--model", "proc:P2DU", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["comparison"]["models"][0]["name"] == "P2DU"
    assert out["comparison"]["models"][0]["fit_percent"] > 85
    report = tmp_path / "r.html"
    assert main(["report", *base, "--model", "tf:2,0", "-o", str(report)]) == 0
    html = report.read_text()
    assert "tf(2,0)" in html and "a1" in html and "Continuous-time model" in html
    a = arxid.analyse(est, val, model="tf:2,0", max_steps=0)
    assert "b0" in render_html(a)
