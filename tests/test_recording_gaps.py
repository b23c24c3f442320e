"""The pre-flight's listing of a recording counts the records' gaps as the run's windows do."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nlp_calib.analysis.streams import time_gaps
from nlp_calib.core.errors import ScenarioError
from nlp_calib.pipeline import scenario_from_mapping
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.pipeline.recording import recording


def _bursty_drive(folder: Path) -> None:
    """A differential drive's joints at 50 Hz and a tracker whose poses arrive in bursts: 12 poses
    2.5 ms apart every 0.3 s, every fourth burst split by 0.1 s (a link that batches its poses)."""
    t = np.arange(0.0, 30.0, 0.02)
    left, right = 2.0 * t, 2.0 * t + 0.3 * np.sin(0.4 * t)
    rows = "\n".join(f"{a:.6f},{b:.9f},{c:.9f}" for a, b, c in zip(t, left, right))
    (folder / "drive.csv").write_text("time,left_wheel_joint,right_wheel_joint\n" + rows + "\n")
    stamps = []
    for k, start in enumerate(np.arange(0.1, 29.5, 0.3)):
        burst = start + 0.0025 * np.arange(12)
        stamps += list(burst + 0.1 * (np.arange(12) >= 6)) if k % 4 == 0 else list(burst)
    ts = np.array(stamps)
    theta = 0.1 * (np.interp(ts, t, right) - np.interp(ts, t, left))
    x, y = 0.1 * np.interp(ts, t, left), 0.05 * np.sin(ts)
    lines = [
        f"{a:.6f} {b:.9f} {c:.9f} 0 0 0 {np.sin(h / 2):.12f} {np.cos(h / 2):.12f}"
        for a, b, c, h in zip(ts, x, y, theta)
    ]
    (folder / "drive.tum").write_text("\n".join(lines) + "\n")


_RAW = {
    "model": "diff_drive",
    "dataset": {
        "joints": "drive.csv",
        "poses": "drive.tum",
        "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
    },
}


def test_the_records_gaps_listed_are_those_no_window_crosses(tmp_path: Path) -> None:
    """A bursty tracker's median interval is milliseconds: intervals of 0.1 s between two halves of
    a burst are over 5 of them but no gap a window skips (under 0.2 s). The listing used to count
    them as gaps too (the pre-flight said 1032 where the run's warning said 859 on a real one)."""
    _bursty_drive(tmp_path)
    sc = scenario_from_mapping(_RAW, "s", tmp_path)
    log = sc.log.source.read(sc.model_form(), strict=True)
    (records,) = [s for s in recording(sc, log).streams if s.name == "records"]
    windows_skip = int(time_gaps(log.time_s).sum())
    dt = np.diff(log.time_s)
    assert np.sum((dt > 0.05) & (dt < 0.2)) > 20  # the split bursts are there, and no gaps
    assert windows_skip == np.sum(dt > 0.2) > 50
    assert records.gaps == windows_skip


def test_a_horizon_that_fits_between_no_gaps_is_refused_with_the_bursts_named(tmp_path: Path) -> None:
    """``horizon_s: 0.5`` over a bursty tracker's 2.5 ms median interval asks for 200 records, and
    no burst holds them: the pre-flight used to judge no window at all and call every parameter
    "not determined, because the drive carries no information on it", planning drives for a σ of
    1e-12 m (the AgileX Scout's public recording, whose poses are stamped on arrival)."""
    _bursty_drive(tmp_path)
    raw = {**_RAW, "residual": {"horizon_s": 0.5}}
    with pytest.raises(
        ScenarioError, match=r"a window of 200 records fits between none of the \d+ gaps"
    ) as err:
        preflight(scenario_from_mapping(raw, "s", tmp_path))
    assert "at most 23 intervals run between two" in str(err.value)
    assert "2.5 ms apart at the median" in str(err.value) and "check the reference's stamps" in str(err.value)
    # One pose per burst leaves windows between the pauses: judged, not refused.
    assert preflight(scenario_from_mapping({**_RAW, "residual": {"horizon": 5}}, "s", tmp_path)) is not None
