"""Model files under faults: a writer killed mid-write (SIGKILL, in a subprocess) leaves either the
old file or the whole new one, never a half-written file. A kill in the instant between naming the
new file and moving it over the old one leaves it whole under its hidden name; the next write
removes it."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import arxid

# A writer that saves two different models over the same path, again and again, with a disk made
# slow (each write() call of the file's bytes sleeps 2 ms), so a kill lands mid-write most times.
_WRITER = textwrap.dedent(
    """
    import os, sys, time
    import numpy as np
    import arxid
    path = sys.argv[1]
    rng = np.random.default_rng(0)
    u = rng.standard_normal((3000, 2))
    y = rng.standard_normal(3000)
    models = [arxid.arx(arxid.IOData(y, u, 0.01), 20, [40, 40], [1, 1]),
              arxid.arx(arxid.IOData(-y, u, 0.01), 20, [40, 40], [1, 1])]
    write = os.write
    def slow_write(fd, data):
        time.sleep(0.002)
        return write(fd, data)
    os.write = slow_write
    print("ready", flush=True)
    for k in range(10**6):
        models[k % 2].to_json(path)
    """
)


@pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL is POSIX")
def test_a_writer_killed_mid_write_leaves_a_whole_model_file(tmp_path):
    path = tmp_path / "model.json"
    rng = np.random.default_rng(5)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    loaded = 0
    for _ in range(6):
        with subprocess.Popen([sys.executable, "-c", _WRITER, str(path)], stdout=subprocess.PIPE, env=env) as proc:
            assert proc.stdout is not None and proc.stdout.readline().strip() == b"ready"
            time.sleep(float(rng.uniform(0.05, 0.4)))
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
        left = [n for n in os.listdir(tmp_path) if n != "model.json"]
        for name in left:  # named only once whole (O_TMPFILE): a complete model file
            assert re.fullmatch(r"\.model\.json\.\d+\.[0-9a-f]+\.tmp", name)
            if hasattr(os, "O_TMPFILE"):
                assert len(arxid.ArxModel.from_json(tmp_path / name).parameters_) == 100
        if path.exists():
            model = arxid.ArxModel.from_json(path)  # the whole file: the schema is checked
            assert len(model.parameters_) == 100
            assert json.loads(path.read_text())["na"] == 20
            loaded += 1
    assert loaded >= 4  # the writer got to save most times (each save takes about 30 ms)
    arxid.ArxModel.from_json(path).to_json(path)  # a later write clears what killed writers left
    assert os.listdir(tmp_path) == ["model.json"]


def test_a_write_removes_the_temporaries_of_writers_that_are_gone(tmp_path):
    rng = np.random.default_rng(1)
    u = rng.standard_normal(200)
    model = arxid.arx(arxid.IOData(np.convolve(u, [0, 1])[:200], u, 0.1), 1, 1, 1)
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead, alive = int(gone.stdout), os.getppid()  # a finished process; a running one (not ours)
    for pid in (dead, alive):
        (tmp_path / f".m.json.{pid}.0badc0de.tmp").write_text("partial")
    (tmp_path / ".other.json.1.00.tmp").write_text("not this file's")
    model.to_json(str(tmp_path / "m.json"))
    assert sorted(os.listdir(tmp_path)) == sorted(["m.json", f".m.json.{alive}.0badc0de.tmp", ".other.json.1.00.tmp"])


def test_a_failed_write_leaves_the_old_file_and_says_why(tmp_path):
    rng = np.random.default_rng(0)
    u = rng.standard_normal(200)
    model = arxid.arx(arxid.IOData(np.convolve(u, [0, 1])[:200], u, 0.1), 1, 1, 1)
    path = tmp_path / "m.json"
    model.to_json(str(path))
    before = path.read_bytes()
    with pytest.raises(arxid.DataError, match="cannot write model file .*nope"):
        model.to_json(str(tmp_path / "nope" / "m.json"))  # a folder that does not exist
    assert path.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["m.json"]
