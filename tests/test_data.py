"""IOData: constructors, experiments, NaN bookkeeping, transformations."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.exceptions import DataError


def test_arrays_are_copied_and_read_only():
    y = np.arange(10.0)
    d = arxid.IOData(y, np.arange(10), ts=0.5, output_name="roll", input_names=["torque"], output_unit="rad")
    y[0] = 99
    assert d.y[0] == 0 and d.u.dtype == np.float64 and d.u.shape == (10, 1)
    with pytest.raises(ValueError):
        d.y[1] = 5
    np.testing.assert_array_equal(d.time, np.arange(10) * 0.5)
    assert d.signal("torque") is not None and d.signal("y") is d.y and d.signal("u1")[3] == 3


def test_repr_summarises():
    y = np.zeros(100)
    y[5] = np.nan
    d = arxid.IOData(
        y,
        np.ones((100, 2)),
        ts=0.002,
        output_name="roll",
        output_unit="rad",
        input_names=["a", "b"],
        extra={"vbat": np.full(100, 4.0)},
        extra_units={"vbat": "V"},
    )
    text = repr(d)
    assert "100 samples" in text and "ts = 0.002 s" in text and "roll [rad]" in text
    assert "vbat [V]" in text and "1 samples hold NaN" in text


def test_from_csv_with_time_column_and_missing_cells(tmp_path):
    p = tmp_path / "flight.csv"
    rows = ["time,roll,torque,vbat"] + [f"{0.01 * i:.2f},{i * 0.1},{(-1) ** i},{4.0 - i * 0.001}" for i in range(50)]
    rows[10] = "0.09,,1,3.99"
    p.write_text("\n".join(rows) + "\n")
    d = arxid.IOData.from_csv(p, output="roll", inputs=["torque"], extra=["vbat"], time="time")
    assert d.ts == pytest.approx(0.01) and d.n_samples == 50 and np.isnan(d.y[9])
    assert d.extra["vbat"][0] == 4.0 and d.n_missing == 1
    d2 = arxid.IOData.from_csv(p, output="roll", inputs=["torque"], ts=0.01)
    np.testing.assert_array_equal(d2.u, d.u)


def test_from_csv_refuses_text_and_needs_ts(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("a;b\n1;2\nx;3\n")
    with pytest.raises(DataError, match="row 3 holds 'x'"):
        arxid.IOData.from_csv(p, output="a", inputs=["b"], ts=1)
    with pytest.raises(DataError, match="give the sampling time"):
        arxid.IOData.from_csv(p, output="b", inputs=["b"])


def test_from_csv_nonuniform_time(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,y,u\n0,1,2\n1,2,3\n3,1,1\n4,2,2\n")
    with pytest.raises(DataError, match="not uniformly sampled"):
        arxid.IOData.from_csv(p, output="y", inputs=["u"], time="t")


def test_from_pandas():
    pd = pytest.importorskip("pandas")
    df = pd.DataFrame({"y": np.arange(20.0), "u1": np.ones(20), "u2": np.arange(20) % 3, "T": np.linspace(20, 25, 20)})
    d = arxid.IOData.from_pandas(df, output="y", inputs=["u1", "u2"], extra=["T"], ts=2.0)
    assert d.n_inputs == 2 and d.input_names == ("u1", "u2") and "T" in d.extra
    back = d.to_pandas()
    np.testing.assert_array_equal(back["u2"].to_numpy(), df["u2"].to_numpy())
    with pytest.raises(DataError, match="no column"):
        arxid.IOData.from_pandas(df, output="y", inputs=["nope"], ts=1)


def test_merge_split_slice_detrend():
    a = arxid.IOData(np.arange(10.0), np.ones(10), ts=1.0)
    b = arxid.IOData(np.arange(5.0), np.zeros(5), ts=1.0)
    m = arxid.IOData.merge([a, b])
    assert m.experiment_starts == (0, 10) and m.n_samples == 15 and m.n_experiments == 2
    np.testing.assert_array_equal(m.time[10:], np.arange(5.0))
    est, val = m.split(0.6)
    assert est.n_samples == 9 and val.n_samples == 6 and val.experiment_starts == (0, 1)
    sl = m[8:12]
    assert sl.experiment_starts == (0, 2)
    lin = m.detrend("linear")
    np.testing.assert_allclose(lin.y, 0, atol=1e-12)
    mean = a.detrend("mean")
    assert mean.y.mean() == pytest.approx(0)
    with pytest.raises(DataError, match="same output"):
        arxid.IOData.merge([a, arxid.IOData(np.zeros(3), np.zeros(3), ts=1.0, output_name="z")])
    with pytest.raises(DataError, match="ts=1.0 and ts=2.0"):
        arxid.IOData.merge([a, arxid.IOData(np.zeros(3), np.zeros(3), ts=2.0)])
    with pytest.raises(DataError, match="between 0 and 1"):
        a.split(1.5)


def test_time_slice():
    d = arxid.IOData(np.arange(100.0), np.ones(100), ts=0.1)
    s = d.time_slice(2.0, 5.0)
    assert s.n_samples == 30 and s.y[0] == 20


def test_duplicate_names_and_extra_length():
    with pytest.raises(DataError, match="unique"):
        arxid.IOData(np.zeros(5), np.zeros(5), ts=1, output_name="u1")
    with pytest.raises(DataError, match="extra signal 'v' has 4 samples"):
        arxid.IOData(np.zeros(5), np.zeros(5), ts=1, extra={"v": np.zeros(4)})


def test_csv_headers_with_units_become_plain_signal_names(tmp_path):
    p = tmp_path / "stand.csv"
    p.write_text("weight[g],pwm,vbat[V],motor speed\n1,2,3.9,4\n2,3,3.8,5\n3,1,3.7,4\n")
    d = arxid.IOData.from_csv(p, output="weight[g]", inputs=["pwm", "motor speed"], extra=["vbat[V]"], ts=1)
    assert d.output_name == "weight" and d.output_unit == "g"
    assert d.input_names == ("pwm", "motor_speed") and d.extra_units == {"vbat": "V"}
    d2 = arxid.IOData.from_csv(p, output="weight", inputs=["pwm"], extra=["vbat"], ts=1)
    np.testing.assert_array_equal(d2.extra["vbat"], [3.9, 3.8, 3.7])


def test_from_csv_refuses_a_binary_file(tmp_path):
    p = tmp_path / "data.csv"
    p.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(DataError, match="not a UTF-8 text CSV"):
        arxid.IOData.from_csv(p, output="y", inputs=["u"], ts=1)


def test_from_csv_reads_a_byte_order_mark(tmp_path):
    p = tmp_path / "excel.csv"
    p.write_bytes("\ufeffy,u\n1,2\n2,3\n".encode("utf-8"))
    d = arxid.IOData.from_csv(p, output="y", inputs=["u"], ts=1)
    assert d.output_name == "y" and d.y.tolist() == [1.0, 2.0]


def test_samples_are_shared_only_when_nobody_can_write_them():
    y, u = np.arange(100.0), np.ones((100, 1))
    d = arxid.IOData(y, u, ts=0.1)
    y[0] = 99.0  # the caller's arrays stay theirs: IOData copied them
    assert d.y[0] == 0.0 and not np.shares_memory(d.y, y)
    with pytest.raises(ValueError):
        d.y[1] = 5.0
    # A slice, a split and a merge read the frozen samples without copying them again.
    est, val = d.split(0.7)
    assert np.shares_memory(est.y, d.y) and np.shares_memory(val.u, d.u)
    merged = arxid.IOData.merge([est, val])
    np.testing.assert_array_equal(merged.y, d.y)
    assert arxid.IOData(merged.y, merged.u, ts=0.1).y is merged.y
    # A read-only view of an array someone can still write is copied.
    base = np.arange(100.0)
    view = base[:]
    view.setflags(write=False)
    e = arxid.IOData(view, u, ts=0.1)
    base[3] = -1.0
    assert e.y[3] == 3.0
