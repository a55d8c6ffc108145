"""What a control engineer reads: the JSON keys of ladder steps and suspects, the plain-word verdicts,
and the command line's flags and messages. Known answers from a seeded battery-drain system."""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.cli import main
from arxid.analysis.verdicts import ladder_headline, lag_ranges, negative_fit_note, residual_sentences


def _battery_data(n=2500, seed=5):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    vbat = np.linspace(4.2, 3.4, n) + 0.01 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.9 * y[t - 1] + 0.3 * u[t - 1] * vbat[t - 1] + 0.02 * rng.standard_normal()
    return arxid.IOData(y, u, 0.01, output_name="y", input_names=("u",), extra={"vbat": vbat})


@pytest.fixture(scope="module")
def analysis():
    return arxid.analyse(_battery_data(), orders=(1, 1, 1), max_steps=2)


def test_ladder_and_suspect_json_keys(analysis):
    d = json.loads(analysis.to_json())
    step_keys = {"added", "structure", "effects", "rms_sim_val", "fit_val", "kind", "orders", "fall"}
    assert all(step_keys <= set(s) for s in d["ladder"])
    first, second = d["ladder"][0], d["ladder"][1]
    assert (
        first["kind"] == "start"
        and first["fall"] is None
        and first["orders"]
        == {
            "na": 1,
            "nb": [1],
            "nk": [1],
            "effects": [],
        }
    )
    assert second["kind"] == "effect" and "vbat" in second["added"]
    assert second["orders"]["effects"] == second["effects"]
    e = analysis.ladder.errors
    assert second["fall"] == pytest.approx((e[0] - e[1]) / e[0])
    old = {"effect", "kind", "score", "p_value", "significant", "rms_sim_val_after", "improvement", "note"}
    assert all(old | {"explained_by", "why"} <= set(s) for s in d["suspects"])
    explained = [s for s in d["suspects"] if s["explained_by"]]
    assert explained, "a battery-drain system has suspects that the battery term explains"
    for s in explained:
        assert s["significant"] is False and s["explained_by"] in s["note"] and s["why"] == s["note"]
    fall = d["error_fall"]
    assert fall["total"] == pytest.approx(fall["effects"] + fall["structure"])
    assert fall["added_effects"] == [st["added"] for st in d["ladder"] if st["kind"] == "effect"]
    assert d["frequency_check"] and {"model", "summary", "bands"} <= set(d["frequency_check"][0])


def test_headline_separates_effects_from_structure_changes():
    """A hand-built ladder: an effect step then a structure step, with known errors."""
    data = _battery_data()
    est, val = data.split(0.7)
    m0 = arxid.arx(est, 1, 1, 1)
    m1 = m0.with_effects(["u*vbat"])
    m2 = arxid.ArxModel(na=2, nb=1, nk=1, effects=["u*vbat"]).fit(est)
    lad = arxid.Ladder(val)
    lad.add(m0)
    lad.add(m1, "u*vbat")
    lad.add(m2, "na+1")
    e = lad.errors
    fall = lad.error_fall()
    assert [lad.step_kind(i) for i in range(3)] == ["start", "effect", "structure"]
    assert fall["effects"] == pytest.approx((e[0] - e[1]) / e[0])
    assert fall["structure"] == pytest.approx((e[1] - e[2]) / e[0])
    text = ladder_headline(lad)
    assert text.startswith(f"The added effects (u*vbat) removed {100 * fall['effects']:.0f} % of the validation error")
    assert "structure changes (na+1)" in text


def test_residual_sentences_say_the_verdicts_in_words(analysis):
    rt = analysis.residual_tests
    lines = residual_sentences(rt)
    assert len(lines) == 1 + len(rt.cross_correlation)  # one sentence per test
    assert lines[0].startswith("The residuals are white: " + ("yes" if rt.is_white else "no"))
    for name, line in zip(rt.cross_correlation, lines[1:]):
        dependent = not rt.independent.get(name, True)
        assert (f"still depend on {name}" in line) == dependent, line
        if dependent and len(rt.cross_outside(name)):
            assert lag_ranges([k for k in rt.cross_outside(name) if k >= 0]) in line
    assert lag_ranges([0, 1, 2, 3, 7, 9, 10]) == "0–3, 7, 9–10"
    assert negative_fit_note(12.0) == "" and "worse than the constant mean" in negative_fit_note(-87.8)


@pytest.fixture(scope="module")
def csv_file(tmp_path_factory):
    d = _battery_data()
    path = tmp_path_factory.mktemp("cli") / "log.csv"
    rows = np.column_stack([d.y, d.u[:, 0], d.extra["vbat"]])
    np.savetxt(path, rows, delimiter=",", header="y,u,vbat", comments="")
    return path


def test_cli_units_reach_the_report_and_report_prints_three_lines(csv_file, tmp_path, capsys):
    out = tmp_path / "r.html"
    argv = [
        "report",
        str(csv_file),
        "--output",
        "y",
        "--inputs",
        "u",
        "--extra",
        "vbat",
        "--ts",
        "0.01",
        "--orders",
        "1,1,1",
        "--max-steps",
        "1",
        "--units",
        "y=m,u=V,vbat=V",
        "--no-progress",
        "-o",
        str(out),
    ]
    assert main(argv) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0].startswith(f"report written to {out}")
    assert lines[1].startswith("Model ARX(1,1,1): validation fit") and "missing effect" in lines[1]
    assert lines[2].startswith("The added effects (")
    assert "frequency" not in lines[0] and ("misses the data" in lines[3] or "matches the data" in lines[3])
    assert len(lines) == 5  # path, three lines, and where the whole diagnosis is
    assert "output: y [m]" in out.read_text()


def test_cli_messages_name_the_flags(csv_file, capsys):
    base = [str(csv_file), "--output", "y", "--inputs", "u"]
    assert main(["sweep", *base, "--no-progress"]) == 2
    assert "--ts SECONDS" in capsys.readouterr().err
    assert main(["sweep", *base, "--ts", "0.01", "--units", "y", "--no-progress"]) == 2
    assert "NAME=UNIT" in capsys.readouterr().err
    assert main(["sweep", *base, "--ts", "0.01", "--na", "1:2", "--nb", "1", "--nk", "0:3", "--top", "3"]) == 0
    text = capsys.readouterr().out
    assert "5 more structures (--all prints every one)" in text and "Model Configuration" not in text
    assert main(["sweep", *base, "--ts", "0.01", "--na", "1:2", "--nb", "1", "--nk", "0:3", "--all"]) == 0
    text = capsys.readouterr().out
    assert "more structures" not in text and text.count("ARX(") >= 8


def test_cli_diagnose_explains_a_negative_fit(tmp_path, capsys):
    """A model that misses a strong drift does worse than the mean: the fit is negative and explained."""
    rng = np.random.default_rng(2)
    n = 2000
    u = rng.standard_normal(n)
    y = np.zeros(n)
    drift = np.linspace(0, 5, n)
    for t in range(1, n):
        y[t] = 0.5 * y[t - 1] + 0.1 * u[t - 1] + 0.5 * (drift[t] - 0.5 * drift[t - 1])
    path = tmp_path / "drift.csv"
    np.savetxt(path, np.column_stack([y, u]), delimiter=",", header="y,u", comments="")
    assert main(["diagnose", str(path), "--output", "y", "--inputs", "u", "--ts", "1", "--orders", "1,1,1"]) == 0
    text = capsys.readouterr().out
    fit_line = next(ln for ln in text.splitlines() if ln.startswith("validation ("))
    assert "fit -" in fit_line  # the drift beats the model: about -900 %
    assert "worse than the constant mean" in text
    assert "residual tests:" in text and text.index("residual tests:") < text.index("details:")
    assert "explained by" in text and "why" in text
