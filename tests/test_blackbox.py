"""Betaflight blackbox logs: the reader against the first intra frame of each log decoded here by
hand (the documented variable-byte encodings and predictors), against the ``blackbox-log`` crate's
own snapshots of the same logs (``tests/data/blackbox_log_snapshots.json``), the text header, and
damaged files. The real logs live in ``../shared/data/betaflight-blackbox`` (tests marked
``realdata``, skipped when absent)."""

from __future__ import annotations

import json
import struct
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

from arxid import IOData
from arxid._base import _core
from arxid.data.blackbox import blackbox_header, read_blackbox
from arxid.data.presets import log_preset
from arxid.exceptions import ArxidWarning, DataError

MARKER = b"H Product:Blackbox flight data recorder by Nicholas Sherlock\n"
SNAPSHOTS = json.loads((Path(__file__).parent / "data" / "blackbox_log_snapshots.json").read_text())
LOGS = [("LOG00037.BFL", 1), ("btfl_001.bbl", 1), ("btfl_001.bbl", 2)]


@pytest.fixture
def blackbox_dir(shared_data) -> Path:
    d = shared_data / "betaflight-blackbox"
    if not d.is_dir():
        pytest.skip(f"{d} is absent")
    return d


def _quiet_read(path, log, fields):
    """The raw columns of a log (the reader's warnings about cut-short logs are checked elsewhere)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ArxidWarning)
        return _core.blackbox_read(path, log, fields)


# ---------------------------------------------------------------- an independent intra-frame decoder
def _log_bytes(data: bytes, log: int) -> bytes:
    starts = [i for i in range(len(data)) if data.startswith(MARKER, i)]
    end = starts[log] if log < len(starts) else len(data)
    return data[starts[log - 1] : end]


def _text_header(log_bytes: bytes) -> tuple[dict[str, str], int]:
    headers, pos = {}, 0
    while log_bytes.startswith(b"H ", pos):
        end = log_bytes.index(b"\n", pos)
        name, _, value = log_bytes[pos + 2 : end].decode().partition(":")
        headers[name] = value
        pos = end + 1
    return headers, pos


def _unsigned_vb(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if byte < 0x80:
            return value, pos


def first_intra_frame(log_bytes: bytes) -> tuple[dict[str, str], dict[str, int]]:
    """The text header and the first I frame, decoded with the encodings of the Blackbox
    Internals document: 0 signed variable-byte (zig-zag), 1 unsigned variable-byte, 3 negative
    14-bit; predictors 0 none, 4 minthrottle, 5 motor[0], 9 vbatref, 11 the minimum motor output."""
    headers, pos = _text_header(log_bytes)
    assert log_bytes[pos : pos + 1] == b"I", "the data section starts with an intra frame"
    pos += 1
    names = headers["Field I name"].split(",")
    signed = [int(x) for x in headers["Field I signed"].split(",")]
    predictors = [int(x) for x in headers["Field I predictor"].split(",")]
    encodings = [int(x) for x in headers["Field I encoding"].split(",")]
    values: dict[str, int] = {}
    for name, sign, predictor, encoding in zip(names, signed, predictors, encodings, strict=True):
        raw, pos = _unsigned_vb(log_bytes, pos)
        if encoding == 0:
            v = (raw >> 1) ^ -(raw & 1)
        elif encoding == 1:
            v = raw
        elif encoding == 3:
            v = -((raw & 0x3FFF) - 0x4000 if raw & 0x2000 else raw & 0x3FFF)
        else:
            raise AssertionError(f"encoding {encoding} of {name} is not in the intra frames of these logs")
        v += {
            0: 0,
            4: int(headers.get("minthrottle", 0)),
            5: values.get("motor[0]", 0),
            9: int(headers.get("vbatref", 0)),
            11: int(headers.get("motorOutput", "0").split(",")[0]),
        }[predictor]
        v = struct.unpack("<i" if sign else "<I", struct.pack("<I", v & 0xFFFFFFFF))[0]
        values[name] = v
    return headers, values


def _scale(name: str, headers: dict[str, str]) -> float:
    if name.startswith("gyroADC"):
        return struct.unpack("<f", struct.pack("<I", int(headers["gyro_scale"], 16)))[0]
    if name in ("vbatLatest", "amperageLatest"):
        return 0.01
    if name.startswith("accSmooth"):
        return 1.0 / int(headers["acc_1G"])
    return 1.0


@pytest.mark.realdata
@pytest.mark.parametrize("name, log", LOGS)
def test_first_intra_frame_equals_a_decoding_by_hand_on_every_field(blackbox_dir, name, log):
    path = blackbox_dir / name
    headers, frame = first_intra_frame(_log_bytes(path.read_bytes(), log))
    fields = [f for f in frame if f not in ("loopIteration", "time")]
    _, _, _, time_us, iteration, columns, units, _ = _quiet_read(path, log, fields)
    assert time_us[0] == frame["time"] and iteration[0] == frame["loopIteration"]
    for f, column in zip(fields, columns, strict=True):
        expect = frame[f] * _scale(f, headers)
        assert column[0] == pytest.approx(expect, rel=1e-9, abs=1e-12), f
    assert dict(zip(fields, units, strict=True))["gyroADC[0]"] == "deg/s"
    assert dict(zip(fields, units, strict=True))["vbatLatest"] == "V"


def _vb(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def encode_intra_frame(headers: dict[str, str], frame: dict[str, int]) -> bytes:
    """An I frame's bytes from its field values: the inverse of :func:`first_intra_frame`."""
    names = headers["Field I name"].split(",")
    predictors = [int(x) for x in headers["Field I predictor"].split(",")]
    encodings = [int(x) for x in headers["Field I encoding"].split(",")]
    out = bytearray(b"I")
    for name, predictor, encoding in zip(names, predictors, encodings, strict=True):
        base = {
            0: 0,
            4: int(headers.get("minthrottle", 0)),
            5: frame.get("motor[0]", 0),
            9: int(headers.get("vbatref", 0)),
            11: int(headers.get("motorOutput", "0").split(",")[0]),
        }[predictor]
        v = struct.unpack("<i", struct.pack("<I", (frame[name] - base) & 0xFFFFFFFF))[0]
        if encoding == 0:
            raw = ((v << 1) ^ (v >> 31)) & 0xFFFFFFFF
        elif encoding == 1:
            raw = v & 0xFFFFFFFF
        else:  # 3: negative 14-bit
            raw = (-v) & 0x3FFF
        out += _vb(raw)
    return bytes(out)


@pytest.mark.realdata
@pytest.mark.parametrize("name, log", LOGS)
def test_every_intra_frame_read_is_in_the_file_byte_for_byte(blackbox_dir, name, log):
    """Each I frame the reader returns, encoded again with the header's encodings and predictors,
    is found in the log's bytes in order: every field of every I frame (one frame in 32 or 16) is
    what the firmware wrote."""
    path = blackbox_dir / name
    data = _log_bytes(path.read_bytes(), log)
    headers, _ = _text_header(data)
    names = headers["Field I name"].split(",")
    fields = [f for f in names if f not in ("loopIteration", "time")]
    _, _, _, time_us, iteration, columns, _, _ = _quiet_read(path, log, fields)
    interval = int(headers["I interval"])
    intra = np.flatnonzero(iteration % interval == 0)
    assert len(intra) >= len(time_us) * int(headers["P interval"]) // interval - 2
    values = {f: np.round(c / _scale(f, headers)).astype(np.int64) for f, c in zip(fields, columns, strict=True)}
    pos = 0
    for k in intra:
        frame = {"loopIteration": int(iteration[k]), "time": int(time_us[k])}
        frame.update({f: int(values[f][k]) for f in fields})
        at = data.find(encode_intra_frame(headers, frame), pos)
        assert at >= 0, f"the I frame of loop iteration {frame['loopIteration']} is not in the file"
        pos = at + 1


@pytest.mark.realdata
@pytest.mark.parametrize("name, log", LOGS)
def test_every_field_matches_the_crates_own_snapshot(blackbox_dir, name, log):
    snap = SNAPSHOTS["files"][name][log - 1]
    path = blackbox_dir / name
    fields = list(snap["fields"])
    _, _, all_fields, time_us, iteration, columns, _, _ = _quiet_read(path, log, fields[1:])
    assert all_fields == fields and len(time_us) == snap["count"]
    scaled = {"Voltage": 1000.0, "Amperage": 1000.0, "Acceleration": 980.665}

    def check(values, expected, what):
        v = np.round(values).astype(np.int64)
        assert min(0, v.min()) == expected["min"] and max(0, v.max()) == expected["max"], what
        assert len(np.unique(v)) == expected["unique"], what
        if expected["histogram"] is not None:
            assert np.bincount(np.abs(v) % 16, minlength=16).tolist() == expected["histogram"], what

    check(time_us, snap["time"], "time")
    check(iteration, snap["fields"]["loopIteration"], "loopIteration")
    for f, column in zip(fields[1:], columns, strict=True):
        check(column * scaled.get(snap["fields"][f]["unit"], 1.0), snap["fields"][f], f)


@pytest.mark.realdata
def test_header_motor_range_and_log_count(blackbox_dir):
    path = blackbox_dir / "btfl_001.bbl"
    text, _ = _text_header(_log_bytes(path.read_bytes(), 2))
    h = blackbox_header(path, log=2)
    assert h.n_logs == 2 and h.headers == text
    assert h.motor_range == (158.0, 2047.0) and h.headers["Firmware revision"].startswith("Betaflight 4.2.11")
    assert h.fields[:2] == ("loopIteration", "axisP[0]") and "gyroADC[0]" in h.fields


@pytest.mark.realdata
def test_iodata_from_blackbox_with_units_pid_sum_and_a_uniform_grid(blackbox_dir):
    path = blackbox_dir / "LOG00037.BFL"
    d = IOData.from_blackbox(
        path, output="gyroADC[0]", inputs=["pidsum[0]"], extra=["setpoint[0]", "vbatLatest", "motor[2]"]
    )
    assert d.ts == pytest.approx(1e-3, rel=1e-6)  # P interval 8 of an 8 kHz loop: 1 kHz
    assert d.output_unit == "deg/s" and d.extra_units == {
        "setpoint_0": "deg/s",
        "vbatLatest": "V",
        "motor_2": "158..2047",
    }
    assert d.n_samples > 16000 and d.n_missing == 0
    vbat = d.extra["vbatLatest"]
    assert 17.0 < vbat.min() < 18.5 and 22.0 < vbat.max() < 23.0  # the 6S sag of SOURCE.md
    # the PID sum equals the sum of its logged terms on the grid (they are held together)
    terms = IOData.from_blackbox(path, output="gyroADC[0]", inputs=["axisP[0]", "axisI[0]", "axisD[0]", "axisF[0]"])
    np.testing.assert_allclose(d.u[:, 0], terms.u.sum(axis=1), rtol=1e-12)


@pytest.mark.realdata
def test_yaw_pid_sum_skips_the_unlogged_d_term(blackbox_dir):
    path = blackbox_dir / "btfl_001.bbl"
    sig = read_blackbox(path, ["gyroADC[2]", "pidsum[2]"], log=2)
    assert "axisD[2]" not in sig.header.fields and sig.frames == 24893
    assert sig.ts == pytest.approx(2e-3, rel=1e-6)


@pytest.mark.realdata
@pytest.mark.parametrize("axis, i", [("roll", 0), ("pitch", 1), ("yaw", 2)])
def test_axis_preset_of_a_betaflight_log_reads(blackbox_dir, axis, i):
    path = blackbox_dir / "LOG00037.BFL"
    p = log_preset(path, axis)
    assert (p.output, p.inputs, p.reference) == (f"gyroADC[{i}]", (f"pidsum[{i}]",), f"setpoint[{i}]")
    assert p.extra == ("vbatLatest", "setpoint[3]", "rcCommand[3]", "motor[0]", "motor[1]", "motor[2]", "motor[3]")
    d = IOData.from_blackbox(path, **p.read_arguments())
    assert d.n_inputs == 1 and len(d.extra) == 8


@pytest.mark.realdata
def test_reader_speed_is_recorded(blackbox_dir, capsys):
    path = blackbox_dir / "LOG00037.BFL"
    fields = list(SNAPSHOTS["files"]["LOG00037.BFL"][0]["fields"])[1:]
    t0 = time.perf_counter()
    _quiet_read(path, 1, fields)
    dt = time.perf_counter() - t0
    with capsys.disabled():
        print(f"\nblackbox reader: {dt / (path.stat().st_size / 1e6):.3f} s/MB (all {len(fields)} fields)")


# ---------------------------------------------------------------- bad files
def test_not_a_blackbox_file_and_a_missing_file_name_the_file(tmp_path):
    bad = tmp_path / "flight.bbl"
    bad.write_bytes(b"\x00\x01 this is not a log" * 100)
    with pytest.raises(DataError, match=r"flight\.bbl is not a Betaflight/INAV blackbox log"):
        IOData.from_blackbox(bad, output="gyroADC[0]", inputs=["pidsum[0]"])
    with pytest.raises(DataError, match="no blackbox log file"):
        IOData.from_blackbox(tmp_path / "absent.bbl", output="gyroADC[0]", inputs=["pidsum[0]"])


def test_a_header_without_frame_definitions_is_a_data_error(tmp_path):
    path = tmp_path / "headers.bfl"
    path.write_bytes(MARKER + b"H Data version:2\nH Firmware revision:Betaflight 4.2.0 (x) F7\n")
    with pytest.raises(DataError, match=r"headers\.bfl log 1: its header cannot be read"):
        IOData.from_blackbox(path, output="gyroADC[0]", inputs=["pidsum[0]"])


@pytest.mark.realdata
def test_no_such_log_or_field_is_named(blackbox_dir):
    path = blackbox_dir / "btfl_001.bbl"
    with pytest.raises(DataError, match=r"btfl_001\.bbl holds 2 log\(s\).*no log 3"):
        IOData.from_blackbox(path, output="gyroADC[0]", inputs=["pidsum[0]"], log=3)
    with pytest.raises(DataError, match=r"btfl_001\.bbl has no field 'gyro\[0\]'.*'gyroADC\[0\]'"):
        IOData.from_blackbox(path, output="gyro[0]", inputs=["pidsum[0]"])
    with pytest.raises(DataError, match="counted from 1"):
        IOData.from_blackbox(path, output="gyroADC[0]", inputs=["pidsum[0]"], log=0)


@pytest.mark.realdata
def test_truncated_and_corrupt_logs_keep_the_frames_that_can_be_read(blackbox_dir, tmp_path):
    data = (blackbox_dir / "LOG00037.BFL").read_bytes()
    cut = tmp_path / "cut.bfl"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(ArxidWarning, match=r"cut\.bfl log 1: the log ends without its end-of-log mark"):
        sig = read_blackbox(cut, ["gyroADC[0]"])
    assert 7000 < sig.frames < 9000
    broken = bytearray(data)
    for k in range(20):  # 20 bursts of corrupt bytes in the data section
        at = 10_000 + k * 20_000
        broken[at : at + 40] = bytes(range(40))
    path = tmp_path / "broken.bfl"
    path.write_bytes(bytes(broken))
    with pytest.warns(ArxidWarning, match=r"broken\.bfl log 1: \d+ frame\(s\) are missing"):
        sig = read_blackbox(path, ["gyroADC[0]", "setpoint[0]"])
    assert sig.frames_lost > 0 and sig.frames + sig.frames_lost >= 16000
    assert np.isnan(sig.values["gyroADC_0"]).sum() <= sig.frames_lost + 100
    header_cut = tmp_path / "header.bfl"
    header_cut.write_bytes(data[:2000])
    with pytest.raises(DataError, match=r"header\.bfl log 1"):
        read_blackbox(header_cut, ["gyroADC[0]"])
