"""The slip check crossed over the registries: every car model (a base that cannot turn on the
spot) with every reference the highway simulator's drive can be given as, the lag fitted and
held, one log and two. Each run either makes the check or says why it could not, never crashes,
writes its files, and ``check`` reads back the σ the run stated."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from nlp_calib.core import poses
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.motions import format_motions
from nlp_calib.models import MODELS
from nlp_calib.models.car_like_ackermann import wheel_angles
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.outputs.write import write_run
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.check import check
from nlp_calib.pipeline.slip_check import MIN_LATERAL, NAME
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results.checks import CAVEAT
from nlp_calib.simulation import rosbag
from nlp_calib.simulation.lidar import LidarSimulationOptions
from nlp_calib.simulation.vehicles import HighwayOptions, RoadOptions, simulate_highway
from nlp_calib.simulation.vendor import vendor_models

EPOCH_NS = 1_700_000_000_000_000_000
#: The Ackermann pair's steering track (m) the cross's car has; held at it, as the model holds it.
STEERING_TRACK = 1.5
#: The bases the check is for: those whose nominal reach has no turn on the spot.
CARS = tuple(n for n, m in MODELS.items() if not m.reach(dict(m.drive.default_truth)).spot_turns)
#: Each car's encoders, read from the cross's joints (a drive motor turns at the rear wheels' mean).
ENCODERS = {
    "car_like": {"steering": "steering", "rear_left_wheel": "rear_left", "rear_right_wheel": "rear_right"},
    "car_like_bicycle": {"steering": "steering", "traction_motor": "motor"},
    "car_like_ackermann": {
        "steering_left": "steering_left",
        "steering_right": "steering_right",
        "rear_left_wheel": "rear_left",
        "rear_right_wheel": "rear_right",
    },
}
#: The references the highway car's drive can be given as: the device's poses as a tracker's,
#: as a camera's (its full mount), its motions over 0.2 s, and a ROS 2 bag of joints and poses.
REFERENCES = ("poses", "camera", "motions", "bag")
#: The cross: every car with every reference; the lag fitted or held and one log or two, so that
#: each pair of any two factors' values is run.
CROSS = [
    (model, ref, ("auto", 0.0)[(i + j) % 2], 1 + (i + j // 2) % 2)
    for i, model in enumerate(sorted(ENCODERS))
    for j, ref in enumerate(REFERENCES)
]


def test_the_cross_covers_every_car_and_says_which_references_do_not_apply() -> None:
    assert set(CARS) == set(ENCODERS), "a car model the cross does not drive"
    pairs = lambda a, b: {(c[a], c[b]) for c in CROSS}  # noqa: E731
    for a in range(4):
        for b in range(a + 1, 4):
            assert len(pairs(a, b)) == len({c[a] for c in CROSS}) * len({c[b] for c in CROSS}), (a, b)
    # No car has a vendor's controller to simulate, and the lidar's simulated drive is a
    # differential drive's in a room: neither reference applies to a car at speed.
    assert not set(CARS) & set(vendor_models())
    assert "car" not in LidarSimulationOptions.__doc__.lower()  # type: ignore[union-attr]


def _joints(sim: Any, truth: dict[str, float]) -> tuple[tuple[str, ...], np.ndarray]:
    """The highway car's joints as each car model reads them: the rear wheels' speeds, a drive
    motor's (their mean), the steering joint's angle and each front wheel's at its Ackermann angle."""
    rear = sim.joint_values[:, :2]
    steering = sim.joint_values[:, 4]
    phi = truth["k_steer"] * steering + truth["steer_offset"]
    pair = [
        (a - truth["steer_offset"]) / truth["k_steer"]
        for a in wheel_angles(phi, truth["wheelbase"], STEERING_TRACK)
    ]
    names = ("rear_left", "rear_right", "motor", "steering", "steering_left", "steering_right")
    return names, np.column_stack([rear, rear.mean(axis=1), steering, *pair])


def _bag(folder: Path, sim: Any, names: tuple[str, ...], values: np.ndarray) -> Path:
    """A ROS 2 bag of the joints' positions (the wheels' speeds integrated) and the device's poses."""
    ns = EPOCH_NS + np.round(sim.joint_time_s * 1e9).astype(np.int64)
    dt = np.diff(sim.joint_time_s, prepend=sim.joint_time_s[0])
    wheels = np.cumsum(values[:, :3] * dt[:, None], axis=0)  # rad: positions grow as they turn
    positions = np.column_stack([wheels, values[:, 3:]])
    messages = [rosbag.joint_state(int(t), names, p) for t, p in zip(ns, positions)]
    pose_ns = EPOCH_NS + np.round(sim.pose_time_s * 1e9).astype(np.int64)
    messages += [rosbag.pose_stamped(int(t), "/device", "map", p) for t, p in zip(pose_ns, sim.poses)]
    return rosbag.write_bag(folder / "bag", messages)


def _dataset(folder: Path, seed: int, model: str, ref: str) -> tuple[dict[str, Any], dict[str, float]]:
    """A minute of the highway car on a road with bends, its axle sliding out of them, as ``model``
    reads it against ``ref``: its dataset entry and truth (the run's names)."""
    folder.mkdir(parents=True)
    road = RoadOptions(heading_change=-2.0, bend_angle=0.03, slip_gain=0.006, pose_noise_time_s=5.0)
    sim = simulate_highway(HighwayOptions(duration_s=60.0, seed=seed, road=road))
    truth = dict(sim.options.truth)
    names, values = _joints(sim, truth)
    encoders = ENCODERS[model]
    if ref == "bag":
        entry: dict[str, Any] = {"bag": str(_bag(folder, sim, names, values)), "tracker": "/device"}
        entry |= {"joint_states": "/joint_states", "joints": list(encoders.values())}
    else:
        ns = EPOCH_NS + np.round(sim.joint_time_s * 1e9).astype(np.int64)
        (folder / "joints.csv").write_text(format_joint_csv(ns, names, values))
        entry = {"joints": str(folder / "joints.csv"), "form": "speeds", "encoders": encoders}
        if ref == "motions":  # the device's motion over each 0.2 s, as a matcher reports it
            k = np.arange(0, sim.pose_time_s.size, 4)
            stamps = EPOCH_NS + np.round(sim.pose_time_s[k] * 1e9).astype(np.int64)
            z = poses.between(sim.poses[k[:-1]], sim.poses[k[1:]])
            (folder / "device.motions.csv").write_text(format_motions(stamps[:-1], stamps[1:], z))
            entry["motions"] = str(folder / "device.motions.csv")
        else:  # the device's poses (TUM), a tracker's or a camera's
            entry["poses"] = str(sim.write(folder / "car")[1])
    return entry, truth


def _scenario(tmp_path: Path, model: str, ref: str, lag: Any, logs: int) -> dict[str, Any]:
    drives = [_dataset(tmp_path / f"log{i}", 31 + i, model, ref) for i in range(logs)]
    truth = drives[0][1]
    known = {"wheelbase": truth["wheelbase"]}
    if model != "car_like_bicycle":
        known["traction_track_width"] = truth["rear_track"]
    if model == "car_like_ackermann":
        known["steering_track_width"] = STEERING_TRACK
    return {
        "model": model,
        "initial_guess": "auto",
        "solvers": ["gauss_newton"],
        **({"dataset": drives[0][0]} if logs == 1 else {"datasets": [d for d, _ in drives]}),
        **({"sensor": "3d"} if ref == "camera" else {}),
        "alignment": {"tracker_lag": lag},
        "known": known,
    }


@pytest.mark.parametrize(("model", "ref", "lag", "logs"), CROSS)
def test_the_slip_check_runs_or_says_why_and_check_reads_back_its_sigma(
    tmp_path: Path, model: str, ref: str, lag: Any, logs: int
) -> None:
    sc = scenario_from_mapping(_scenario(tmp_path, model, ref, lag, logs), "car", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    found = next((r for r in run.checks.more if r.name == NAME), None)
    assert found is not None, "the slip check said nothing on a car"
    record = found.record
    if record.get("made", True):  # made: every examined parameter's σ of the slip stated
        assert record["std_slip"] and set(record["fits"]) <= set(
            run.reports["gauss_newton"].uncertainty.names
        )
        assert "sensor_x" in record["moved"]  # the slip told, whatever the model and reference
    else:  # not made: why, in its words and the record, and on these bends a caveat of the verdict
        assert record["why"] and record["why"] in found.words and "not made" in found.words
        assert found.level == CAVEAT and record["lateral_mps2"] >= MIN_LATERAL
        assert any("slip check was not made" in r for r in run.verdict.reasons)
    assert ref not in ("poses", "bag") or record["made"]  # a tracker's minute at 20 Hz is binned
    out = tmp_path / "out"
    write_run(run, out)
    stored = read_calibration(out / "calibration.yaml")
    std, free = run.std("gauss_newton"), run.reports["gauss_newton"].uncertainty.free
    for name in free:  # the σ the run stated, in the file check reads
        assert stored.std[name] == pytest.approx(std[name], rel=1e-6), name
    assert json.loads((out / "result.json").read_text())[NAME] == json.loads(json.dumps(record))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again = check(stored, sc)
    drift = next(r for r in again.checks.more if r.name == "drift").record
    params = run.reports["gauss_newton"].result.param_dict()
    read = {c["name"]: c for c in drift["changes"] if c["name"] in free}
    # Every parameter the calibration vouches for is judged; a lag is each log's own, and what it
    # lists as not determined is named as not judged.
    doubted = stored.spreads.doubted
    assert set(read) == {n for n in free if not n.startswith(LAG_PARAM) and n not in doubted}
    assert set(doubted) == set(run.doubts("gauss_newton"))
    said = [r for r in drift["reasons"] if "not judged: " in r]
    unjudged = said[0].split("not judged: ")[1].split(" (")[0].split(", ") if said else []
    assert set(doubted) <= set(unjudged), (doubted, drift["reasons"])
    for name, c in read.items():  # the stored value and the σ the run stated, as check reads them
        assert c["stored"] == pytest.approx(params[name]) and c["std_stored"] == pytest.approx(std[name])
