"""The analysis of a fleet on a Dask LocalCluster (``arxid.analyse(logs, client=...)``) against the
in-process analysis of the same logs merged as experiments of one IOData (each log's last 30 %
validating): same structure, same suspects with the same statistics to rounding, same ladder errors;
and the logs the missing effect is named in are exactly those simulated with it.

The plant: a second-order plant driven by u; in the logs "with the effect" its input is scaled by a
sagging battery (u·vbat/4.2, as in benches/analyse_scale.py) or passes through a cubic (u + 0.3 u³);
the other logs have a constant gain, vbat and a decoy logged in every log. The cluster is the
session's (tests/conftest.py), skipped without the dask extra.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.data.logs import merged_parts
from arxid.diagnosis.cluster_records import diagnose_fleet, diagnose_logs
from arxid.diagnosis.extension import candidate_list
from arxid.diagnosis.pooled_refits import PooledRefits as FleetRefits
from arxid.diagnosis.scoring import Scoring
from arxid.exceptions import ArxidError
from arxid.fleet.cluster import WorkerLogs

N = 1500
CANDIDATES = ["u1*vbat", "u1^3", "vbat", "decoy", "u1^2", "const", "time", "na+1", "nb+1"]
REL = 1e-9


def _log(seed: int, effect: str | None):
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(N)) * 0.5 + 0.5 * rng.standard_normal(N)
    sag = np.linspace(0.0, 1.0, N)
    vbat = 4.2 - 0.9 * sag + 0.01 * rng.standard_normal(N)
    decoy = 20.0 + 0.05 * np.cumsum(rng.standard_normal(N)) / np.sqrt(N / 4000)
    drive = {"battery": u * vbat / 4.2, "cubic": u + 0.3 * u**3, None: 0.9 * u}[effect]
    a = [1.0, -1.5, 0.7]
    y = lfilter([0.0, 0.5, 0.25], a, drive) + lfilter([1.0], a, 0.02 * rng.standard_normal(N))
    return arxid.IOData(y, u, 0.001, extra={"vbat": vbat, "decoy": decoy})


def _fleet(seed: int, effect: str, n_logs: int = 5) -> tuple[list, list[str]]:
    """``n_logs`` logs; the effect in the logs at the positions the seed picks (at least one, not all)."""
    rng = np.random.default_rng(100 + seed)
    k = int(rng.integers(1, n_logs))
    with_effect = sorted(int(i) for i in rng.choice(n_logs, size=k, replace=False))
    logs = [_log(10 * seed + i, effect if i in with_effect else None) for i in range(n_logs)]
    return logs, [f"log {i + 1}" for i in with_effect]


def _close(a: float, b: float) -> bool:
    return bool(np.isclose(a, b, rtol=REL, atol=1e-300) or (np.isnan(a) and np.isnan(b)))


def _assert_same(fleet, local) -> None:
    """Same structure, missing effect, suspects (order and statistics) and ladder errors."""
    assert fleet.model.structure_name() == local.model.structure_name()
    np.testing.assert_allclose(fleet.model.parameters_, local.model.parameters_, rtol=1e-10, atol=1e-13)
    assert fleet.missing_effect == local.missing_effect
    assert [s.effect for s in fleet.diagnosis.suspects] == [s.effect for s in local.diagnosis.suspects]
    for f, s in zip(fleet.diagnosis.suspects, local.diagnosis.suspects, strict=True):
        assert f.significant == s.significant, f.effect
        for name in ("score", "f_statistic", "rms_sim_val_after"):
            assert _close(getattr(f, name), getattr(s, name)), (f.effect, name, getattr(f, name), getattr(s, name))
        # p-values below ~1e-300 are zero in both; elsewhere relative
        for name in ("p_value_raw", "p_value"):
            a, b = getattr(f, name), getattr(s, name)
            assert np.isclose(a, b, rtol=1e-8, atol=1e-250), (f.effect, name, a, b)
    assert [st.added for st in fleet.ladder.steps] == [st.added for st in local.ladder.steps]
    np.testing.assert_allclose(fleet.ladder.errors, local.ladder.errors, rtol=REL)
    assert _close(fleet.diagnosis.rms_sim_val, local.diagnosis.rms_sim_val)
    assert _close(fleet.diagnosis.fit_val, local.diagnosis.fit_val)


@pytest.mark.parametrize(
    ("seed", "effect", "expected"), [(0, "battery", "u1*vbat"), (1, "cubic", "u1^3"), (7, "battery", "u1*vbat")]
)
def test_fleet_analysis_matches_in_process_and_names_the_logs(dask_client, seed, effect, expected):
    logs, with_effect = _fleet(seed, effect)
    est, val = merged_parts(logs, None, 0.3)
    local = arxid.analyse(est, val, orders=(2, 2, 1), candidates=CANDIDATES, max_steps=2)
    fleet = arxid.analyse(logs, client=dask_client, orders=(2, 2, 1), candidates=CANDIDATES, max_steps=2)
    _assert_same(fleet, local)
    assert fleet.missing_effect == expected
    assert fleet.logs_with_effect == tuple(with_effect)
    out = fleet.to_dict()
    assert out["fleet"]["logs_with_effect"] == with_effect
    assert ", ".join(with_effect) in out["fleet"]["sentence"]
    assert [e["log"] for e in out["fleet"]["logs"]] == [f"log {i + 1}" for i in range(len(logs))]
    assert fleet.to_json()  # JSON-ready


def test_fleet_sweep_choice_matches_in_process(dask_client):
    """With a grid, the fleet sweep's choice is the in-process one on the merged logs."""
    logs, _ = _fleet(2, "battery", n_logs=4)
    est, val = merged_parts(logs, None, 0.3)
    grid = {"na": [1, 2, 3], "nb": [1, 2], "nk": [0, 1, 2]}
    fleet = arxid.analyse(logs, client=dask_client, grid=grid, candidates=CANDIDATES, max_steps=1)
    local = arxid.analyse(est, val, grid=grid, candidates=CANDIDATES, max_steps=1)
    _assert_same(fleet, local)
    assert fleet.choice.rank == local.choice.rank


def test_the_default_grid_on_a_cluster_is_the_in_process_one_grown_the_same_way(dask_client):
    """No orders and no grid: the cluster sweeps the default grid and grows it where the logs are,
    as the in-process analysis does. Three records of a flexible arm (sixth order, outside the
    default grid na 1..4, nb 1..3) give the same grids tried and the same structure, well outside it."""
    from test_robust_grid import arm_record

    logs = [arm_record(seed) for seed in range(3)]
    est, val = merged_parts(logs, None, 0.3)
    fleet = arxid.analyse(logs, client=dask_client, candidates=["const"], max_steps=0)
    local = arxid.analyse(est, val, candidates=["const"], max_steps=0)
    assert fleet.grid == arxid.analysis.grid_of() and fleet.sweep.growth.grew
    assert [r.text for r in fleet.sweep.growth.rounds] == [r.text for r in local.grid_growth.rounds]
    assert fleet.model.structure_name() == local.model.structure_name() and fleet.model.na_ > 4
    np.testing.assert_allclose(fleet.model.parameters_, local.model.parameters_, rtol=1e-8, atol=1e-12)
    # a given grid is swept as given, on the cluster as in process
    given = arxid.analyse(logs, client=dask_client, grid={"na": [1, 2, 3, 4]}, candidates=["const"], max_steps=0)
    assert given.sweep.growth.stop in ("off", "inside") and len(given.sweep) == 72


def test_per_log_test_is_the_in_process_test_on_that_log(dask_client):
    """A log's statistic is the added-variable test of the top suspect on that log's rows alone."""
    logs, with_effect = _fleet(3, "battery", n_logs=4)
    workers = WorkerLogs(dask_client, logs, validation=0.3)
    model = FleetRefits(workers).fit(2, (2,), (1,), ())
    fd = diagnose_fleet(model, workers, candidates=CANDIDATES)
    assert fd.diagnosis.top is not None and fd.diagnosis.top.effect == "u1*vbat"
    for i, ev in enumerate(fd.evidence):
        est = logs[i].split(0.7)[0]
        cands, _ = candidate_list(CANDIDATES, model, est)  # the same rows as the diagnosis'
        scored, _ = Scoring(model, est, cands).run(0.01, 0)
        top = next(s for s in scored if s["c"].label == "u1*vbat")
        assert _close(ev.score, top["score"]) and _close(ev.f_statistic, top["f"])
        assert np.isclose(ev.p_value, top["p"], rtol=1e-8, atol=1e-250)
    assert fd.logs_with_effect == tuple(with_effect)
    # the same from the list of logs and an in-process model of the merged estimation parts
    est, _ = merged_parts(logs, None, 0.3)
    again = diagnose_logs(arxid.arx(est, 2, 2, 1), logs, dask_client, candidates=CANDIDATES)
    assert [s.effect for s in again.diagnosis.suspects] == [s.effect for s in fd.diagnosis.suspects]
    assert again.logs_with_effect == fd.logs_with_effect
    # and from arxid.diagnose given the client, as arxid.analyse takes one
    given = arxid.diagnose(arxid.arx(est, 2, 2, 1), logs, client=dask_client, candidates=CANDIDATES)
    assert [s.effect for s in given.diagnosis.suspects] == [s.effect for s in fd.diagnosis.suspects]
    scores = [[s.score for s in d.diagnosis.suspects] for d in (given, again)]
    np.testing.assert_allclose(*scores, rtol=REL)
    assert given.logs_with_effect == fd.logs_with_effect
    with pytest.raises(ArxidError, match="give no validation= with client="):
        arxid.diagnose(arxid.arx(est, 2, 2, 1), logs, logs[0], client=dask_client)


def test_fleet_analysis_refuses_what_it_cannot_do(dask_client):
    logs, _ = _fleet(4, "battery", n_logs=2)
    with pytest.raises(ArxidError, match="with client=, analyse takes no validation data.*or neither"):
        arxid.analyse(logs, logs[0], client=dask_client, orders=(2, 2, 1))
    workers = WorkerLogs(dask_client, logs)  # no validation share
    model = FleetRefits(workers).fit(2, (2,), (1,), ())
    with pytest.raises(ArxidError, match="validation"):
        diagnose_fleet(model, workers)


def test_cli_fleet_names_the_logs(dask_client, tmp_path, capsys):
    """``arxid fleet 'dir/*.npz' --scheduler ... --json``: the workers read the files; the JSON names
    the logs with the effect and gives the in-process answer."""
    import json

    from arxid.analysis.cli import main

    logs, with_effect = _fleet(5, "battery", n_logs=4)
    for i, d in enumerate(logs):
        np.savez(tmp_path / f"flight{i}.npz", y=d.y, u=d.u[:, 0], vbat=d.extra["vbat"], decoy=d.extra["decoy"])
    argv = ["fleet", str(tmp_path / "flight*.npz"), "--output", "y", "--inputs", "u", "--extra", "vbat,decoy"]
    argv += ["--ts", "0.001", "--orders", "2,2,1", "--candidates", "u*vbat,vbat,const,dz(u,0.3)", "--max-steps", "1"]
    assert main([*argv, "--scheduler", dask_client.scheduler.address, "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    named = [f"flight{int(n.split()[1]) - 1}.npz" for n in with_effect]
    assert out["fleet"]["logs_with_effect"] == named
    assert out["suspects"][0]["effect"] == "u*vbat" and out["suspects"][0]["significant"]
    est, val = merged_parts(logs, None, 0.3)
    local = arxid.diagnose(arxid.arx(est, 2, 2, 1), est, val, candidates=["u1*vbat", "vbat", "const", "dz(u1,0.3)"])
    assert np.isclose(out["suspects"][0]["score"], local.suspects[0].score, rtol=REL)
    assert np.isclose(out["suspects"][0]["p_value"], local.suspects[0].p_value, rtol=1e-8, atol=1e-250)
    assert "dz(u,0.3)" in [s["effect"] for s in out["suspects"]]  # the threshold's comma kept
    assert np.isclose(out["ladder"][1]["rms_sim_val"], local.suspects[0].rms_sim_val_after, rtol=REL)
    assert main(["fleet", str(tmp_path / "nothing*.npz"), "--output", "y", "--inputs", "u", "--orders", "2,2,1"]) == 2


def test_fleet_analysis_with_automatic_candidates(dask_client):
    """``candidates="auto"`` on a fleet (the union of what each worker's logs suggest, no threshold
    scans) finds the battery and names the logs with it."""
    logs, with_effect = _fleet(6, "battery", n_logs=4)
    fleet = arxid.analyse(logs, client=dask_client, orders=(2, 2, 1), max_steps=1)
    assert fleet.missing_effect == "u1*vbat"
    assert fleet.logs_with_effect == tuple(with_effect)
    assert any("threshold scan" in s.note for s in fleet.diagnosis.suspects)  # said, not silently dropped


@pytest.mark.parametrize("options", [{"initial": "estimate"}, {"horizon": 5}])
def test_fleet_analysis_other_error_measures(dask_client, options):
    """Estimated initial conditions and k-step errors are pooled from the workers as well."""
    logs, with_effect = _fleet(11, "battery", n_logs=4)
    est, val = merged_parts(logs, None, 0.3)
    local = arxid.analyse(est, val, orders=(2, 2, 1), candidates=CANDIDATES, max_steps=1, **options)
    fleet = arxid.analyse(logs, client=dask_client, orders=(2, 2, 1), candidates=CANDIDATES, max_steps=1, **options)
    _assert_same(fleet, local)
    assert fleet.horizon == local.horizon == options.get("horizon")
    assert fleet.logs_with_effect == tuple(with_effect)


def test_fleet_analysis_with_missing_samples(dask_client):
    """Two missing output samples in one log: a candidate reaching further back (``na+1``) is tested on
    the rows both have, from factors of its own, as in process; the answer is still the same."""
    logs, with_effect = _fleet(12, "battery", n_logs=4)
    y = np.array(logs[1].y)
    y[[300, 1400]] = np.nan
    logs[1] = arxid.IOData(y, logs[1].u, 0.001, extra=dict(logs[1].extra))
    est, val = merged_parts(logs, None, 0.3)
    local = arxid.analyse(est, val, orders=(2, 2, 1), candidates=CANDIDATES, max_steps=1)
    fleet = arxid.analyse(logs, client=dask_client, orders=(2, 2, 1), candidates=CANDIDATES, max_steps=1)
    _assert_same(fleet, local)
    assert np.isfinite(next(s.score for s in fleet.diagnosis.suspects if s.effect == "na+1"))
    assert fleet.logs_with_effect == tuple(with_effect)


def test_one_record_given_as_records_is_the_same_diagnosis():
    """``diagnose(model, OneRecord(est, val))`` is ``diagnose(model, est, val)``: the records are where
    the procedure runs, not a second procedure."""
    from arxid.diagnosis.suspects import OneRecord

    est, val = _log(21, "battery").split(0.7)
    model = arxid.arx(est, 2, 2, 1)
    direct = arxid.diagnose(model, est, val, candidates=CANDIDATES)
    given = arxid.diagnose(model, OneRecord(est, val), candidates=CANDIDATES)
    assert [s.effect for s in given.suspects] == [s.effect for s in direct.suspects]
    assert given.top is not None and given.top.effect == "u1*vbat"
    for a, b in zip(given.suspects, direct.suspects, strict=True):
        assert _close(a.score, b.score) and _close(a.rms_sim_val_after, b.rms_sim_val_after), a.effect
    with pytest.raises(ArxidError, match="records hold their own validation data"):
        arxid.diagnose(model, OneRecord(est, val), val)


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("arxid.diagnosis.fleet_diagnose", "arxid.diagnosis.cluster_records"),
        ("arxid.diagnosis.fleet_scoring", "arxid.diagnosis.statistics"),
        ("arxid.diagnosis.fleet_refit", "arxid.diagnosis.pooled_refits"),
    ],
)
def test_the_fleet_modules_old_paths_still_import(old, new):
    import importlib
    import sys

    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=f"{old} moved to {new}"):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)


@pytest.mark.parametrize("options", [{"orders": (2, 2, 1), "max_steps": 2}, {"max_steps": 1}])
def test_one_record_on_a_cluster_is_the_analysis_in_process(dask_client, options):
    """``analyse(data)`` and ``analyse([data], client=...)`` (a fleet of one) give the same answers to
    rounding: structure (the given orders, or the default grid swept and grown where the log is),
    ranking, statistics, fits and ladder errors; the one log is the log the effect shows in."""
    data = _log(31, "battery")
    local = arxid.analyse(data, candidates=CANDIDATES, **options)
    fleet = arxid.analyse([data], client=dask_client, candidates=CANDIDATES, **options)
    _assert_same(fleet, local)
    assert local.missing_effect == "u1*vbat"
    assert fleet.grid == local.grid and fleet.choice.rank == local.choice.rank
    for f, s in zip(fleet.diagnosis.suspects, local.diagnosis.suspects, strict=True):
        if s.model is not None:  # the refits' parameters, where the suspect was refitted
            np.testing.assert_allclose(f.model.parameters_, s.model.parameters_, rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(fleet.final_model.parameters_, local.final_model.parameters_, rtol=1e-9, atol=1e-13)
    assert fleet.logs_with_effect == ("log 1",)
