"""How fast the command line answers on small data: ``arxid --help`` and ``arxid diagnose`` on a
2,000-sample CSV file, each a fresh process, in absolute seconds (issue 42: under 0.3 s and 0.8 s).

The file is a thrust stand run of arxid's own simulator (``arxid.datasets.thrust_stand``, 20 s at
100 Hz: thrust, PWM command, battery voltage), diagnosed with the default grid as a user would:
``arxid diagnose FILE --output thrust --inputs pwm --extra vbat --ts 0.01``. Each command runs once
to warm up (and to write Python's bytecode caches, which an installed package has; the child
processes may write them even where ``PYTHONDONTWRITEBYTECODE`` is set here), then ``--runs`` times;
the median, min and max wall times and the median CPU time are printed, with a bare Python start for
scale.

    python benches/cli_start.py [--runs 7]
    python benches/cli_start.py --stages     # where one diagnose's time goes, stage by stage

``--stages`` runs the command's chain in a fresh process, stage by stage (imports, reading,
sweep, diagnosis and ladder, checks, printing), with the wall and CPU seconds of each.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import arxid

TARGETS = {"arxid --help": 0.3, "arxid diagnose (2,000 samples)": 0.8}


def command() -> list[str]:
    """The installed ``arxid`` script next to this Python, else the module."""
    script = shutil.which("arxid", path=str(Path(sys.executable).parent))
    return [script] if script else [sys.executable, "-m", "arxid.analysis.cli"]


def write_flight(path: Path) -> None:
    d = arxid.datasets.thrust_stand(seed=0, duration=20.0, ts=0.01)
    columns = np.column_stack([d.y, d.u[:, 0], d.extra["vbat"]])
    np.savetxt(path, columns, fmt="%.9g", delimiter=",", header="thrust,pwm,vbat", comments="")


def run_times(argv: list[str], runs: int, env: dict) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system) seconds of each run after a warm-up: on a shared machine the CPU
    time says what the command costs, the wall time what a user waits."""
    walls, cpus = [], []
    for i in range(runs + 1):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, env=env)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if i:  # the first run warms up
            walls.append(wall)
            cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus


#: The chain of ``arxid diagnose``, stage by stage, in a fresh process (argv[1]: the file).
STAGES = """
import sys, time
marks = [("start", time.perf_counter(), time.process_time())]
def mark(name):
    marks.append((name, time.perf_counter(), time.process_time()))
import numpy
mark("import numpy")
from arxid.analysis import cli
from arxid.analysis.cli_data import load
from arxid.analysis.pipeline import analyse
mark("import arxid (the pipeline)")
argv = ["diagnose", sys.argv[1], "--output", "thrust", "--inputs", "pwm", "--extra", "vbat", "--ts", "0.01"]
est, val = load(cli.build_parser("diagnose").parse_args(argv))
mark("parse the arguments, read the file")
a = analyse(est, val)
mark("analyse")
text = "\\n".join(a.summary_lines(n_suspects=12))
mark("the printed text")
for (_, w0, c0), (name, w1, c1) in zip(marks, marks[1:]):
    print(f"{name:<40}{w1 - w0:>8.3f}s{c1 - c0:>8.3f}s")
    if name == "analyse":
        for stage, seconds in a.timings.items():
            print(f"  {stage:<38}{seconds:>8.3f}s")
wall, cpu = marks[-1][1] - marks[0][1], marks[-1][2] - marks[0][2]
print(f"{'total (after the interpreter started)':<40}{wall:>8.3f}s{cpu:>8.3f}s")
"""


def stages(flight: Path, env: dict) -> None:
    print(f"{'stage of arxid diagnose (2,000 samples)':<40}{'wall':>9}{'cpu':>9}")
    subprocess.run([sys.executable, "-c", STAGES, str(flight)], check=True, env=env)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--stages", action="store_true", help="where one diagnose's time goes, stage by stage")
    options = parser.parse_args()
    runs = options.runs
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    arxid_cmd = command()
    with tempfile.TemporaryDirectory() as tmp:
        flight = Path(tmp) / "thrust_stand.csv"
        write_flight(flight)
        if options.stages:
            stages(flight, env)
            return
        diagnose = [*arxid_cmd, "diagnose", str(flight), "--output", "thrust", "--inputs", "pwm", "--extra", "vbat"]
        cases = {
            "python alone": [sys.executable, "-c", "pass"],
            "arxid --help": [*arxid_cmd, "--help"],
            "arxid diagnose (2,000 samples)": [*diagnose, "--ts", "0.01", "--no-progress"],
        }
        print(f"command line on small data: wall seconds of a fresh process over {runs} runs, {os.cpu_count()} cores")
        print(f"{'command':<32}{'median':>9}{'min':>9}{'max':>9}{'cpu':>9}{'target (wall)':>15}")
        for name, argv in cases.items():
            t, cpu = run_times(argv, runs, env)
            target = TARGETS.get(name)
            verdict = "" if target is None else f"{'< ' if statistics.median(t) < target else 'MISSED < '}{target:g} s"
            cells = f"{statistics.median(t):>8.3f}s{min(t):>8.3f}s{max(t):>8.3f}s{statistics.median(cpu):>8.3f}s"
            print(f"{name:<32}{cells}{verdict:>15}")
        print(f"load average at the end: {os.getloadavg()[0]:.1f} (the targets are for an idle machine)")


if __name__ == "__main__":
    main()
