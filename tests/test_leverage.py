"""The ``leverage`` check: a direction that one stretch of the drive alone determines is named, and
its parameters kept from the hand-off; a drive that turns throughout has none."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import SINUSOIDS_HEAD

from nlp_calib import Calibration, load_scenario
from nlp_calib.analysis.degeneracy import MOTION_BLOCK, motion_scale, motion_terms
from nlp_calib.core import poses3d
from nlp_calib.results.checks import CAVEAT
from nlp_calib.results.run import DOUBTFUL, UNDETERMINED
from nlp_calib.sensors import BESIDE, SENSORS

MOUNT = (0.36, 0.06, 0.10, -1.58, 0.012, -1.55)
RADIUS, SEPARATION = 0.1, 0.57
#: The one turn of the straight drive: its seconds, at its start (inside the first of the 20
#: stretches the uncertainty sums the information of: about 1.5 s each).
TURN = (0.2, 1.0)


def _drive(folder: Path, left: np.ndarray, right: np.ndarray, dt: float = 0.01) -> None:
    """A differential drive's joints at 100 Hz (wheel speeds ``left``, ``right`` in rad/s per
    interval) and a camera's poses at 50 Hz on it, noiseless to six decimals."""
    travel = 0.5 * RADIUS * (left + right) * dt
    turn = RADIUS * (right - left) / SEPARATION * dt
    planar = np.zeros((left.size + 1, 3))
    for k in range(left.size):
        x, y, th = planar[k]
        c = np.sinc(turn[k] / (2 * np.pi)) * travel[k]
        planar[k + 1] = (x + c * np.cos(th + turn[k] / 2), y + c * np.sin(th + turn[k] / 2), th + turn[k])
    poses = poses3d.compose(poses3d.from_planar(planar), poses3d.mount_pose(np.array(MOUNT)))
    t = np.arange(left.size + 1) * dt
    with (folder / "cam.tum").open("w") as f:
        for k in range(0, t.size, 2):
            f.write(f"{1e9 + t[k]:.6f} " + " ".join(f"{v:.6f}" for v in poses[k]) + "\n")
    angles = np.column_stack([t, *(np.concatenate([[0], np.cumsum(w * dt)]) for w in (left, right))])
    with (folder / "cam.joints.csv").open("w") as f:
        f.write("time,left_wheel_joint,right_wheel_joint\n")
        for row in angles:
            f.write(f"{1e9 + row[0]:.6f},{row[1]:.6f},{row[2]:.6f}\n")


def _run(folder: Path, left: np.ndarray, right: np.ndarray):  # type: ignore[no-untyped-def]
    _drive(folder, left, right)
    path = folder / "cam.yaml"
    # A nominal robot to start from (the data-driven start needs turns in many windows).
    guess = (
        "initial_guess: {left_wheel_radius: 0.098, right_wheel_radius: 0.102, wheel_separation: 0.55,"
        " sensor_x: 0.3, sensor_y: 0.0, sensor_roll: -1.57, sensor_pitch: 0.0, sensor_yaw: -1.57}\n"
    )
    head = SINUSOIDS_HEAD.replace("initial_guess: auto\n", guess)
    path.write_text(head + "alignment: {tracker_lag: 0.0}\nsolvers: [gauss_newton]\n")
    return Calibration(load_scenario(path)).run(["gauss_newton"])


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_what_one_turn_of_a_straight_drive_alone_determines_is_named_and_kept_from_handoff(
    tmp_path: Path,
) -> None:
    """30 s straight at 2 rad/s but for one turn of 0.8 s at its start: the turn alone determines
    the wheel separation (the same drive without it leaves it free). The check names it with the
    stretch holding the turn, and no hand-off file writes it as calibrated."""
    t = np.arange(3000) * 0.01
    turning = (t >= TURN[0]) & (t < TURN[1])
    run = _run(tmp_path, np.where(turning, 0.0, 2.0), np.where(turning, 4.0, 2.0))
    found = next((c for c in run.checks.more if c.name == "leverage"), None)
    assert found is not None and found.level == CAVEAT
    stretches = found.record["stretches"]
    assert len(stretches) == 1, stretches
    first, stop = stretches[0]["records"]
    # The stretch holds the turn's records (the tracker's, at 50 Hz), and the rest falls short.
    assert first <= TURN[0] / 0.02 and TURN[1] / 0.02 <= stop, (first, stop)
    assert "wheel_separation" in stretches[0]["parameters"]
    assert 0.0 <= stretches[0]["shortfall"] < 1.0
    assert any("determined only through records" in r for r in run.verdict.reasons)
    status = run.handoff_status("gauss_newton")
    assert status["wheel_separation"][0] == DOUBTFUL, status["wheel_separation"]
    # Independently: the drive without its turn does not determine the wheel separation.
    straight = _run(tmp_path, np.full(3000, 2.0), np.full(3000, 2.0))
    assert straight.verdict.level == UNDETERMINED
    assert "wheel_separation" in straight.reports["gauss_newton"].held or not np.isfinite(
        straight.std("gauss_newton")["wheel_separation"]
    )


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_turn_across_two_stretches_is_found_by_the_two_together(tmp_path: Path) -> None:
    """The straight drive's one turn across the boundary of the first two of the 20 stretches
    (about 1.5 s each): neither alone determines the wheel separation's direction's loss, the two
    together do, and the check names both with their records."""
    t = np.arange(3000) * 0.01
    turning = (t >= 1.1) & (t < 1.9)
    run = _run(tmp_path, np.where(turning, 0.0, 2.0), np.where(turning, 4.0, 2.0))
    found = next((c for c in run.checks.more if c.name == "leverage"), None)
    assert found is not None and found.level == CAVEAT
    (stretch,) = found.record["stretches"]
    first, stop = stretch["records"]
    assert stretch["stretches"] == 2 and first <= 1.1 / 0.02 and 1.9 / 0.02 <= stop, stretch
    assert "wheel_separation" in stretch["parameters"]
    assert any("two neighbouring of 20 stretches" in r for r in run.verdict.reasons)
    assert run.handoff_status("gauss_newton")["wheel_separation"][0] == DOUBTFUL


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_a_drive_that_turns_throughout_has_no_stretch_of_its_own(tmp_path: Path) -> None:
    """The same 30 s, the wheels at 2 ± cos(0.7 t) rad/s: every stretch turns both ways, and no
    stretch alone determines anything."""
    t = np.arange(3000) * 0.01
    run = _run(tmp_path, 2.0 - np.cos(0.7 * t), 2.0 + np.cos(0.7 * t))
    assert run.verdict.level != UNDETERMINED, run.verdict.reasons
    assert not [c for c in run.checks.more if c.name == "leverage"]


@pytest.mark.parametrize("kind", sorted(SENSORS))
def test_each_windows_motion_term_is_the_whole_arrays_to_the_bit(kind: str) -> None:
    """The windows' motion terms are taken a block at a time, once per stretch search: each is the
    whole array's arithmetic to the bit, and a subset's mean is its motion scale."""
    sensor = SENSORS[kind]("fixed")
    rng = np.random.default_rng(2)
    n = 2 * MOTION_BLOCK + 11
    z = rng.normal(size=(sensor.z_rows, n))
    if kind.startswith("3d"):
        z[3:7] = poses3d.rotvec_to_quat(0.3 * rng.normal(size=(n, 3))).T
    if kind in BESIDE.values():  # each window the reference's or the gyro's (its last row)
        z[-1] = rng.uniform(size=n) > 0.5
    omega = rng.uniform(1.0, 1e4, sensor.error_rows)
    fns = SimpleNamespace(sensor=sensor)
    terms = motion_terms(fns, z, omega)
    whole = np.sum(omega[:, None] * sensor.tangent(z) ** 2, axis=0)
    assert terms.tobytes() == whole.tobytes()
    rest = rng.uniform(size=n) > 0.3
    subset = np.float64(motion_scale(fns, z[:, rest], omega))
    assert subset.tobytes() == np.mean(terms[rest]).tobytes()
