"""Hostile input, round five, a fresh set (issue 40): members of each class the first set did not
hold, generated here and run as a user runs them.

- a fixed transform no robot has (a quaternion that is no rotation, an offset of kilometres, a
  sensor frame that is one of REP 105's base frames, a lidar whose scan plane stands up) is refused
  naming the transform, never handed off;
- units the data get wrong, the wheels' (revolutions, rev/s) and the reference's own (positions in
  mm or cm, a heading in degrees, lidar ranges in mm), are named as such, not as another cause;
- a ``--dask`` transport this Dask cannot use is one line naming it, not an internal error.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_hostile5 import _joints_as, _motions_scenario, lidar_scenario, one_line_error, scan_message

from nlp_calib.cli import main
from nlp_calib.simulation.lidar import LidarSimulationOptions, simulate_lidar
from nlp_calib.simulation.rosbag import TF, header, joint_state, write_bag


def run(argv: Sequence[object], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def sim() -> Any:
    return simulate_lidar(LidarSimulationOptions(duration_s=6.0, beams=180, degraded_fraction=0.0, seed=2))


def transform(parent: str, child: str, xyz: Sequence[float], q: Sequence[float]) -> Any:
    """A ``/tf_static`` message of one transform, its quaternion ``(x, y, z, w)`` as given."""

    def build(ts: Any) -> Any:
        v = ts.types["geometry_msgs/msg/Vector3"](x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))
        rot = ts.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
        tf = ts.types["geometry_msgs/msg/TransformStamped"](
            header=header(ts, 0, parent),
            child_frame_id=child,
            transform=ts.types["geometry_msgs/msg/Transform"](translation=v, rotation=rot),
        )
        return ts.types[TF](transforms=[tf])

    return ("/tf_static", TF, 0, build)


def bag(
    sim: Any,
    folder: Path,
    *,
    frame: str = "laser",
    parent: str = "base_link",
    xyz: Sequence[float] = (0.2, 0.0, 0.3),
    q: Sequence[float] = (0.0, 0.0, 0.0, 1.0),
    scale: float = 1.0,
) -> Path:
    """The simulated drive as a bag: its scans in ``frame`` (ranges times ``scale``, the limits with
    them) under one transform from ``parent``."""
    out = [transform(parent, frame, xyz, q)]
    out += [
        joint_state(round(t * 1e9), sim.joint_names, r) for t, r in zip(sim.joint_time_s, sim.joint_positions)
    ]
    out += [
        scan_message(round(t * 1e9), r * scale, frame=frame, range_min=0.05 * scale, range_max=15.0 * scale)
        for t, r in zip(sim.scan_time_s, sim.ranges)
    ]
    return write_bag(folder / "bag", out)


def _roll(deg: float) -> tuple[float, float, float, float]:
    return (math.sin(math.radians(deg) / 2), 0.0, 0.0, math.cos(math.radians(deg) / 2))


def _pitch(deg: float) -> tuple[float, float, float, float]:
    return (0.0, math.sin(math.radians(deg) / 2), 0.0, math.cos(math.radians(deg) / 2))


#: Each transform no robot has, and what its refusal must say.
TRANSFORMS: dict[str, tuple[dict[str, Any], tuple[str, ...]]] = {
    "quaternion of zeros": ({"q": (0.0, 0.0, 0.0, 0.0)}, ("of norm 0: not a rotation",)),
    "quaternion of norm 1e-20": ({"q": (0.0, 0.0, 0.0, 1e-20)}, ("not a rotation",)),
    "quaternion of norm 2": ({"q": (0.0, 0.0, 0.0, 2.0)}, ("of norm 2: not a rotation",)),
    "quaternion w infinite": ({"q": (0.0, 0.0, 0.0, math.inf)}, ("is not finite",)),
    "offset 1e300 m": ({"xyz": (1e300, 0.0, 0.3)}, ("1e+300 m away", "a unit?")),
    "offset in mm": ({"xyz": (200.0, 0.0, 300.0)}, ("300 m away",)),
    "scans in base_footprint": (
        {"frame": "base_footprint"},
        ("'base_footprint' is the base frame (REP 105)",),
    ),
    "scans in /base_stabilized": (
        {"frame": "/base_stabilized"},
        ("'base_stabilized' is the base frame (REP 105)",),
    ),
    "rolled 90°": ({"q": _roll(90.0)}, ("tilts the lidar's frame 'laser' 90° from level", "roll 90°")),
    "pitched 45°": ({"q": _pitch(45.0)}, ("45° from level", "pitch 45°")),
}


@pytest.mark.parametrize("fault", list(TRANSFORMS))
def test_a_transform_no_robot_has_is_refused_naming_it(
    fault: str, sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    kwargs, needles = TRANSFORMS[fault]
    sc = lidar_scenario(bag(sim, tmp_path, **kwargs))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    one_line_error(err, *needles)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "q",
    [_roll(180.0), _roll(8.0), _pitch(-10.0), (0.0, 0.0, 0.0, 1.004)],
    ids=["upside down", "8°", "-10°", "1.004"],
)
def test_a_level_or_upside_down_lidar_and_a_rounded_quaternion_are_taken(
    q: Sequence[float], tmp_path: Path
) -> None:
    """What tf2 takes (a quaternion within 1 % of unit norm squared), a lidar tilted a little, and
    one upside down (its scans mirrored: the run's sign check answers for those)."""
    from nlp_calib.logs.bag_tf import static_mount
    from nlp_calib.sources.lidar import MAX_TILT

    out = write_bag(tmp_path / "bag", [transform("base_link", "laser", (0.2, 0.0, 0.3), q)])
    mount = static_mount(out, "base_link", "laser")
    assert mount is not None and mount[:3] == pytest.approx((0.2, 0.0, 0.3))
    level = abs(math.cos(mount[3]) * math.cos(mount[4]))
    assert level >= math.cos(MAX_TILT)


def test_lidar_ranges_in_millimetres_are_named(
    sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = lidar_scenario(bag(sim, tmp_path, scale=1000.0))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    one_line_error(err, "ranges look like millimetres", "give them in metres")


# ----------------------------------------------------------------------------- units, wheels' and reference's


def _preflight_units(sc: Path) -> tuple[str, ...]:
    from nlp_calib.pipeline import load_scenario
    from nlp_calib.pipeline.preflight import preflight

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = preflight(load_scenario(sc))
    return tuple(f.words for f in report.units)


def _scaled_columns(path: Path, columns: Sequence[int], factor: float) -> None:
    head, *rows = path.read_text().splitlines()
    fields = [r.split(",") for r in rows]
    for f in fields:
        for c in columns:
            f[c] = repr(float(f[c]) * factor)
    path.write_text("\n".join([head, *(",".join(f) for f in fields)]) + "\n")


@pytest.mark.parametrize(
    ("fault", "needle", "recovered"),
    [
        ("speeds in rev/s", "speeds look like rev/s", "radius"),
        ("positions in revolutions", "angles look like revolutions", "radius"),
        ("motions in mm", "positions look like millimetres", "wheel"),
        ("motions in cm", "positions look like centimetres", "wheel"),
        ("motions θ in degrees", "heading looks like degrees", "between"),
    ],
)
def test_a_unit_the_data_get_wrong_is_named_whose_it_is(
    fault: str, needle: str, recovered: str, tmp_path: Path
) -> None:
    """Each finding names the unit, whose it is (the wheels' or the reference's), and the robot's
    true size in that unit: the truth's 0.1 m radius within 5 %, or its track (the pre-flight's
    rough estimate from the sensor's heading alone) within 15 %."""
    form = "speeds" if "speeds" in fault else "positions"
    sc = _motions_scenario(tmp_path, form, duration=20.0)
    joints, motions = tmp_path / "drive.csv", tmp_path / "drive.motions.csv"
    if fault == "speeds in rev/s":
        _joints_as(joints, "speeds", 1 / (2 * math.pi))
    elif fault == "positions in revolutions":
        _scaled_columns(joints, [1, 2], 1 / (2 * math.pi))
    elif fault.startswith("motions in"):
        _scaled_columns(motions, [2, 3], 1000.0 if "mm" in fault else 100.0)
    else:
        _scaled_columns(motions, [4], 180 / math.pi)
    words = _preflight_units(sc)
    assert len(words) == 1 and needle in words[0], words
    lead = {"radius": "one of ", "wheel": "a wheel of ", "between": "read as degrees, "}[recovered]
    size = float(words[0].split(lead)[1].split(" m")[0])
    if recovered == "between":
        assert size == pytest.approx(0.45, rel=0.15), words
    else:
        assert size / 1000 == pytest.approx(0.1, rel=0.05), words


def test_the_data_as_they_are_raise_no_unit_finding(tmp_path: Path) -> None:
    assert _preflight_units(_motions_scenario(tmp_path, duration=20.0)) == ()


def test_a_pivot_in_place_is_no_heading_in_degrees(tmp_path: Path) -> None:
    """A differential drive turning half a turn on the spot (a UMBmark-style session's pivot run),
    its tracker 20 mm off the axle's middle: no curve is gentle in radians, and with the heading
    read as degrees the tracker's small circle looked like gentle travel of a 8 mm wheel on a 40 mm
    track (a real OptiOdom session was stopped with exit 5 so). The wheels turn opposite ways
    there: a pivot, whatever the heading's unit; the radians are right and nothing is found."""
    from nlp_calib.logs.joint_log import format_joint_csv
    from nlp_calib.logs.tum import format_tum

    radius, separation, offset = 0.042, 0.2, 0.02
    t = np.arange(0.0, 11.0, 0.05)
    heading = 0.5 * np.pi * (1.0 - np.cos(np.pi * t / t[-1]))  # 0 to π, the turn rate smooth
    wheel = heading * separation / (2.0 * radius)
    ns = (1_700_000_000.0 + t) * 1e9
    stamps = np.round(ns).astype(np.int64)
    poses = np.zeros((t.size, 7))
    poses[:, 0], poses[:, 1] = offset * np.cos(heading), offset * np.sin(heading)
    poses[:, 5], poses[:, 6] = np.sin(heading / 2.0), np.cos(heading / 2.0)
    (tmp_path / "pivot.tum").write_text(format_tum(stamps, poses))
    (tmp_path / "pivot.csv").write_text(format_joint_csv(stamps, ("left", "right"), np.c_[-wheel, wheel]))
    sc = tmp_path / "pivot.yaml"
    sc.write_text(
        "name: pivot\nmodel: diff_drive\ndataset: {joints: pivot.csv, poses: pivot.tum, encoders: "
        "{left_wheel: left, right_wheel: right}}\ninitial_guess: auto\nsolvers: [gauss_newton]\n"
    )
    words = _preflight_units(sc)
    assert not any("degrees" in w for w in words), words


def test_a_wheel_share_check_names_no_robot_of_large_wheels(tmp_path: Path) -> None:
    """A wheelchair's drive wheels (a radius about half the track) are no unit mistake."""
    from nlp_calib.analysis.units import MAX_RADIUS_SHARE, TRACK_RANGE, _reference_units

    assert 0.3 / 0.56 < MAX_RADIUS_SHARE
    assert _reference_units(0.3, 0.56) == [] and _reference_units(0.1, TRACK_RANGE[0]) == []


# ----------------------------------------------------------------------------- --dask transports


def test_a_dask_transport_this_dask_cannot_use_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("distributed")
    from distributed.comm.registry import get_backend

    try:
        get_backend("ucx").get_connector()
    except Exception:  # the case under test: no usable ucx here
        pass
    else:
        pytest.skip("this Dask has a working ucx transport")
    from conftest import write_sim

    log = write_sim(tmp_path, "drive.txt", records=300, seed=1)
    code, _, err = run(
        ["batch", log, "--model", "diff_drive", "--out", tmp_path / "o", "--dask", "ucx://h:1"], capsys
    )
    assert code == 2, err
    one_line_error(err, "cannot connect over ucx://", "distributed-ucxx")
    assert not np.any([p.name == "summary.csv" for p in tmp_path.rglob("*")])


# ----------------------------------------------------------------------------- codegen's output folder


@pytest.mark.parametrize("scratch", ["", ".codegen"])
def test_codegen_writes_whatever_the_folders_path_holds(
    scratch: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An output folder whose path holds the generated file's name (CasADi asserted it did not: an
    internal error), and one holding a link where a scratch folder went (written through it)."""
    from conftest import write_sim

    log = write_sim(tmp_path, "drive.txt", records=300, seed=1)
    sc = tmp_path / "s.yaml"
    sc.write_text(
        f"dataset: {str(log)!r}\nmodel: tricycle\nsolvers: [gauss_newton]\nvalidation: {{blocks: 0}}\n"
    )
    out = tmp_path / "copy_of_nlp_calib_residual.c" / "c"
    mine = tmp_path / "mine"
    if scratch:
        mine.mkdir()
        out.mkdir(parents=True)
        (out / scratch).symlink_to(mine)
    code, _, err = run(["codegen", sc, "--out", out], capsys)
    assert code == 0, err
    assert "Autogenerated by nlp_calib" in (out / "nlp_calib_residual.h").read_text()
    assert not mine.exists() or list(mine.iterdir()) == []


def test_scans_without_a_frame_id_are_said(sim: Any, tmp_path: Path) -> None:
    from nlp_calib.core.errors import NlpCalibWarning
    from nlp_calib.logs.scans import read_scans

    with pytest.warns(
        NlpCalibWarning, match=r"carry no frame_id; the hand-off files name their frame 'laser'"
    ):
        assert read_scans(bag(sim, tmp_path, frame=""), "/scan").frame == "laser"


def test_an_odometry_topic_of_two_child_frames_is_refused_naming_them(tmp_path: Path) -> None:
    from nlp_calib.logs.bag_files import BagError
    from nlp_calib.logs.bag_reader import read_pose_topic
    from nlp_calib.simulation.rosbag import odometry

    msgs = [odometry((k + 1) * 20_000_000, "odom", "base_link", (0.01 * k, 0.0, 0.0)) for k in range(50)]
    msgs += [
        odometry((k + 1) * 20_000_000 + 7, "odom", "other_link", (5.0, 0.0, 0.0)) for k in range(0, 50, 10)
    ]
    path = write_bag(tmp_path / "bag", msgs)
    with pytest.raises(BagError, match=r"holds the poses of 2 child frames \(base_link, other_link\)"):
        read_pose_topic(path, "/odom")
    assert read_pose_topic(path, "/odom", "base_link").n == 50
