"""IOData.from_ulog: PX4 flight logs onto one grid (commands held, measurements interpolated,
dropouts as NaN), on a synthetic ULog written here and on a real log from pyulog's test data."""

from __future__ import annotations

import struct

import numpy as np
import pytest

import arxid

pyulog = pytest.importorskip("pyulog", reason="needs the px4 extra: pip install 'arxid[px4]'")


def _msg(kind: bytes, payload: bytes) -> bytes:
    return struct.pack("<HB", len(payload), kind[0]) + payload


def write_ulog(path, topics: dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]) -> None:
    """A minimal valid ULog (version 1): header, flag bits, one format and subscription per topic
    (``uint64_t timestamp`` then float fields, a ``timestamp_sample`` field as uint64_t), and the
    data messages in time order."""
    out = bytearray(b"ULog\x01\x12\x35" + bytes([1]) + struct.pack("<Q", 0))
    out += _msg(b"B", bytes(8) + bytes(8) + struct.pack("<3Q", 0, 0, 0))

    def kind(field: str) -> tuple[str, str]:
        return ("uint64_t", "Q") if field == "timestamp_sample" else ("float", "f")

    for name, (_, fields) in topics.items():
        spec = "uint64_t timestamp;" + "".join(f"{kind(f)[0]} {f};" for f in fields)
        out += _msg(b"F", f"{name}:{spec}".encode())
    events = []
    for msg_id, (name, (t_us, fields)) in enumerate(topics.items()):
        out += _msg(b"A", struct.pack("<BH", 0, msg_id) + name.encode())
        form = "<HQ" + "".join(kind(f)[1] for f in fields)
        for k, t in enumerate(t_us):
            values = [int(v[k]) if kind(f)[1] == "Q" else float(v[k]) for f, v in fields.items()]
            events.append((int(t), msg_id, struct.pack(form, msg_id, int(t), *values)))
    for _, _, payload in sorted(events, key=lambda e: (e[0], e[1])):
        out += _msg(b"D", payload)
    path.write_bytes(bytes(out))


@pytest.fixture
def synthetic(tmp_path):
    # gyro at 500 Hz with a 40 ms dropout at 1.0 s; command at 250 Hz; setpoint at 50 Hz; battery at 10 Hz
    t_gyro = np.arange(0, 2_000_000, 2000)
    t_gyro = t_gyro[(t_gyro < 1_000_000) | (t_gyro >= 1_040_000)]
    t_cmd = np.arange(500, 2_000_000, 4000)
    t_sp = np.arange(1000, 2_000_000, 20000)
    t_bat = np.arange(0, 2_000_000, 100_000)
    topics = {
        "vehicle_angular_velocity": (t_gyro, {"xyz[0]": np.sin(t_gyro * 1e-6 * 7), "xyz[1]": 0 * t_gyro}),
        "actuator_controls_0": (t_cmd, {"control[0]": np.cos(t_cmd * 1e-6 * 5)}),
        "vehicle_rates_setpoint": (t_sp, {"roll": np.sign(np.sin(t_sp * 1e-6 * 3))}),
        "battery_status": (t_bat, {"voltage_v": 16.0 - t_bat * 1e-6}),
    }
    path = tmp_path / "flight.ulg"
    write_ulog(path, topics)
    return path, topics


def test_synthetic_log_on_one_grid(synthetic):
    path, topics = synthetic
    d = arxid.IOData.from_ulog(
        path,
        output="vehicle_angular_velocity.xyz[0]",
        inputs=["actuator_controls_0.control[0]"],
        extra=["vehicle_rates_setpoint.roll", "battery_status.voltage_v"],
        ts=0.002,
    )
    assert d.ts == 0.002
    assert d.output_name == "vehicle_angular_velocity_xyz_0" and d.output_unit == "rad/s"
    assert d.input_names == ("actuator_controls_0_control_0",) and d.input_units == ("1",)
    assert d.extra_units == {"vehicle_rates_setpoint_roll": "rad/s", "battery_status_voltage_v": "V"}
    t = 0.001 + np.arange(d.n_samples) * 0.002  # from the latest first sample (the setpoint's, 1 ms)
    # measurement: linear interpolation between samples; exact at sample times
    ok = np.isfinite(d.y)
    tg, vg = topics["vehicle_angular_velocity"][0] * 1e-6, topics["vehicle_angular_velocity"][1]["xyz[0]"]
    np.testing.assert_allclose(d.y[ok], np.interp(t[ok], tg, vg.astype(np.float32)), atol=1e-6)
    # the 40 ms dropout is a NaN gap (never bridged), and nothing else is missing from the gyro
    gap = (t > 0.998) & (t < 1.040)
    assert np.all(np.isnan(d.y[gap])) and np.all(np.isfinite(d.y[~gap]))
    # commands: zero-order hold (the last command at or before each grid time)
    tc, vc = topics["actuator_controls_0"][0] * 1e-6, topics["actuator_controls_0"][1]["control[0]"]
    last = np.searchsorted(tc, t + 1e-9, side="right") - 1
    np.testing.assert_array_equal(d.u[:, 0], vc.astype(np.float32)[last])
    sp = d.extra["vehicle_rates_setpoint_roll"]
    assert set(np.unique(sp)) <= {-1.0, 0.0, 1.0}  # a held step setpoint is never smeared
    np.testing.assert_allclose(d.extra["battery_status_voltage_v"], 16.0 - t, atol=1e-5)


def test_errors_name_what_the_log_holds(synthetic, tmp_path):
    path, _ = synthetic
    with pytest.raises(arxid.DataError, match="no topic 'vehicle_attitude'"):
        arxid.IOData.from_ulog(path, output="vehicle_attitude.q[0]", inputs=["actuator_controls_0.control[0]"])
    with pytest.raises(arxid.DataError, match="its fields are"):
        arxid.IOData.from_ulog(
            path, output="vehicle_angular_velocity.xyz[5]", inputs=["actuator_controls_0.control[0]"]
        )
    with pytest.raises(arxid.DataError, match="topic.field"):
        arxid.IOData.from_ulog(path, output="gyro", inputs=["actuator_controls_0.control[0]"])
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"not a log at all")
    with pytest.raises(arxid.DataError, match="not a readable ULog"):
        arxid.IOData.from_ulog(bad, output="a.b", inputs=["c.d"])


def test_commands_at_their_issue_and_measurements_at_their_sample(tmp_path):
    """PX4 stamps a command's ``timestamp_sample`` with the gyro sample it answers: the command is
    placed at its ``timestamp`` (issued 0.4 ms later), the gyro at its ``timestamp_sample``."""
    t_gyro = np.arange(0, 400_000, 1000)  # 1 kHz, published 0.3 ms after the sample
    t_cmd = t_gyro + 430  # each command issued 0.43 ms after the sample it answers
    w = np.sin(t_gyro * 1e-6 * 20)
    logged = t_gyro >= 2000  # the gyro's log starts 2 ms in: the grid starts there, at its sample
    topics = {
        "vehicle_angular_velocity": (t_gyro[logged] + 300, {"timestamp_sample": t_gyro[logged], "xyz[0]": w[logged]}),
        "actuator_controls_0": (t_cmd, {"timestamp_sample": t_gyro, "control[0]": np.arange(len(t_cmd)) % 7}),
    }
    write_ulog(tmp_path / "stamps.ulg", topics)
    d = arxid.IOData.from_ulog(
        tmp_path / "stamps.ulg",
        output="vehicle_angular_velocity.xyz[0]",
        inputs=["actuator_controls_0.control[0]"],
        ts=0.0001,
    )
    t = 2e-3 + 1e-4 * np.arange(d.n_samples)
    np.testing.assert_allclose(d.y, np.interp(t, t_gyro * 1e-6, w.astype(np.float32)), atol=1e-6)
    # command k held from its issue, 1e-3 k + 0.43 ms (not from 1e-3 k), to the next one
    k = np.floor((t - 430e-6) / 1e-3).astype(int)
    np.testing.assert_array_equal(d.u[:, 0], k % 7)


@pytest.mark.realdata
def test_real_px4_log_matches_pyulog_at_the_sample_times(shared_data):
    path = shared_data / "px4-ulog" / "sample_log_small.ulg"
    if not path.is_file():
        pytest.skip("px4-ulog/sample_log_small.ulg is absent from the shared data")
    d = arxid.IOData.from_ulog(
        path,
        output="vehicle_angular_velocity.xyz[0]",
        inputs=["actuator_controls_0.control[0]"],
        extra=["vehicle_rates_setpoint.roll"],
    )
    topics = ["vehicle_angular_velocity", "actuator_controls_0", "vehicle_rates_setpoint"]
    log = pyulog.ULog(str(path), topics)

    def times(topic: str) -> np.ndarray:  # a command when issued, a measurement when sampled
        data = log.get_dataset(topic).data
        command = topic.startswith("actuator") or "setpoint" in topic
        return data["timestamp_sample" if "timestamp_sample" in data and not command else "timestamp"] * 1e-6

    t = times("vehicle_angular_velocity")
    x = log.get_dataset("vehicle_angular_velocity").data["xyz[0]"].astype(float)
    # the grid starts at the latest first sample of the three topics, with the gyro's median step
    assert d.ts == pytest.approx(float(np.median(np.diff(t))))
    grid = max(times(topic)[0] for topic in topics) + d.ts * np.arange(d.n_samples)
    assert grid[0] >= t[0]
    ok = np.isfinite(d.y)
    assert ok.sum() > 2000
    np.testing.assert_allclose(d.y[ok], np.interp(grid[ok], t, x), rtol=0, atol=1e-12)
    # the log's first gyro interval is a 164 ms dropout: a NaN gap at the start, never interpolated
    dropout = (grid > t[0]) & (grid < t[1])
    assert dropout.sum() > 50 and np.all(np.isnan(d.y[dropout]))
    assert np.all(np.isfinite(d.y[grid >= t[1]]))
    # the command is held from when the controller issued it, 0.4 ms after the gyro sample it answers
    cmd = log.get_dataset("actuator_controls_0").data
    issued, sampled = cmd["timestamp"] * 1e-6, cmd["timestamp_sample"] * 1e-6
    assert np.median(issued - sampled) == pytest.approx(419e-6, abs=2e-6)
    held = np.isfinite(d.u[:, 0])
    last = np.searchsorted(issued, grid[held] + 1e-9, side="right") - 1
    np.testing.assert_array_equal(d.u[held, 0], cmd["control[0]"].astype(float)[last])
    # the feedback test sees the attitude controller in this log
    assert arxid.feedback(d[int(dropout.sum()) + 1 :]).feedback


def test_cli_diagnoses_a_closed_loop_flight_log(tmp_path, capsys):
    import json

    from arxid.analysis.cli import main
    from arxid.datasets import pi_loop

    d = pi_loop(1, 3000)  # a rate loop at 100 Hz under a PI controller, logged as PX4 would
    t_us = np.arange(d.n_samples) * 10_000
    topics = {
        "vehicle_angular_velocity": (t_us, {"xyz[0]": d.y}),
        "actuator_controls_0": (t_us + 100, {"control[0]": d.u[:, 0]}),
        "vehicle_rates_setpoint": (t_us + 50, {"roll": d.extra["r"]}),
    }
    path = tmp_path / "flight.ulg"
    write_ulog(path, topics)
    argv = ["diagnose", str(path), "--output", "vehicle_angular_velocity.xyz[0]"]
    argv += ["--inputs", "actuator_controls_0.control[0]", "--extra", "vehicle_rates_setpoint.roll"]
    argv += ["--na", "1:3", "--nb", "1:3", "--nk", "0:2", "--no-progress", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["feedback"]["feedback"] is True
    notes = " ".join(out["notes"])
    assert "closed loop" in notes and "reference vehicle_rates_setpoint_roll" in notes
    assert out["closed_loop"]["key"] == "iv-reference"
    assert out["closed_loop"]["references"] == ["vehicle_rates_setpoint_roll"]


@pytest.mark.realdata
def test_cli_runs_on_the_real_px4_log(shared_data, capsys):
    from arxid.analysis.cli import main

    path = shared_data / "px4-ulog" / "sample_log_small.ulg"
    if not path.is_file():
        pytest.skip("px4-ulog/sample_log_small.ulg is absent from the shared data")
    argv = ["diagnose", str(path), "--output", "vehicle_angular_velocity.xyz[0]"]
    argv += ["--inputs", "actuator_controls_0.control[0]", "--na", "1:2", "--nb", "1:2", "--nk", "0:2", "--no-progress"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "Feedback:" in text and "closed loop" in text
