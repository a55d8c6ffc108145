"""Shared fixtures: seeded synthetic systems with known parameters, and the real-data folder."""

from __future__ import annotations

import functools
import os
import pickle
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]

#: The test files with the longest summed test time, longest first (measured with --durations on
#: 2026-11-29). pytest-xdist's ``--dist loadfile`` hands a worker one file at a time in this order,
#: so the long files start early and the short ones fill the gaps: a long file handed out last
#: kept one worker busy alone at the end of the run.
LONGEST_FIRST = (
    "test_robust_integrator.py",
    "test_cli.py",
    "test_report.py",
    "test_polynomial_diagnosis.py",
    "test_robust_grid.py",
    "test_robust_ladder.py",
    "test_missing.py",
    "test_browser.py",
    "test_one_truth.py",
    "test_closed_loop_chain.py",
    "test_report_scale.py",
    "test_robust_decoys.py",
    "test_fuzz.py",
    "test_tfest_pipeline.py",
    "test_shapes.py",
    "test_flight_log_chain.py",
    "test_state_space_analysis.py",
    "test_fleet_analysis.py",
    "test_procest_core.py",
    "test_readable.py",
    "test_memory_bounds.py",
    "test_state_space_browser.py",
    "test_robust_demo_cli.py",
)


#: A folder shared by the xdist workers of this run (None without xdist): see :func:`made_once`.
SHARED_RUN_DIR: Path | None = None


def pytest_configure(config):
    """xdist otherwise reorders the files by their number of tests, which puts the few long
    report and browser tests last; the order of :data:`LONGEST_FIRST` is kept instead. A worker's
    temporary folder (``--basetemp``, given by xdist) lies in the run's, which they share."""
    global SHARED_RUN_DIR
    if hasattr(config.option, "loadscopereorder"):
        config.option.loadscopereorder = False
    if hasattr(config, "workerinput") and config.option.basetemp:
        SHARED_RUN_DIR = Path(config.option.basetemp).parent


def pytest_collection_modifyitems(config, items):
    """The files of :data:`LONGEST_FIRST` first, in its order; the others after, as collected."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


def shared_data_dir() -> Path | None:
    """``$ARXID_SHARED_DATA``, else ``../shared/data`` beside the repository, else ``/work/shared/data``."""
    for cand in (os.environ.get("ARXID_SHARED_DATA"), REPO.parent / "shared" / "data", "/work/shared/data"):
        if cand and Path(cand).is_dir():
            return Path(cand)
    return None


@pytest.fixture
def shared_data() -> Path:
    d = shared_data_dir()
    if d is None:
        pytest.skip("real measured data folder ../shared/data is absent (set ARXID_SHARED_DATA)")
    return d


def simulate_arx(a, bs, nks, u, noise=None):
    """y(t) = -Σ a_i y(t-i) + Σ_i Σ_j b_ij u_i(t-nk_i-j) + e(t), from rest (a without the leading 1)."""
    u = np.atleast_2d(np.asarray(u, dtype=float).T).T
    n = u.shape[0]
    y = np.zeros(n)
    e = np.zeros(n) if noise is None else noise
    for t in range(n):
        acc = e[t]
        for i, ai in enumerate(a, start=1):
            if t - i >= 0:
                acc -= ai * y[t - i]
        for col, (b, nk) in enumerate(zip(bs, nks)):
            for j, bj in enumerate(b):
                if t - nk - j >= 0:
                    acc += bj * u[t - nk - j, col]
        y[t] = acc
    return y


@pytest.fixture(scope="session")
def dask_client():
    """One ``LocalCluster(n_workers=2, processes=True)`` for every fleet test of the session (started
    here, closed at the end; its dashboard on a random port, as 8787 may be taken by a concurrent
    cluster); skipped without the dask extra."""
    distributed = pytest.importorskip("distributed", reason="needs the dask extra: pip install 'arxid[dask]'")
    cluster = distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0", silence_logs=40
    )
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


def _read_or_die(path, marker):
    """Reads a log; the first worker to read the third log (flight2.npz) dies (os._exit) in the middle
    of the run, once (``marker`` records that it happened)."""
    import distributed

    from arxid.fleet import logs as fleet

    try:
        distributed.get_worker()
    except ValueError:  # on the client
        return fleet.load_experiment(path)
    if path.endswith("flight2.npz") and not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(1)
    return fleet.load_experiment(path)


def worker_killing_reader(marker: str):
    """A ``read=`` for fleet tests that kills one Dask worker once, pickled by value (the workers do
    not import this file)."""
    import functools
    import sys

    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    return functools.partial(_read_or_die, marker=marker)


def _read_and_record(path, record):
    """Reads a log, and notes in the file ``record`` each read that happens on the client."""
    import distributed

    from arxid.fleet import logs as fleet

    try:
        distributed.get_worker()
    except ValueError:  # on the client
        with open(record, "a") as f:
            f.write(os.path.basename(path) + "\n")
    return fleet.load_experiment(path)


def client_read_recorder(record: str):
    """A ``read=`` for fleet tests that notes every log read on the client (not on a worker) in the
    file ``record``; pickled by value (the workers do not import this file)."""
    import functools
    import sys

    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    return functools.partial(_read_and_record, record=record)


def made_once(name: str, make: Callable[[], Any]) -> Any:
    """``make()``, made by one xdist worker of the run and read (pickled) by the others.

    Several test files use the demo flights and their analyses, and xdist spreads the files over
    the workers: each worker simulated and analysed the same flights again. Now the first worker to
    ask claims ``name`` (a file created exclusively) and writes the result when done; a worker that
    finds it claimed waits for that file, or makes it itself if making it failed there. Without
    xdist, or when the result never comes (its worker died), ``make()`` runs here.
    """
    if SHARED_RUN_DIR is None:
        return make()
    path = SHARED_RUN_DIR / f"made-once-{name}.pickle"
    claim = path.with_suffix(".claim")
    try:
        os.close(os.open(claim, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        deadline = time.monotonic() + 600
        while time.monotonic() < deadline and claim.exists():
            if path.exists():
                return pickle.loads(path.read_bytes())
            time.sleep(0.05)
        return pickle.loads(path.read_bytes()) if path.exists() else make()
    try:
        value = make()
    except BaseException:
        claim.unlink()  # the others make it themselves (and fail as loudly)
        raise
    part = path.with_suffix(f".{os.getpid()}.part")
    part.write_bytes(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL))
    part.replace(path)  # whole or absent for the readers
    return value


@functools.cache
def demo_data_once(seed: int):
    """``arxid.analysis.demo.demo_data(seed)`` (the flight and the facts of its simulation), simulated
    once per run (about 1.4 s of CPU each, see :func:`made_once`): read it, do not change it."""
    from arxid.analysis.demo import demo_data

    return made_once(f"demo-data-{seed}", lambda: demo_data(seed=seed))


def _demo_flight(seed: int):
    """The demo simulator's flight ``seed`` (20 s, 9,500 samples), simulated once per session."""
    return demo_data_once(seed)[0]


@pytest.fixture(scope="session")
def demo_flight():
    """``demo_flight(seed)``: a demo flight, shared by every test that asks for the same seed
    (each takes seconds to simulate). Validate on another seed: a separate flight of the same
    aircraft, with its own battery level, drift and noise."""
    return _demo_flight


@functools.cache
def _demo_analysis(seed: int):
    """``arxid.analyse`` of demo flight ``seed`` validated on flight ``seed + 1000``, ``expect="stable"``."""
    import arxid

    return made_once(
        f"demo-analysis-{seed}",
        lambda: arxid.analyse(_demo_flight(seed), _demo_flight(seed + 1000), expect="stable"),
    )


@pytest.fixture(scope="session")
def demo_analysis():
    """``demo_analysis(seed)``: the analysis of a demo flight validated on a separate flight (seed
    + 1000, ``expect="stable"``), made once per session for every test that asks for the same seed.
    Read it, do not change it."""
    return _demo_analysis


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory):
    """``run_demo`` on a 10 s flight, run once per session: ``(report path, printed story, DemoResult)``.
    The demo's text and its report are read by several tests (each run takes seconds). Read them,
    do not change them."""
    import io

    from arxid.analysis.demo import run_demo

    path = tmp_path_factory.mktemp("demo") / "demo.html"
    out = io.StringIO()
    res = run_demo(path, duration=10.0, stream=out)
    return path, out.getvalue(), res
