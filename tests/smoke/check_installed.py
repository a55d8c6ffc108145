"""Smoke suite of an installed wheel: the core API, the CLI, and each optional extra either working
(full install) or failing with a message that names it (base install: numpy, scipy and threadpoolctl only).

Run by ``tests/smoke/run.sh`` in a fresh venv without cargo on PATH; it is not collected by the
project's own test run (its files are ``check_*.py``, see ``tests/smoke/pytest.ini``).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import io
import json
import os
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import arxid

REPO = Path(__file__).resolve().parents[2]
HAS = {name: importlib.util.find_spec(name) is not None for name in ("tqdm", "matplotlib", "control", "pandas")}


def _arx_data(n=3000, seed=0):
    """y(t) = 1.5 y(t−1) − 0.7 y(t−2) + 0.5 u(t−3) + 0.25 u(t−4) + small noise."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(4, n):
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u[t - 3] + 0.25 * u[t - 4] + 1e-4 * rng.standard_normal()
    return arxid.IOData(y, u, ts=0.01, output_name="roll", input_names=["torque"])


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_package_is_the_installed_wheel_and_no_rust_toolchain_is_on_path():
    site = Path(arxid.__file__).resolve()
    assert REPO / "python" not in site.parents, f"arxid imported from the source tree: {site}"
    assert Path(sys.prefix) in site.parents and (site.parent / "_base" / "_core.abi3.so").is_file()
    assert shutil.which("cargo") is None and shutil.which("rustc") is None


def test_version_and_licence_come_from_the_one_place():
    cargo_version = re.search(r'^version = "(.+)"', (REPO / "Cargo.toml").read_text(), re.M).group(1)
    assert arxid.__version__ == cargo_version == importlib.metadata.version("arxid")
    meta = importlib.metadata.metadata("arxid")
    assert meta["License-Expression"] == "MIT"
    installed = {r.split(";")[0].split(">")[0].strip() for r in meta.get_all("Requires-Dist") if "extra" not in r}
    assert installed == {"numpy", "scipy", "threadpoolctl"}


def test_fit_recovers_the_parameters():
    model = arxid.arx(_arx_data(), na=2, nb=2, nk=3)
    np.testing.assert_allclose(model.parameters_, [-1.5, 0.7, 0.5, 0.25], atol=2e-3)


@pytest.mark.parametrize("progress", [False, True])
def test_sweep_with_and_without_progress(progress, monkeypatch):
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        result = arxid.sweep(
            _arx_data(), na=range(1, 4), nb=range(1, 3), nk=range(2, 5), validation=0.3, progress=progress
        )
        arxid.sweep(_arx_data(), na=range(1, 3), nb=range(1, 3), nk=range(2, 4), validation=0.3, progress=progress)
    best = result.best()
    assert (best.na_, best.nb_, best.nk_) == (2, (2,), (3,))
    notes = [str(w.message) for w in seen if issubclass(w.category, arxid.ArxidWarning)]
    if not progress:
        assert notes == [] and terminal.getvalue() == ""
    elif HAS["tqdm"]:
        assert notes == [] and "arxid.sweep" in terminal.getvalue()
    else:  # no bar, and one warning for both sweeps
        assert terminal.getvalue() == "" and len(notes) == 1 and "pip install 'arxid[progress]'" in notes[0]


def test_diagnose_finds_the_battery_gain():
    rng = np.random.default_rng(0)
    n = 4000
    u = np.repeat(rng.uniform(-1, 1, n // 10 + 1), 10)[:n]
    vbat = 3.0 + 1.2 * np.abs(np.sin(np.arange(n) / 600.0))
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.8 * y[t - 1] + 0.3 * u[t - 1] * vbat[t - 1] + 0.01 * rng.standard_normal()
    est, val = arxid.IOData(y, u, 0.01, extra={"vbat": vbat}).split(0.6)
    diagnosis = arxid.diagnose(arxid.arx(est, 1, 1, 1), est, val)
    assert diagnosis.top.effect == "u1*vbat"
    np.testing.assert_allclose(diagnosis.apply(0).effect_parameters["u1*vbat"], [0.3], atol=0.01)


def test_to_json_round_trip(tmp_path):
    data = _arx_data()
    model = arxid.arx(data, 2, 2, 3)
    model.to_json(tmp_path / "model.json")
    loaded = arxid.ArxModel.from_json(tmp_path / "model.json")
    np.testing.assert_array_equal(loaded.parameters_, model.parameters_)
    np.testing.assert_array_equal(loaded.predict(data), model.predict(data))
    np.testing.assert_array_equal(loaded.simulate(data.u), model.simulate(data.u))


def test_csv_reading_with_whatever_reader_is_installed(tmp_path):
    path = tmp_path / "flight.csv"
    path.write_text("time,roll[rad],torque\n0,1.5,0.25\n0.01,,1e-3\n0.02,nan,-2\n")
    d = arxid.IOData.from_csv(path, output="roll", inputs=["torque"], time="time")
    assert d.ts == pytest.approx(0.01) and d.output_unit == "rad" and d.u[:, 0].tolist() == [0.25, 1e-3, -2.0]
    path.write_text("time,roll,torque\n0,1,2\n1,2\n")
    with pytest.raises(arxid.DataError, match="line 3 has 2 fields"):
        arxid.IOData.from_csv(path, output="roll", inputs=["torque"], time="time")


def test_plot_works_or_names_the_plot_extra():
    result = arxid.compare(arxid.arx(_arx_data(), 2, 2, 3), _arx_data(seed=1))
    if HAS["matplotlib"]:
        assert len(result.plot().axes) >= 1
    else:
        with pytest.raises(arxid.MissingDependencyError, match=r"pip install 'arxid\[plot\]'"):
            result.plot()


def test_to_control_works_or_names_the_control_extra():
    model = arxid.arx(_arx_data(), 2, 2, 3)
    if HAS["control"]:
        assert model.to_control().dt == 0.01
    else:
        with pytest.raises(arxid.MissingDependencyError, match=r"pip install 'arxid\[control\]'"):
            model.to_control()
    assert model.to_scipy().dt == 0.01  # scipy is a base dependency


def _cli(*args, cwd=None):
    exe = Path(sys.executable).with_name("arxid")
    return subprocess.run([str(exe), *args], capture_output=True, text=True, cwd=cwd, env=dict(os.environ))


def test_cli_help_and_fit(tmp_path):
    help_run = _cli("--help")
    assert help_run.returncode == 0 and "fit" in help_run.stdout
    data = _arx_data()
    rows = "\n".join(f"{float(y)!r},{float(u)!r}" for y, u in zip(data.y, data.u[:, 0]))
    (tmp_path / "log.csv").write_text("roll,torque\n" + rows + "\n")
    fit = ["fit", "--output", "roll", "--inputs", "torque", "--ts", "0.01", "--orders", "2,2,3", "--no-progress"]
    out = _cli(*fit, "--json", "log.csv", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert report["structure"] == "ARX(2,2,3)"
    np.testing.assert_allclose(report["model"]["parameters"], [-1.5, 0.7, 0.5, 0.25], atol=2e-3)
    bad = _cli(*fit, "nope.csv", cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "does not exist" in bad.stderr
