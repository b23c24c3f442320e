"""``ROBOT.yaml``: what a text log's header carries, for a bag, which has no header.

The initial guess of the kinematic parameters, each encoder's range and the sensor's nominal pose
and frame name; anything left out takes the model's default (the values its simulated robot
uses), so a bag imports without the file and ``initial_guess: auto`` needs none of it. Validated on
load like a scenario: unknown keys, wrong types and values the header cannot hold are one-line
errors naming the file and the key.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from nlp_calib.core.config import fail, from_mapping, read_yaml
from nlp_calib.core.errors import ConfigError
from nlp_calib.core.ranges import MAGNITUDE, Range
from nlp_calib.logs import LogHeader
from nlp_calib.logs.bag_tf import Mount
from nlp_calib.models import KinematicModel, encoders
from nlp_calib.models.radians import default_guess, units_of

#: ``#joints_max_enc_values``: the text header's range of an encoder range.
ENCODER_RANGE = Range(1, 2**32, integer=True)
COUNTS_PER_TURN = Range(0.0, 2.0**32, lo_open=True)
_FRAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_./-]*")


@dataclass(frozen=True)
class RobotDescription:
    """The keys of ``ROBOT.yaml``: ``initial_guess`` (kinematic parameters), ``encoder_ranges`` (the
    header's range of each encoder, by the model's encoder names), ``counts_per_turn`` (a wheel
    encoder's counts per wheel turn, for the controller's radii), ``sensor_pose`` ``[x, y, theta]``
    (m, m, rad) of the sensor in the base frame and ``sensor_frame``, the sensor's frame name in
    the hand-off files."""

    initial_guess: Mapping[str, float] = field(default_factory=dict)
    encoder_ranges: Mapping[str, int] = field(default_factory=dict)
    counts_per_turn: Mapping[str, float] = field(default_factory=dict)
    sensor_pose: tuple[float, float, float] | None = None
    sensor_frame: str | None = None


def load_robot(path: str | Path, model: KinematicModel) -> RobotDescription:
    """Read and validate ``ROBOT.yaml`` for ``model``."""
    source = str(path)
    robot: RobotDescription = from_mapping(RobotDescription, read_yaml(Path(path), "robot"), source)
    params, names = model.kinematic_params, encoders(model)
    for name, value in robot.initial_guess.items():
        if name not in params:
            hint = (
                "; give the sensor's pose as sensor_pose: [x, y, theta]" if name.startswith("sensor") else ""
            )
            fail(
                f"{source}: initial_guess.{name}",
                f"not a parameter of {model.name}: {', '.join(params)}{hint}",
            )
        _check(MAGNITUDE, value, f"{source}: initial_guess.{name}")
    for key, limit in (("encoder_ranges", ENCODER_RANGE), ("counts_per_turn", COUNTS_PER_TURN)):
        for name, ticks in getattr(robot, key).items():
            if name not in names:
                fail(f"{source}: {key}.{name}", f"not an encoder of {model.name}: {', '.join(names)}")
            _check(limit, ticks, f"{source}: {key}.{name}")
    for axis, value in zip(("x", "y", "theta"), robot.sensor_pose or ()):
        _check(MAGNITUDE, value, f"{source}: sensor_pose.{axis}")
    frame = robot.sensor_frame
    if frame is not None and not _FRAME.fullmatch(frame):
        fail(f"{source}: sensor_frame", f"a frame name of letters, digits and _./- , got {frame!r}")
    return robot


def _check(limit: Range, value: float, where: str) -> None:
    reason = limit.problem(value)
    if reason is not None:
        fail(where, reason)


def robot_header(
    model: KinematicModel,
    robot: RobotDescription | None = None,
    sensor_frame: str | None = None,
    mount: Mount | None = None,
) -> LogHeader:
    """The header a text log of ``model`` would carry: ``robot``'s values over the model's defaults;
    the sensor's pose from ``robot``, else from ``mount`` (``/tf_static``), else the default; the
    sensor frame from ``robot``, else ``sensor_frame`` (the tracked frame), else ``sensor``. For a
    model reading joints in radians the encoder ranges are 0 (no ticks to count)."""
    robot = robot or RobotDescription()
    guess = {**default_guess(model), **robot.initial_guess}
    ranges = {**model.drive.default_ranges, **robot.encoder_ranges}
    pose = robot.sensor_pose or tuple(float(guess[n]) for n in ("sensor_x", "sensor_y", "sensor_theta"))
    if robot.sensor_pose is None and mount is not None:
        pose = (mount[0], mount[1], mount[5])
    radians = units_of(model) == "radians"
    frame = robot.sensor_frame or (sensor_frame or "").strip("/") or "sensor"
    if not _FRAME.fullmatch(frame):
        raise ConfigError(
            f"the sensor frame {frame!r} cannot name a header's frame; set sensor_frame in ROBOT.yaml"
        )
    names = encoders(model)
    nominal = dict.fromkeys(robot.initial_guess, "ROBOT.yaml")
    if robot.sensor_pose is not None or mount is not None:
        where = "ROBOT.yaml" if robot.sensor_pose is not None else "/tf_static"
        nominal.update(dict.fromkeys(("sensor_x", "sensor_y", "sensor_theta"), where))
    return LogHeader(
        kinematic_model=model.log_names[0],
        parameters={model.header_names[n]: float(guess[n]) for n in model.kinematic_params},
        encoder_names=names,
        encoder_max=tuple(0 if radians else int(ranges[n]) for n in names),
        sensor_frame=frame,
        T_base_sensor=(float(pose[0]), float(pose[1]), float(pose[2])),
        encoder_units="radians" if radians else "counts",
        sensor_z_roll_pitch=None if robot.sensor_pose is not None or mount is None else mount[2:5],
        nominal=nominal,
        counts_per_turn=dict(robot.counts_per_turn),
    )
