"""Hostile input, round five (issue 40): output paths, text that becomes settings, mounts and
units that cannot be right, ordinary faults as one-line errors, and the memory a large file costs.

Each class's members are generated here (a lidar bag with one thing wrong, a name with each kind of
line break, each address form ``--dask`` must refuse) and run as a user runs them, through the
command line in this process: a refusal is exit 2 with one line naming the cause, never an
internal error, a replaced file or a hand-off of what cannot be right.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from conftest import REPO

from nlp_calib.cli import main
from nlp_calib.simulation.lidar import LidarSimulationOptions, simulate_lidar
from nlp_calib.simulation.rosbag import LASER_SCAN, header, joint_state, tf_static, write_bag

T0 = 1_700_000_000 * 10**9


def run(argv: Sequence[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str, *needles: str) -> str:
    """The one ``error:`` line of ``err``, holding every needle and no internal error."""
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    assert "internal error" not in lines[0], lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# ----------------------------------------------------------------------------- lidar bags


@pytest.fixture(scope="module")
def lidar_sim() -> Any:
    return simulate_lidar(LidarSimulationOptions(duration_s=6.0, beams=180, degraded_fraction=0.0, seed=2))


def scan_message(ns: int, ranges: np.ndarray, **fields: Any) -> Any:
    """A LaserScan of 180 beams over the full turn (``fields`` override the message's values)."""
    n = max(ranges.size, 1)
    values = {
        "angle_min": -math.pi,
        "angle_max": -math.pi + 2 * math.pi * (n - 1) / n,
        "angle_increment": 2 * math.pi / n,
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": 0.05,
        "range_max": 15.0,
    }
    values.update(fields)
    frame = values.pop("frame", "laser")
    stamp = values.pop("stamp", ns)

    def build(ts: Any) -> Any:
        return ts.types[LASER_SCAN](
            header=header(ts, stamp, frame),
            ranges=np.asarray(ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
            **{k: float(v) for k, v in values.items()},
        )

    return ("/scan", LASER_SCAN, ns, build)


Mutate = Callable[[int, int, np.ndarray], list[Any]]


def lidar_bag(
    sim: Any, folder: Path, mutate: Mutate | None = None, tf: tuple[float, ...] = (0.2, 0.0, 0.3)
) -> Path:
    """The simulated drive as a bag, each scan ``k`` (stamp ``ns``, ranges) made into the messages
    ``mutate`` returns (default: the scan as it is)."""
    ns = [round(t * 1e9) for t in sim.scan_time_s]
    out = [tf_static(round(sim.joint_time_s[0] * 1e9), "base_link", "laser", tf, 0.0)]
    out += [joint_state(round(t * 1e9), sim.joint_names, r) for t, r in zip(sim.joint_time_s, sim.joint_positions)]
    for k, (stamp, r) in enumerate(zip(ns, sim.ranges)):
        out += mutate(k, stamp, r) if mutate else [scan_message(stamp, r)]
    return write_bag(folder / "bag", out)


def lidar_scenario(bag: Path) -> Path:
    sc = bag.parent / "lidar.yaml"
    sc.write_text(
        f"name: lidar\nmodel: diff_drive\ndataset: {{bag: {json.dumps(str(bag))}, joint_states: /joint_states, "
        "joints: [left_wheel_joint, right_wheel_joint], scan: /scan}\ninitial_guess: auto\n"
        "solvers: [gauss_newton]\nvalidation: {blocks: 0}\n"
    )
    return sc


LIDAR_FAULTS: dict[str, tuple[Mutate, tuple[str, ...]]] = {
    "every range NaN": (lambda k, ns, r: [scan_message(ns, np.full_like(r, np.nan))], ("no valid lidar returns", "NaN")),
    "every range inf": (lambda k, ns, r: [scan_message(ns, np.full_like(r, np.inf))], ("no valid lidar returns",)),
    "every range negative": (lambda k, ns, r: [scan_message(ns, -r)], ("no valid lidar returns", "negative")),
    "range_max tiny": (lambda k, ns, r: [scan_message(ns, r, range_max=0.06)], ("no valid lidar returns", "beyond")),
    "range_max below range_min": (lambda k, ns, r: [scan_message(ns, r, range_max=0.01)], ("admit no return",)),
    "empty ranges": (lambda k, ns, r: [scan_message(ns, r[:0], angle_max=-math.pi)], ("holds no ranges",)),
    "angle_min inf": (lambda k, ns, r: [scan_message(ns, r, angle_min=math.inf)], ("not finite",)),
    "angle_increment NaN": (lambda k, ns, r: [scan_message(ns, r, angle_increment=math.nan)], ("not finite",)),
    "increment does not fit the count": (
        lambda k, ns, r: [scan_message(ns, r, angle_increment=2 * math.pi / 180 * 0.38)],
        ("beam geometry does not fit", "180 ranges"),
    ),
    "angle_max does not fit the count": (
        lambda k, ns, r: [scan_message(ns, r, angle_max=0.5)],
        ("beam geometry does not fit",),
    ),
    "zero increment": (lambda k, ns, r: [scan_message(ns, r, angle_increment=0.0)], ("beam geometry",)),
    "all scans one stamp": (lambda k, ns, r: [scan_message(ns, r, stamp=T0)], ("carry one stamp", "stamps: receive")),
    "scans 1 ns apart": (
        lambda k, ns, r: [scan_message(ns, r, stamp=T0 + k)],
        ("faster than any lidar sweeps", "stamps: receive"),
    ),
    "frame_id is the base": (lambda k, ns, r: [scan_message(ns, r, frame="base_link")], ("base frame", "base_link")),
}


@pytest.mark.parametrize("fault", list(LIDAR_FAULTS))
def test_a_lidar_bag_that_cannot_be_right_is_refused_naming_the_cause(
    fault: str, lidar_sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mutate, needles = LIDAR_FAULTS[fault]
    sc = lidar_scenario(lidar_bag(lidar_sim, tmp_path, mutate))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    one_line_error(err, *needles)
    assert not (tmp_path / "out").exists()


def test_a_nan_on_tf_static_is_refused(lidar_sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sc = lidar_scenario(lidar_bag(lidar_sim, tmp_path, tf=(0.2, math.nan, 0.3)))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    one_line_error(err, "/tf_static", "'laser' in 'base_link' is not finite")


@pytest.mark.parametrize("how", ["twice", "duplicate stamps"])
def test_scans_sharing_a_stamp_are_dropped_counted_and_said(
    how: str, lidar_sim: Any, tmp_path: Path
) -> None:
    from nlp_calib.core.errors import NlpCalibWarning
    from nlp_calib.logs.scans import read_scans

    def doubled(k: int, ns: int, r: np.ndarray) -> list[Any]:
        again = r if how == "twice" else r + 0.01
        return [scan_message(ns, r), *([scan_message(ns, again)] if k % 4 == 1 else [])]

    bag = lidar_bag(lidar_sim, tmp_path, doubled)
    n = lidar_sim.scan_time_s.size
    extra = len(range(1, n, 4))
    with pytest.warns(NlpCalibWarning, match=rf"{extra} of {n + extra} scans .* carry the stamp of the scan before"):
        scans = read_scans(bag, "/scan")
    assert scans.n == n and np.all(np.diff(scans.stamp_ns) > 0)
    assert np.allclose(scans.ranges, lidar_sim.ranges.astype(np.float32), equal_nan=True)
