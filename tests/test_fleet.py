"""Fleets of logs (arxid.fleet): a sweep over many logs on a Dask LocalCluster equals the in-process
sweep of the same logs, merged and per log, also when a worker dies in the middle of the sweep."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.fleet import logs as fleet
from conftest import client_read_recorder, worker_killing_reader

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
def client(dask_client):
    return dask_client


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
    # The unit-root test reads the structures from the fleet's factor, as in process.
    assert got.integrating == ref.integrating and got.integrating_reason == ref.integrating_reason
    r_got, r_ref = got.estimation_factor, ref.estimation_factor  # equal up to the sign of each row
    np.testing.assert_allclose(r_got.T @ r_got, r_ref.T @ r_ref, rtol=1e-10, atol=1e-8)
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


def test_a_worker_killed_mid_sweep_is_retried_and_the_result_is_complete(logs, client, tmp_path):
    read = worker_killing_reader(str(tmp_path / "killed"))
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, read=read, progress=False)
    assert os.path.exists(tmp_path / "killed"), "no worker was killed"
    _assert_equal(got, _in_process(logs))


def test_the_client_reads_no_log_until_the_result_needs_the_samples(logs, client, tmp_path):
    record = tmp_path / "client_reads"
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, read=client_read_recorder(str(record)))
    assert not record.exists(), "the client read logs during the sweep"
    ref = _in_process(logs)
    # Shapes and names are known without the samples.
    assert got.estimation.n_samples == ref.estimation.n_samples
    assert got.estimation.experiment_starts == ref.estimation.experiment_starts
    assert got.validation.segments == ref.validation.segments
    assert got.estimation.input_names == ref.estimation.input_names
    assert not record.exists()
    # A model of the result reads the logs on the client, once, and equals the in-process one.
    model = got.model(0)
    assert sorted(record.read_text().split()) == sorted(os.path.basename(p) for p in logs)
    np.testing.assert_allclose(model.parameters_, ref.model(0).parameters_, rtol=1e-12)
    np.testing.assert_array_equal(got.estimation.y, ref.estimation.y)
    np.testing.assert_array_equal(got.validation.u, ref.validation.u)
    assert len(record.read_text().split()) == 2 * N_LOGS  # estimation once, validation once


def test_missing_validation_samples_give_the_in_process_fit_percent(client, tmp_path):
    paths = []
    for i in range(3):
        d = _log(10 + i)
        y, u = d.y.copy(), d.u.copy()
        if i == 1:  # dropouts in the validation part of one log only: output, then an input
            y[2000:2040] = np.nan
            u[2200:2210, 1] = np.nan  # the output is measured there, but no structure predicts it
        path = tmp_path / f"gap{i}.npz"
        np.savez(path, y=y, u=u, ts=d.ts)
        paths.append(str(path))
    got = arxid.sweep(paths, **GRID, validation=0.3, client=client, progress=False, expect="stable")
    ref = _in_process(paths, expect="stable")
    _assert_equal(got, ref)
    assert np.isfinite(got.fit_val).all()


def test_effects_on_a_cluster_equal_the_in_process_sweep(logs, client):
    # An input effect (a column each worker computes within each log) and an output term (simulated).
    effects = ["sign(u1)", "y^3"]
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, effects=effects, progress=False)
    ref = _in_process(logs, effects=effects)
    _assert_equal(got, ref)
    assert got.effects == tuple(effects) and got.structure_name(0).endswith("+ sign(u1) + y^3")


def test_logs_on_demand_refuse_logs_that_changed_since_the_sweep(client, tmp_path):
    paths = []
    for i in range(2):
        d = _log(20 + i)
        path = tmp_path / f"log{i}.npz"
        np.savez(path, y=d.y, u=d.u, ts=d.ts)
        paths.append(str(path))
    got = arxid.sweep(paths, **GRID, validation=0.3, client=client, progress=False, expect="stable")
    head = got.estimation[:5]  # the first samples came with the shapes
    np.testing.assert_array_equal(head.y, _log(20).y[:5])
    d = _log(20, n=2000)
    np.savez(paths[0], y=d.y, u=d.u, ts=d.ts)
    with pytest.raises(arxid.DataError, match="changed since the workers read them"):
        got.model(0)


def test_a_worker_killed_mid_per_log_sweep_is_retried_and_every_log_is_swept(logs, client, tmp_path):
    read = worker_killing_reader(str(tmp_path / "killed"))
    got = arxid.sweep(logs, **GRID, validation=0.3, client=client, read=read, per_experiment=True, progress=False)
    assert os.path.exists(tmp_path / "killed"), "no worker was killed"
    assert got.failed == () and got.names == tuple(os.path.basename(p) for p in logs)
    for path, table in zip(logs, got.tables):
        _assert_equal(table, arxid.sweep(fleet.load_experiment(path), **GRID, validation=0.3, progress=False))


def _broken_logs(logs, tmp_path):
    """The fleet with a truncated copy of its second log and a corrupt (not numpy) third one."""
    truncated, corrupt = tmp_path / "truncated.npz", tmp_path / "corrupt.npz"
    data = Path(logs[1]).read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    corrupt.write_bytes(b"PK\x03\x04" + bytes(range(256)) * 8)
    return [logs[0], str(truncated), str(corrupt), *logs[3:]]


@pytest.mark.parametrize("on_cluster", [False, True])
def test_corrupt_and_truncated_logs_are_named_while_the_others_are_swept(logs, client, tmp_path, on_cluster):
    fleet_logs = _broken_logs(logs, tmp_path)
    kw = {"client": client} if on_cluster else {}
    got = arxid.sweep(fleet_logs, **GRID, validation=0.3, per_experiment=True, progress=False, **kw)
    assert [name for name, _ in got.failed] == ["truncated.npz", "corrupt.npz"]
    assert all("cannot read log" in reason for _, reason in got.failed), got.failed
    assert got.names == tuple(os.path.basename(p) for p in [logs[0], *logs[3:]])
    for path, table in zip([logs[0], *logs[3:]], got.tables):
        _assert_equal(table, arxid.sweep(fleet.load_experiment(path), **GRID, validation=0.3, progress=False))
    assert "2 log(s) could not be swept" in got.summary() and "truncated.npz: cannot read log" in got.summary()


def test_a_fleet_whose_every_log_is_broken_is_an_error(logs, tmp_path):
    fleet_logs = _broken_logs(logs, tmp_path)[1:3]
    with pytest.raises(arxid.DataError, match="no log of the fleet could be swept; truncated.npz: cannot read log"):
        arxid.sweep(fleet_logs, **GRID, validation=0.3, per_experiment=True, progress=False)


def test_a_corrupt_log_in_a_merged_fleet_sweep_is_named(logs, client, tmp_path):
    fleet_logs = _broken_logs(logs, tmp_path)
    with pytest.raises(arxid.DataError, match="cannot read log 'truncated.npz'"):
        arxid.sweep(fleet_logs, **GRID, validation=0.3, progress=False)
    # On a cluster the shares are read at once: whichever broken log fails first is named.
    with pytest.raises(arxid.DataError, match=r"cannot read log '(truncated|corrupt)\.npz'"):
        arxid.sweep(fleet_logs, **GRID, validation=0.3, progress=False, client=client)
