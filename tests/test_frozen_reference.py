"""A frozen reference (``tracker_stuck``) over every kind of reference the registry fits: a
tracker's or a camera's poses repeated exactly, a scan matcher's increments that read no motion at
all, alone or beside a gyro, while the wheels turn. Each is found with one rule, its windows are
left out, and a robot standing still (its wheels too) is never one; a gyro cannot show it."""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from nlp_calib.logs.imu import format_gyro_csv
from nlp_calib.logs.joint_log import format_joint_csv
from nlp_calib.logs.motions import format_motions
from nlp_calib.logs.reference import Motions, PoseMotions, Poses
from nlp_calib.logs.tum import format_tum
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.sensors import BESIDE, SENSORS
from nlp_calib.simulation.beside import simulate_beside, simulate_camera_beside, tracker_poses
from nlp_calib.simulation.camera import CameraNoise, CameraSimulationOptions
from nlp_calib.simulation.imu import ImuSimulationOptions
from nlp_calib.simulation.lidar import LidarSimulationOptions

ENCODERS = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
BASE = {
    "model": "diff_drive",
    "initial_guess": "auto",
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
    "validation": {"blocks": 0},
}
#: Reference stamps the frozen stretch repeats (and the one it repeats): 1 s of a 10 Hz scanner.
HELD = 10
ns = lambda t: np.round(np.asarray(t) * 1e9).astype(np.int64)  # noqa: E731


@dataclass(frozen=True)
class Drive:
    """One drive's wheel joints, its reference's stamps and readings, and a gyro's rates beside it."""

    joint_t: np.ndarray
    joint_names: tuple[str, ...]
    joints: np.ndarray
    stamps: np.ndarray  # the reference's, s
    poses: np.ndarray  # (n, 7) TUM poses at the stamps
    gyro_t: np.ndarray
    rates: np.ndarray

    def where(self, turning: bool) -> int:
        """The first of ``HELD + 1`` stamps in the drive's middle over which no joint sample moves,
        or (``turning``) every one does, the slowest such stretch: the zero motions a frozen
        reference reads there are hardest to tell from its noise."""
        step = np.abs(np.diff(self.joints, axis=0)).sum(axis=1)
        n, found = self.stamps.size, []
        for i in range(n // 8, 7 * n // 8):
            inside = (self.joint_t[1:] > self.stamps[i]) & (self.joint_t[:-1] < self.stamps[i + HELD])
            if not turning and not np.any(step[inside] > 0):
                return i
            if turning and np.all(step[inside] > 0):
                found.append((float(step[inside].sum()), i))
        assert found, "no such stretch in the drive"
        return min(found)[1]


def _planar(seed: int) -> Drive:
    lidar = LidarSimulationOptions(duration_s=30.0, seed=seed, beams=16, degraded_fraction=0.0)
    sim = simulate_beside(lidar, ImuSimulationOptions(seed=seed))
    T = tracker_poses(sim.lidar)
    rng = np.random.default_rng(seed)
    T = T + rng.normal(0.0, [0.001, 0.001, 0.001], T.shape)  # a tracker's noise, never repeating
    half = T[:, 2] / 2
    tum = np.column_stack([T[:, :2], np.zeros((len(T), 3)), np.sin(half), np.cos(half)])
    s = sim.lidar
    return Drive(
        s.joint_time_s,
        s.joint_names,
        s.joint_positions,
        s.scan_time_s,
        tum,
        sim.imu.imu_time_s,
        sim.imu.rates,
    )


def _camera(seed: int) -> Drive:
    noise = CameraNoise(position=0.001, rotation=0.0017)
    camera = CameraSimulationOptions(duration_s=30.0, seed=seed, image_rate_hz=10.0, noise=noise)
    sim = simulate_camera_beside(camera, ImuSimulationOptions(seed=seed))
    c = sim.camera
    return Drive(
        c.joint_time_s,
        c.joint_names,
        c.joint_positions,
        c.image_time_s,
        c.camera_poses,
        sim.imu.imu_time_s,
        sim.imu.rates,
    )


def _poses_held(d: Drive, i: int | None) -> np.ndarray:
    """The reference's poses, those of stamps ``i + 1 … i + HELD`` repeating stamp ``i``'s."""
    P = np.array(d.poses)
    if i is not None:
        P[i + 1 : i + HELD + 1] = P[i]
    return P


def _planar_increments(P: np.ndarray) -> np.ndarray:
    """Consecutive TUM poses' planar motions (x, y, θ), exactly zero between equal poses."""
    theta = 2.0 * np.arctan2(P[:, 5], P[:, 6])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    dx, dy = np.diff(P[:, 0]), np.diff(P[:, 1])
    dth = np.angle(np.exp(1j * np.diff(theta)))
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, dth])


def _write(
    folder: Path, d: Drive, reference: str, i: int | None, gyro_held: bool = False
) -> dict[str, object]:
    """The drive's files (its reference frozen from stamp ``i``) and their dataset block."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "joints.csv").write_text(format_joint_csv(ns(d.joint_t), d.joint_names, d.joints))
    dataset: dict[str, object] = {"joints": str(folder / "joints.csv"), "encoders": ENCODERS}
    if reference == "poses":
        (folder / "ref.tum").write_text(format_tum(ns(d.stamps), _poses_held(d, i)))
        dataset["poses"] = str(folder / "ref.tum")
    elif reference == "motions":
        z = _planar_increments(d.poses)
        if i is not None:
            z[i : i + HELD] = 0.0  # the matcher read no motion over HELD increments
        text = format_motions(ns(d.stamps[:-1]), ns(d.stamps[1:]), z, {"converged": np.ones(len(z))})
        (folder / "ref.csv").write_text(text)
        dataset["motions"] = str(folder / "ref.csv")
    rates = np.array(d.rates)
    if gyro_held and i is not None:
        k = int(np.searchsorted(d.gyro_t, d.stamps[i]))
        rates[k + 1 : k + 1 + 20 * HELD] = rates[k]  # the gyro republishes its last rate (1 s)
    (folder / "gyro.csv").write_text(format_gyro_csv(d.gyro_t, rates))
    return dataset


@dataclass(frozen=True)
class Kind:
    """A reference kind the registry fits: its sensor, the files it reads, the reference kind its
    log is, and whether a frozen reference of it can be told at all."""

    sensor: str
    reference: str  # "poses", "motions" or "" (the gyro alone)
    gyro: bool
    log_kind: str
    drive: Callable[[int], Drive]
    frozen_can_show: bool = True


KINDS = {
    "tracker poses": Kind("planar", "poses", False, Poses.name, _planar),
    "camera 3-D poses": Kind("3d", "poses", False, Poses.name, _camera),
    "scan matches": Kind("planar", "motions", False, Motions.name, _planar),
    "tracker poses beside a gyro": Kind(BESIDE[("planar", "gyro")], "poses", True, PoseMotions.name, _planar),
    "scan matches beside a gyro": Kind(BESIDE[("planar", "gyro")], "motions", True, Motions.name, _planar),
    "camera 3-D poses beside a gyro": Kind(BESIDE[("3d", "gyro")], "poses", True, PoseMotions.name, _camera),
    "gyro rates": Kind("gyro", "", True, Motions.name, _planar, frozen_can_show=False),
}


def test_every_registered_sensor_is_a_kind_here() -> None:
    assert {k.sensor for k in KINDS.values()} == set(SENSORS)


def _calibration(
    folder: Path, kind: Kind, dataset: dict[str, object], handling: str = "exclude"
) -> Calibration:
    pair = {v: k for k, v in BESIDE.items()}.get(kind.sensor)
    sensor: object = kind.sensor if pair is None else {"mount": pair[0], "beside": pair[1]}
    raw = {**BASE, "sensor": sensor, "dataset": dict(dataset), "faults": {"handling": handling}}
    if kind.gyro:
        raw["dataset"]["gyro"] = str(folder / "gyro.csv")  # type: ignore[index]
    if kind.sensor.startswith("3d"):
        raw["known"] = {"sensor_z": 0.30}
    if kind.sensor == "gyro":
        raw["known"] = {"wheel_separation": 0.5}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = scenario_from_mapping(raw, f"{folder.name}.yaml", folder)
        return Calibration(sc)


def _stuck(calib: Calibration) -> list[object]:
    return [f for f in calib.findings.report.faults if f.kind == "tracker_stuck"]


@pytest.mark.parametrize("name", list(KINDS))
def test_a_frozen_reference_is_found_where_the_wheels_turn_and_never_where_they_stand(
    name: str, tmp_path: Path
) -> None:
    kind = KINDS[name]
    d = kind.drive(11)
    i = d.where(turning=True)
    frozen = _calibration(
        tmp_path / "frozen", kind, _write(tmp_path / "frozen", d, kind.reference, i, not kind.frozen_can_show)
    )
    log = frozen.log
    assert log.reference.kind.name == kind.log_kind
    stuck = _stuck(frozen)
    if not kind.frozen_can_show:
        # Its rates held read as a steady turn does: never told from one, never named.
        assert stuck == []
        return
    assert len(stuck) == 1, [(f.kind, f.first, f.last) for f in frozen.findings.report.faults]
    f = stuck[0]
    held = d.stamps[i + HELD] - d.stamps[i]
    assert abs((log.time_s[f.last + 1] - log.time_s[f.first]) - held) < 1e-6, f
    # The wheels are not blamed for it: the path over a frozen stretch is unknown (here the robot
    # reverses inside the camera's, which poses interpolated over it miss).
    assert frozen.findings.report.encoder_faults == ()
    # No window of the fit starts or ends at a repeated pose.
    bad = frozen.findings.report.bad_records(log.n_records)
    assert np.flatnonzero(bad).tolist() == list(range(f.first + 1, f.last + 2))
    # The drive as logged, and held where the robot stands still (wheels and all): none.
    clean = _calibration(tmp_path / "clean", kind, _write(tmp_path / "clean", d, kind.reference, None))
    assert _stuck(clean) == []
    still = d.where(turning=False)
    standing = _calibration(tmp_path / "still", kind, _write(tmp_path / "still", d, kind.reference, still))
    assert _stuck(standing) == []


@pytest.mark.parametrize("name", [n for n, k in KINDS.items() if k.frozen_can_show])
def test_left_out_a_frozen_reference_moves_no_parameter_by_its_sigma(name: str, tmp_path: Path) -> None:
    """The fit with the frozen stretch (left out) against the drive's as logged: a thirtieth of the
    drive less data shifts each parameter by about 0.2σ. Kept, a frozen tracker's or camera's
    stretch (alone or beside a gyro) moves a wheel's radius by 4 to 7σ; a scan matcher's zero
    increments, each one small wrong window of hundreds, by 0.35σ."""
    kind = KINDS[name]
    d = kind.drive(11)
    i = d.where(turning=True)
    dataset = _write(tmp_path / "frozen", d, kind.reference, i)
    frozen = _calibration(tmp_path / "frozen", kind, dataset)
    clean = _calibration(tmp_path / "clean", kind, _write(tmp_path / "clean", d, kind.reference, None))
    a, b = frozen.run(["gauss_newton"]), clean.run(["gauss_newton"])
    std = b.std("gauss_newton")
    ours = a.reports["gauss_newton"].result.param_dict()
    clean_params = b.reports["gauss_newton"].result.param_dict()
    for p, value in clean_params.items():
        if std.get(p, 0.0) > 0:
            assert abs(ours[p] - value) < std[p], (p, ours[p], value, std[p])
    if kind.log_kind != Motions.name:
        # Poses (or their differences): the stretch's last window holds the whole catch-up, and
        # kept it moves a parameter by over 3σ: leaving it out is what holds the fit.
        kept = _calibration(tmp_path / "frozen", kind, dataset, "keep")
        moved = kept.run(["gauss_newton"]).reports["gauss_newton"].result.param_dict()
        assert max(abs(moved[p] - v) / std[p] for p, v in clean_params.items() if std.get(p, 0.0) > 0) > 3.0
