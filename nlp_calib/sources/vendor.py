"""A robot's own wheel odometry (its vendor's) and a reference: corrections to the vendor's model.

The scenario's block names the odometry, the vendor's model it was integrated with and the
reference (a TUM trajectory, or a file of the sensor's own motions)::

    dataset: {odometry: odom.txt, poses: tracker.tum,
              vendor: {left_wheel_radius: 0.1, right_wheel_radius: 0.1, wheel_separation: 0.5}}

The odometry is a ``t x y θ`` file, or a bag's ``nav_msgs/Odometry`` topic (``odometry: drive/,
odometry_topic: /odom``). The base's motion between two of its poses is turned back into the
wheels' angles by the vendor's model (``vendor``: its values of the scenario's model's parameters,
in joint units), as the model says (:meth:`readings_from_odometry`; a model that cannot turn its
odometry back says so): the calibrated parameters over the vendor's are the corrections its
controller takes, and the run starts from the vendor's (``initial_guess: from_file``). The
reference is read as a joint log's (``poses``) or a motions file's (``motions``).
"""

from __future__ import annotations

import warnings
from collections.abc import Hashable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from nlp_calib.core.config import coerce, from_mapping
from nlp_calib.core.errors import ConfigError, DatasetError, ModelError, NlpCalibWarning
from nlp_calib.logs import Log, LogHeader
from nlp_calib.logs.bag_joints import timed_by_tracker
from nlp_calib.logs.bag_reader import (
    CLOCK_OFFSET,
    DEFAULT_MAX_GAP_S,
    MAX_GAP,
    Stamped,
    is_bag,
    read_pose_topic,
)
from nlp_calib.logs.log import frozen
from nlp_calib.logs.motions import read_motions, timed_by_motions
from nlp_calib.logs.tum import read_tum
from nlp_calib.logs.vendor import read_odometry
from nlp_calib.models import KinematicModel, OdometryInverse, encoders
from nlp_calib.models.base import reference
from nlp_calib.models.radians import in_units
from nlp_calib.sources.base import check_block, file_identity
from nlp_calib.sources.robot import RobotDescription, robot_header

#: The keys a vendor block must have (and one reference: poses or motions).
REQUIRED = ("odometry", "vendor")


@dataclass(frozen=True)
class VendorSource:
    """The vendor's odometry (``odometry``: a ``t x y θ`` file, or a bag with ``odometry_topic``)
    and its model (``vendor``: the model's parameters), the reference (``poses``: a TUM file;
    or ``motions``: a motions file), the longest gap between odometry poses a reference stamp is
    interpolated across (``max_gap``, s), the seconds added to the odometry's stamps
    (``clock_offset``) and the sensor's frame (its URDF link)."""

    kind: ClassVar[str] = "vendor"
    record_word: ClassVar[str] = "pose"
    joint_units: ClassVar[str] = "radians"
    odometry: Path
    vendor: Mapping[str, float]
    poses: Path | None = None
    motions: Path | None = None
    odometry_topic: str | None = None
    max_gap: float = DEFAULT_MAX_GAP_S
    clock_offset: float = 0.0
    sensor_frame: str | None = None

    def __post_init__(self) -> None:
        for key, value in self.vendor.items():
            if not np.isfinite(value):
                raise ConfigError(f"vendor.{key}: the vendor's value, a finite number, got {value!r}")
        for key, limit in (("max_gap", MAX_GAP), ("clock_offset", CLOCK_OFFSET)):
            if (reason := limit.problem(getattr(self, key))) is not None:
                raise ConfigError(f"{key} (seconds) {reason}")
        if (self.poses is None) == (self.motions is None):
            raise ConfigError(
                "name the reference: poses (a TUM file) or motions (a motions file), one of them"
            )

    @property
    def path(self) -> Path:
        return self.odometry

    @property
    def numbered(self) -> Path:
        return self.reference

    @property
    def reference(self) -> Path:
        ref = self.poses if self.poses is not None else self.motions
        assert ref is not None
        return ref

    def files(self) -> tuple[Path, ...]:
        return (self.odometry, self.reference)

    def clock(self) -> str:
        return f"the stamps of {self.odometry.name} and of {self.reference.name}, each on its own"

    def identity(self) -> Hashable:
        return (file_identity(self.odometry), file_identity(self.reference))

    def joints(self, model: KinematicModel) -> Stamped:
        """The joints' angles (``model``'s, in radians) that the vendor's model turns its odometry
        back into, on the reference's clock (positions, then no velocities)."""
        if self.odometry_topic is not None or is_bag(self.odometry):
            if self.odometry_topic is None:
                raise ConfigError(
                    f"odometry_topic: {self.odometry} is a bag; name its nav_msgs/Odometry topic"
                )
            topic = read_pose_topic(self.odometry, self.odometry_topic)
            time_ns, base, path = topic.stamp_ns, topic.values[:, :3], str(self.odometry)
            if topic.drops.counts:  # every message not used is counted and said
                warnings.warn(
                    f"{path}: {self.odometry_topic}: {topic.n} messages used, dropped: "
                    f"{topic.drops.describe()}",
                    NlpCalibWarning,
                    stacklevel=2,
                )
        else:
            odometry = read_odometry(self.odometry)
            time_ns, base, path = odometry.time_ns, odometry.poses, odometry.path
        check_arcs(path, base)
        readings = vendor_readings(model, base, self.vendor)
        values = np.column_stack([readings[e] for e in encoders(model)])
        values = np.hstack([values, np.full(values.shape, np.nan)])
        return Stamped(path, time_ns + round(self.clock_offset * 1e9), values)

    def header(self, model: KinematicModel, frame: str | None) -> LogHeader:
        """The vendor's model as the initial guess (the mount at the model's default)."""
        return robot_header(model, RobotDescription(initial_guess=dict(self.vendor)), frame)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        model = in_units(model, "radians")
        joints, names = self.joints(model), encoders(model)
        header = self.header(model, self.sensor_frame)
        if self.motions is not None:
            return timed_by_motions(
                self.odometry, joints, read_motions(self.motions), names, self.max_gap, header
            )
        poses = read_tum(self.reference)
        tracker = Stamped(str(self.reference), poses.time_ns, poses.planar_and_3d())
        log = timed_by_tracker(self.odometry, joints, tracker, names, self.max_gap, header)
        return replace(log, line_numbers=frozen(poses.line_numbers[log.line_numbers - 1]))

    def moved(self, path: Path) -> VendorSource:
        return replace(self, odometry=path)

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, Mapping) and "odometry" in raw

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return True

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> VendorSource:
        check_block(cls, raw, where, "vendor odometry", REQUIRED, "docs/vendor.md", also)
        source: VendorSource = from_mapping(cls, raw, where)
        odometry, poses, motions = (
            None if raw.get(k) is None else _resolved(coerce(raw[k], Path, f"{where}.{k}"), base_dir)
            for k in ("odometry", "poses", "motions")
        )
        assert odometry is not None  # required
        return replace(source, odometry=odometry, poses=poses, motions=motions)


def vendor_readings(
    model: KinematicModel, base: np.ndarray, vendor: Mapping[str, float]
) -> dict[str, np.ndarray]:
    """The readings ``model`` with the vendor's values ``vendor`` turns the odometry ``base`` back
    into (each encoder's, by name), once the values are checked against the model's parameters."""
    missing = [n for n in model.kinematic_params if n not in vendor]
    unknown = [n for n in vendor if n not in model.kinematic_params]
    if missing or unknown:
        raise ConfigError(
            f"vendor: give the vendor's {', '.join(model.kinematic_params)} (missing: "
            f"{', '.join(missing) or 'none'}; unknown: {', '.join(unknown) or 'none'})"
        )
    # A gain or a length of zero is no model; an offset of zero is the usual one.
    zero = [n for n, v in vendor.items() if v == 0.0 and reference(model, n)[0] == "relative"]
    if zero:
        raise ConfigError(f"vendor: {', '.join(zero)} of zero is no model to turn odometry back with")
    if not isinstance(model, OdometryInverse):
        raise ModelError(f"the {model.name} model cannot turn a robot's odometry back into its joints")
    readings = model.readings_from_odometry(base, vendor)  # a model that cannot turn it back says so first
    _check_lengths(model, vendor)
    return readings


def _check_lengths(model: KinematicModel, vendor: Mapping[str, float]) -> None:
    """Refuse a vendor's model no robot has (outside the model's plausible ranges), naming
    millimetres where its lengths over 1000 are a robot's."""
    ranges, units = model.physical_ranges, model.units
    outside = {n: v for n, v in vendor.items() if n in ranges and not ranges[n][0] <= v <= ranges[n][1]}
    if not outside:
        return
    listed = ", ".join(f"{n} {v:g}" for n, v in outside.items())
    lengths = {n: v / 1000.0 for n, v in vendor.items() if units.get(n) == "m"}
    fixed = {**vendor, **lengths}
    if set(outside) <= set(lengths) and all(ranges[n][0] <= fixed[n] <= ranges[n][1] for n in outside):
        words = ", ".join(f"{n}: {v:g}" for n, v in lengths.items())
        raise ConfigError(
            f"vendor: {listed} lie outside what a robot can have: the vendor's model looks given in "
            f"millimetres; give its lengths in metres ({words})"
        )
    limits = ", ".join(
        f"{n} in [{ranges[n][0]:g}, {ranges[n][1]:g}] {units.get(n, '')}".rstrip() for n in outside
    )
    raise ConfigError(
        f"vendor: {listed} lie outside what a robot can have ({limits}); give the vendor's own values"
    )


#: A step of the odometry moves sideways (off the arc its turn draws) by more than this share of
#: its length where it is not an arc; steps shorter than :data:`ARC_MIN_STEP` (m) are not judged
#: (the file's printed digits dominate them).
ARC_SIDEWAYS = 0.05
ARC_MIN_STEP = 1e-4
#: The odometry is not arcs where more than this share of its judged steps are not.
ARC_SHARE = 0.5


def _off_arc(base: np.ndarray, theta_scale: float = 1.0) -> tuple[float, int]:
    """The share of the odometry's steps (longer than :data:`ARC_MIN_STEP`) that are not arcs (they
    move sideways to the chord their turn draws by more than :data:`ARC_SIDEWAYS` of their length),
    with its heading read times ``theta_scale``; and how many steps were judged."""
    theta = np.unwrap(base[:, 2] * theta_scale)
    d = np.diff(base[:, :2], axis=0)
    chord = np.hypot(d[:, 0], d[:, 1])
    judged = chord > ARC_MIN_STEP
    mid = theta[:-1] + 0.5 * np.diff(theta)
    sideways = np.abs(-np.sin(mid) * d[:, 0] + np.cos(mid) * d[:, 1])
    n = int(judged.sum())
    return (float(np.mean(sideways[judged] > ARC_SIDEWAYS * chord[judged])) if n else 0.0), n


def check_arcs(path: str, base: np.ndarray) -> None:
    """Refuse odometry that a model turning it back cannot reproduce: every such model reads each
    step as the arc of a wheeled base (:func:`~nlp_calib.models.drives.arcs`), so its joints
    re-integrated give the odometry back only where the steps are arcs. A heading in degrees is
    named (read as radians, the steps are arcs)."""
    share, n = _off_arc(base)
    if n < 10 or share <= ARC_SHARE:
        return
    said = (
        f"{100 * share:.0f} % of its {n} steps move sideways, off the arc their turn draws (by more than "
        f"{100 * ARC_SIDEWAYS:g} % of their length), where a wheeled base's odometry moves along its heading"
    )
    if _off_arc(base, np.pi / 180.0)[0] <= ARC_SHARE / 5:
        raise DatasetError(
            path,
            None,
            f"{said}; read in degrees, its θ makes them arcs: its θ is in degrees; give it in radians "
            "(REP 103)",
        )
    raise DatasetError(
        path,
        None,
        f"{said}: the vendor's model turns it back into joints that, integrated again, do not give it back "
        "(odometry of a base that slides sideways, or poses of another frame than the base's); the "
        "vendor's odometry cannot be calibrated against as it is",
    )


def _resolved(path: Path, base_dir: Path) -> Path:
    return path if path.is_absolute() else base_dir / path
