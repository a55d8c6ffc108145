"""Fleets of logs (arxid.fleet): a sweep over many logs on a Dask LocalCluster equals the in-process
sweep of the same logs, merged and per log, also when a worker dies in the middle of the sweep."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid import fleet

distributed = pytest.importorskip("distributed", reason="needs the dask extra: pip install 'arxid[dask]'")

GRID = dict(na=range(1, 4), nb=range(1, 3), nk=range(0, 4))
N_LOGS = 5


def _log(seed, n=2500):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    a = [1, -1.4, 0.5 + 0.02 * seed]
    y = lfilter([0, 0, 0.5, 0.2], a, u[:, 0]) + lfilter([0, -0.3], a, u[:, 1])
    y += lfilter([1], a, 0.03 * rng.standard_normal(n))
    return arxid.IOData(y, u, ts=0.01)


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fleet")
    paths = []
    for i in range(N_LOGS):
        d = _log(i)
        path = folder / f"flight{i}.npz"
        np.savez(path, y=d.y, u=d.u, ts=d.ts)
        paths.append(str(path))
    return paths


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0", silence_logs=40
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def _in_process(paths, **kw):
    parts = [fleet.load_experiment(p).split(0.7) for p in paths]
    est = arxid.IOData.merge([e for e, _ in parts])
    val = arxid.IOData.merge([v for _, v in parts])
    return arxid.sweep(est, **GRID, validation=val, progress=False, **kw)


def _assert_equal(a, b):
    assert len(a) == len(b)
    assert [a.structure_name(i) for i in range(len(a))] == [b.structure_name(i) for i in range(len(b))]
    for name in ("rms_val", "rms_est", "rms_val_one_step", "rms_est_one_step", "fit_val", "fpe"):
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=1e-10, atol=1e-13, err_msg=name)
    for pa, pb in zip(a.parameters, b.parameters):
        np.testing.assert_allclose(pa, pb, rtol=1e-10, atol=1e-13)
    np.testing.assert_array_equal(a.stage, b.stage)


def test_merged_fleet_on_dask_equals_the_in_process_sweep(logs, client):
    ref = _in_process(logs)
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, progress=False)
    _assert_equal(got, ref)
    assert got.n_est == ref.n_est and got.n_val == ref.n_val
    # Two stages over the fleet: the same as two stages in process.
    ref2 = _in_process(logs, top=5)
    got2 = arxid.sweep(logs, **GRID, validation=0.3, client=client, progress=False, top=5)
    _assert_equal(got2, ref2)
    # In process (no client), from IOData objects: the same steps, the same numbers.
    mem = arxid.sweep([fleet.load_experiment(p) for p in logs], **GRID, validation=0.3, progress=False)
    _assert_equal(mem, ref)


def test_per_log_fleet_on_dask_equals_each_logs_sweep(logs, client):
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, per_experiment=True, progress=False)
    assert isinstance(got, fleet.FleetSweep) and len(got.tables) == N_LOGS
    for path, table in zip(logs, got.tables):
        ref = arxid.sweep(fleet.load_experiment(path), **GRID, validation=0.3, progress=False)
        _assert_equal(table, ref)
    assert got.names == tuple(os.path.basename(p) for p in logs)
    assert sum(got.counts.values()) == N_LOGS
    assert got.chosen[0] == got.tables[0].structure_name(0)
    assert f"{N_LOGS} logs swept separately" in got.summary()


def _kill_once(path, marker):
    """Reads a log; the first worker to read the third log dies (os._exit) in the middle of it."""
    try:
        distributed.get_worker()
    except ValueError:  # on the client
        return fleet.load_experiment(path)
    if path.endswith("flight2.npz") and not os.path.exists(marker):
        open(marker, "w").close()
        os._exit(1)
    return fleet.load_experiment(path)


def test_a_worker_killed_mid_sweep_is_retried_and_the_result_is_complete(logs, client, tmp_path):
    import functools

    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])
    read = functools.partial(_kill_once, marker=str(tmp_path / "killed"))
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, read=read, progress=False)
    assert os.path.exists(tmp_path / "killed"), "no worker was killed"
    _assert_equal(got, _in_process(logs))
