"""One ARX model over a fleet of logs (arxid.fleet.fit): a list of logs is fitted as the logs
concatenated with gaps (so no regressor straddles two logs); on a Dask LocalCluster (shared with the
fleet sweep tests) the model equals the in-process fit to 1e-10, from IOData objects and from CSV
files; one model per log equals each log's own fit, and the fleet summary is numpy's statistics of
those parameters, with the odd log named."""

from __future__ import annotations

import os

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid._base import metrics
from arxid.exceptions import DataError, IdentifiabilityError
from arxid.fleet import fit as fleet_fit
from arxid.models.effects import compile_effects
from arxid.models.regressors import regressor_matrix
from conftest import worker_killing_reader

EFFECTS = ("u1*vbat", "const", "y^3")
ORDERS = dict(na=2, nb=2, nk=1)
N_LOGS = 5


def _log(seed, n=2000, gain=0.5, names=("u1", "vbat"), ts=0.01):
    """y = B/A u with A = 1 − 1.4 q⁻¹ + (0.5 + 0.02 seed) q⁻², a product term u1·vbat, an offset and
    coloured noise; seed 3 drops one sample (a NaN) so that rows are left out."""
    rng = np.random.default_rng(seed)
    u = np.column_stack([rng.standard_normal(n), 3.7 + 0.3 * rng.standard_normal(n)])
    a = [1, -1.4, 0.5 + 0.02 * seed]
    y = lfilter([0, gain, 0.2], a, u[:, 0]) + lfilter([0, -0.3], a, u[:, 1]) + lfilter([0, 0.05], a, u[:, 0] * u[:, 1])
    y += 0.1 + lfilter([1], a, 0.03 * rng.standard_normal(n))
    if seed == 3:
        y[777] = np.nan
    return arxid.IOData(y, u, ts=ts, output_name="pitch_rate", input_names=list(names))


@pytest.fixture(scope="module")
def logs():
    return [_log(i) for i in range(N_LOGS)]


@pytest.fixture(scope="module")
def csv_logs(logs, tmp_path_factory):
    """The logs as CSV files (time, output with its unit, inputs), read back with ``read=``."""
    folder = tmp_path_factory.mktemp("fleet_csv")
    paths = []
    for i, d in enumerate(logs):
        path = folder / f"flight{i}.csv"
        table = np.column_stack([d.time, d.y, d.u])
        np.savetxt(path, table, delimiter=",", header="t,pitch_rate[rad/s],u1,vbat[V]", comments="", fmt="%.17g")
        paths.append(str(path))
    return paths


READ = dict(output="pitch_rate", inputs=["u1", "vbat"], ts=0.01)


def _assert_same_model(got, ref, rtol=1e-10):
    assert got.structure_name() == ref.structure_name()
    assert got.regressor_names_ == ref.regressor_names_
    assert (got.n_rows_, got.n_skipped_) == (ref.n_rows_, ref.n_skipped_)
    assert (got.ts, got.output_name, got.input_names) == (ref.ts, ref.output_name, ref.input_names)
    np.testing.assert_allclose(got.parameters_, ref.parameters_, rtol=rtol, atol=1e-13)
    np.testing.assert_allclose(got.covariance_, ref.covariance_, rtol=rtol, atol=1e-16)
    for name in ("rss_", "noise_variance_", "loss_", "fpe_", "aic_", "aicc_", "naic_", "bic_", "fit_percent_"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=rtol, err_msg=name)


# ----------------------------------------------------------------------------- in process
def test_a_list_of_logs_is_fitted_as_the_logs_concatenated_with_gaps(logs):
    got = arxid.arx(logs, **ORDERS, effects=EFFECTS)
    # The same logs one after the other, separated by NaN gaps as long as the largest lag: every
    # regression row touching a gap is left out, so no row straddles two logs.
    gap = 3

    def cat(rows):
        return np.concatenate([np.concatenate([r, np.full((gap,) + r.shape[1:], np.nan)]) for r in rows])

    gapped = arxid.IOData(
        cat([d.y for d in logs]),
        cat([d.u for d in logs]),
        ts=0.01,
        output_name="pitch_rate",
        input_names=["u1", "vbat"],
    )
    ref = arxid.arx(gapped, **ORDERS, effects=EFFECTS)
    assert got.n_rows_ == ref.n_rows_
    np.testing.assert_allclose(got.parameters_, ref.parameters_, rtol=1e-10)
    np.testing.assert_allclose(got.covariance_, ref.covariance_, rtol=1e-10)
    np.testing.assert_allclose(got.rss_, ref.rss_, rtol=1e-10)
    # numpy.linalg.lstsq on every log's own regressor rows, stacked.
    rows = [regressor_matrix(d, 2, compile_effects(EFFECTS, d, (2, 2), (1, 1))) for d in logs]
    phi, y = np.vstack([r[0] for r in rows]), np.concatenate([r[1] for r in rows])
    np.testing.assert_allclose(got.parameters_, np.linalg.lstsq(phi, y, rcond=None)[0], rtol=1e-9)
    assert got.n_rows_ == len(y) and got.n_skipped_ == 3  # one NaN output: three rows lost
    # ArxModel.fit takes the list too, and IOData.merge of the logs is the same data.
    _assert_same_model(arxid.ArxModel(**ORDERS, effects=EFFECTS).fit(logs), got, rtol=0)
    _assert_same_model(arxid.arx(arxid.IOData.merge(logs), **ORDERS, effects=EFFECTS), got, rtol=0)


def test_the_fit_percent_of_parts_equals_the_fit_percent_of_the_whole():
    rng = np.random.default_rng(5)
    y = 1e3 * rng.standard_normal(1000) + 4e3
    pred = y + 100 * rng.standard_normal(1000)
    y[10], pred[500:520] = np.nan, np.nan
    cuts = [0, 7, 300, 301, 1000]
    parts = [metrics.fit_percent_part(y[a:b], pred[a:b]) for a, b in zip(cuts, cuts[1:])]
    assert metrics.fit_percent_of_parts(parts) == pytest.approx(metrics.fit_percent(y, pred), rel=1e-13)
    # A part that diverged makes the whole diverge, judged by the largest |y| of all parts.
    wild = pred.copy()
    wild[900] = 1.5e3 * np.nanmax(np.abs(y))
    parts = [metrics.fit_percent_part(y[a:b], wild[a:b]) for a, b in zip(cuts, cuts[1:])]
    assert metrics.fit_percent_of_parts(parts) == metrics.fit_percent(y, wild) == -np.inf


# ----------------------------------------------------------------------------- on a Dask cluster
def test_the_dask_fit_equals_the_in_process_fit(logs, dask_client):
    ref = arxid.arx(logs, **ORDERS, effects=EFFECTS)
    got = arxid.arx(logs, **ORDERS, effects=EFFECTS, client=dask_client)
    _assert_same_model(got, ref)
    assert got.data_ is None and ref.data_ is not None
    # Without effects, and per-input orders.
    ref = arxid.arx(logs, 3, [2, 1], [1, 2])
    _assert_same_model(arxid.ArxModel(na=3, nb=[2, 1], nk=[1, 2]).fit(logs, client=dask_client), ref)
    # The model predicts like the in-process one.
    np.testing.assert_allclose(
        got.predict(logs[0], horizon=1),
        arxid.arx(logs, **ORDERS, effects=EFFECTS).predict(logs[0], horizon=1),
        rtol=1e-9,
    )


def test_the_dask_fit_of_csv_files_equals_the_in_process_fit(csv_logs, logs, dask_client):
    ref = arxid.arx(csv_logs, **ORDERS, effects=EFFECTS, read=READ)
    _assert_same_model(ref, arxid.arx(logs, **ORDERS, effects=EFFECTS))
    assert ref.output_unit == "rad/s"
    got = arxid.arx(csv_logs, **ORDERS, effects=EFFECTS, read=READ, client=dask_client)
    _assert_same_model(got, ref)
    assert got.output_unit == "rad/s" and got.input_units == ("", "V")


def test_a_worker_killed_mid_fit_is_retried_and_the_model_is_the_same(logs, dask_client, tmp_path):
    paths = []
    for i, d in enumerate(logs):
        paths.append(str(tmp_path / f"flight{i}.npz"))
        np.savez(paths[-1], y=d.y, u=d.u, ts=d.ts)
    read = worker_killing_reader(str(tmp_path / "killed"))
    got = arxid.arx(paths, **ORDERS, effects=("const",), client=dask_client, read=read)
    assert os.path.exists(tmp_path / "killed"), "no worker was killed"
    ref = arxid.arx([arxid.IOData(d.y, d.u, ts=d.ts) for d in logs], **ORDERS, effects=("const",))
    _assert_same_model(got, ref)


def test_collinear_regressors_are_named_the_same_on_dask(dask_client):
    twin = [arxid.IOData(d.y, np.column_stack([d.u[:, 0], 2 * d.u[:, 0]]), ts=0.01) for d in (_log(0), _log(1))]
    with pytest.raises(IdentifiabilityError) as local:
        arxid.arx(twin, 1, 1, 1)
    with pytest.raises(IdentifiabilityError) as remote:
        arxid.arx(twin, 1, 1, 1, client=dask_client)
    assert str(remote.value) == str(local.value)
    assert remote.value.regressors == local.value.regressors == ("u1(t-1)", "u2(t-1)")


# ----------------------------------------------------------------------------- one model per log
def test_one_model_per_log_equals_each_logs_fit_and_the_odd_log_is_named(dask_client):
    fleet_logs = [_log(i, gain=0.8 if i == 4 else 0.5) for i in range(8)]
    local = arxid.arx(fleet_logs, **ORDERS, effects=EFFECTS, per_experiment=True)
    remote = arxid.arx(fleet_logs, **ORDERS, effects=EFFECTS, per_experiment=True, client=dask_client)
    assert isinstance(local, fleet_fit.FleetModels) and local.names == tuple(f"log {i + 1}" for i in range(8))
    for d, a, b in zip(fleet_logs, local.models, remote.models):
        ref = arxid.arx(d, **ORDERS, effects=EFFECTS)
        _assert_same_model(a, ref, rtol=0)
        _assert_same_model(b, ref)
        assert b.data_ is None
    theta = np.array([m.parameters_ for m in local.models])
    spread = {s.name: s for s in local.spread()}
    b1 = spread["u1(t-1)"]
    assert (b1.mean, b1.min, b1.max) == (theta[:, 2].mean(), theta[:, 2].min(), theta[:, 2].max())
    assert b1.std == pytest.approx(theta[:, 2].std(ddof=1), rel=1e-12)
    # Log 5 was flown with gain 0.8 instead of 0.5: only that log, only for that parameter.
    assert b1.outliers == ("log 5",)
    assert abs(b1.max - 0.8) < 0.02 and b1.spread_ratio > 10
    # a2 = 0.5 + 0.02·seed spreads evenly across the fleet: far more than its noise, yet no odd one
    # out; a1 is the same in every log, so it spreads as its standard errors say.
    a2, a1 = spread["pitch_rate(t-2)"], spread["pitch_rate(t-1)"]
    assert a2.spread_ratio > 10 and a2.outliers == ()
    assert a1.spread_ratio < 2 and a1.outliers == ()
    text = local.summary()
    assert "8 logs fitted separately with ARX(2,2,1)" in text and "log 5" in text
    assert list(local.to_pandas().index) == list(local.names)


def test_the_outlier_rule_uses_the_mean_deviation_when_most_logs_agree():
    names = [f"log {i}" for i in range(6)]
    values = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.3])
    assert fleet_fit.outlier_logs(values, np.full(6, 0.01), names) == ("log 5",)
    # Within three of its own standard errors of the median, it is not an outlier.
    assert fleet_fit.outlier_logs(values, np.full(6, 0.2), names) == ()


# ----------------------------------------------------------------------------- bad input
def test_an_empty_list_is_refused(dask_client):
    for kw in ({}, {"client": dask_client}, {"per_experiment": True}, {"per_experiment": True, "client": dask_client}):
        with pytest.raises(DataError, match="list of logs is empty"):
            arxid.arx([], 2, 2, 1, **kw)


@pytest.mark.parametrize(
    "odd, message",
    [
        (
            dict(names=("u1", "throttle")),
            r"log 'log 3' has inputs \['u1', 'throttle'\] but log 'log 1' has \['u1', 'vbat'\]",
        ),
        (dict(ts=0.02), r"log 'log 3' is sampled at ts=0.02 s but log 'log 1' at ts=0.01 s"),
    ],
)
def test_logs_that_differ_are_refused_naming_the_log(odd, message, dask_client):
    mixed = [_log(0), _log(1), _log(2, **odd)]
    for kw in ({}, {"client": dask_client}, {"per_experiment": True}, {"per_experiment": True, "client": dask_client}):
        with pytest.raises(DataError, match=message):
            arxid.arx(mixed, 2, 2, 1, **kw)
    with pytest.raises(DataError, match=message):  # the fleet sweep reads its logs the same way
        arxid.sweep(mixed, na=2, nb=2, nk=1, validation=0.3, progress=False)


def test_an_unreadable_path_is_refused_naming_the_log(csv_logs, tmp_path, dask_client):
    missing = str(tmp_path / "flight_lost.csv")
    broken = tmp_path / "flight_broken.npz"
    broken.write_text("not a numpy file")
    for bad in (missing, str(broken)):
        name = os.path.basename(bad)
        for kw in ({}, {"client": dask_client}, {"per_experiment": True, "client": dask_client}):
            with pytest.raises(DataError, match=f"cannot read log '{name}'"):
                arxid.arx([csv_logs[0], bad], 2, 2, 1, read=READ, **kw)


def test_client_and_per_experiment_need_a_list(logs, dask_client):
    with pytest.raises(DataError, match="client= fits a list of logs"):
        arxid.arx(logs[0], 2, 2, 1, client=dask_client)
    with pytest.raises(DataError, match="per_experiment=True fits each log of a list"):
        arxid.arx(logs[0], 2, 2, 1, per_experiment=True)
