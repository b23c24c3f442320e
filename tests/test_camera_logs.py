"""A camera user's inputs: TUM trajectories, joint CSVs, their pairing and the camera Log."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, assert_close, cli

from nlp_calib.core import poses3d
from nlp_calib.core.errors import DatasetError, NlpCalibWarning
from nlp_calib.logs import (
    JointInput,
    camera_log,
    format_joint_csv,
    format_tum,
    pair,
    planar_track,
    read_joint_csv,
    read_tum,
)
from nlp_calib.logs.camera import interval_inputs, positions_at

GOOD_TUM = """# timestamp tx ty tz qx qy qz qw
100.00 0 0 0 0 0 0 1
100.02 0.01 0 0 0 0 0.00499998 0.99998750
100.04 0.02 0.0001 0 0 0 0.0099998 0.99995
"""


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def one_line_error(exc: pytest.ExceptionInfo[DatasetError]) -> str:
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_tum_is_read_with_its_stamps_poses_and_lines(tmp_path: Path) -> None:
    traj = read_tum(write(tmp_path, "a.tum", GOOD_TUM))
    assert traj.n_poses == 3
    assert_close(traj.time_s, [100.0, 100.02, 100.04])
    assert list(traj.line_numbers) == [2, 3, 4]
    assert_close(np.linalg.norm(traj.poses[:, 3:], axis=1), np.ones(3), rtol=1e-15)


@pytest.mark.parametrize("columns", [7, 9])
def test_tum_with_another_number_of_columns_names_file_and_line(tmp_path: Path, columns: int) -> None:
    bad = GOOD_TUM.splitlines()
    bad[2] = " ".join(["100.02"] + ["0"] * (columns - 2) + ["1"])
    p = write(tmp_path, "a.tum", "\n".join(bad) + "\n")
    with pytest.raises(DatasetError) as exc:
        read_tum(p)
    layout = "'timestamp tx ty tz qx qy qz qw' (8 numbers)"
    assert one_line_error(exc) == f"{p}:3: has {columns} columns; a TUM line is {layout}"


def test_tum_quaternion_far_from_unit_is_refused(tmp_path: Path) -> None:
    p = write(tmp_path, "a.tum", GOOD_TUM.replace("0.99995\n", "0.5\n"))
    with pytest.raises(DatasetError) as exc:
        read_tum(p)
    assert one_line_error(exc).startswith(f"{p}:4: the quaternion has norm 0.5")


def test_tum_quaternion_close_to_unit_is_normalised_with_one_warning(tmp_path: Path) -> None:
    p = write(
        tmp_path, "a.tum", GOOD_TUM.replace("0 0 0 1\n", "0 0 0 1.001\n").replace("0.99995\n", "0.99795\n")
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        traj = read_tum(p)
    messages = [str(w.message) for w in caught if issubclass(w.category, NlpCalibWarning)]
    assert len(messages) == 1 and messages[0].startswith(f"{p}: 2 quaternion(s) are not of unit norm")
    assert "line 4" in messages[0] and messages[0].endswith("normalised")
    assert_close(np.linalg.norm(traj.poses[:, 3:], axis=1), np.ones(3), rtol=1e-15)


def test_a_warning_the_command_meets_twice_is_printed_once(tmp_path: Path) -> None:
    """``init`` reads a TUM file to draft the scenario and again to check the draft: its warning
    about quaternions off unit norm reaches the terminal once (main printed it twice)."""
    data = REPO / "scenarios" / "data"
    (tmp_path / "drive.csv").write_text((data / "camera_demo.joints.csv").read_text())
    rows = (data / "camera_demo.tum").read_text().splitlines()
    first = rows[0].split()
    rows[0] = " ".join([*first[:4], *(repr(1.00001 * float(v)) for v in first[4:])])
    (tmp_path / "drive.tum").write_text("\n".join(rows) + "\n")
    done = cli("init", str(tmp_path / "drive.csv"), "--out", str(tmp_path / "drive.yaml"))
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("quaternion(s) are not of unit norm") == 1, done.stderr


@pytest.mark.parametrize(("old", "new"), [("100.04", "100.02"), ("100.04", "99.0")])
def test_tum_timestamps_out_of_order_are_refused(tmp_path: Path, old: str, new: str) -> None:
    p = write(tmp_path, "a.tum", GOOD_TUM.replace(old, new))
    with pytest.raises(DatasetError) as exc:
        read_tum(p)
    msg = one_line_error(exc)
    assert msg.startswith(f"{p}:4: timestamp") and "previous one" in msg and "on line 3" in msg


@pytest.mark.parametrize(
    ("field", "why"), [("nan", "non-finite"), ("inf", "non-finite"), ("x1", "not a number")]
)
def test_tum_values_that_are_not_finite_numbers_are_refused(tmp_path: Path, field: str, why: str) -> None:
    p = write(tmp_path, "a.tum", GOOD_TUM.replace("0.01 0 0 0", f"{field} 0 0 0"))
    with pytest.raises(DatasetError) as exc:
        read_tum(p)
    msg = one_line_error(exc)
    assert msg.startswith(f"{p}:3: ") and why in msg


def test_tum_written_and_read_back(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    t_ns = 1_700_000_000_000_000_000 + np.cumsum(rng.integers(10_000_000, 30_000_000, 20))
    poses = np.column_stack([rng.normal(size=(20, 3)), poses3d.rotvec_to_quat(rng.normal(size=(20, 3)))])
    traj = read_tum(write(tmp_path, "w.tum", format_tum(t_ns, poses)))
    assert np.array_equal(traj.time_ns, t_ns)
    assert_close(traj.poses, poses, rtol=0, atol=1e-14)


GOOD_CSV = """time,left,right
10.00,0.0,0.0
10.01,0.1,0.2
10.02,0.3,0.5
10.03,0.6,0.9
"""


def test_joint_csv_is_read_by_name(tmp_path: Path) -> None:
    joints = read_joint_csv(write(tmp_path, "j.csv", GOOD_CSV))
    assert joints.names == ("left", "right")
    assert_close(joints.column("right"), [0.0, 0.2, 0.5, 0.9])
    with pytest.raises(DatasetError, match=r"has no joint 'middle'.*; its joints are left, right"):
        joints.column("middle")


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        (GOOD_CSV.replace("time,left", "stamp,left"), 1, "expected a header row 'time,<joint>"),
        (GOOD_CSV.replace("left,right", "left,left"), 1, "non-empty and distinct"),
        (
            GOOD_CSV.replace("10.01,0.1,0.2", "10.01,0.1"),
            3,
            "has 2 fields; expected 3 comma-separated numbers",
        ),
        (GOOD_CSV.replace("10.02,0.3", "10.02,nan"), 4, "non-finite"),
        (GOOD_CSV.replace("10.03", "10.02"), 5, "is not after the previous one"),
    ],
)
def test_joint_csv_errors_name_file_and_line(tmp_path: Path, text: str, line: int, words: str) -> None:
    p = write(tmp_path, "j.csv", text)
    with pytest.raises(DatasetError) as exc:
        read_joint_csv(p)
    msg = one_line_error(exc)
    assert msg.startswith(f"{p}:{line}: ") and words in msg


def _ns(t: np.ndarray) -> np.ndarray:
    return np.round(t * 1e9).astype(np.int64)


def _joints(tmp_path: Path, t0: float = 99.9, n: int = 200) -> Path:
    t = t0 + 0.01 * np.arange(n)
    return write(
        tmp_path, "j.csv", format_joint_csv(_ns(t), ("left", "right"), np.column_stack([3 * t, -(t**2)]))
    )


def test_pairing_interpolates_joints_at_shifted_stamps(tmp_path: Path) -> None:
    traj = read_tum(write(tmp_path, "a.tum", GOOD_TUM))
    rec = pair(traj, read_joint_csv(_joints(tmp_path)), reach_s=0.05)
    rows = [JointInput("left"), JointInput("right", "angle", 2.0)]
    stamps = traj.time_s - 0.013
    expected = np.stack([np.diff(3 * stamps), 2.0 * -(stamps[:-1] ** 2)])
    # Linear interpolation is exact on the linear joint and within the grid's curvature on the other.
    assert_close(rec.inputs(rows, lag_s=0.013), expected, rtol=1e-6)
    assert_close(rec.inputs(rows)[0], np.diff(3 * traj.time_s), rtol=1e-12)


def test_no_overlap_in_time_is_an_error_naming_both_files(tmp_path: Path) -> None:
    traj = read_tum(write(tmp_path, "a.tum", GOOD_TUM))
    joints = read_joint_csv(_joints(tmp_path, t0=200.0))
    with pytest.raises(DatasetError) as exc:
        pair(traj, joints)
    msg = one_line_error(exc)
    assert msg.startswith(f"{traj.path}: no overlap in time with the joint log {joints.path}")
    assert "record both on one clock" in msg


def test_pairing_keeps_the_images_inside_the_joints_span(tmp_path: Path) -> None:
    traj = read_tum(write(tmp_path, "a.tum", GOOD_TUM))
    rec = pair(traj, read_joint_csv(_joints(tmp_path, t0=100.01)))
    assert rec.n_records == 2 and rec.outside == 1
    with pytest.raises(DatasetError, match="outside the joints' span"):
        positions_at(rec.joints, ["left"], np.array([50.0]))
    assert interval_inputs(rec.joints, rec.images.time_s, [JointInput("left")]).shape == (1, 1)


def test_camera_log_holds_the_3d_poses_and_a_levelled_planar_track(tmp_path: Path) -> None:
    """A camera tilted by a known rotation drives a known planar path: the levelled track is that
    path up to a rotation and an offset in the plane; the 3-D poses survive select()."""
    rng = np.random.default_rng(3)
    theta = np.cumsum(rng.uniform(-0.05, 0.1, 100))
    xy = np.cumsum(np.column_stack([np.cos(theta), np.sin(theta)]) * 0.05, axis=0)
    planar = np.column_stack([xy, theta])
    tilt = poses3d.mount_pose(np.array([0.1, 0.2, 0.3, -2.0, 0.1, -1.5]))
    world = poses3d.compose(poses3d.from_planar(planar), np.broadcast_to(tilt, (100, 7)))
    t = 100.0 + 0.02 * np.arange(100)
    traj = read_tum(write(tmp_path, "c.tum", format_tum(_ns(t), world)))
    rec = pair(traj, read_joint_csv(_joints(tmp_path, t0=99.0, n=400)))
    log = camera_log(rec, "any_kind")
    assert log.T_world_sensor_3d is not None and log.T_world_sensor_3d.shape == (100, 7)
    track = planar_track(world)
    assert_close(np.abs(track[:, 2] - track[0, 2]), np.abs(theta - theta[0]), atol=1e-9)
    step = np.linalg.norm(np.diff(track[:, :2], axis=0), axis=1)
    assert_close(step, np.linalg.norm(np.diff(world[:, :3], axis=0), axis=1), rtol=1e-9)
    part = log.select(10, 20)
    assert part.T_world_sensor_3d is not None
    assert_close(part.T_world_sensor_3d, world[10:20], atol=1e-12)
