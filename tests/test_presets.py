"""Axis presets: the rate, controller output, setpoint and extra signals of one axis in each kind
of flight log, and a clear DataError when a log holds no signal for the axis."""

from __future__ import annotations

import pytest

from arxid import IOData
from arxid.data.presets import AXES, axis_preset, log_kind, log_preset
from arxid.exceptions import DataError

BLACKBOX = {f"{n}[{i}]" for n in ("gyroADC", "axisP", "axisI", "axisD", "setpoint", "motor") for i in range(4)}
BLACKBOX |= {"vbatLatest", "loopIteration"}


@pytest.mark.parametrize("axis", AXES)
def test_blackbox_preset_uses_the_pid_sum_and_the_setpoint(axis):
    i = AXES.index(axis)
    p = axis_preset("blackbox", axis, BLACKBOX)
    assert (p.output, p.inputs, p.reference) == (f"gyroADC[{i}]", (f"pidsum[{i}]",), f"setpoint[{i}]")
    assert p.extra == ("vbatLatest", "setpoint[3]", "motor[0]", "motor[1]", "motor[2]", "motor[3]")
    assert p.read_arguments()["extra"][0] == f"setpoint[{i}]"


def test_ulog_preset_prefers_the_torque_setpoint_and_falls_back_to_actuator_controls():
    new = {"vehicle_angular_velocity.xyz[1]", "vehicle_torque_setpoint.xyz[1]", "vehicle_rates_setpoint.pitch"}
    assert axis_preset("ulog", "pitch", new).inputs == ("vehicle_torque_setpoint.xyz[1]",)
    old = {"vehicle_angular_velocity.xyz[1]", "actuator_controls_0.control[1]", "vehicle_rates_setpoint.pitch"}
    assert axis_preset("ulog", "pitch", old | {"battery_status.voltage_v"}).extra == ("battery_status.voltage_v",)


def test_a_log_without_the_axis_signals_is_a_clear_data_error():
    with pytest.raises(DataError, match=r"flight\.bbl holds no yaw setpoint: it logs no 'setpoint\[2\]'"):
        axis_preset("blackbox", "yaw", BLACKBOX - {"setpoint[2]"}, source="flight.bbl")
    with pytest.raises(DataError, match="holds no roll controller output"):
        axis_preset("blackbox", "roll", BLACKBOX - {"axisP[0]", "axisI[0]", "axisD[0]"})
    with pytest.raises(DataError, match=r"no RATE message but PIDR/PIDP/PIDY \(an ArduPlane log\?\)"):
        axis_preset("dataflash", "roll", {"ATT.Roll", "PIDR.Act", "PIDR.Tar"})
    with pytest.raises(DataError, match="unknown axis"):
        axis_preset("blackbox", "thrust", BLACKBOX)
    with pytest.raises(DataError, match="unknown log kind"):
        axis_preset("csv", "roll", BLACKBOX)


def test_log_kind_by_suffix():
    assert [log_kind(p) for p in ("a.BBL", "b.bfl", "c.txt", "d.BIN", "e.ulg")] == [
        "blackbox",
        "blackbox",
        "blackbox",
        "dataflash",
        "ulog",
    ]
    with pytest.raises(DataError, match="not a flight log"):
        log_kind("flight.csv")


def test_a_txt_file_is_a_blackbox_log_only_when_it_starts_as_one(tmp_path):
    export = tmp_path / "export.txt"
    export.write_text("t,y,u\n0,1,2\n")
    with pytest.raises(DataError, match=r"export\.txt is a text file, not a blackbox log"):
        log_kind(export)
    log = tmp_path / "LOG00001.TXT"
    log.write_bytes(b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n")
    assert log_kind(log) == "blackbox"


@pytest.mark.realdata
def test_ulog_preset_on_the_real_px4_log_reads(shared_data):
    path = shared_data / "px4-ulog" / "sample_log_small.ulg"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    p = log_preset(path, "roll")
    assert p.output == "vehicle_angular_velocity.xyz[0]" and p.reference == "vehicle_rates_setpoint.roll"
    d = IOData.from_ulog(path, **p.read_arguments())
    assert d.n_samples > 100 and d.input_names == ("actuator_controls_0_control_0",)
