"""The ``arxid`` command line: every command, exit codes, ``--json`` shapes, one-line errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from arxid.analysis.cli import main, parse_range

TRUE_A, TRUE_B, TRUE_NK = -0.8, 0.5, 2


def _strict_json(text: str):
    """json.loads that refuses NaN/Infinity literals (they are not JSON)."""

    def bad(c):
        raise AssertionError(f"non-JSON constant {c} in output")

    return json.loads(text, parse_constant=bad)


def _first_order(n=1500, seed=0, noise=0.0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(TRUE_NK, n):
        y[t] = -TRUE_A * y[t - 1] + TRUE_B * u[t - TRUE_NK]
    return u, y + noise * rng.standard_normal(n)


def _battery_system(n=3000, seed=1):
    """The gain scales with a draining battery voltage that the model does not know about."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    vbat = np.linspace(4.2, 3.4, n) + 0.01 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.9 * y[t - 1] + 0.3 * u[t - 1] * vbat[t - 1] + 0.02 * rng.standard_normal()
    return u, y, vbat


@pytest.fixture
def csv_file(tmp_path):
    u, y = _first_order()
    p = tmp_path / "data.csv"
    t = np.arange(len(u)) * 0.01
    np.savetxt(p, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="")
    return p


@pytest.fixture
def noisy_csv(tmp_path):
    u, y = _first_order(noise=0.01)
    p = tmp_path / "noisy.csv"
    np.savetxt(p, np.column_stack([u, y]), delimiter=",", header="u,y", comments="")
    return p


@pytest.fixture
def battery_csv(tmp_path):
    u, y, vbat = _battery_system()
    p = tmp_path / "battery.csv"
    np.savetxt(p, np.column_stack([u, y, vbat]), delimiter=",", header="u,y,vbat", comments="")
    return p


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------------------------------- fit
def test_fit_json_recovers_the_true_parameters(capsys, csv_file):
    code, out, err = run(
        capsys,
        "fit",
        csv_file,
        "--output",
        "y",
        "--inputs",
        "u",
        "--ts",
        0.01,
        "--orders",
        "1,1,2",
        "--split",
        0.7,
        "--json",
    )
    assert code == 0, err
    d = _strict_json(out)
    assert d["structure"] == "ARX(1,1,2)"
    np.testing.assert_allclose(d["model"]["parameters"], [TRUE_A, TRUE_B], atol=1e-9)
    assert d["rms_sim_val"] < 1e-8 and d["fit_val"] > 99.99


def test_fit_table_time_column_and_save(capsys, csv_file, tmp_path):
    path = tmp_path / "m.json"
    code, out, err = run(
        capsys, "fit", csv_file, "--output", "y", "--inputs", "u", "--time", "t", "--orders", "1,1,2", "--save", path
    )
    assert code == 0, err
    assert "ARX(1,1,2)" in out and "one-step fit on estimation" in out
    import arxid

    m = arxid.ArxModel.from_json(path)
    np.testing.assert_allclose(m.parameters_, [TRUE_A, TRUE_B], atol=1e-9)
    assert m.ts == pytest.approx(0.01)


def test_fit_reads_npz_with_ts_inside(capsys, tmp_path):
    u, y = _first_order(800)
    p = tmp_path / "log.npz"
    np.savez(p, u=u, y=y, ts=np.array(0.05))
    code, out, err = run(capsys, "fit", p, "--output", "y", "--inputs", "u", "--orders", "1,1,2", "--json")
    assert code == 0, err
    d = _strict_json(out)
    np.testing.assert_allclose(d["model"]["parameters"], [TRUE_A, TRUE_B], atol=1e-9)
    assert "rms_sim_val" not in d  # no validation asked for


def test_fit_with_effect(capsys, battery_csv):
    code, out, err = run(
        capsys,
        "fit",
        battery_csv,
        "--output",
        "y",
        "--inputs",
        "u",
        "--extra",
        "vbat",
        "--ts",
        0.01,
        "--orders",
        "1,1,1",
        "--effects",
        "u*vbat",
        "--json",
    )
    assert code == 0, err
    d = _strict_json(out)
    assert d["model"]["effects"] == ["u*vbat"]
    # y = 0.9 y(t-1) + 0.3 u vbat: the product term carries the gain, the plain input none
    np.testing.assert_allclose(d["model"]["parameters"], [-0.9, 0.0, 0.3], atol=0.01)


# ---------------------------------------------------------------------------------------- sweep
def test_sweep_json_finds_the_true_structure(capsys, noisy_csv):
    code, out, err = run(
        capsys,
        "sweep",
        noisy_csv,
        "--output",
        "y",
        "--inputs",
        "u",
        "--ts",
        0.01,
        "--na",
        "1:2",
        "--nb",
        "1:2",
        "--nk",
        "0:3",
        "--json",
        "--no-progress",
    )
    assert code == 0, err
    d = _strict_json(out)
    assert d["n_structures"] == 2 * 2 * 4
    assert d["best"]["nk"] == [TRUE_NK]
    assert d["best"]["rms_val"] < 0.02  # noise 0.01 on the output
    assert d["horizon"] is None and d["measure"] == "free-run simulation"
    assert len(d["table"]) == 16 and {"structure", "na", "nb", "nk", "rms_val"} <= set(d["table"][0])
    assert d["table"][0]["rms_val"] <= d["table"][1]["rms_val"]
    if d["best"]["structure"] == "ARX(1,1,2)":
        np.testing.assert_allclose(d["best"]["parameters"], [TRUE_A, TRUE_B], atol=0.02)


def test_sweep_table(capsys, csv_file):
    code, out, err = run(
        capsys,
        "sweep",
        csv_file,
        "--output",
        "y",
        "--inputs",
        "u",
        "--ts",
        0.01,
        "--na",
        "1",
        "--nb",
        "1",
        "--nk",
        "1,2",
        "--top",
        "5",
    )
    assert code == 0, err
    assert "2 structures" in out and "best sane structure: ARX(1,1,2)" in out
    assert "ARX(1,1,1)" in out  # the table lists both


# ---------------------------------------------------------------------------------------- diagnose
def test_diagnose_json_contract_and_battery_found(capsys, battery_csv):
    code, out, err = run(
        capsys,
        "diagnose",
        battery_csv,
        "--output",
        "y",
        "--inputs",
        "u",
        "--extra",
        "vbat",
        "--ts",
        0.01,
        "--orders",
        "1,1,1",
        "--split",
        0.7,
        "--json",
    )
    assert code == 0, err
    d = _strict_json(out)  # exactly one JSON object on stdout
    assert {"model", "baseline", "residual_tests", "suspects", "ladder", "choice"} <= set(d)
    assert {"na", "nb", "nk", "effects"} <= set(d["model"])
    assert {"rms_sim_val", "rms_pred_val", "fit_val", "horizon"} <= set(d["baseline"])
    for s in d["suspects"]:
        assert {"effect", "score", "p_value", "significant", "rms_sim_val_after"} <= set(s)
    for step in d["ladder"]:
        assert {"effects", "rms_sim_val"} <= set(step)
    top = next(s for s in d["suspects"] if s["significant"])
    assert "vbat" in top["effect"]
    assert d["ladder"][-1]["rms_sim_val"] < 0.6 * d["ladder"][0]["rms_sim_val"]


def test_diagnose_tables(capsys, battery_csv):
    code, out, err = run(
        capsys,
        "diagnose",
        battery_csv,
        "--output",
        "y",
        "--inputs",
        "u",
        "--extra",
        "vbat",
        "--ts",
        0.01,
        "--orders",
        "1,1,1",
        "--max-steps",
        1,
    )
    assert code == 0, err
    assert "suspects" in out and "error ladder" in out and "missing effect:" in out
    with pytest.raises(json.JSONDecodeError):
        json.loads(out)


# ---------------------------------------------------------------------------------------- report, demo
def test_report_writes_self_contained_html(capsys, battery_csv, tmp_path):
    path = tmp_path / "r.html"
    code, out, err = run(
        capsys,
        "report",
        battery_csv,
        "--output",
        "y",
        "--inputs",
        "u",
        "--extra",
        "vbat",
        "--ts",
        0.01,
        "--na",
        "1:2",
        "--nb",
        "1",
        "--nk",
        "0:2",
        "-o",
        path,
        "--max-steps",
        1,
        "--json",
    )
    assert code == 0, err
    d = _strict_json(out)
    assert d["report"] == str(path) and d["bytes"] == path.stat().st_size
    html = path.read_text()
    assert html.count('<img src="data:image/png;base64,') >= 8
    assert "http://" not in html and "https://" not in html
    for section in (
        "Data",
        "Order sweep",
        "Model equation",
        "Step-response checks",
        "Measured against simulated",
        "Residual tests",
        "Where it fails",
        "Which effect is missing",
        "Error ladder",
    ):
        assert section in html


def test_demo_short_flight(capsys, tmp_path):
    path = tmp_path / "demo.html"
    code, out, err = run(capsys, "demo", "-o", path, "--duration", 8, "--json", "--no-progress")
    assert code == 0, err
    d = _strict_json(out)
    assert d["report"] == str(path) and path.stat().st_size > 10_000
    assert d["ladder"][0]["effects"] == []
    assert "error ladder" in err.lower()  # the story goes to stderr with --json


def test_default_demo_tells_the_battery_story(capsys, tmp_path, demo_flight):
    """``make demo`` runs exactly this: the default 20 s flight, before/after numbers, the grid edge."""
    import re

    import arxid

    path = tmp_path / "arxid-demo-report.html"
    code, out, err = run(capsys, "demo", "-o", path, "--no-progress")
    assert code == 0, err
    assert "Missing effect: collective*vbat" in out and "battery" in out
    # The demo says what the API says about the grid edge (its choice sits on the default grid's nk edge).
    edge = arxid.analyse(demo_flight(0), max_steps=2).choice.grid_edge
    assert edge and edge in out
    m = re.search(r"before ([0-9.e+-]+) m/s\^2 -> after ([0-9.e+-]+) m/s\^2", out)
    assert m, out
    before, after = float(m.group(1)), float(m.group(2))
    assert after < 0.5 * before
    assert "Error ladder" in out and path.stat().st_size > 100_000


# ---------------------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "argv, needle",
    [
        (["fit", "{csv}", "--inputs", "u", "--ts", "0.01", "--orders", "1,1,2"], "--output"),
        (["fit", "{csv}", "--output", "y", "--inputs", "u", "--ts", "0.01", "--orders", "1,1"], "--orders"),
        (["fit", "{csv}", "--output", "y", "--inputs", "nope", "--ts", "0.01", "--orders", "1,1,2"], "nope"),
        (["fit", "{csv}", "--output", "y", "--inputs", "u", "--orders", "1,1,2"], "ts"),
        (
            ["fit", "missing.csv", "--output", "y", "--inputs", "u", "--ts", "0.01", "--orders", "1,1,2"],
            "does not exist",
        ),
        (["sweep", "{csv}", "--output", "y", "--inputs", "u", "--ts", "0.01", "--split", "1.5"], "split"),
        (
            [
                "diagnose",
                "{csv}",
                "--output",
                "y",
                "--inputs",
                "u",
                "--ts",
                "0.01",
                "--orders",
                "1,1,2",
                "--split",
                "0.9995",
            ],
            "validation",
        ),
        (["sweep", "{csv}", "--output", "y", "--inputs", "u", "--ts", "0.01", "--na", "4:1"], "--na"),
        (["sweep", "{csv}", "--output", "y", "--inputs", "u", "--ts", "0.01", "--nk", "x"], "--nk"),
        (["fit", "{csv}", "--output", "y", "--inputs", "u", "--ts", "-1", "--orders", "1,1,2"], "ts"),
        (
            [
                "fit",
                "{csv}",
                "--output",
                "y",
                "--inputs",
                "u",
                "--ts",
                "0.01",
                "--orders",
                "1,1,2",
                "--effects",
                "bogus*",
            ],
            "bogus",
        ),
        (
            [
                "diagnose",
                "{csv}",
                "--output",
                "y",
                "--inputs",
                "u",
                "--ts",
                "0.01",
                "--orders",
                "1,1,2",
                "--horizon",
                "0",
            ],
            "horizon",
        ),
        (["frobnicate"], "frobnicate"),
        (["demo", "--duration", "0"], "--duration"),
        (["demo", "--duration", "nan"], "--duration"),
        (["demo", "--duration", "1e9"], "at most"),
        (["demo", "--seed", "-1"], "seed"),
        ([], "command"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(capsys, csv_file, argv, needle):
    code, out, err = run(capsys, *[a.replace("{csv}", str(csv_file)) for a in argv])
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert needle in lines[0] and "Traceback" not in err


def _bad_files(tmp_path):
    rng = np.random.default_rng(0)
    n = 300
    y, u = rng.standard_normal(n), rng.standard_normal(n)
    (tmp_path / "binary.csv").write_bytes(bytes(range(256)) * 10)
    np.save(tmp_path / "array.npy", y)
    np.savez(tmp_path / "twod.npz", y=y, u=rng.standard_normal((n // 2, 2)), ts=0.01)
    np.savez(tmp_path / "text.npz", y=y, u=np.array(["a"] * n), ts=0.01)
    np.savez(tmp_path / "complex.npz", y=y, u=u + 1j, ts=0.01)
    np.savez(tmp_path / "ts_text.npz", y=y, u=u, ts="abc")
    np.savez(tmp_path / "nan_extra.npz", y=y, u=u, vbat=np.full(n, np.nan), ts=0.01)
    np.savetxt(
        tmp_path / "nan_output.csv", np.column_stack([np.full(n, np.nan), u]), delimiter=",", header="y,u", comments=""
    )


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["fit", "binary.csv", "--orders", "1,1,1"], "binary.csv"),
        (["fit", "array.npy", "--orders", "1,1,1"], "array.npy"),
        (["fit", "twod.npz", "--orders", "1,1,1"], "'u'"),
        (["fit", "text.npz", "--orders", "1,1,1"], "'u'"),
        (["fit", "complex.npz", "--orders", "1,1,1"], "'u'"),
        (["fit", "ts_text.npz", "--orders", "1,1,1"], "ts"),
        (["diagnose", "nan_extra.npz", "--extra", "vbat", "--orders", "1,1,1"], "'vbat'"),
        (["sweep", "nan_output.csv", "--na", "1:2", "--nb", "1", "--nk", "1"], "'y'"),
    ],
)
def test_bad_data_files_exit_2_with_one_line(tmp_path, argv, needle):
    """In a real process (warnings are not errors there): exit 2, one line naming the problem."""
    _bad_files(tmp_path)
    argv = [argv[0], str(tmp_path / argv[1]), *argv[2:], "--output", "y", "--inputs", "u"]
    if argv[1].endswith(".csv"):
        argv += ["--ts", "0.01"]
    p = subprocess.run([sys.executable, "-m", "arxid.cli", *argv], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2, p.stderr
    assert p.stdout == ""
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in p.stderr, p.stderr
    assert needle in lines[0]


@pytest.mark.parametrize("command", ["fit", "sweep", "diagnose", "report", "demo"])
def test_help_has_an_example(capsys, command):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and f"arxid {command}" in out


def test_fit_help_does_not_promise_a_default_split(capsys):
    """fit validates only when asked (--split or --validation); its help must not say 0.7 by default."""
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "default 0.7" not in out and "no validation" in out


def test_parse_range():
    assert list(parse_range("1:4", "na")) == [1, 2, 3, 4]  # a lazy range
    assert parse_range("0,2,5", "nk") == [0, 2, 5]
    assert parse_range("3", "nb") == [3]


def test_entry_point_process_exit_codes(csv_file):
    """The real process: exit 2 and one line on stderr for bad data, JSON on stdout on success."""
    bad = subprocess.run(
        [
            sys.executable,
            "-m",
            "arxid.cli",
            "fit",
            str(csv_file),
            "--output",
            "zz",
            "--inputs",
            "u",
            "--ts",
            "0.01",
            "--orders",
            "1,1,2",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1 and "Traceback" not in bad.stderr
    ok = subprocess.run(
        [
            sys.executable,
            "-m",
            "arxid.cli",
            "fit",
            str(csv_file),
            "--output",
            "y",
            "--inputs",
            "u",
            "--ts",
            "0.01",
            "--orders",
            "1,1,2",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ok.returncode == 0, ok.stderr
    assert _strict_json(ok.stdout)["structure"] == "ARX(1,1,2)"
