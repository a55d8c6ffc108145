"""``arxid bench`` and the numpy reference it (and ``benches/``) measure the sweep against.

The reference is checked against arxid's own numbers (it must compute the same thing, or the ratio
means nothing); the command is checked for its JSON keys, the consistency of its figures (rates are
counts over the measured time) and its one-line errors. No test asserts a time.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.benchmark import SweepBenchmark, benchmark_sweep, synthetic_records
from arxid.analysis.cli import main
from arxid.exceptions import DataError
from arxid.selection.baseline import ArxGrid, numpy_sweep

KEYS = {
    "data",
    "samples_estimation",
    "samples_validation",
    "n_inputs",
    "grid",
    "structures",
    "simulated",
    "repeat",
    "threads",
    "sweep_seconds",
    "structures_per_second",
    "samples_per_second",
    "numpy_seconds",
    "numpy_structures_timed",
    "numpy_extrapolated",
    "ratio_to_numpy",
    "agreement",
    "multiply_adds",
    "fma_bound_seconds",
    "multiply_adds_per_second",
    "analyse_seconds",
}


def _structures(res):
    return [(int(res.na[i]), tuple(map(int, res.nb[i])), tuple(map(int, res.nk[i]))) for i in range(len(res))]


@pytest.mark.parametrize(("n_inputs", "seed"), [(1, 3), (2, 5), (3, 7)])
def test_numpy_reference_computes_what_the_sweep_computes(n_inputs, seed):
    """Same one-step validation losses and free-run errors as arxid's sweep, every structure."""
    est, val = synthetic_records(3000, n_inputs, seed)
    res = arxid.sweep(
        est, na=range(1, 4), nb=range(1, 3), nk=range(0, 4), validation=val, progress=False,
        simulate_estimation=False, expect="stable", top=None,
    )  # fmt: skip
    ref = numpy_sweep(est, val, _structures(res))
    np.testing.assert_allclose(ref.loss_one_step, np.asarray(res.rms_val_one_step) ** 2, rtol=1e-9)
    np.testing.assert_allclose(ref.rms_free_run, res.rms_val, rtol=1e-9)
    # the true structure (na 2, nb 2, nk i + 1 for input i) is exact up to the noise
    assert ref.rms_free_run.min() < 0.2


def test_numpy_reference_envelope_and_errors():
    g = ArxGrid.of([(2, (1, 3), (4, 0)), (1, (2, 0), (0, 5))])
    assert (g.na_max, g.span, g.lag, g.n_inputs) == (2, 5, 4, 2)
    assert g.columns((2, (1, 3), (4, 0))) == [0, 1, 2 + 4, 7, 8, 9]
    est, val = synthetic_records(500)
    bad = arxid.IOData(np.r_[est.y[:-1], np.nan], est.u, ts=est.ts)
    with pytest.raises(DataError, match="complete"):
        numpy_sweep(bad, val, [(1, (1,), (0,))])
    with pytest.raises(DataError, match="too short"):
        numpy_sweep(est, val, [(300, (1,), (0,))])


def _check_consistent(out: dict) -> None:
    assert set(out) == KEYS
    t = out["sweep_seconds"]
    assert t > 0
    assert out["structures_per_second"] == pytest.approx(out["structures"] / t, rel=1e-12)
    n_all = out["samples_estimation"] + out["samples_validation"]
    assert out["samples_per_second"] == pytest.approx(n_all / t, rel=1e-12)
    assert out["ratio_to_numpy"] == pytest.approx(out["numpy_seconds"] / t, rel=1e-12)
    assert out["fma_bound_seconds"] == pytest.approx(out["multiply_adds"] / out["multiply_adds_per_second"], rel=1e-12)
    g = out["grid"]
    assert out["structures"] == len(g["na"]) * (len(g["nb"]) * len(g["nk"])) ** out["n_inputs"]
    assert 0 < out["simulated"] <= min(out["structures"], 1000)
    assert out["agreement"] < 1e-8  # the two computed the same losses


def test_cli_bench_on_a_csv_file(tmp_path, capsys):
    est, _ = synthetic_records(2000, 1, seed=4)
    p = tmp_path / "log.csv"
    np.savetxt(p, np.column_stack([est.y, est.u]), delimiter=",", header="y,u", comments="")
    argv = [str(p), "--output", "y", "--inputs", "u", "--ts", "0.01", "--na", "1:3", "--nb", "1:2", "--nk", "0:2"]
    assert main(["bench", *argv, "--repeat", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    _check_consistent(out)
    assert out["data"] == "log.csv"
    assert (out["samples_estimation"], out["samples_validation"]) == (1400, 600)  # the default 0.7 split
    assert out["structures"] == out["simulated"] == 18  # small grid: every structure simulated
    assert not out["numpy_extrapolated"] and out["numpy_structures_timed"] == 18
    assert out["analyse_seconds"] is None
    # multiply-adds of the free runs: (na + nb + 1) per structure per simulated sample
    lag = 3  # largest na, and largest nk + nb - 1
    per_sample = sum(na + nb + 1 for na in range(1, 4) for nb in range(1, 3) for _ in range(3))
    assert out["multiply_adds"] == per_sample * (600 - lag)
    # the same in sentences, with --split and --analyse
    assert main(["bench", *argv, "--split", "0.5", "--repeat", "1", "--analyse"]) == 0
    text = capsys.readouterr().out
    assert "1,000 estimation + 1,000 validation samples" in text
    assert "structures/s" in text and "samples/s" in text and "x faster" in text and "FMA" in text
    assert "arxid analyse" in text


def test_cli_bench_on_synthetic_data(capsys):
    argv = ["bench", "--samples", "1500", "--synthetic-inputs", "2", "--na", "1:2", "--nb", "1:2", "--nk", "0:1"]
    assert main([*argv, "--repeat", "2", "--baseline-structures", "10", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    _check_consistent(out)
    assert out["n_inputs"] == 2 and out["structures"] == 32 and out["repeat"] == 2
    assert out["samples_estimation"] == out["samples_validation"] == 1500
    assert out["numpy_extrapolated"] and out["numpy_structures_timed"] == 10
    assert out["data"].startswith("synthetic")


def test_benchmark_sweep_is_the_cli_and_grows_to_two_stages():
    est, val = synthetic_records(1200, 3, seed=2)
    b = benchmark_sweep(est, val, {"na": [1, 2], "nb": [1, 2], "nk": [0, 1, 2, 3]}, repeat=1, baseline_structures=50)
    assert isinstance(b, SweepBenchmark)
    assert b.structures == 2 * 8**3 and b.simulated == 1000  # two stages: the best 1,000 simulated
    _check_consistent(b.to_dict())
    assert str(b).splitlines()[0].startswith("data: synthetic")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--samples", "10"], "--samples 10 is too few"),
        (["--repeat", "0"], "--repeat must be at least 1"),
        (["--baseline-structures", "0"], "--baseline-structures must be at least 1"),
        (["--output", "y"], "--output describe DATA"),
        (["--split", "0.5"], "--split describe DATA"),
        (["--na", "x"], "--na"),
        (["--samples", "300", "--na", "1:200"], "too short for the grid"),
    ],
)
def test_cli_bench_bad_arguments(argv, message, capsys):
    assert main(["bench", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_cli_bench_bad_data_arguments(tmp_path, capsys):
    est, _ = synthetic_records(600)
    y = est.y.copy()
    y[100] = np.nan
    p = tmp_path / "gappy.csv"
    np.savetxt(p, np.column_stack([y, est.u]), delimiter=",", header="y,u", comments="")
    base = ["bench", str(p), "--ts", "0.01"]
    for argv, message in [
        ([*base, "--output", "y", "--inputs", "u", "--samples", "1000"], "either DATA or --samples"),
        ([*base, "--output", "y"], "DATA needs --output COL and --inputs"),
        ([*base, "--output", "y", "--inputs", "u"], "missing samples"),
        ([*base, "--output", "nope", "--inputs", "u"], "nope"),
    ]:
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
