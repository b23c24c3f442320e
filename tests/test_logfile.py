"""The log reader: header, records, wraps, timestamps and errors."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from conftest import parse_lines
from hypothesis import event, given, settings
from hypothesis import strategies as st

from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.core.numeric import wrapped_difference
from nlp_calib.models import get_model, header_parameters
from nlp_calib.sources import load_log

HEADER = """#kinematic_model: traction_drive_wheel
#parameters: [ Ksteer Ktraction axis_length steer_offset ]
#parameter_values: 0.1 0.0106141 1.4 0
#joints_max_enc: [ steering traction_wheel ]
#joints_max_enc_values: 8192 5000
#laser wrt base_link
#\ttranslation:\t[ 1.5, 0.25, 0 ],
#\trotation:\t [ 0, 0, 0.258819, 0.9659258 ]
"""


def record(t: str, steer: int, traction: int, pose: str = "0 0 0") -> str:
    return f"time: {t} ticks: {steer} {traction} model_pose:   {pose}  tracker_pose: 0.1 0.2 0.3"


def lines(*records: str) -> list[str]:
    return (HEADER + "\n".join(records)).splitlines()


def test_header_values() -> None:
    ds = parse_lines(lines(record("10.5", 290, 100), record("10.6", 291, 200)))
    h = ds.header
    assert h.kinematic_model == "traction_drive_wheel"
    # The header keeps its own names; the model maps them onto its parameters.
    raw = {"Ksteer": 0.1, "Ktraction": 0.0106141, "axis_length": 1.4, "steer_offset": 0.0}
    assert dict(h.parameters) == raw
    assert header_parameters(get_model("tricycle"), h) == {
        "k_steer": 0.1,
        "k_traction": 0.0106141,
        "axis_length": 1.4,
        "steer_offset": 0.0,
    }
    assert h.encoder_names == ("steering", "traction_wheel")
    assert h.encoder_max == (8192, 5000)
    assert h.sensor_frame == "laser"
    x, y, th = h.T_base_sensor
    assert (x, y) == (1.5, 0.25)
    assert th == pytest.approx(math.radians(30.0), abs=1e-6)


def test_time_keeps_nanoseconds_relative_to_first() -> None:
    ds = parse_lines(lines(record("1700000123.456789012", 1, 1), record("1700000123.456789013", 1, 1)))
    assert ds.time_s[0] == 0.0
    assert ds.time_s[1] == pytest.approx(1e-9, rel=1e-12)


def test_wraparound_increment_uses_modulus_2_pow_32() -> None:
    ds = parse_lines(lines(record("0.0", 1, 4294967290), record("0.1", 1, 5), record("0.2", 1, 2)))
    # 4294967290 -> 5 is +11 ticks across the wrap; 5 -> 2 is 3 ticks backwards.
    np.testing.assert_array_equal(ds.increments("traction_wheel"), [11, -3])


def test_negative_increment_across_wrap_backwards() -> None:
    np.testing.assert_array_equal(wrapped_difference(np.array([3, 4294967295, 4294967000])), [-4, -295])


def test_model_pose_with_several_spaces() -> None:
    ds = parse_lines(lines(record("0.0", 1, 1, "0.132287    0.000139038  0.00210208"), record("0.1", 1, 2)))
    np.testing.assert_array_equal(ds.model_pose[0], [0.132287, 0.000139038, 0.00210208])


def test_arrays_are_read_only() -> None:
    ds = parse_lines(lines(record("0.0", 1, 1), record("0.1", 1, 2)))
    with pytest.raises(ValueError):
        ds.ticks[0, 0] = 5


def test_malformed_line_reports_file_and_line(tmp_path: Path) -> None:
    text = HEADER + record("0.0", 1, 1) + "\n" + "time: 0.1 ticks: 1 model_pose: 0 0 0 tracker_pose: 0 0 0\n"
    p = tmp_path / "bad.txt"
    p.write_text(text)
    with pytest.raises(DatasetError) as exc:
        load_log(p)
    assert f"{p}:10:" in str(exc.value)
    assert "'ticks:' needs 2 value(s), found 1" in str(exc.value)


def test_non_numeric_field_is_named() -> None:
    with pytest.raises(DatasetError, match=r"<log>:9: tracker_pose: expected numbers"):
        parse_lines(lines(record("0.0", 1, 1).replace("0.1 0.2 0.3", "0.1 abc 0.3"), record("0.1", 1, 2)))


def test_missing_header_field() -> None:
    text = [ln for ln in lines(record("0.0", 1, 1), record("0.1", 1, 2)) if "joints_max_enc_values" not in ln]
    with pytest.raises(DatasetError, match="joints_max_enc_values"):
        parse_lines(text)


def test_real_log(real_log: Path) -> None:
    ds = load_log(real_log)
    assert ds.n_records == 2434
    inc = ds.increments("traction_wheel")
    # The counter wraps once, between records 58 and 59 (0-based), going forwards.
    jumps = np.flatnonzero(np.abs(np.diff(ds.encoder("traction_wheel"))) > 2**31)
    np.testing.assert_array_equal(jumps, [58])
    assert inc[58] == 526 - 4294962835 + 2**32
    assert np.abs(inc).max() < 40000
    assert 0.08 < np.mean(inc == 0) < 0.1
    assert ds.header.T_base_sensor == (1.5, 0.0, 0.0)


# --- hostile files: streamed, bounded, and nothing doubtful passes silently -----------------------


def write(tmp_path: Path, text: str | bytes, name: str = "log.txt") -> Path:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


def two_records() -> str:
    return HEADER + record("0.0", 1, 1) + "\n" + record("0.1", 2, 2) + "\n"


def test_special_files_are_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "fifo.txt"
    os.mkfifo(fifo)  # opening it for reading would block until a writer comes
    for target in (fifo, tmp_path):
        with pytest.raises(DatasetError, match="not a regular file") as exc:
            load_log(target)
        assert str(target) in str(exc.value)


def test_a_utf8_byte_order_mark_is_skipped(tmp_path: Path) -> None:
    plain = load_log(write(tmp_path, two_records()))
    bom = load_log(write(tmp_path, b"\xef\xbb\xbf" + two_records().encode(), "bom.txt"))
    np.testing.assert_array_equal(bom.ticks, plain.ticks)
    assert bom.header == plain.header


def test_windows_and_old_mac_line_ends_read_the_same(tmp_path: Path) -> None:
    plain = load_log(write(tmp_path, two_records()))
    for sep, name in (("\r\n", "crlf.txt"), ("\r", "cr.txt")):
        other = load_log(write(tmp_path, two_records().replace("\n", sep).encode(), name))
        np.testing.assert_array_equal(other.T_world_sensor, plain.T_world_sensor)
        np.testing.assert_array_equal(other.line_numbers, plain.line_numbers)


def test_a_header_key_given_twice_names_both_lines() -> None:
    text = lines(record("0.0", 1, 1), record("0.1", 2, 2))
    text.insert(5, "#parameter_values: 0.2 0.0106141 1.4 0")
    with pytest.raises(
        DatasetError, match=r"<log>:6: header line '#parameter_values:' appears twice, at lines 3 and 6"
    ):
        parse_lines(text)


def test_a_tilted_sensor_rotation_is_named(tmp_path: Path) -> None:
    roll90 = [math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)]
    text = [
        f"#\trotation:\t [ {', '.join(str(q) for q in roll90)} ]" if "rotation" in ln else ln
        for ln in lines(record("0.0", 1, 1), record("0.1", 2, 2))
    ]
    with pytest.raises(
        DatasetError, match=r"<log>:8: sensor rotation .* tilts the sensor 90.0° out of the plane"
    ):
        parse_lines(text)
    with pytest.warns(NlpCalibWarning, match=r"<log>:8: sensor rotation .* tilts the sensor 90.0°"):
        ds = parse_lines(text, strict=False)
    assert ds.header.T_base_sensor[2] == pytest.approx(0.0)  # the yaw of a pure roll


def test_implausible_magnitudes_are_named_not_solved(tmp_path: Path) -> None:
    bad = record("0.1", 2, 2).replace("tracker_pose: 0.1 0.2 0.3", "tracker_pose: 1e308 0.2 0.3")
    text = lines(record("0.0", 1, 1), bad, record("0.2", 3, 3))
    with pytest.raises(
        DatasetError, match=r"<log>:10: tracker_pose is 1e\+308 0.2 0.3; a value beyond ±1e\+06"
    ):
        parse_lines(text)
    with pytest.warns(NlpCalibWarning, match="dropped 1 of 3 records"):
        ds = parse_lines(text, strict=False)
    assert [d.line for d in ds.dropped] == [10] and ds.n_records == 2
    huge_mount = [
        ln.replace("1.5, 0.25, 0", "2e7, 0.25, 0") for ln in lines(record("0.0", 1, 1), record("0.1", 2, 2))
    ]
    with pytest.raises(DatasetError, match=r"<log>:7: sensor translation 2e\+07 0.25 0: a value beyond"):
        parse_lines(huge_mount)


def test_a_line_too_long_for_a_record_is_named(tmp_path: Path) -> None:
    text = two_records() + "x" * 200_000 + "\n" + record("0.2", 3, 3) + "\n"
    with pytest.raises(DatasetError, match=r":11: a line of 200000 bytes; a record is one line"):
        load_log(write(tmp_path, text))


def test_garbage_stops_the_read_early(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A large file of garbage is not read to its end, strictly or not (bounded errors)."""
    from nlp_calib.logs import reader

    monkeypatch.setattr(reader, "BLOCK_BYTES", 1 << 16)
    garbage = "".join(f"garbage line {k} with no record in it\n" for k in range(200_000))
    path = write(tmp_path, HEADER + garbage)  # about 7 MB: over a hundred blocks
    read: list[int] = []
    chunks = reader._chunks

    def counted(fh: object) -> object:
        for chunk in chunks(fh):  # type: ignore[arg-type]
            read.append(len(chunk))
            yield chunk

    monkeypatch.setattr(reader, "_chunks", counted)
    with pytest.raises(DatasetError, match=r":9: a record starts with 'time:', got 'garbage'"):
        load_log(path)
    assert len(read) <= 3  # the header, the first block of records and the one after it
    read.clear()
    with pytest.raises(
        DatasetError, match=r"record lines cannot be used \(the first, line 9: a record starts"
    ):
        load_log(path, strict=False)
    assert sum(read) < path.stat().st_size / 10


def test_too_many_header_lines_is_not_a_log(tmp_path: Path) -> None:
    text = HEADER + "#\n" * 20_000 + two_records()
    with pytest.raises(DatasetError, match="'#' lines before any record: not a log"):
        load_log(write(tmp_path, text))


def test_block_reader_times_and_counters_are_the_per_line_readers() -> None:
    """The block reader's times and counters, read as array operations, against the per-line
    reader's regular expression and Python's ``int`` on every form a token may take."""
    from nlp_calib.logs import records

    rng = np.random.default_rng(0)
    times = [
        b"4000000000.1",
        b"3999999999.999999999999",
        b"9999999999.5",
        b"0",
        b".5",
        b"5.",
        b"-0.000000001",
    ]
    times += [b"12345678901", b"0525089.84", b"1700000000.040136771"]
    for _ in range(3000):
        whole = "".join(rng.choice(list("0123456789"), rng.integers(0, 12)))
        frac = "".join(rng.choice(list("0123456789"), rng.integers(0, 14)))
        token = ("-" if rng.random() < 0.1 else "") + whole + ("." + frac if rng.random() < 0.8 else "")
        times.append(token.encode() if token.strip("-") else b"7")

    def per_line(token: bytes) -> int:
        try:
            return records._parse_time_ns(token.decode(), "log", 1)
        except DatasetError:
            return records._NOT_A_TIME

    def located(tokens: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        starts = np.cumsum([0] + [len(t) + 1 for t in tokens[:-1]])
        return np.frombuffer(b" ".join(tokens), np.uint8), starts, starts + np.array([len(t) for t in tokens])

    np.testing.assert_array_equal(records._times_ns(*located(times)), [per_line(t) for t in times])
    ints = [str(v).encode() for v in rng.integers(-(10**18) + 1, 10**18, 3000)]
    ints += [b"0", b"-0", b"7", b"999999999999999999", b"-999999999999999999", b"4294947296"]
    np.testing.assert_array_equal(records._integers(*located(ints)), [int(t) for t in ints])


_FLOATS = st.floats(allow_nan=False, allow_infinity=False).map(repr)
#: Pose tokens: mostly numbers as loggers write them, now and then one no record may hold.
_TOKENS = st.one_of(
    _FLOATS,
    _FLOATS,
    _FLOATS,
    st.integers(-(10**6), 10**6).map(str),
    st.sampled_from(["1e5", "-0", "1_0", "+1", "0x10", ".5", "5.", "1.2.3", "nan", "inf", "--1", "١٢"]),
)
#: Counter readings: mostly in range, now and then too long for a record.
_TICKS = st.one_of(st.integers(-(10**18) + 1, 10**18 - 1), st.integers(-(10**19), 10**19))


@settings(max_examples=60, deadline=None)
@given(
    times=st.lists(
        st.tuples(st.integers(0, 4 * 10**9), st.text("0123456789", max_size=12), st.booleans()),
        min_size=1,
        max_size=6,
    ),
    ticks=st.lists(_TICKS, min_size=12, max_size=12),
    poses=st.lists(_TOKENS, min_size=36, max_size=36),
    blank=st.booleans(),
)
def test_a_clean_block_reads_as_the_general_reader_reads_it(
    times: list[tuple[int, str, bool]], ticks: list[int], poses: list[str], blank: bool
) -> None:
    """The compiled reader of plain records gives the general reader's values to the bit, and
    leaves every block with a line it does not take as plain to it (which names that line)."""
    from nlp_calib.logs import records

    lines = []
    for k, (whole, frac, dot) in enumerate(times):
        t = f"{whole}.{frac}" if dot else str(whole)
        p = poses[6 * k : 6 * k + 6]
        lines.append(
            f"time: {t} ticks: {ticks[2 * k]} {ticks[2 * k + 1]} model_pose: {' '.join(p[:3])} "
            f"tracker_pose: {' '.join(p[3:])}"
        )
    blob = ("\n\n" if blank else "\n").join(lines).encode() + b"\n"
    clean = records.parse_clean_block(blob, 7, 2)
    general = records.parse_block(blob, 7, 2) if clean is None else None
    if clean is None:
        event("left to the general reader")
        return  # the general reader reads it (the reader's own tests hold it to its messages)
    event("read as plain records")
    saved = records.parse_clean_block
    try:
        records.parse_clean_block = lambda *args: None  # type: ignore[assignment]
        general = records.parse_block(blob, 7, 2)
    finally:
        records.parse_clean_block = saved
    assert general.others.size == 0 and general.comments.size == 0
    for field in ("lines", "t_ns", "ticks", "poses"):
        a, b = np.asarray(getattr(clean, field)), np.asarray(getattr(general, field))
        assert a.shape == b.shape and a.tobytes() == b.tobytes(), field


def test_a_bad_line_in_a_clean_looking_log_is_still_named(tmp_path: Path) -> None:
    demo = Path(__file__).resolve().parents[1] / "scenarios" / "data" / "demo_tricycle.txt"
    header = [line for line in demo.read_text().splitlines()[:40] if line.startswith("#")]
    good = "time: 1700000000.{:09d} ticks: 5 7 model_pose: 0 0 0 tracker_pose: 1 2 0.5"
    records = [good.format(k) for k in range(50)]
    records[30] = records[30].replace("ticks: 5", "ticks: +5")  # int() reads it; a log may not hold it
    log = tmp_path / "log.txt"
    log.write_text("\n".join(header + records) + "\n")
    line = len(header) + 31
    with pytest.raises(DatasetError, match=rf"log\.txt:{line}: ticks: expected 2 integers"):
        load_log(log, get_model("tricycle"))
