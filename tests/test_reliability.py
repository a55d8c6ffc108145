"""Reliability under hostile conditions: processes, signals, memory limits, corrupt model files and
the typed errors of bad arguments. Each test is named after the promise it guards
(docs/reliability.md lists them)."""

from __future__ import annotations

import json
import math
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from scipy import signal as sps

import arxid
from arxid._base import _core
from arxid._base.limits import _cgroup_left, available_memory
from arxid.exceptions import ArxidError, DataError, NotFittedError, OrderError


def _system(n: int, seed: int = 0, noise: float = 0.05) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = sps.lfilter([0.0, 0.5, 0.25], [1.0, -1.5, 0.7], u) + noise * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=0.01)


@pytest.fixture(scope="module")
def data() -> arxid.IOData:
    return _system(3000)


@pytest.fixture(scope="module")
def model(data) -> arxid.ArxModel:
    return arxid.arx(data, 2, 2, 1)


# ------------------------------------------------------------------------------------- processes
@pytest.mark.parametrize("method", ["fork", "forkserver", "spawn"])
def test_worker_process_fits_after_the_parent_used_the_core(data, method):
    arxid.arx(data, 2, 2, 1)  # the parent's thread pool exists now
    with mp.get_context(method).Pool(1) as pool:
        child = pool.apply_async(arxid.arx, (data, 2, 2, 1)).get(timeout=120)
    np.testing.assert_allclose(child.parameters_, arxid.arx(data, 2, 2, 1).parameters_, rtol=0, atol=0)


def test_raw_fork_child_fits_and_sweeps(data):
    arxid.sweep(data, range(1, 3), range(1, 3), range(0, 3), progress=False)
    pid = os.fork()
    if pid == 0:  # pragma: no cover - runs in the child
        code = 1
        try:
            arxid.arx(data, 2, 2, 1)
            arxid.sweep(data, range(1, 3), range(1, 3), range(0, 3), progress=False)
            code = 0
        finally:
            os._exit(code)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            assert os.waitstatus_to_exitcode(status) == 0
            return
        time.sleep(0.05)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    pytest.fail("the forked child hung in the core")


# ------------------------------------------------------------------------------------- signals
# A sweep of many structures on long data (tens of seconds) that is interrupted after it started.
_LONG_SWEEP = textwrap.dedent(
    """
    import sys, time
    import numpy as np
    from scipy import signal as sps
    import arxid
    rng = np.random.default_rng(0)
    u = rng.standard_normal(60_000)
    y = sps.lfilter([0, 0.5], [1, -0.9], u) + 0.1 * rng.standard_normal(60_000)
    d = arxid.IOData(y, u, ts=0.01)
    print("start", flush=True)
    t = time.monotonic()
    try:
        # top=None: every structure simulated (a two-stage sweep of this grid ends in about a second).
        # nk to 999: about 7 s on an idle 2-core machine with AVX-512 (to 399 took 1.6 s there, and
        # ended before the signal 1.5 s after "start").
        arxid.sweep(d, range(1, 11), range(1, 11), range(0, 1000), validation=0.3, progress=False, top=None)
        print("finished", time.monotonic() - t, flush=True)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
    """
)


def _sigint_default() -> None:
    """Child processes take SIGINT's default action: started from a background job (``cmd &``), a
    test run inherits SIGINT ignored, and Python then installs no KeyboardInterrupt handler."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _interrupt(cmd: list[str], wait_for: str, delay: float = 1.0) -> tuple[str, int, float]:
    """Start ``cmd``, wait for ``wait_for`` on its stdout (or ``delay`` after the start when empty),
    send SIGINT and return (rest of stdout, exit code, seconds from the signal to the exit)."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_sigint_default)
    try:
        if wait_for:
            assert proc.stdout is not None and proc.stdout.readline().strip() == wait_for
        time.sleep(delay)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        return out, proc.returncode, time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.timed  # a latency bound: run alone (make test runs these after the parallel run)
def test_ctrl_c_interrupts_a_long_sweep_promptly():
    out, code, latency = _interrupt([sys.executable, "-c", _LONG_SWEEP], "start", delay=1.5)
    assert out.strip() == "interrupted", out
    assert code == 0
    # The core stops within one group of simulations; 2 s leaves room for a loaded CI machine
    # (docs/reliability.md quotes the latency measured on an idle one).
    assert latency < 2.0, latency


# An output-error fit of 1.2 million samples from a poor start: about 60 Gauss-Newton steps of
# 0.1-0.2 s each (5-10 s in all). A timer thread sends SIGINT into the iterations after 1 s; the
# script prints the seconds from the signal to the KeyboardInterrupt.
_LONG_OE_FIT = textwrap.dedent(
    """
    import os, signal, threading, time
    import numpy as np
    from scipy import signal as sps
    import arxid
    rng = np.random.default_rng(0)
    n = 1_200_000
    u = rng.standard_normal(n)
    y = sps.lfilter([0, 0.5, 0.2, 0.1], [1, -2.2, 1.9, -0.6], u) + 0.5 * rng.standard_normal(n)
    d = arxid.IOData(y, u, ts=0.01)
    sent = []
    def interrupt():
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)
    threading.Timer(1.0, interrupt).start()
    try:
        arxid.oe(d, 3, 3, 1, tolerance=0.0, max_iterations=10**6, start=[0.1, 0.1, 0.1, -0.5, 0.1, 0.05])
        print("finished", flush=True)
    except KeyboardInterrupt:
        print("interrupted", time.monotonic() - sent[0], flush=True)
    """
)


@pytest.mark.timed  # a latency bound: run alone (make test runs these after the parallel run)
def test_ctrl_c_interrupts_a_long_output_error_fit_promptly():
    proc = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", _LONG_OE_FIT],
        capture_output=True,
        text=True,
        timeout=120,
        preexec_fn=_sigint_default,
    )
    word, *latency = proc.stdout.split()
    assert word == "interrupted" and proc.returncode == 0, proc.stdout + proc.stderr
    # The core checks between Gauss-Newton steps and their phases and between the damped trial
    # steps: measured 0.02-0.14 s on a shared machine; without the checks the fit runs on for
    # seconds after the signal. 0.5 s leaves room for a loaded CI machine.
    assert float(latency[0]) < 0.5, latency


# Predictions and simulations that run for seconds in the core: a k-step prediction of a model with
# an output-derived effect (k steps per sample), the free-run simulation of a high-order one, and
# a k-step prediction of an output-error model with a long horizon. A timer sends SIGINT after
# 1 s; each prints the seconds from the signal to the KeyboardInterrupt.
_LONG_PREDICTIONS = textwrap.dedent(
    """
    import os, signal, sys, threading, time
    import numpy as np
    import arxid
    which = sys.argv[1]
    rng = np.random.default_rng(0)
    if which == "arx k-step":
        n = 100_000
        u = rng.standard_normal(n)
        y = np.zeros(n)
        for t in range(2, n):
            y[t] = 0.5 * y[t - 1] + u[t - 1] - 0.01 * y[t - 1] ** 3
        d = arxid.IOData(y, u, ts=0.01)
        m = arxid.arx(d, 2, 2, 1, effects=["y^3"])
        call = lambda: m.predict(d, horizon=3000)
    elif which == "arx simulate":
        u = rng.standard_normal(2000)
        y = np.convolve(u, [0, 1, 0.5])[:2000] + 0.01 * rng.standard_normal(2000)
        m = arxid.arx(arxid.IOData(y, u, ts=0.01), 100, 100, 1, effects=["y^3"])
        long_u = rng.standard_normal(5_000_000)
        call = lambda: m.simulate(long_u)
    else:
        n = 400_000
        u = rng.standard_normal(n)
        y = np.convolve(u, [0, 1, 0.5])[:n] + 0.1 * rng.standard_normal(n)
        m = arxid.oe(arxid.IOData(y[:5000], u[:5000], ts=0.01), 2, 2, 1)
        d = arxid.IOData(y, u, ts=0.01)
        call = lambda: m.predict(d, horizon=20_000)
    sent = []
    def interrupt():
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)
    threading.Timer(1.0, interrupt).start()
    try:
        call()
        print("finished", flush=True)
    except KeyboardInterrupt:
        print("interrupted", time.monotonic() - sent[0], flush=True)
    """
)


@pytest.mark.timed  # a latency bound: run alone (make test runs these after the parallel run)
@pytest.mark.parametrize("which", ["arx k-step", "arx simulate", "oe k-step"])
def test_ctrl_c_interrupts_a_long_prediction_or_simulation_promptly(which):
    proc = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", _LONG_PREDICTIONS, which],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=_sigint_default,
    )
    word, *latency = proc.stdout.split()
    assert word == "interrupted" and proc.returncode == 0, proc.stdout + proc.stderr
    # The core looks at the flag every few thousand samples (milliseconds); without the checks
    # these calls run on for 10 s or more after the signal. 0.5 s leaves room for a loaded machine.
    assert float(latency[0]) < 0.5, latency


@pytest.mark.timed  # a latency bound: run alone (make test runs these after the parallel run)
def test_ctrl_c_stops_the_cli_with_exit_130(tmp_path):
    rng = np.random.default_rng(0)
    u = rng.standard_normal(400_000)
    y = sps.lfilter([0, 0.5], [1, -0.9], u)
    np.savez(tmp_path / "log.npz", y=y, u=u, ts=0.01)
    cmd = [sys.executable, "-m", "arxid.analysis.cli", "sweep", str(tmp_path / "log.npz"), "--output", "y"]
    cmd += ["--inputs", "u", "--na", "1:10", "--nb", "1:10", "--nk", "0:599", "--json"]
    # About 9 s in all on an idle 2-core machine with AVX-512 at 400k samples (150k took 3.9 s there
    # and ended before a signal 4 s in; two stages, the reduction of the 611-column regressor most of
    # it): a signal 2.5 s in lands in the work, after the imports even on a loaded machine. There,
    # signals 1.5-4 s in stopped it within 0.12 s; 4.5-6 s in waited 1.2-2.9 s (the stretch not yet
    # found, below), so the signal goes well before it.
    # While the full suite ran, about 1 run in 6 ended killed by the signal (-2) instead of 130: on
    # a loaded machine the signal landed in the imports, before main (see the next test, which
    # covers them). One retry is kept for a signal in the interpreter's own start, before arxid.
    seen = []
    for _ in range(2):
        out, code, latency, err = _interrupt_with_stderr(cmd, delay=2.5)
        if code != -signal.SIGINT:
            break
        seen.append(err)
    assert code == 130 and out == "", (code, seen)
    # Two stretches that looked at the flag too rarely are fixed: the one QR of all the stacked block
    # factors (now reduced four at a time, rust/arx/reduce.rs) and the one-step ranking's tasks of
    # 2,048 structures (now a look every 64, rust/sweep/one_step.rs): signals 5.5-8.5 s in stop in
    # 0.06-0.15 s idle, where 2.3-2.6 s was measured. A signal 3.5-5 s in still waits up to 2.2 s
    # idle, for a stretch not yet found (the process is in the core's ranking then): 3 s until it is.
    assert latency < 3.0, latency


@pytest.mark.parametrize("launch", ["module", "script"])
def test_ctrl_c_while_the_cli_starts_exits_130(launch, tmp_path):
    """A Ctrl-C in the second or more the command spends importing numpy, scipy and the core (before
    ``main`` runs) exits 130 too, for ``python -m arxid.cli`` and the ``arxid`` script alike: it
    ended killed by SIGINT (-2) before. With PYTHONPROFILEIMPORTTIME the child reports each import as
    it completes; the signal goes when arxid's first module is in, the rest of the package still to
    come."""
    if launch == "script":
        script = Path(sys.executable).with_name("arxid")
        if not script.is_file():
            pytest.skip("the arxid script is not installed beside this Python")
        cmd = [str(script)]
    else:
        cmd = [sys.executable, "-m", "arxid.cli"]
    np.savez(tmp_path / "log.npz", y=np.arange(100.0), u=np.arange(100.0) % 3, ts=0.01)
    cmd += ["sweep", str(tmp_path / "log.npz"), "--output", "y", "--inputs", "u"]
    env = {**os.environ, "PYTHONPROFILEIMPORTTIME": "1"}
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, preexec_fn=_sigint_default
    )
    try:
        assert proc.stderr is not None
        seen = []
        for line in proc.stderr:
            seen.append(line)
            if line.rstrip().endswith("arxid._base.launch"):
                break
        assert not any(line.rstrip().endswith("arxid.analysis.cli") for line in seen)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err[-2000:]
    assert out == "" and err.rstrip().endswith("arxid: interrupted")


def _interrupt_with_stderr(cmd: list[str], delay: float) -> tuple[str, int, float, str]:
    """:func:`_interrupt` keeping what the process wrote to stderr."""
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_sigint_default)
    try:
        time.sleep(delay)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
        return out, proc.returncode, time.monotonic() - sent, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


# ------------------------------------------------------------------------------------- memory
_LIMITED = textwrap.dedent(
    """
    import resource, numpy as np, arxid
    from arxid._base import _core
    from arxid._base.limits import available_memory
    with open("/proc/self/status") as fh:
        vm = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))
    # Room for the interpreter, numpy, threads and the 16 MB of data, not for the work.
    limit = vm + 768 * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    assert available_memory() <= limit
    rng = np.random.default_rng(0)
    d = arxid.IOData(rng.standard_normal(1_000_000), rng.standard_normal(1_000_000), ts=0.01)
    for call in (lambda: arxid.arx(d, 2000, 2000, 0), lambda: arxid.sweep(d, nk=range(1, 3 * 10**7), progress=False)):
        try:
            call()
            print("accepted")
        except arxid.DataError as exc:
            print("refused", "needs about" in str(exc) or "too large" in str(exc))
    # Past the Python estimate, straight into the core: a MemoryError, not an abort.
    try:
        _core.fit(d.y, d.u, [0], 300, [300], [0], [])
        print("core accepted")
    except MemoryError:
        print("core MemoryError")
    """
)


def test_memory_limit_refuses_large_work_before_allocating():
    if sys.platform != "linux":
        pytest.skip("RLIMIT_AS and /proc are Linux")
    proc = subprocess.run([sys.executable, "-c", _LIMITED], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.split("\n")[:3] == ["refused True", "refused True", "core MemoryError"], proc.stdout


def test_cgroup_limit_counts_as_available_memory(tmp_path):
    (tmp_path / "memory.max").write_text("1073741824\n")
    (tmp_path / "memory.current").write_text("268435456\n")
    assert _cgroup_left(tmp_path) == 1073741824 - 268435456
    (tmp_path / "memory.max").write_text("max\n")
    assert _cgroup_left(tmp_path) is None
    assert 0 < available_memory()


def test_sweep_refuses_an_absurd_grid_without_building_it(data):
    t = time.monotonic()
    with pytest.raises(DataError, match="too large"):
        arxid.sweep(data, nk=range(1, 3 * 10**7), progress=False)
    with pytest.raises(DataError, match="too large"):
        arxid.sweep(data, na=range(10**12, 0, -1), progress=False)
    assert time.monotonic() - t < 5  # not minutes of building tuples


# ------------------------------------------------------------------------------------- prediction
def _reference_k_step(m: arxid.ArxModel, d: arxid.IOData, k: int, t: int) -> float:
    """The k-step prediction at t by the model's recursion from measured outputs up to t - k."""
    a, b = m.a, m.b[0]
    lag = max(m.first_lag_, len(a) - 1, len(b) - 1)
    c = max(t - k, lag - 1)
    y = list(d.y[: c + 1])
    for tau in range(c + 1, t + 1):
        ar = sum(a[i] * y[tau - i] for i in range(1, len(a)))
        y.append(-ar + sum(b[j] * d.u[tau - j, 0] for j in range(len(b))))
    return y[t]


def test_k_step_prediction_is_a_filter_for_any_horizon(data, model):
    n = data.n_samples
    for k in (1, 2, 7, 150, n - 3, n, 10**9):
        pred = model.predict(data, horizon=k)
        for t in (3, 4, 10, 151, 1500, n - 1):
            assert pred[t] == pytest.approx(_reference_k_step(model, data, k, t), rel=1e-9, abs=1e-12)
    # A horizon past the record is the free run from the initial conditions.
    np.testing.assert_allclose(model.predict(data, horizon=10**9), model.predict(data, None), rtol=1e-9, atol=1e-12)


def test_k_step_prediction_of_a_nonlinear_model_refuses_hours_of_work():
    d = _system(400_000)
    m = arxid.arx(d, 2, 2, 1, effects=["y^3"])
    with pytest.raises(DataError, match="multiply-adds"):
        m.predict(d, horizon=300_000)


# ------------------------------------------------------------------------------------- numerics
@pytest.mark.parametrize("scale", [1e154, 1e-200])
def test_outputs_near_the_float_range_limits_are_not_falsely_rank_deficient(data, scale):
    d = arxid.IOData(data.y * scale, data.u * scale, ts=data.ts)
    m = arxid.arx(d, 2, 2, 1)
    phi = np.column_stack([-d.y[1:-1], -d.y[:-2], d.u[1:-1, 0], d.u[:-2, 0]])
    with np.errstate(over="ignore"):  # lstsq's own norms overflow near 1e154 (it still solves)
        ref = np.linalg.lstsq(phi, d.y[2:], rcond=None)[0]
    np.testing.assert_allclose(m.parameters_, ref, rtol=1e-9)
    # Output scaled, input not: lstsq's cut-off drops the inputs, the column scaling does not.
    mixed = arxid.arx(arxid.IOData(data.y * scale, data.u, ts=data.ts), 2, 2, 1)
    np.testing.assert_allclose(mixed.parameters_[:2], m.parameters_[:2], rtol=1e-9)
    np.testing.assert_allclose(mixed.parameters_[2:] / scale, m.parameters_[2:], rtol=1e-9)


def test_noise_free_residuals_are_white_not_round_off_artefacts():
    d = _system(2000, noise=0.0)
    r = arxid.residuals(arxid.arx(d, 2, 2, 1), d)
    assert r.is_white and "NOT white" not in str(r)
    noisy = _system(2000, noise=0.05)
    assert arxid.residuals(arxid.arx(noisy, 1, 1, 1), noisy).is_white is False


def test_sweep_json_writes_null_for_structures_that_could_not_be_fitted():
    n = 600
    u = np.tile([1.0, -1.0], n // 2)  # period 2: u(t-2) = u(t), so nb >= 3 is rank deficient
    y = sps.lfilter([0, 1.0], [1, -0.5], u) + 0.01 * np.random.default_rng(0).standard_normal(n)
    res = arxid.sweep(arxid.IOData(y, u, ts=1.0), na=1, nb=range(1, 4), nk=1, progress=False)
    rows = json.loads(res.to_json())["structures"]
    assert any(r["error"] for r in rows)
    failed = [r for r in rows if r["error"]]
    assert all(v is None for r in failed for k, v in r.items() if k.startswith("rms"))


# ------------------------------------------------------------------------------------- model files
def _mutated(model, **changes):
    d = json.loads(model.to_json())
    for path, value in changes.items():
        node = d
        *parents, last = path.split("__")
        for p in parents:
            node = node[p]
        node[int(last) if isinstance(node, list) else last] = value
    return json.dumps(d)


@pytest.mark.parametrize(
    "changes, field",
    [
        ({"layout__output_terms": [["pow", 3, -1]]}, "parameters"),
        ({"layout__nk": [5]}, "layout.nk[0]"),
        ({"n_rows": 0}, "n_rows"),
        ({"parameters__0": [1.0]}, "parameters[0]"),
        ({"parameters__0": math.nan}, "parameters[0]"),
        ({"ts": -1}, "ts"),
        ({"input_names": 5}, "input_names"),
        ({"surprise": 1}, "surprise"),
        ({"version": 2}, "version"),
        ({"covariance": [[1.0]]}, "covariance"),
    ],
)
def test_model_file_breaking_the_schema_names_the_field(model, changes, field):
    with pytest.raises(DataError, match=r"corrupt model file: " + field.replace("[", r"\[").replace("]", r"\]")):
        arxid.ArxModel.from_json_text(_mutated(model, **changes))


def test_model_file_unknown_term_kind_is_named():
    d = _system(1000)
    m = arxid.arx(d, 2, 2, 1, effects=["y^3"])
    with pytest.raises(DataError, match=r"layout.output_terms\[0\]\[0\]"):
        arxid.ArxModel.from_json_text(_mutated(m, layout__output_terms=[["cube", 3, -1]]))
    with pytest.raises(DataError, match=r"layout.output_terms\[0\]"):
        arxid.ArxModel.from_json_text(_mutated(m, layout__output_terms=[["abs", 1, -1]]))


def test_model_file_deep_nesting_and_non_json_are_corrupt():
    with pytest.raises(DataError, match="corrupt model file"):
        arxid.ArxModel.from_json_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(DataError, match="corrupt model file"):
        arxid.ArxModel.from_json_text("{nope")


def test_model_file_text_and_path_are_explicit(model, tmp_path):
    text = model.to_json()
    path = tmp_path / "m.json"
    path.write_text(text)
    for loaded in (
        arxid.ArxModel.from_json_text(text),
        arxid.ArxModel.from_json_file(path),
        arxid.ArxModel.from_json(str(path)),
        arxid.ArxModel.from_json(text),
        arxid.ArxModel.from_json("\ufeff" + text),  # BOM-prefixed text is text, not a path
    ):
        np.testing.assert_array_equal(loaded.parameters_, model.parameters_)
        assert loaded.to_json() == text


def test_model_file_refuses_what_is_not_a_regular_file(tmp_path):
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero", tmp_path):
        t = time.monotonic()
        with pytest.raises(DataError, match="not a regular file"):
            arxid.ArxModel.from_json(path)
        assert time.monotonic() - t < 5
    with pytest.raises(DataError, match="must be a str or path"):
        arxid.ArxModel.from_json(3)  # never a file descriptor
    os.fstat(0)  # still open


# ------------------------------------------------------------------------------------- typed errors
@pytest.mark.parametrize(
    "call",
    [
        lambda d, m: arxid.IOData(d.y, d.u, d.ts, input_names=5),
        lambda d, m: arxid.IOData(d.y, d.u, d.ts, extra=5),
        lambda d, m: arxid.IOData(d.y, d.u, d.ts, experiment_starts=5),
        lambda d, m: arxid.IOData(None, d.u, d.ts),
        lambda d, m: arxid.arx(d, 2, 2, 1, effects=None),
        lambda d, m: arxid.arx(d, 2, 2, 1, effects="const"),
        lambda d, m: arxid.arx(d, 2, 2, [2**64]),
        lambda d, m: arxid.sweep(d, 2, 2, [2**64], progress=False),
        lambda d, m: arxid.sweep(d, 2, 2, 1, horizon=2**64, progress=False),
        lambda d, m: arxid.sweep(d, 2, 2, 1, n_threads=2**64, progress=False),
        lambda d, m: m.predict(d, horizon=2**64),
        lambda d, m: arxid.arx(d, 2, 2, 1, n_threads=2**64),
        lambda d, m: m.step(10, input=5),
        lambda d, m: m.zeros(5),
        lambda d, m: m.to_control(input=5),
        lambda d, m: arxid.sweep(d, 1, 1, range(2), progress=False).plot(5),
        lambda d, m: d.time_slice(math.nan, 1.0),
        lambda d, m: arxid.sweep(d, 2, 2, 1, validation=arxid.IOData(d.y, d.u, 0.02), progress=False),
        lambda d, m: arxid.sweep(
            d, 2, 2, 1, validation=arxid.IOData(d.y, d.u, d.ts, input_names=["x"]), progress=False
        ),
        lambda d, m: arxid.compare(m, arxid.IOData(d.y, d.u, 0.02)),
        lambda d, m: arxid.compare(m, arxid.IOData(d.y, d.u, d.ts, output_name="z")),
    ],
)
def test_bad_arguments_raise_typed_arxid_errors(data, model, call):
    with pytest.raises(ArxidError) as info:
        call(data, model)
    assert str(info.value)


def test_unfitted_model_polynomials_say_not_fitted():
    m = arxid.ArxModel(na=1, nb=1, nk=1)
    for call in (m.poles, m.dc_gain, lambda: m.a, lambda: m.b):
        with pytest.raises(NotFittedError, match="not fitted"):
            call()


def test_optional_iodata_fields_accept_none(data):
    d = arxid.IOData(data.y, data.u, data.ts, extra=None, experiment_starts=None, input_names=None)
    assert d.extra == {} and d.experiment_starts == (0,) and d.input_names == ("u1",)


def test_masked_samples_become_missing(data):
    y = np.ma.masked_array(data.y, mask=np.arange(data.n_samples) % 100 == 5)
    d = arxid.IOData(y, data.u, data.ts)
    assert np.isnan(d.y[5]) and np.isnan(d.y[105]) and d.n_missing == 30
    assert arxid.arx(d, 2, 2, 1).n_skipped_ > 0


def test_time_slice_accepts_infinite_bounds(data):
    assert data.time_slice(0, math.inf).n_samples == data.n_samples
    assert data.time_slice(-math.inf, 1.0).n_samples == 100


def test_core_orders_error_is_typed_not_overflow():
    with pytest.raises(OrderError):
        _core.max_lag(1, [1], [1], [("cube", 1, -1)])
