"""The README's command-line walk-through on two demo flights, as a new user would run it.

The README writes two flights (estimation and validation from separate seeds) and diagnoses them
twice: with the collective thrust command as input the battery is named first and the error falls;
with the true motor speeds (which already carry the battery's sag) nothing is named. The commands
are read from the README, so the text and the test cannot drift apart; they are also run on another
pair of seeds, which the README never showed.
"""

from __future__ import annotations

import contextlib
import io
import json
import re
import shlex
from pathlib import Path

import pytest

from arxid.analysis.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_commands() -> list[list[str]]:
    """The ``arxid`` lines of the README's command-line walk-through, split as a shell would."""
    block = re.search(r"## From the command line.*?```sh\n(.*?)```", README.read_text(encoding="utf-8"), re.S)
    assert block, "README.md has no '## From the command line' section with a sh block"
    return [shlex.split(line)[1:] for line in block.group(1).splitlines() if line.startswith("arxid ")]


def run(argv: list[str]) -> str:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        assert main(argv) == 0
    return out.getvalue()


def reseeded(argv: list[str], seed: int) -> list[str]:
    """The same command on flight ``seed`` (estimation) or ``seed + 1000`` (validation)."""
    if argv[:2] == ["demo", "--seed"]:
        return [*argv[:2], str(seed if int(argv[2]) < 1000 else seed + 1000), *argv[3:]]
    return argv


@pytest.mark.parametrize("seed", [None, 4])
def test_readme_walk_through_names_the_battery_and_nothing_with_true_motor_speeds(tmp_path, monkeypatch, seed):
    monkeypatch.chdir(tmp_path)
    commands = readme_commands()
    writes = [c for c in commands if c[0] == "demo"]
    diagnoses = [c for c in commands if c[0] == "diagnose"]
    assert len(writes) == 2 and len(diagnoses) == 2
    for argv in writes:
        run(argv if seed is None else reseeded(argv, seed))
    command, true_speeds = (json.loads(run([*argv, "--json", "--no-progress"])) for argv in diagnoses)

    first = command["ladder"][1]
    assert any("vbat" in e for e in first["effects"]), command["ladder"]
    assert first["rms_sim_val"] < 0.9 * command["ladder"][0]["rms_sim_val"]
    assert command["sweep"]["integrating"] is False and command["sweep"]["horizon"] is None
    if seed is None:  # the fall the README states, to the percent it prints
        stated = float(re.search(r"error falls by (\d+) %", README.read_text(encoding="utf-8")).group(1))
        fall = 100 * (1 - first["rms_sim_val"] / command["ladder"][0]["rms_sim_val"])
        assert abs(fall - stated) < 1.0, (fall, stated)

    assert len(true_speeds["ladder"]) == 1, true_speeds["ladder"]  # nothing added
    assert not any(s["significant"] for s in true_speeds["suspects"])
