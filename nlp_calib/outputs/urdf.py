"""The user's own URDF with the sensor re-posed: ``robot.urdf`` from ``--urdf ROBOT.urdf --sensor-link LINK``.

The joint whose child is ``LINK`` gets the calibrated mount: x, y and yaw of the sensor in
``base_link`` calibrated; its height, roll and pitch kept as the description has them. The joint
may hang below ``base_link`` through other fixed joints: its new origin is the calibrated pose
seen from its parent. :func:`placed` makes the mount record that joint (every hand-off file then
states the user's joint, to the last digit); :func:`reposed` writes it into the description.
Everything else in the file stays byte for byte the user's: the file is not re-serialised; the
parsed document says where that joint's ``<origin>`` element lies, and only that element's start
tag is written again, from its parsed attributes (``xyz`` and ``rpy`` new, the others as they
were). Rotations follow URDF: fixed axes, ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.

What ROS's URDF parser (urdfdom, on TinyXML2) would not read as the file means is refused before
any work, each with the line: UTF-16 or UTF-32 text, entity declarations (which
it does not expand), a root that is not ``<robot>``, an unexpanded xacro file, two joints or two
links of one name, a joint with two ``<parent>``, ``<child>`` or ``<origin>`` elements (it reads
the first and ignores the rest), two joints with one child link (a link has one parent) and a
joint whose links the file does not declare.
"""

from __future__ import annotations

import math
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
#: Byte order marks of the encodings ROS's parser cannot read (UTF-32's first: it starts as UTF-16's).
_BOMS = {
    b"\xff\xfe\x00\x00": "UTF-32",
    b"\x00\x00\xfe\xff": "UTF-32",
    b"\xff\xfe": "UTF-16",
    b"\xfe\xff": "UTF-16",
}
_UTF8_BOM = b"\xef\xbb\xbf"
#: The elements of a joint ROS reads once (the first of each).
_ONCE = ("parent", "child", "origin")
#: A joint's elements read: those, and its ``<limit>`` (a revolute joint's angles: a steered
#: wheel's reach, which the plan keeps within).
_READ = (*_ONCE, "limit")


@dataclass
class _Element:
    """Where an element's start tag begins (byte offset and line) and its attributes, in order."""

    start: int
    line: int
    attrs: dict[str, str]


@dataclass
class _Joint:
    name: str
    kind: str
    start: int
    line: int
    parent: str = ""
    child: str = ""
    origin: dict[str, str] = field(default_factory=dict)
    origin_start: int | None = None
    seen: dict[str, list[_Element]] = field(default_factory=dict)


@dataclass(frozen=True)
class Description:
    """A URDF's text and its joints by child link."""

    path: Path
    text: bytes
    joints: dict[str, _Joint]
    encoding: str = "utf-8"


class _Reader:
    """The ``<robot>``'s joints and links as expat reports them, with their byte offsets."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.parser = xml.parsers.expat.ParserCreate()
        self.encoding = "utf-8"
        self.depth = 0
        self.joints: list[_Joint] = []
        self.links: dict[str, int] = {}
        self.current: _Joint | None = None
        p = self.parser
        p.StartElementHandler, p.EndElementHandler = self.start, self.end
        p.EntityDeclHandler = self.entity
        p.XmlDeclHandler = self.declaration

    def declaration(self, version: str, encoding: str | None, standalone: int) -> None:
        if encoding is not None and encoding.lower().replace("_", "-") not in ("utf-8", "utf8"):
            if "16" in encoding or "32" in encoding:  # a BOM-less multi-byte file: no byte offsets
                raise self.fail(1, f"declares the encoding {encoding}; ROS's URDF parser reads UTF-8")
            self.encoding = encoding

    def fail(self, line: int | None, problem: str) -> UsageError:
        where = f"{self.path}:{line}" if line is not None else str(self.path)
        return UsageError(f"{where}: {problem} (--urdf)")

    def entity(self, name: str, *_: object) -> None:
        raise self.fail(
            self.parser.CurrentLineNumber,
            f"declares the entity {name!r}; ROS's URDF parser does not expand entities: write their text "
            "out (or generate the file with xacro) and give that file",
        )

    def start(self, name: str, attrs: dict[str, str]) -> None:
        line, at = self.parser.CurrentLineNumber, self.parser.CurrentByteIndex
        self.depth += 1
        if self.depth == 1:
            self._root(name, attrs, line)
        elif name.startswith("xacro:"):
            raise self.fail(line, f"<{name}> is xacro: run xacro on the file and give its output")
        elif self.depth == 2 and name == "joint":
            self.current = _Joint(attrs.get("name", ""), attrs.get("type", ""), at, line)
        elif self.depth == 2 and name == "link":
            self._link(attrs.get("name", ""), line)
        elif self.depth == 3 and self.current is not None and name in _READ:
            self.current.seen.setdefault(name, []).append(_Element(at, line, dict(attrs)))

    def _root(self, name: str, attrs: dict[str, str], line: int) -> None:
        if name != "robot":
            raise self.fail(line, f"the root element is <{name}>; a URDF's is <robot>")
        if any(k.startswith("xmlns:xacro") for k in attrs):
            raise self.fail(line, "is a xacro file: run xacro on it and give its output")

    def _link(self, name: str, line: int) -> None:
        if name in self.links:
            raise self.fail(line, f"a second link named {name!r} (the first on line {self.links[name]})")
        self.links[name] = line

    def end(self, name: str) -> None:
        if self.depth == 2 and name == "joint" and self.current is not None:
            self.joints.append(self.current)
            self.current = None
        self.depth -= 1


def _check_joint(reader: _Reader, joint: _Joint) -> None:
    """The joint as ROS reads it, or an error where ROS would read something else or nothing."""
    if not joint.name:
        raise reader.fail(joint.line, "a <joint> without a name")
    for what in _ONCE:
        found = joint.seen.get(what, [])
        if len(found) > 1:
            lines = ", ".join(str(e.line) for e in found)
            raise reader.fail(
                found[1].line,
                f"joint {joint.name!r} has {len(found)} <{what}> elements (lines {lines}); ROS reads the "
                "first and ignores the rest: keep one",
            )
    for what in ("parent", "child"):
        found = joint.seen.get(what, [])
        link = found[0].attrs.get("link", "") if found else ""
        if not link:
            raise reader.fail(joint.line, f"joint {joint.name!r} names no {what} link")
        if link not in reader.links:
            raise reader.fail(joint.line, f"joint {joint.name!r}: its {what} link {link!r} is not declared")
        setattr(joint, what, link)
    if origin := joint.seen.get("origin"):
        joint.origin, joint.origin_start = origin[0].attrs, origin[0].start


def _parse(path: Path, text: bytes) -> tuple[dict[str, _Joint], str]:
    for bom, name in _BOMS.items():
        if text.startswith(bom):
            raise UsageError(
                f"{path}: is {name} text; ROS's URDF parser reads UTF-8: convert it (iconv -f {name} -t "
                "UTF-8) and give that file (--urdf)"
            )
    reader = _Reader(path)
    try:
        reader.parser.Parse(text, True)
    except xml.parsers.expat.ExpatError as exc:
        raise UsageError(f"{path}:{exc.lineno}: not a URDF ({exc}); give the robot's .urdf file") from None
    joints: dict[str, _Joint] = {}
    names: dict[str, _Joint] = {}
    for joint in reader.joints:
        _check_joint(reader, joint)
        if joint.name in names:
            raise reader.fail(
                joint.line,
                f"a second joint named {joint.name!r} (the first on line {names[joint.name].line})",
            )
        names[joint.name] = joint
        if joint.child in joints:
            first = joints[joint.child]
            raise reader.fail(
                joint.line,
                f"joints {first.name!r} (line {first.line}) and {joint.name!r} both have the child link "
                f"{joint.child!r}; a link has one parent joint",
            )
        joints[joint.child] = joint
    return joints, reader.encoding


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
    description = Description(path, text, *_parse(path, text))
    T_base_parent(description, link)  # refuses what cannot be re-posed, before any work
    return description


def joint_limits(d: Description) -> dict[str, float]:
    """The largest angle (rad, either way) each revolute joint with a ``<limit>`` takes, by joint
    name: how far a steered wheel turns (a continuous joint has no limit; a prismatic one no angle)."""
    out = {}
    for joint in d.joints.values():
        found = joint.seen.get("limit")
        if joint.kind != "revolute" or not found:
            continue
        ends = []
        for key in ("lower", "upper"):
            text = found[0].attrs.get(key, "0")
            try:
                value = float(text)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                raise UsageError(
                    f"{d.path}:{found[0].line}: joint {joint.name!r}: <limit {key}={text!r}> is not a finite "
                    "number of radians (--urdf)"
                )
            ends.append(abs(value))
        out[joint.name] = max(ends)
    return out


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


def _start_tag(name: str, attrs: dict[str, str], closed: bool, encoding: str) -> bytes:
    """A start tag written from parsed attributes, in their order, each value escaped, in the
    file's encoding."""
    # Imported here: xml.sax.saxutils pulls in urllib.request, http.client and ssl, a tenth of a
    # second of every run's start, for the one command that edits a user's URDF.
    from xml.sax.saxutils import quoteattr

    written = "".join(f" {k}={quoteattr(v)}" for k, v in attrs.items())
    return f"<{name}{written}{'/>' if closed else '>'}".encode(encoding, errors="xmlcharrefreplace")


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
    # What the fit did not determine well enough stays the user's too: "keep yours".
    kept_from = dict.fromkeys((*mount.nominal, *mount.undetermined), f"kept from {d.path.name} (--urdf)")
    return mount.under(joint.parent, joint.name, joint.child, origin, pose, kept_from)


def reposed(d: Description, link: str, mount: SensorMount) -> bytes:
    """``d``'s text with ``link``'s joint at ``mount``'s origin (from :func:`placed`)."""
    joint = d.joints[link]
    text = origin_text(mount)
    if joint.origin_start is None:  # no <origin>: one goes right after the joint's start tag
        end = _tag_end(d, joint.start, b"<joint")
        return d.text[:end] + _start_tag("origin", text, True, d.encoding) + d.text[end:]
    start = joint.origin_start
    end = _tag_end(d, start, b"<origin")
    closed = d.text[:end].endswith(b"/>")
    tag = _start_tag("origin", {**joint.origin, **text}, closed, d.encoding)
    return d.text[:start] + tag + d.text[end:]


def _tag_end(d: Description, start: int, opening: bytes) -> int:
    """Where the start tag the parser placed at ``start`` ends (past its ``>``)."""
    match = _TAG_END.match(d.text, start)
    if not d.text.startswith(opening, start) or match is None:  # the parser's offsets are bytes of the file
        raise UsageError(f"{d.path}: cannot find the element the parser read at byte {start} (--urdf)")
    return match.end()
