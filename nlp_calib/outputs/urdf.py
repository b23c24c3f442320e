"""The user's own URDF with the sensor re-posed: ``robot.urdf`` from ``--urdf ROBOT.urdf --sensor-link LINK``.

The joint whose child is ``LINK`` gets the calibrated mount: x, y and yaw of the sensor in
``base_link`` calibrated; its height, roll and pitch kept as the description has them. The joint
may hang below ``base_link`` through other fixed joints: its new origin is the calibrated pose
seen from its parent. :func:`placed` makes the mount record that joint (every hand-off file then
states the user's joint, to the last digit); :func:`reposed` writes it into the description.
Everything else in the file stays byte for byte the user's: the file is not re-serialised, only
the ``xyz`` and ``rpy`` of that one ``<origin>`` are rewritten in place.
Rotations follow URDF: fixed axes, ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.
"""

from __future__ import annotations

import re
import xml.parsers.expat
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import open_regular
from nlp_calib.results.mount import COMPONENTS, SensorMount

BASE_LINK = "base_link"
#: The largest description read (a URDF with meshes inlined is still far below this).
MAX_BYTES = 16 * 1024 * 1024
_TAG_END = re.compile(rb"""(?:[^>"']|"[^"]*"|'[^']*')*>""")


@dataclass
class _Joint:
    name: str
    kind: str
    start: int
    parent: str = ""
    child: str = ""
    origin: dict[str, str] = field(default_factory=dict)
    origin_start: int | None = None


@dataclass(frozen=True)
class Description:
    """A URDF's text and its joints by child link."""

    path: Path
    text: bytes
    joints: dict[str, _Joint]


def _parse(path: Path, text: bytes) -> dict[str, _Joint]:
    joints: dict[str, _Joint] = {}
    current: list[_Joint] = []
    parser = xml.parsers.expat.ParserCreate()

    def start(name: str, attrs: dict[str, str]) -> None:
        if name == "joint" and "name" in attrs:
            current.append(_Joint(attrs["name"], attrs.get("type", ""), parser.CurrentByteIndex))
        elif current and name in ("parent", "child"):
            setattr(current[-1], name, attrs.get("link", ""))
        elif current and name == "origin":
            current[-1].origin, current[-1].origin_start = dict(attrs), parser.CurrentByteIndex

    def end(name: str) -> None:
        if name == "joint" and current:
            joint = current.pop()
            joints[joint.child] = joint

    parser.StartElementHandler, parser.EndElementHandler = start, end
    try:
        parser.Parse(text, True)
    except xml.parsers.expat.ExpatError as exc:
        raise UsageError(f"{path}:{exc.lineno}: not a URDF ({exc}); give the robot's .urdf file") from None
    return joints


def load(path: Path, link: str) -> Description:
    """Read ``path`` and check that ``link`` hangs below ``base_link`` through fixed joints."""
    try:
        with open_regular(path) as fh:
            text = fh.read(MAX_BYTES + 1)
    except FileNotFoundError:
        raise UsageError(f"{path}: no such URDF file (--urdf)") from None
    except OSError as exc:  # a FIFO or a device (SpecialFileError), or unreadable
        raise UsageError(f"{path}: cannot read the URDF (--urdf): {exc}") from None
    if len(text) > MAX_BYTES:
        raise UsageError(f"{path}: larger than {MAX_BYTES >> 20} MiB; is it the robot's URDF?")
    description = Description(path, text, _parse(path, text))
    T_base_parent(description, link)  # refuses what cannot be re-posed, before any work
    return description


def _rotation(rpy: np.ndarray) -> np.ndarray:
    r, p, y = rpy
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _rpy(R: np.ndarray) -> np.ndarray:
    pitch = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
    return np.array([np.arctan2(R[2, 1], R[2, 2]), pitch, np.arctan2(R[1, 0], R[0, 0])])


def _numbers(joint: _Joint, key: str, path: Path) -> np.ndarray:
    text = joint.origin.get(key, "0 0 0")
    try:
        values = np.array([float(v) for v in text.split()])
    except ValueError:
        values = np.zeros(0)
    if values.shape != (3,) or not np.all(np.isfinite(values)):
        raise UsageError(f"{path}: joint {joint.name!r}: origin {key}={text!r} is not three numbers")
    return values


def _transform(joint: _Joint, path: Path) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = _rotation(_numbers(joint, "rpy", path))
    T[:3, 3] = _numbers(joint, "xyz", path)
    return T


def T_base_parent(d: Description, link: str) -> np.ndarray:
    """The pose of ``link``'s parent in ``base_link``, through the fixed joints above it."""
    if link not in d.joints:
        raise UsageError(
            f"{d.path}: no joint has the child link {link!r} (--sensor-link); links with a joint: "
            f"{', '.join(sorted(d.joints)) or 'none'}"
        )
    T, current, seen = np.eye(4), d.joints[link].parent, {link}
    while current != BASE_LINK:
        above = d.joints.get(current)
        if above is None or current in seen:
            raise UsageError(
                f"{d.path}: link {link!r} is not below {BASE_LINK!r} (the frame of the calibrated mount)"
            )
        if above.kind != "fixed":
            raise UsageError(
                f"{d.path}: between {BASE_LINK!r} and {link!r} lies the {above.kind} joint {above.name!r}; "
                "the calibrated mount can only be written below fixed joints"
            )
        T, current = _transform(above, d.path) @ T, above.parent
        seen.add(current)
    return T


def _set(tag: bytes, key: str, value: str) -> bytes:
    pattern = re.compile(rb"""(\s%s\s*=\s*)(["'])(.*?)\2""" % key.encode())
    if pattern.search(tag):
        return pattern.sub(lambda m: m.group(1) + m.group(2) + value.encode() + m.group(2), tag, count=1)
    closing = tag.rfind(b"/>") if tag.endswith(b"/>") else len(tag) - 1
    return tag[:closing] + f' {key}="{value}"'.encode() + tag[closing:]


def origin_text(mount: SensorMount) -> dict[str, str]:
    """The ``xyz`` and ``rpy`` attributes of ``mount``'s joint, every digit kept: every hand-off
    file writes these same strings."""
    return {
        "xyz": " ".join(repr(float(v)) for v in mount.xyz),
        "rpy": " ".join(repr(float(v)) for v in mount.rpy),
    }


def placed(d: Description, link: str, mount: SensorMount) -> SensorMount:
    """``mount`` as ``d``'s own joint of ``link``: the calibrated components in ``base_link``, the
    others (a planar fit's height, roll and pitch) as ``d`` has them, the origin in the joint's
    parent."""
    joint = d.joints[link]
    T_bp = T_base_parent(d, link)
    T_bs = T_bp @ _transform(joint, d.path)
    kept = dict(zip(COMPONENTS, (*map(float, T_bs[:3, 3]), *map(float, _rpy(T_bs[:3, :3])))))
    pose = {c: mount.pose[c] if c in mount.calibrated else kept[c] for c in COMPONENTS}
    T_new = np.eye(4)
    T_new[:3, :3] = _rotation(np.array([pose["roll"], pose["pitch"], pose["yaw"]]))
    T_new[:3, 3] = [pose["x"], pose["y"], pose["z"]]
    T_joint = np.linalg.solve(T_bp, T_new)
    xyz = tuple(float(v) for v in T_joint[:3, 3])
    rpy = tuple(float(v) for v in _rpy(T_joint[:3, :3]))
    origin = ((xyz[0], xyz[1], xyz[2]), (rpy[0], rpy[1], rpy[2]))
    kept_from = dict.fromkeys(mount.nominal, f"kept from {d.path.name} (--urdf)")
    return mount.under(joint.parent, joint.name, origin, pose, kept_from)


def reposed(d: Description, link: str, mount: SensorMount) -> bytes:
    """``d``'s text with ``link``'s joint at ``mount``'s origin (from :func:`placed`)."""
    joint = d.joints[link]
    text = origin_text(mount)
    if joint.origin_start is None:  # no <origin>: one goes right after the joint's start tag
        end = _TAG_END.match(d.text, joint.start).end()  # type: ignore[union-attr]
        return d.text[:end] + f'<origin xyz="{text["xyz"]}" rpy="{text["rpy"]}"/>'.encode() + d.text[end:]
    start = joint.origin_start
    end = _TAG_END.match(d.text, start).end()  # type: ignore[union-attr]
    tag = _set(_set(d.text[start:end], "xyz", text["xyz"]), "rpy", text["rpy"])
    return d.text[:start] + tag + d.text[end:]
