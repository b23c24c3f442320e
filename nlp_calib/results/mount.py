"""The sensor's mount as every hand-off file states it: one record, built once, that
``sensor_mount.urdf.xml``, ``robot.urdf`` and ``calibration.yaml`` all format, so they never
disagree.

The record is the fixed joint that places the sensor's link on the robot: its links, its name and
its origin, the sensor's pose in ``base_link`` with each component's 1σ, and which components the
fit calibrated and where each other one comes from (a bag's ``/tf_static``, the user's URDF, a
held value). Rotations follow URDF: fixed axes, ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

#: The frame the calibrated mount is given in.
BASE_LINK = "base_link"
#: The components of a pose, in the order URDF's ``xyz`` and ``rpy`` give them.
COMPONENTS: tuple[str, ...] = ("x", "y", "z", "roll", "pitch", "yaw")

Triple = tuple[float, float, float]


@dataclass(frozen=True)
class SensorMount:
    """The fixed joint ``joint`` from link ``parent`` to the sensor's link ``child``, its origin
    ``xyz``/``rpy`` (the child in the parent); ``pose``: the sensor in ``base_link`` by component
    (:data:`COMPONENTS`), ``std`` the 1σ of each calibrated one (in ``base_link``);
    ``calibrated``: the components the fit estimated; ``nominal``: each other component and where
    its value comes from; ``kind``: the sensor's mount as fitted (``planar`` or ``3d``);
    ``undetermined``: each component the fit estimated but did not determine well enough to use
    (a caveat of the verdict, or held at its guess), with why: not calibrated, and no URDF file
    states it (:meth:`doubting`)."""

    kind: str
    parent: str
    child: str
    joint: str
    xyz: Triple
    rpy: Triple
    pose: Mapping[str, float]
    std: Mapping[str, float]
    calibrated: tuple[str, ...]
    nominal: Mapping[str, str]
    undetermined: Mapping[str, str] = field(default_factory=dict)

    @classmethod
    def on_base(
        cls,
        kind: str,
        child: str,
        pose: Mapping[str, float],
        std: Mapping[str, float],
        nominal: Mapping[str, str],
    ) -> SensorMount:
        """The sensor's link on ``base_link`` itself at ``pose`` (every component of
        :data:`COMPONENTS`); the components not in ``nominal`` are the calibrated ones, with their
        1σ in ``std``."""
        values = tuple(float(pose[c]) for c in COMPONENTS)
        calibrated = tuple(c for c in COMPONENTS if c not in nominal)
        return cls(
            kind=kind,
            parent=BASE_LINK,
            child=child,
            joint=f"{BASE_LINK}_to_{child}",
            xyz=(values[0], values[1], values[2]),
            rpy=(values[3], values[4], values[5]),
            pose=dict(zip(COMPONENTS, values)),
            std={c: float(std.get(c, math.nan)) if c in calibrated else math.nan for c in COMPONENTS},
            calibrated=calibrated,
            nominal=dict(nominal),
        )

    def under(
        self,
        parent: str,
        joint: str,
        child: str,
        origin: tuple[Triple, Triple],
        pose: Mapping[str, float],
        nominal: Mapping[str, str],
    ) -> SensorMount:
        """The same sensor as the link ``child`` of ``joint`` below ``parent`` (a robot
        description's own joint and link, which every hand-off file then names): its ``origin``
        (xyz, rpy) in the parent, the sensor's ``pose`` in ``base_link`` with the components the
        fit did not calibrate taken from that description (``nominal``)."""
        return SensorMount(
            kind=self.kind,
            parent=parent,
            child=child,
            joint=joint,
            xyz=origin[0],
            rpy=origin[1],
            pose={c: float(pose[c]) for c in COMPONENTS},
            std=self.std,
            calibrated=self.calibrated,
            nominal={
                **{c: nominal.get(c, self.nominal[c]) for c in self.nominal},
                **{
                    c: f"{nominal[c]} (not determined well enough to use: {why})"
                    for c, why in self.undetermined.items()
                    if c in nominal
                },
            },
            undetermined={c: why for c, why in self.undetermined.items() if c not in nominal},
        )

    def holding(self, given: Mapping[str, str]) -> SensorMount:
        """The same mount with the components in ``given`` (component → where its value comes
        from: ``known:``, ``fixed:``) said to be given, not calibrated: no 1σ, and listed with
        the nominal ones."""
        held = [c for c in self.calibrated if c in given]
        if not held:
            return self
        return dataclasses.replace(
            self,
            std={c: math.nan if c in given else s for c, s in self.std.items()},
            calibrated=tuple(c for c in self.calibrated if c not in given),
            nominal={**self.nominal, **{c: given[c] for c in held}},
        )

    def doubting(self, doubts: Mapping[str, str]) -> SensorMount:
        """The same mount with the calibrated components in ``doubts`` (component → why) not
        determined well enough to use: no longer calibrated, no 1σ, listed under ``undetermined``."""
        doubted = {c: why for c, why in doubts.items() if c in self.calibrated}
        if not doubted:
            return self
        return dataclasses.replace(
            self,
            std={c: math.nan if c in doubted else s for c, s in self.std.items()},
            calibrated=tuple(c for c in self.calibrated if c not in doubted),
            undetermined={**self.undetermined, **doubted},
        )

    def words(self) -> str:
        """What was calibrated and where the rest comes from, in words."""
        sources: dict[str, list[str]] = {}
        for component, source in self.nominal.items():
            sources.setdefault(source, []).append(component)
        rest = "; ".join(f"{', '.join(names)} {source}" for source, names in sources.items())
        doubted = "; ".join(
            f"{c} not determined well enough to use ({why})" for c, why in self.undetermined.items()
        )
        said = [
            f"calibrated: {', '.join(self.calibrated) or 'none'}",
            *([rest] if rest else []),
            *([doubted] if doubted else []),
        ]
        return "; ".join(said)


@dataclass(frozen=True)
class LogMount:
    """One log's own mount, in a fit of several logs with a mount each: the log (its name) and the
    mount (its sensor's link named apart where logs share a frame's name)."""

    log: str
    mount: SensorMount
