"""Each model's inputs from joint positions in radians (a joint log, a camera recording).

A robot that logs joint angles rather than encoder ticks gives each model its interval inputs
from named joints: a wheel's change of angle, a steering joint's angle. The model's gains then
come out in robot units: a wheel's radius in m per rad, a traction wheel's travel in m per
revolution. :data:`JOINT_MAPS` holds, per registered model, the rows it reads (for
:meth:`nlp_calib.logs.CameraRecording.inputs`), the default joint names, the kinematic truth the
camera simulator uses in those units, and how the simulator turns a drive's channels into joint
angles. (How a scenario names the joints is the pipeline's business.)
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from nlp_calib.core.errors import ModelError
from nlp_calib.logs import JointInput
from nlp_calib.models.tricycle import TricycleDrive

Channels = Mapping[str, np.ndarray]


@dataclass(frozen=True)
class JointMap:
    """A model's joints: ``rows`` (input order), the simulator's kinematic truth in joint units,
    and ``angles(truth, channels)`` → each joint's angle (rad) from the drive's channels."""

    rows: tuple[JointInput, ...]
    default_truth: Mapping[str, float]
    angles: Callable[[Mapping[str, float], Channels], dict[str, np.ndarray]]

    @property
    def joints(self) -> tuple[str, ...]:
        return tuple(r.joint for r in self.rows)


def _wheels(truth: Mapping[str, float], channels: Channels) -> dict[str, np.ndarray]:
    return {
        "left_wheel_joint": channels["left"] / truth["k_left"],
        "right_wheel_joint": channels["right"] / truth["k_right"],
    }


def _tricycle(truth: Mapping[str, float], channels: Channels, drive: TricycleDrive) -> dict[str, np.ndarray]:
    gain = drive.steering_gain(truth, np.sign(channels["direction"]))
    return {
        "traction_wheel_joint": 2.0 * np.pi * channels["front"] / truth["k_traction"],
        "steering_joint": (channels["phi"] - truth["steer_offset"]) / gain,
    }


_TRICYCLE_ROWS = (
    JointInput("traction_wheel_joint", "increment", 1.0 / (2.0 * np.pi)),
    JointInput("steering_joint", "angle"),
)
_TRICYCLE_TRUTH = {"k_steer": 0.55, "k_traction": 0.5, "axis_length": 1.5, "steer_offset": -0.05}

JOINT_MAPS: Mapping[str, JointMap] = MappingProxyType(
    {
        "diff_drive": JointMap(
            (JointInput("left_wheel_joint"), JointInput("right_wheel_joint")),
            MappingProxyType({"k_left": 0.1, "k_right": 0.1005, "baseline": 0.45}),
            _wheels,
        ),
        "tricycle": JointMap(
            _TRICYCLE_ROWS,
            MappingProxyType(_TRICYCLE_TRUTH),
            lambda t, c: _tricycle(t, c, TricycleDrive()),
        ),
    }
)


def joint_map(model_name: str) -> JointMap:
    """The joint map of the model registered as ``model_name``."""
    if model_name not in JOINT_MAPS:
        raise ModelError(
            f"the model {model_name!r} has no joint map yet; models with one: {', '.join(JOINT_MAPS)}"
        )
    return JOINT_MAPS[model_name]
