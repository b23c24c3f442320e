"""Sensors are plug-ins: one class and one registry line, from the scenario to the hand-off files.

The toy sensor is a planar lidar mounted upside down (roll π): it sees the world mirrored, so the
motion it reports is the mirror image ``(x, −y, −θ)`` of a planar sensor's at its place, and its
URDF joint has roll π. It owns its error term, its start, its canonical form and its write-back;
nothing else in the package is told about it.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml
from conftest import write_sim

from nlp_calib.analysis.metrics import GEOMETRIES
from nlp_calib.cli.main import main
from nlp_calib.models.base import KinematicModel
from nlp_calib.results.mount import SensorMount
from nlp_calib.sensors import SENSORS, sensor_for
from nlp_calib.sensors.base import BaseMotion, SensorStart
from nlp_calib.sensors.planar import PlanarPose
from nlp_calib.symbolic import se2

FLIP = np.array([1.0, -1.0, -1.0])


class UpsideDownLidar(PlanarPose):
    """A planar lidar mounted upside down: its motions are a planar sensor's, mirrored."""

    kind = "upside_down_lidar"

    def residual(self, z: ca.SX, mount: ca.SX, M: ca.SX) -> ca.SX:
        return se2.between(z, FLIP * se2.conjugate(mount, M))

    def predict(self, mount: ca.SX, M: ca.SX) -> ca.SX:
        return FLIP * se2.conjugate(mount, M)

    def closed_form(
        self,
        model: KinematicModel,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: BaseMotion,
        known: Mapping[str, float],
    ) -> SensorStart:
        return SensorStart(model.initial_guess(U, FLIP[:, None] * z[:3], base_motion))

    def canonical(
        self, model: KinematicModel, params: Mapping[str, float], fixed: Sequence[str]
    ) -> dict[str, float]:
        return dict(params)

    def mount_pose(
        self,
        params: Mapping[str, float],
        std: Mapping[str, float],
        frame: str,
        nominal: tuple[float, float, float] | None,
    ) -> SensorMount:
        pose = {"x": params["sensor_x"], "y": params["sensor_y"], "z": 0.0, "roll": np.pi, "pitch": 0.0}
        return SensorMount.on_base(
            self.kind,
            frame,
            {**pose, "yaw": params["sensor_theta"]},
            {"x": std["sensor_x"], "y": std["sensor_y"], "yaw": std["sensor_theta"]},
            {"z": "0 (not known)", "roll": "π: mounted upside down", "pitch": "0: mounted upside down"},
        )


def _mirrored(text: str) -> str:
    """The log with its tracker poses mirrored, as the upside-down lidar reports them."""

    def flip(m: re.Match[str]) -> str:
        x, y, th = (float(v) for v in m[1].split())
        return f"tracker_pose: {x!r} {-y!r} {-th!r}"

    return re.sub(r"tracker_pose: ([^\n]*?)(?=\s*$)", flip, text, flags=re.M)


def test_a_new_sensor_is_one_class_and_one_registry_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(SENSORS, UpsideDownLidar.kind, lambda scale: UpsideDownLidar())
    sensor_for.cache_clear()
    log = write_sim(tmp_path, records=1200, seed=41, tracker_noise_xy=0.001, tracker_noise_theta=0.001)
    truth = json.loads(log.with_suffix(".truth.json").read_text())["params"]
    log.write_text(_mirrored(log.read_text()))
    path = tmp_path / "lidar.yaml"
    path.write_text(
        yaml.safe_dump(
            {
                "name": "lidar",
                "model": "tricycle",
                "sensor": "upside_down_lidar",
                "dataset": str(log),
                "initial_guess": "auto",
                "residual": {"horizon": 10},
                "solvers": ["gauss_newton"],
            }
        )
    )
    try:
        assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 0
    finally:
        sensor_for.cache_clear()
    out = tmp_path / "out"
    doc = yaml.safe_load((out / "calibration.yaml").read_text())
    assert doc["sensor"]["kind"] == "upside_down_lidar"
    assert json.loads((out / "result.json").read_text())["sensor"]["kind"] == "upside_down_lidar"
    p = doc["parameters"]
    for name in ("sensor_x", "sensor_y"):
        assert abs(p[name] - truth[name]) < 0.01, name
    assert abs(p["sensor_theta"] - truth["sensor_theta"]) < 0.005
    joint = (out / "sensor_mount.urdf.xml").read_text()
    assert f'rpy="{np.pi!r} 0.0 {p["sensor_theta"]!r}"' in joint
    assert "upside down" in joint


def test_every_registered_sensor_describes_itself() -> None:
    for kind in SENSORS:
        sensor = sensor_for(kind)
        # Every group is one the metrics can score (a pose group, or a gyro's integrated rates).
        assert sensor.kind == kind and sensor.group in GEOMETRIES
        assert set(sensor.units) == set(sensor.params) and set(sensor.held) <= set(sensor.params)
        assert set(sensor.reference) >= set(sensor.params) - set(sensor.held)
