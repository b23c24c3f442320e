"""The log reader: header, records, wraps, timestamps and errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import parse_lines

from nlp_calib.core.errors import DatasetError
from nlp_calib.core.numeric import wrapped_difference
from nlp_calib.models import get_model, header_parameters, load_log

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
