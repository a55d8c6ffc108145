"""ArduPilot DataFlash logs: the reader against an independent decoder written here (FMT records
define struct layouts), a synthetic ArduCopter log the test writes (FMT, UNIT, FMTU, then RATE and
BAT messages from a simulated rate loop), the real ArduPlane log, and damaged files."""

from __future__ import annotations

import struct
import time
from pathlib import Path

import numpy as np
import pytest

from arxid import IOData
from arxid._base import _core
from arxid.data.dataflash import dataflash_formats, read_dataflash
from arxid.data.presets import log_preset
from arxid.exceptions import ArxidWarning, DataError

HEAD = b"\xa3\x95"
FMT_ID = 0x80

# DataFlash format characters: struct code and the divisor of the centi-unit types.
_CODES = {
    "b": ("b", 1), "B": ("B", 1), "h": ("h", 1), "H": ("H", 1), "i": ("i", 1), "I": ("I", 1),
    "f": ("f", 1), "d": ("d", 1), "n": ("4s", 1), "N": ("16s", 1), "Z": ("64s", 1),
    "c": ("h", 100), "C": ("H", 100), "e": ("i", 100), "E": ("I", 100), "L": ("i", 1),
    "M": ("B", 1), "q": ("q", 1), "Q": ("Q", 1), "a": ("64s", 1),
}  # fmt: skip


# ---------------------------------------------------------------- an independent decoder and writer
def decode(data: bytes) -> dict[str, dict[str, list]]:
    """Every message of a DataFlash log by name and field: plain struct unpacking, one byte at a
    time past anything that is not a known message."""
    formats = {FMT_ID: ("FMT", "<BB4s16s64s", 89, ["Type", "Length", "Name", "Format", "Labels"], [1] * 5)}
    out: dict[str, dict[str, list]] = {}
    pos = 0
    while pos + 3 <= len(data):
        if data[pos : pos + 2] != HEAD or data[pos + 2] not in formats:
            pos += 1
            continue
        name, layout, length, labels, scale = formats[data[pos + 2]]
        if pos + length > len(data):
            break
        values = struct.unpack(layout, data[pos + 3 : pos + length])
        pos += length
        if name == "FMT":
            mtype, mlen, mname, mfmt, mlabels = values
            fmt = mfmt.rstrip(b"\0").decode()
            formats[mtype] = (
                mname.rstrip(b"\0").decode(),
                "<" + "".join(_CODES[c][0] for c in fmt),
                mlen,
                mlabels.rstrip(b"\0").decode().split(","),
                [_CODES[c][1] for c in fmt],
            )
            continue
        rec = out.setdefault(name, {label: [] for label in labels})
        for label, v, s in zip(labels, values, scale, strict=True):
            rec[label].append(v / s if s != 1 else v)
    return out


def fmt_record(mtype: int, name: str, fmt: str, labels: str) -> bytes:
    length = 3 + struct.calcsize("<" + "".join(_CODES[c][0] for c in fmt))
    return (
        HEAD + bytes([FMT_ID]) + struct.pack("<BB4s16s64s", mtype, length, name.encode(), fmt.encode(), labels.encode())
    )


def message(mtype: int, fmt: str, *values) -> bytes:
    return HEAD + bytes([mtype]) + struct.pack("<" + "".join(_CODES[c][0] for c in fmt), *values)


RATE_FMT = "Qffffffffffff"
RATE_LABELS = "TimeUS,RDes,R,ROut,PDes,P,POut,YDes,Y,YOut,ADes,A,AOut"
BAT_FMT = "QBfff"
BAT_LABELS = "TimeUS,Inst,Volt,VoltR,Curr"


def write_copter_log(path: Path, n: int = 4000, dt_us: int = 2500, seed: int = 0) -> dict:
    """An ArduCopter log from a simulated roll-rate loop: RATE at 400 Hz, BAT at 10 Hz for two
    batteries (instances 0 and 1). Returns the values written, as float32 round-trips them."""
    rng = np.random.default_rng(seed)
    rdes = np.repeat(rng.choice([-90.0, 0.0, 90.0], n // 200 + 1), 200)[:n]  # deg/s steps
    r, out = np.zeros(n), np.zeros(n)
    integ = 0.0
    for k in range(1, n):
        err = rdes[k - 1] - r[k - 1]
        integ += 0.0025 * err
        out[k - 1] = np.clip(0.004 * err + 0.01 * integ, -1, 1)
        r[k] = 0.95 * r[k - 1] + 8.0 * out[k - 1] + rng.normal(0, 0.3)
    t_us = 1_000_000 + dt_us * np.arange(n)
    f32 = lambda a: np.asarray(a, dtype=np.float32).astype(np.float64)  # noqa: E731
    blob = bytearray(fmt_record(FMT_ID, "FMT", "BBnNZ", "Type,Length,Name,Format,Labels"))
    blob += fmt_record(0x81, "RATE", RATE_FMT, RATE_LABELS)
    blob += fmt_record(0x82, "BAT", BAT_FMT, BAT_LABELS)
    blob += fmt_record(0x83, "UNIT", "QbZ", "TimeUS,Id,Label")
    blob += fmt_record(0x84, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds")
    for uid, label in [(ord("s"), "s"), (ord("k"), "deg/s"), (ord("v"), "V"), (ord("A"), "A"), (ord("#"), "instance")]:
        blob += message(0x83, "QbZ", 0, uid, label.encode())
    blob += message(0x84, "QBNN", 0, 0x81, b"skk-kk-kk-kk-", b"")
    blob += message(0x84, "QBNN", 0, 0x82, b"s#vvA", b"")
    bat_t, volt = [], []
    for k in range(n):
        blob += message(0x81, RATE_FMT, int(t_us[k]), rdes[k], r[k], out[k], *([0.0] * 9))
        if k % 40 == 0:
            for inst in (0, 1):
                v = 16.8 - 1e-4 * k - 0.3 * abs(out[k]) - inst
                blob += message(0x82, BAT_FMT, int(t_us[k]), inst, v, v, 10.0 * abs(out[k]))
                if inst == 0:
                    bat_t.append(t_us[k])
                    volt.append(v)
    path.write_bytes(bytes(blob))
    return dict(t_us=t_us.astype(float), rdes=f32(rdes), r=f32(r), out=f32(out), bat_t=np.array(bat_t), volt=f32(volt))


@pytest.fixture
def copter(tmp_path):
    path = tmp_path / "copter.bin"
    return path, write_copter_log(path)


# ---------------------------------------------------------------- the synthetic Copter log
def test_raw_columns_equal_the_values_written(copter):
    path, truth = copter
    messages, lost, n_messages, n_bytes, formats = _core.dataflash_read(
        path, [("RATE", "R"), ("RATE", "RDes"), ("RATE", "ROut"), ("BAT", "Volt")]
    )
    rate_t, rate_inst, (r, rdes, out), units = dict(messages)["RATE"]
    assert lost == 0 and n_bytes == path.stat().st_size
    assert rate_inst is None and units == ["deg/s", "deg/s", ""]
    np.testing.assert_array_equal(rate_t, truth["t_us"])
    np.testing.assert_array_equal(r, truth["r"])
    np.testing.assert_array_equal(rdes, truth["rdes"])
    np.testing.assert_array_equal(out, truth["out"])
    bat_t, bat_inst, (volt,), bat_units = dict(messages)["BAT"]
    assert bat_units == ["V"] and set(bat_inst) == {0.0, 1.0}
    np.testing.assert_array_equal(volt[bat_inst == 0], truth["volt"])
    assert {name: (fields, count) for name, fields, count in formats}["RATE"] == (RATE_LABELS.split(","), 4000)


def test_iodata_from_a_copter_log_is_read_back_exactly(copter):
    path, truth = copter
    d = IOData.from_dataflash(path, output="RATE.R", inputs=["RATE.ROut"], extra=["RATE.RDes", "BAT.Volt"])
    assert d.ts == pytest.approx(0.0025, rel=1e-12)
    assert (d.output_name, d.input_names, tuple(d.extra)) == ("RATE_R", ("RATE_ROut",), ("RATE_RDes", "BAT_Volt"))
    assert d.output_unit == "deg/s" and d.extra_units["BAT_Volt"] == "V"
    # the grid falls on RATE's times (BAT is logged with a RATE message), to rounding of the times
    k = np.arange(d.n_samples)
    assert d.n_samples == len(truth["t_us"]) - 39  # the last BAT message bounds the grid
    for got, want in [(d.y, truth["r"]), (d.u[:, 0], truth["out"]), (d.extra["RATE_RDes"], truth["rdes"])]:
        np.testing.assert_allclose(got, want[k], rtol=1e-9, atol=1e-9 * np.abs(want).max())
    grid_us = truth["t_us"][k]
    expect = np.interp(grid_us, truth["bat_t"], truth["volt"])
    np.testing.assert_allclose(d.extra["BAT_Volt"], expect, rtol=1e-9)


def test_instance_picks_the_second_battery(copter):
    path, truth = copter
    d0 = IOData.from_dataflash(path, output="BAT.Volt", inputs=["BAT.Curr"])
    d1 = IOData.from_dataflash(path, output="BAT.Volt", inputs=["BAT.Curr"], instance=1)
    np.testing.assert_allclose(d0.y - d1.y, 1.0, rtol=1e-6)
    with pytest.raises(DataError, match="instance"):
        IOData.from_dataflash(path, output="BAT.Volt", inputs=["BAT.Curr"], instance=5)


def test_unknown_message_or_field_is_named(copter):
    path, _ = copter
    with pytest.raises(DataError, match=r"copter\.bin logs no message 'PIDR'.*RATE"):
        IOData.from_dataflash(path, output="PIDR.Act", inputs=["RATE.ROut"])
    with pytest.raises(DataError, match=r"copter\.bin message 'RATE' has no field 'Roll'"):
        IOData.from_dataflash(path, output="RATE.Roll", inputs=["RATE.ROut"])
    with pytest.raises(DataError, match="MESSAGE.Field"):
        IOData.from_dataflash(path, output="rate r", inputs=["RATE.ROut"])
    assert "RATE" in dataflash_formats(path)


# ---------------------------------------------------------------- damaged files
def test_wrong_magic_empty_and_missing_files_name_the_file(tmp_path):
    bad = tmp_path / "notalog.bin"
    bad.write_bytes(b"PK\x03\x04" + bytes(200))
    with pytest.raises(DataError, match=r"notalog\.bin is not an ArduPilot DataFlash log"):
        IOData.from_dataflash(bad, output="RATE.R", inputs=["RATE.ROut"])
    empty = tmp_path / "empty.bin"
    empty.write_bytes(b"")
    with pytest.raises(DataError, match=r"empty\.bin is not an ArduPilot DataFlash log"):
        IOData.from_dataflash(empty, output="RATE.R", inputs=["RATE.ROut"])
    with pytest.raises(DataError, match="no DataFlash log file"):
        IOData.from_dataflash(tmp_path / "absent.bin", output="RATE.R", inputs=["RATE.ROut"])


def test_truncated_and_corrupt_files_keep_what_can_be_read_and_count_the_rest(copter, tmp_path):
    path, truth = copter
    data = bytearray(path.read_bytes())
    cut = tmp_path / "cut.bin"
    cut.write_bytes(bytes(data[:-30]))  # the last message cut short
    with pytest.warns(ArxidWarning, match=r"cut\.bin: \d+ of \d+ bytes .* could not be decoded"):
        sig = read_dataflash(cut, ["RATE.R"])
    assert sig.bytes_lost > 0
    # corrupt bytes in the middle: the messages before and after are read, the damaged ones lost
    middle = len(data) // 2
    data[middle : middle + 200] = bytes(range(200))
    broken = tmp_path / "broken.bin"
    broken.write_bytes(bytes(data))
    messages, lost, *_ = _core.dataflash_read(broken, [("RATE", "R")])
    t = dict(messages)["RATE"][0]
    # DataFlash has no checksum: a message whose header survived is decoded, whatever its payload
    assert 200 - 2 * 55 <= lost < 400
    assert len(truth["t_us"]) - 8 <= len(t) < len(truth["t_us"])
    assert np.isin(t, truth["t_us"]).sum() >= len(t) - 2


def test_a_format_shorter_than_a_message_header_is_a_data_error(tmp_path):
    blob = fmt_record(FMT_ID, "FMT", "BBnNZ", "Type,Length,Name,Format,Labels")
    blob += HEAD + bytes([FMT_ID]) + struct.pack("<BB4s16s64s", 0x81, 1, b"BAD", b"Q", b"TimeUS")
    blob += HEAD + b"\x81" + bytes(10)
    path = tmp_path / "short.bin"
    path.write_bytes(blob)
    try:
        _core.dataflash_read(path, [])
    except DataError as e:  # either read around or refused: never a panic
        assert "short.bin" in str(e)


# ---------------------------------------------------------------- the real ArduPlane log
@pytest.fixture
def plane_log(shared_data) -> Path:
    path = shared_data / "ardupilot-dataflash" / "pilot_0004.BIN"
    if not path.is_file():
        pytest.skip(f"{path} is absent")
    return path


@pytest.mark.realdata
def test_real_log_equals_an_independent_decoding_on_every_field_read(plane_log):
    truth = decode(plane_log.read_bytes())
    wanted = {
        "ATT": ["DesRoll", "Roll", "DesPitch", "Pitch", "Yaw"],
        "PIDR": ["Tar", "Act", "P", "I", "D", "FF"],
        "PIDY": ["Tar", "Act", "P", "I", "D", "FF"],
        "XKF1": ["Roll", "Pitch", "VN", "PD"],
        "GPS": ["NSats", "HDop", "Lat", "Lng", "Alt", "Spd"],
        "MAG": ["MagX", "MagY", "MagZ"],
    }
    pairs = [(m, f) for m, fs in wanted.items() for f in fs]
    messages, lost, n_messages, n_bytes, _ = _core.dataflash_read(plane_log, pairs)
    got = dict(messages)
    assert n_bytes == plane_log.stat().st_size and lost < 100
    for m, fs in wanted.items():
        t, _, columns, _ = got[m]
        np.testing.assert_array_equal(t, np.asarray(truth[m]["TimeUS"], dtype=float))
        for f, col in zip(fs, columns, strict=True):
            expect = np.asarray(truth[m][f], dtype=float)
            np.testing.assert_allclose(col, expect, rtol=1e-9, atol=0, err_msg=f"{m}.{f}")


@pytest.mark.realdata
def test_real_plane_log_reads_onto_a_grid(plane_log):
    with pytest.warns(ArxidWarning, match="bytes"):
        d = IOData.from_dataflash(plane_log, output="PIDR.Act", inputs=["PIDR.Tar"], extra=["ATT.Roll"])
    assert d.n_samples > 1000 and d.output_unit in ("deg/s", "")
    assert d.extra_units["ATT_Roll"] == "deg"


@pytest.mark.realdata
def test_reader_speed_is_recorded(plane_log, capsys):
    t0 = time.perf_counter()
    _core.dataflash_read(plane_log, [("ATT", "Roll"), ("PIDR", "Act")])
    dt = time.perf_counter() - t0
    with capsys.disabled():
        print(f"\nDataFlash reader: {dt / (plane_log.stat().st_size / 1e6):.3f} s/MB")


# ---------------------------------------------------------------- axis presets on DataFlash logs
def test_copter_axis_preset_reads_rate_loop_and_battery(copter):
    path, truth = copter
    p = log_preset(path, "roll")
    assert (p.output, p.inputs, p.reference) == ("RATE.R", ("RATE.ROut",), "RATE.RDes")
    assert p.extra == ("BAT.Volt", "RATE.AOut")
    d = IOData.from_dataflash(path, **p.read_arguments())
    assert d.output_name == "RATE_R" and d.input_names == ("RATE_ROut",) and list(d.extra)[0] == "RATE_RDes"
    assert log_preset(path, "yaw").inputs == ("RATE.YOut",)


@pytest.mark.realdata
def test_axis_preset_on_the_real_plane_log_says_what_is_missing(plane_log):
    with pytest.raises(DataError, match=r"pilot_0004\.BIN holds no roll rate \(output\).*no RATE message but PIDR"):
        log_preset(plane_log, "roll")


@pytest.mark.realdata
def test_a_message_defined_but_never_logged_is_named(plane_log):
    with pytest.warns(ArxidWarning, match="bytes"), pytest.raises(DataError, match="defines RATE but logs no RATE"):
        IOData.from_dataflash(plane_log, output="RATE.R", inputs=["RATE.ROut"])
    assert "RATE" in dataflash_formats(plane_log, logged=False) and "RATE" not in dataflash_formats(plane_log)
