"""One resampler for every log: jittered and multi-rate samples on a uniform grid, commands held,
measurements interpolated, dropouts NaN; and the CSV path (``resample=True``, ``--resample``)."""

from __future__ import annotations

import numpy as np
import pytest

from arxid import IOData
from arxid.data.resample import on_grid, resample
from arxid.exceptions import DataError


def test_jittered_linear_signal_is_recovered_exactly_and_commands_are_held():
    rng = np.random.default_rng(3)
    t = np.arange(1000) * 1e-3 + rng.uniform(-3e-4, 3e-4, 1000)
    r = resample({"gyro": (t, 5.0 + 2.0 * t), "cmd": (t, np.floor(t * 10))}, hold=["cmd"], ts=1e-3)
    assert r.ts == 1e-3 and r.held == {"gyro": False, "cmd": True}
    assert np.allclose(np.diff(r.time), 1e-3, rtol=0, atol=1e-12)
    # linear interpolation of a straight line is exact
    np.testing.assert_allclose(r.values["gyro"], 5.0 + 2.0 * r.time, rtol=1e-12)
    # the held command equals the last sample at or before each grid time
    last = np.searchsorted(t, r.time, side="right") - 1
    np.testing.assert_array_equal(r.values["cmd"], np.floor(t[last] * 10))
    assert not np.isnan(r.values["gyro"]).any()


def test_default_step_is_the_median_interval_of_the_first_signal():
    t = np.cumsum(np.r_[0.0, np.full(99, 0.004)])
    r = resample({"a": (t, t), "b": (t[::2], t[::2])})
    assert r.ts == pytest.approx(0.004)


def test_multi_rate_signals_share_one_grid_over_their_common_span():
    t_fast = np.arange(0.0, 2.0, 0.0025)  # 400 Hz rate loop
    t_slow = np.arange(0.05, 1.95, 0.1)  # 10 Hz battery
    r = resample({"rate": (t_fast, np.sin(t_fast)), "vbat": (t_slow, 16 - t_slow)})
    assert r.ts == pytest.approx(0.0025)
    assert r.time[0] == pytest.approx(0.05) and r.time[-1] <= 1.85 + 1e-12
    np.testing.assert_allclose(r.values["vbat"], 16 - r.time, rtol=1e-12)
    np.testing.assert_allclose(r.values["rate"], np.interp(r.time, t_fast, np.sin(t_fast)), rtol=1e-12)


def test_a_dropout_longer_than_max_gap_becomes_nan_never_bridged():
    t = np.r_[np.arange(0, 1, 0.01), np.arange(1.5, 2.5, 0.01)]
    v = np.ones_like(t)
    r = resample({"y": (t, v), "u": (t, v)}, hold=["u"], ts=0.01)
    gap = (r.time > t[99] + 1e-9) & (r.time < 1.5 - 1e-9)
    assert gap.sum() >= 45
    for name in ("y", "u"):
        assert np.isnan(r.values[name][gap]).all()
        assert np.isfinite(r.values[name][~gap]).all()
    # a max_gap longer than the dropout bridges it
    bridged = resample({"y": (t, v)}, ts=0.01, max_gap=0.6)
    assert np.isfinite(bridged.values["y"]).all()


def test_unsorted_times_are_sorted_and_grid_edges_are_nan():
    t = np.array([0.3, 0.0, 0.2, 0.1])
    out = on_grid(np.sort(t), np.array([0.0, 1.0, 2.0, 3.0]), np.array([-0.1, 0.05, 0.4]), False, 1.0)
    assert np.isnan(out[0]) and out[1] == pytest.approx(0.5) and np.isnan(out[2])
    r = resample({"x": (t, t * 10)}, ts=0.1)
    np.testing.assert_allclose(r.values["x"], r.time * 10)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(ts=-1.0), "ts must be a positive"),
        (dict(max_gap=0.0), "max_gap must be a positive"),
    ],
)
def test_bad_arguments_are_data_errors(kwargs, match):
    t = np.arange(10.0)
    with pytest.raises(DataError, match=match):
        resample({"x": (t, t)}, **kwargs)


def test_signals_that_never_overlap_or_have_one_sample_are_refused():
    t = np.arange(10.0)
    with pytest.raises(DataError, match="never logged at the same time"):
        resample({"a": (t, t), "b": (t + 20, t)}, source="log.bin")
    with pytest.raises(DataError, match="fewer than 2 samples"):
        resample({"a": (np.array([1.0]), np.array([1.0]))})


def _jittered_csv(tmp_path):
    rng = np.random.default_rng(7)
    n = 400
    t = np.arange(n) * 0.001 + rng.uniform(-1.5e-4, 1.5e-4, n)
    u = np.sign(np.sin(t * 40))
    y = 3.0 * t
    path = tmp_path / "jitter.csv"
    np.savetxt(path, np.column_stack([t, y, u]), delimiter=",", header="t,y[deg/s],u", comments="")
    return path, t, y, u


def test_csv_with_jitter_is_refused_with_a_hint_and_read_with_resample(tmp_path):
    path, t, y, u = _jittered_csv(tmp_path)
    with pytest.raises(DataError, match=r"resample=True \(CLI: --resample\)"):
        IOData.from_csv(path, output="y", inputs=["u"], time="t")
    d = IOData.from_csv(path, output="y", inputs=["u"], time="t", resample=True)
    assert d.ts == pytest.approx(np.median(np.diff(t)))
    assert d.output_unit == "deg/s"
    grid = t[0] + d.ts * np.arange(d.n_samples)
    np.testing.assert_allclose(d.y, 3.0 * grid, rtol=1e-9)
    last = np.searchsorted(t, grid, side="right") - 1
    np.testing.assert_array_equal(d.u[:, 0], u[last])
    with pytest.raises(DataError, match="needs the time column"):
        IOData.from_csv(path, output="y", inputs=["u"], ts=0.001, resample=True)


def test_cli_resample_flag(tmp_path):
    from arxid.analysis.cli import build_parser, load_data

    path, *_ = _jittered_csv(tmp_path)
    d = load_data(str(path), "y", ["u"], time_col="t", resample=True)
    assert d.n_samples > 390
    args = build_parser().parse_args(
        ["diagnose", str(path), "--output", "y", "--inputs", "u", "--time", "t", "--resample"]
    )
    assert args.resample is True
