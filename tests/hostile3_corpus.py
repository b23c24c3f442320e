"""The round-three hostile corpus (issue 24): cases and the harness that judges them.

A case builds its inputs in a fresh folder and says what it runs and what must hold afterwards
(:class:`Expect`); :func:`judge` applies the rules every case shares. ``tests/test_hostile3.py``
runs them. Classes: ``bags`` (kinds of file, damaged bags and metadata), ``values`` (what a bag's
messages claim), ``datasets`` (several logs), ``ipopt`` (IPOPT's own files), ``yaml`` (YAML 1.1
forms) and ``aliasing`` (outputs over inputs, the tool's own names, links, edited outputs).
"""

from __future__ import annotations

import contextlib
import io
import math
import os
import random
import shutil
import socket
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import REPO
from test_bags import JS, POSE, Message, _header, drive_messages, joint_state, write_bag

from nlp_calib import cli
from nlp_calib.logs import Log, read_log
from nlp_calib.logs.writer import format_time
from nlp_calib.models import get_model
from nlp_calib.pipeline import load_scenario

JOINTS = ("front_steer", "front_drive")
TRICYCLE = get_model("tricycle")
T0_NS = 1_700_000_000 * 10**9
CLASSES = ("bags", "values", "datasets", "ipopt", "yaml", "aliasing")
#: A run that has not ended by then is a hang.
DEADLINE_S = 120

# ------------------------------------------------------------------------------- the harness


@dataclass(frozen=True)
class Outcome:
    code: int
    out: str
    err: str


@dataclass
class Expect:
    """What a case runs and what must hold afterwards.

    ``codes``: the exit codes allowed; ``needles``: text the error line holds (with a non-zero
    exit), or the output holds (exit 0); ``keep``: files or folders that must be unchanged;
    ``absent``: files that must not appear; ``child``: run in a child process with a deadline
    (the input could block); ``check``: the values a silent result would get wrong.
    """

    argv: list[str]
    codes: tuple[int, ...]
    needles: tuple[str, ...] = ()
    keep: tuple[Path, ...] = ()
    absent: tuple[Path, ...] = ()
    cwd: Path | None = None
    child: bool = False
    check: Callable[[Outcome], None] | None = None


@dataclass(frozen=True)
class World:
    """The shared inputs: a simulated drive as a text log, a second drive, and the first's bags."""

    folder: Path
    log_path: Path
    second: Path
    log: Log
    bags: dict[str, Path] = field(default_factory=dict)
    #: Folders a command wrote over the first drive, kept for the cases that start from them.
    written: dict[tuple[str, ...], Path] = field(default_factory=dict)

    def messages(self, **kwargs: Any) -> list[Message]:
        return drive_messages(self.log, T0_NS, **kwargs)


Build = Callable[[World, Path], Expect]


@dataclass(frozen=True)
class Case:
    cls: str
    name: str
    build: Build


def snapshot(path: Path) -> object:
    """What ``path`` holds (a file's bytes, a link's target, a folder's files), to compare later."""
    if path.is_symlink():
        return os.readlink(path)
    if path.is_dir():
        return {str(p.relative_to(path)): snapshot(p) for p in sorted(path.rglob("*")) if not p.is_dir()}
    if path.exists() and not path.is_file():
        return "<special>"
    return path.read_bytes() if path.exists() else None


def run_in_process(argv: Sequence[str], cwd: Path | None = None) -> Outcome:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.ExitStack() as stack:
        if cwd is not None:
            stack.enter_context(contextlib.chdir(cwd))
        stack.enter_context(contextlib.redirect_stdout(out))
        stack.enter_context(contextlib.redirect_stderr(err))
        code = cli.main(list(argv))
    return Outcome(code, out.getvalue(), err.getvalue())


def run_child(argv: Sequence[str], cwd: Path | None = None) -> Outcome:
    """The command in a child with a deadline: an input that blocks is a hang, not a stuck suite."""
    env = dict(os.environ, PYTHONWARNINGS="ignore", PYTHONPATH=str(REPO))
    command = [sys.executable, "-m", "nlp_calib", *argv]
    try:
        proc = subprocess.run(
            command, cwd=cwd or REPO, env=env, capture_output=True, text=True, timeout=DEADLINE_S
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"hang: nlp-calib {' '.join(argv)} did not end within {DEADLINE_S} s")
    return Outcome(proc.returncode, proc.stdout, proc.stderr)


def judge(expect: Expect, outcome: Outcome) -> None:
    """The rules every case is held to (see the module docstring of ``test_hostile3``)."""
    assert "Traceback" not in outcome.err and "internal error" not in outcome.err, outcome.err
    assert outcome.code in expect.codes, (outcome.code, outcome.err)
    lines = outcome.err.strip().splitlines()
    assert all(ln.startswith(("error: ", "warning: ")) for ln in lines), outcome.err
    if outcome.code != 0:
        errors = [ln for ln in lines if ln.startswith("error: ")]
        assert len(errors) == 1, outcome.err
        for needle in expect.needles:
            assert needle in errors[0], f"{needle!r} not in {errors[0]!r}"
    else:
        for needle in expect.needles:
            assert needle in outcome.out + outcome.err, f"{needle!r} not in the output: {outcome.err}"


def scenario(folder: Path, dataset: str, extra: str = "", name: str = "case.yaml") -> Path:
    path = folder / name
    path.write_text(
        f"{dataset}\nmodel: tricycle\nresidual: {{horizon: 10}}\nsolvers: [gauss_newton]\n"
        f"validation: {{blocks: 0}}\n{extra}"
    )
    return path


def bag_mapping(bag: Path) -> str:
    joints = ", ".join(JOINTS)
    topics = "joint_states: /joint_states, tracker: /tracker/pose, joint_units: counts"
    return f"{{bag: '{bag}', {topics}, joints: [{joints}]}}"


def import_bag(bag: Path | str, out: Path, *extra: str) -> list[str]:
    topics = ["--joint-states", "/joint_states", "--joints", ",".join(JOINTS), "--tracker", "/tracker/pose"]
    topics += ["--joint-units", "counts"]
    return ["import-bag", str(bag), "--out", str(out), "--model", "tricycle", *topics, *extra]


def run_out(sc: Path, out: Path, *extra: str) -> list[str]:
    return ["run", str(sc), "--out", str(out), *extra]


def joint_run(entries: Sequence[str], tmp: Path, codes: tuple[int, ...], needles: tuple[str, ...]) -> Expect:
    sc = scenario(tmp, "datasets:\n" + "".join(f"  - {e}\n" for e in entries))
    return Expect(run_out(sc, tmp / "out"), codes, needles)


# ----------------------------------------------------------------------------- bags: kinds


def fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def unix_socket(path: Path) -> Path:
    sock = socket.socket(socket.AF_UNIX)
    sock.bind(str(path))
    sock.close()  # the socket file stays
    return path


def link_to_fifo(tmp: Path) -> Path:
    (tmp / "x.bag").symlink_to(fifo(tmp / "pipe"))
    return tmp / "x.bag"


_OPEN_HINT = "a ROS 1 bag is a .bag file"


def special_bag(make: Callable[[Path], Path], needle: str, w: World, tmp: Path) -> Expect:
    bag = make(tmp)
    return Expect(import_bag(bag, tmp / "out.txt"), (2,), (str(bag), needle, _OPEN_HINT), child=True)


def special_in_folder(name: str, make: Callable[[Path], Path], needle: str, w: World, tmp: Path) -> Expect:
    folder = tmp / "bag"
    shutil.copytree(w.bags["sqlite3"], folder)
    (folder / name).unlink(missing_ok=True)
    make(folder / name)
    needles = (str(folder / name), needle, "a bag folder holds regular files only")
    return Expect(import_bag(folder, tmp / "out.txt"), (2,), needles, child=True)


def scenario_bag_fifo(w: World, tmp: Path) -> Expect:
    sc = scenario(tmp, f"dataset: {bag_mapping(fifo(tmp / 'x.bag'))}")
    return Expect(run_out(sc, tmp / "out"), (2,), ("x.bag", "a FIFO", _OPEN_HINT), child=True)


def empty_bag(w: World, tmp: Path) -> Expect:
    (tmp / "x.bag").write_bytes(b"")
    return Expect(
        import_bag(tmp / "x.bag", tmp / "out.txt"), (2,), ("x.bag", "cannot open the bag", "repair")
    )


def folder_bag(w: World, tmp: Path) -> Expect:
    (tmp / "x.bag").mkdir()
    return Expect(import_bag(tmp / "x.bag", tmp / "out.txt"), (2,), ("x.bag", "without metadata.yaml"))


def robot_fifo(w: World, tmp: Path) -> Expect:
    argv = import_bag(w.bags["ros1"], tmp / "out.txt", "--robot", str(fifo(tmp / "robot.yaml")))
    return Expect(argv, (2,), ("robot.yaml", "not a regular file"), child=True)


def data_fifo(w: World, tmp: Path) -> Expect:
    sc = scenario(tmp, f"dataset: {w.log_path}")
    argv = run_out(sc, tmp / "out", "--data", str(fifo(tmp / "drive.txt")))
    return Expect(argv, (2,), ("drive.txt", "a FIFO", "pass the log file itself"), child=True)


def sim_config_fifo(w: World, tmp: Path) -> Expect:
    argv = ["simulate", "--config", str(fifo(tmp / "sim.yaml")), "--out", str(tmp / "s.txt")]
    return Expect(argv, (2,), ("sim.yaml", "not a regular file"), child=True)


KIND_CASES = [
    ("import-bag on a FIFO named x.bag", partial(special_bag, lambda t: fifo(t / "x.bag"), "a FIFO")),
    (
        "import-bag on a socket named x.bag",
        partial(special_bag, lambda t: unix_socket(t / "x.bag"), "a socket"),
    ),
    ("import-bag on /dev/zero", partial(special_bag, lambda t: Path("/dev/zero"), "a device")),
    ("import-bag on /dev/null", partial(special_bag, lambda t: Path("/dev/null"), "a device")),
    ("import-bag on a link to a FIFO", partial(special_bag, link_to_fifo, "a FIFO")),
    ("a bag folder whose .db3 is a FIFO", partial(special_in_folder, "bag.db3", fifo, "a FIFO")),
    (
        "a bag folder whose metadata.yaml is a FIFO",
        partial(special_in_folder, "metadata.yaml", fifo, "a FIFO"),
    ),
    ("a bag folder holding a socket", partial(special_in_folder, "extra.sock", unix_socket, "a socket")),
    ("a scenario's bag block naming a FIFO", scenario_bag_fifo),
    ("an empty x.bag", empty_bag),
    ("a folder named x.bag", folder_bag),
    ("ROBOT.yaml a FIFO", robot_fifo),
    ("--data a FIFO", data_fifo),
    ("simulate --config a FIFO", sim_config_fifo),
]

# ----------------------------------------------------------------------------- bags: damage

#: (format, seed) of the damaged bags: bytes flipped or zeroed in the middle, or the file cut.
DAMAGE = [(fmt, seed) for fmt in ("ros1", "sqlite3", "mcap") for seed in range(14)]


def damaged_copy(src: Path, dst: Path, seed: int) -> None:
    rng = random.Random(seed)
    data = bytearray(src.read_bytes())
    mode = ("flip", "zero", "cut")[seed % 3]
    lo = len(data) // 8  # past the file header: "damaged in the middle"
    if mode == "cut":
        del data[rng.randrange(lo, len(data)) :]
    else:
        at, n = rng.randrange(lo, len(data) - 64), rng.choice([1, 8, 64])
        data[at : at + n] = bytes(rng.randrange(256) for _ in range(n)) if mode == "flip" else bytes(n)
    dst.write_bytes(bytes(data))


def damaged_bag(fmt: str, seed: int, w: World, tmp: Path) -> Expect:
    src = w.bags[fmt]
    if fmt == "ros1":
        bag = tmp / "damaged.bag"
        damaged_copy(src, bag, seed)
    else:
        bag = tmp / "damaged"
        shutil.copytree(src, bag)
        (data,) = [p for p in bag.iterdir() if p.suffix in (".db3", ".mcap")]
        damaged_copy(src / data.name, data, seed)
    # Undetected damage (a changed digit) imports; detected damage is one line naming the bag.
    return Expect(import_bag(bag, tmp / "out.txt"), (0, 2), (str(bag),), keep=(bag,))


METADATA_EDITS: dict[str, Callable[[str], str]] = {
    "empty": lambda t: "",
    "not a mapping": lambda t: "[1, 2",
    "cut in half": lambda t: t[: len(t) // 2],
    "a topic name lost": lambda t: t.replace("name: /joint_states", "name:"),
    "an unknown version": lambda t: t.replace("version: 9", "version: 99"),
    "a hash split over lines": lambda t: t.replace("type_description_hash: ", "type_description_hash:\n   "),
}


def damaged_metadata(fmt: str, how: str, w: World, tmp: Path) -> Expect:
    bag = tmp / "bag"
    shutil.copytree(w.bags[fmt], bag)
    (bag / "metadata.yaml").write_text(METADATA_EDITS[how]((bag / "metadata.yaml").read_text()))
    return Expect(import_bag(bag, tmp / "out.txt"), (0, 2), (str(bag),), keep=(bag,))


def middle_damaged_ros1(src: Path, dst: Path) -> Path:
    """A ROS 1 bag with a message record's header zeroed a third of the way in."""
    data = bytearray(src.read_bytes())
    start = data.find(b"op=\x02", len(data) // 3)
    assert start > 0
    data[start - 8 : start + 64] = bytes(72)
    dst.write_bytes(bytes(data))
    return dst


def ros1_middle(w: World, tmp: Path) -> Expect:
    bag = middle_damaged_ros1(w.bags["ros1"], tmp / "middle.bag")
    needles = (str(bag), "cannot read the bag past message", "damaged", "reindex")
    return Expect(import_bag(bag, tmp / "out.txt"), (2,), needles, keep=(bag,))


DAMAGE_CASES = [
    *((f"{fmt} bag damaged, seed {seed}", partial(damaged_bag, fmt, seed)) for fmt, seed in DAMAGE),
    *(
        (f"{fmt} metadata.yaml {how}", partial(damaged_metadata, fmt, how))
        for fmt in ("sqlite3", "mcap")
        for how in METADATA_EDITS
    ),
    ("ros1 bag damaged in the middle (the issue's case)", ros1_middle),
]

# ----------------------------------------------------------------------------- values in bags

NOT_A_ROTATION = "tracker poses whose quaternion is not a rotation"
MALFORMED = "JointState messages whose position and name lists differ in length or name a joint twice"


def pose_with_quaternion(ns: int, xy: Sequence[float], q: Sequence[float]) -> Callable[[Any], Any]:
    def build(ts: Any) -> Any:
        point = ts.types["geometry_msgs/msg/Point"](x=float(xy[0]), y=float(xy[1]), z=0.3)
        quat = ts.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])
        body = ts.types["geometry_msgs/msg/Pose"](position=point, orientation=quat)
        return ts.types[POSE](header=_header(ts, ns), pose=body)

    return build


def scaled_quaternions(scale: Callable[[int], float], w: World) -> list[Message]:
    """The drive with each tracker quaternion ``k`` multiplied by ``scale(k)``."""
    out = [m for m in w.messages() if m[1] == JS]
    stamps = T0_NS + np.round(w.log.time_s * 1e9).astype(np.int64)
    for k, (ns, pose) in enumerate(zip(stamps.tolist(), w.log.T_world_sensor.tolist())):
        q = [scale(k) * c for c in (0.0, 0.0, math.sin(pose[2] / 2), math.cos(pose[2] / 2))]
        out.append(("/tracker/pose", POSE, ns + 1000, pose_with_quaternion(ns, pose[:2], q)))
    return out


def joint_states_replaced(
    bad: Callable[[int], tuple[Sequence[str], Sequence[float]] | None], w: World
) -> list[Message]:
    """The drive with JointState message ``k`` holding ``bad(k)`` (names, positions) when not None."""
    out = []
    for k, m in enumerate(x for x in w.messages() if x[1] == JS):
        spec = bad(k)
        out.append(m if spec is None else (m[0], m[1], m[2], joint_state(m[2], spec[0], spec[1])))
    return out + [m for m in w.messages() if m[1] == POSE]


def bad_nanosec(build: Callable[[Any], Any], nanosec: int) -> Callable[[Any], Any]:
    def rebuilt(ts: Any) -> Any:
        msg = build(ts)
        msg.header.stamp.nanosec = nanosec
        return msg

    return rebuilt


def bad_stamp(topic: str, number: int, w: World) -> list[Message]:
    """The drive with message ``number`` on ``topic`` stamped 3 s off, as nanosec 3e9 + x."""
    out, seen = [], 0
    for m in w.messages():
        seen += m[0] == topic
        if m[0] == topic and seen == number:
            m = (m[0], m[1], m[2], bad_nanosec(m[3], 3 * 10**9 + m[2] % 10**9))
        out.append(m)
    return out


def imported(tmp: Path) -> Log:
    return read_log(tmp / "out.txt", TRICYCLE.encoder_kinds)


def headings_close(w: World, tmp: Path, atol: float, _: Outcome) -> None:
    """The imported headings are the drive's (interpolated where a pose was dropped), never 0."""
    got = imported(tmp)
    assert got.n_records >= w.log.n_records - 1  # the last encoder message may lose its bracket
    assert np.array_equal(got.time_s, w.log.time_s[: got.n_records])
    truth = w.log.T_world_sensor[: got.n_records, 2]
    err = np.abs(np.remainder(got.T_world_sensor[:, 2] - truth + np.pi, 2 * np.pi) - np.pi)
    assert float(err.max()) <= atol, float(err.max())


def bag_values(
    messages: Callable[[World], list[Message]],
    codes: tuple[int, ...],
    needles: tuple[str, ...],
    atol: float | None,
    w: World,
    tmp: Path,
) -> Expect:
    bag = write_bag(tmp / "drive", "mcap", messages(w))
    check = None if atol is None else partial(headings_close, w, tmp, atol)
    return Expect(import_bag(bag, tmp / "out.txt"), codes, needles, check=check)


def stamps_exact(w: World, tmp: Path, offset_ns: int, _: Outcome) -> None:
    got = imported(tmp)
    assert got.n_records == w.log.n_records and not got.dropped
    assert np.array_equal(got.time_s, w.log.time_s)  # to the nanosecond
    first = next(ln for ln in (tmp / "out.txt").read_text().splitlines() if ln.startswith("time:"))
    assert first.split()[1] == format_time(offset_ns)


def shifted_stamps(offset_ns: int, w: World, tmp: Path) -> Expect:
    # Header stamps before 1970 (ROS 2's seconds are signed); the bag's record times are not.
    messages = [(m[0], m[1], m[2] - offset_ns + T0_NS, m[3]) for m in drive_messages(w.log, offset_ns)]
    bag = write_bag(tmp / "drive", "mcap", messages)
    check = partial(stamps_exact, w, tmp, offset_ns)
    return Expect(import_bag(bag, tmp / "out.txt"), (0,), ("300 of 300",), check=check)


def _values(
    name: str,
    messages: Callable[[World], list[Message]],
    codes: tuple[int, ...],
    needles: tuple[str, ...],
    atol: float | None = None,
) -> tuple[str, Build]:
    return name, partial(bag_values, messages, codes, needles, atol)


VALUE_CASES = [
    # A lost target publishes zeros: those poses are dropped and their encoder messages take the
    # poses on either side (80 ms apart), never heading 0.
    _values(
        "every 10th tracker quaternion (0, 0, 0, 0)",
        partial(scaled_quaternions, lambda k: 0.0 if k % 10 == 5 else 1.0),
        (0,),
        (f"30 {NOT_A_ROTATION}", "300 of 300 encoder messages paired"),
        0.05,
    ),
    _values(
        "every tracker quaternion of norm 0.5",
        partial(scaled_quaternions, lambda k: 0.5),
        (2,),
        ("tracker", "0 usable message(s)", f"300 {NOT_A_ROTATION}"),
    ),
    _values(
        "every other tracker quaternion of norm 0.5",
        partial(scaled_quaternions, lambda k: 0.5 if k % 2 else 1.0),
        (0,),
        (f"150 {NOT_A_ROTATION}",),
        0.05,
    ),
    _values(
        "tracker quaternions of norm 1.0005 (normalised)",
        partial(scaled_quaternions, lambda k: 1.0005),
        (0,),
        ("300 tracker quaternions normalised",),
        1e-12,
    ),
    _values(
        "tracker quaternions of norm 1.002 on a third",
        partial(scaled_quaternions, lambda k: 1.002 if k % 3 == 0 else 1.0),
        (0,),
        (f"100 {NOT_A_ROTATION}",),
    ),
    _values(
        "a NaN tracker quaternion",
        partial(scaled_quaternions, lambda k: math.nan if k == 7 else 1.0),
        (0,),
        (f"1 {NOT_A_ROTATION}",),
    ),
    _values(
        "an infinite tracker quaternion",
        partial(scaled_quaternions, lambda k: math.inf if k == 9 else 1.0),
        (0,),
        (f"1 {NOT_A_ROTATION}",),
    ),
    _values(
        "30 JointState messages with a position too short",
        partial(joint_states_replaced, lambda k: (JOINTS, [1.0]) if k % 10 == 3 else None),
        (0,),
        (f"30 {MALFORMED}", "270 of 270 encoder messages paired"),
    ),
    _values(
        "JointState messages with a position too long",
        partial(joint_states_replaced, lambda k: (JOINTS, [1.0, 2.0, 3.0]) if k < 5 else None),
        (0,),
        (f"5 {MALFORMED}",),
    ),
    _values(
        "JointState messages naming a joint twice",
        partial(joint_states_replaced, lambda k: ((*JOINTS, JOINTS[0]), [1.0, 2.0, 3.0]) if k == 0 else None),
        (0,),
        (f"1 {MALFORMED}",),
    ),
    _values(
        "every JointState message malformed",
        partial(joint_states_replaced, lambda k: (JOINTS, [])),
        (2,),
        ("joint_states", "0 usable message(s)", f"300 {MALFORMED}"),
    ),
    _values(
        "a JointState stamp with nanosec 3e9",
        partial(bad_stamp, "/joint_states", 17),
        (2,),
        ("message 17 on '/joint_states'", "nanosec", "[0, 10^9)", "fix its stamps"),
    ),
    _values(
        "a tracker stamp with nanosec 3e9",
        partial(bad_stamp, "/tracker/pose", 2),
        (2,),
        ("message 2 on '/tracker/pose'", "nanosec"),
    ),
    ("negative stamps (a drive before 1970)", partial(shifted_stamps, -20 * 10**9 - 123_456_789)),
    ("stamps crossing zero", partial(shifted_stamps, -5 * 10**9 - 7)),
]

# ----------------------------------------------------------------------------- several logs


def datasets_case(
    entries: Callable[[World, Path], list[str]],
    codes: tuple[int, ...],
    needles: tuple[str, ...],
    child: bool,
    w: World,
    tmp: Path,
) -> Expect:
    expect = joint_run(entries(w, tmp), tmp, codes, needles)
    expect.keep, expect.child = (w.log_path,), child
    return expect


def damaged_entry(w: World, tmp: Path) -> list[str]:
    return [str(w.log_path), bag_mapping(middle_damaged_ros1(w.bags["ros1"], tmp / "bad.bag"))]


def bag_entry(messages: Callable[[World], list[Message]], w: World, tmp: Path) -> list[str]:
    return [str(w.log_path), bag_mapping(write_bag(tmp / "entry", "mcap", messages(w)))]


def copied_entry(name: str, w: World, tmp: Path) -> list[str]:
    shutil.copy(w.log_path, tmp / name)
    return [str(w.log_path), str(tmp / name)]


def linked_entry(w: World, tmp: Path) -> list[str]:
    (tmp / "link.txt").symlink_to(w.log_path)
    return [str(w.log_path), str(tmp / "link.txt")]


def folder_entry(w: World, tmp: Path) -> list[str]:
    (tmp / "logs").mkdir()
    return [str(w.log_path), str(tmp / "logs")]


def negative_text_entry(w: World, tmp: Path) -> list[str]:
    """The second drive as a text log whose stamps run from -30 s."""
    lines, k = [], 0
    for line in w.second.read_text().splitlines():
        if line.startswith("time:"):
            line = f"time: {format_time(-30 * 10**9 + k * 40_000_000)} " + line.split(" ", 2)[2]
            k += 1
        lines.append(line)
    (tmp / "neg.txt").write_text("\n".join(lines) + "\n")
    return [str(w.log_path), str(tmp / "neg.txt")]


def _datasets(
    name: str,
    entries: Callable[[World, Path], list[str]],
    codes: tuple[int, ...],
    needles: tuple[str, ...],
    child: bool = False,
) -> tuple[str, Build]:
    return name, partial(datasets_case, entries, codes, needles, child)


def _special(make: Callable[[Path], Path]) -> Callable[[World, Path], list[str]]:
    return lambda w, tmp: [str(w.log_path), str(make(tmp))]


DATASET_CASES = [
    _datasets(
        "an entry that is a FIFO", _special(lambda t: fifo(t / "b.txt")), (2,), ("b.txt", "a FIFO"), True
    ),
    _datasets(
        "an entry that is /dev/zero",
        _special(lambda t: Path("/dev/zero")),
        (2,),
        ("/dev/zero", "a device"),
        True,
    ),
    _datasets(
        "an entry that is /dev/null",
        _special(lambda t: Path("/dev/null")),
        (2,),
        ("/dev/null", "a device"),
        True,
    ),
    _datasets("an entry that is a folder", folder_entry, (2,), ("logs", "a folder")),
    _datasets("a damaged bag entry", damaged_entry, (2,), ("bad.bag", "damaged")),
    _datasets(
        "a bag entry with lost-target quaternions",
        partial(bag_entry, partial(scaled_quaternions, lambda k: 0.0 if k % 10 == 5 else 1.0)),
        (0,),
        (f"30 {NOT_A_ROTATION}",),
    ),
    _datasets(
        "a bag entry with malformed JointStates",
        partial(
            bag_entry, partial(joint_states_replaced, lambda k: (JOINTS, [1.0]) if k % 10 == 0 else None)
        ),
        (0,),
        (f"30 {MALFORMED}",),
    ),
    _datasets(
        "a bag entry with a stamp's nanosec 3e9",
        partial(bag_entry, partial(bad_stamp, "/joint_states", 40)),
        (2,),
        ("entry", "nanosec"),
    ),
    # Its folder drops the leading dot: no user name can take a staging folder's.
    _datasets(
        "a log named like the staging folders", partial(copied_entry, ".nlp_calib_staging.a.txt"), (0,), ()
    ),
    _datasets("the same log through a symbolic link", linked_entry, (2,), ("datasets[1]",)),
    _datasets("a text log with negative stamps", negative_text_entry, (0,), ()),
]

# ----------------------------------------------------------------------------- IPOPT's own files

STRAY_OPT = "output_file mine.txt\nacceptable_tol 1e3\nacceptable_iter 1\nacceptable_obj_change_tol 1e3\n"


def solver_result(out: Path, solver: str) -> dict[str, Any]:
    import json

    return dict(json.loads((out / "result.json").read_text())["solvers"][solver])


def same_as_clean_run(sc: Path, tmp: Path, out: Path, _: Outcome) -> None:
    """The stray file changed nothing: the same IPOPT solution as from a folder without it."""
    clean = tmp / "clean"
    assert run_in_process(run_out(sc, clean), tmp).code == 0
    assert solver_result(out, "ipopt")["params"] == solver_result(clean, "ipopt")["params"]
    assert solver_result(out, "ipopt")["iterations"] > 1


def stray_opt(beside: bool, w: World, tmp: Path) -> Expect:
    cwd = tmp / "work"
    cwd.mkdir()
    (cwd / "ipopt.opt").write_text(STRAY_OPT)
    sc = scenario(cwd if beside else tmp, f"dataset: {w.log_path}")
    sc.write_text(sc.read_text().replace("[gauss_newton]", "[gauss_newton, ipopt]"))
    out = tmp / "out"
    absent = (cwd / "mine.txt", tmp / "mine.txt", REPO / "mine.txt")
    check = partial(same_as_clean_run, sc, tmp, out)
    return Expect(run_out(sc, out), (0,), keep=(cwd / "ipopt.opt",), absent=absent, cwd=cwd, check=check)


def file_option(key: str, value: str, w: World, tmp: Path) -> Expect:
    (tmp / "victim.txt").write_text("mine\n")
    sc = scenario(tmp, f"dataset: {w.log_path}", f"ipopt: {{options: {{{key}: {value}}}}}\n")
    needles = ("case.yaml", f"ipopt: options.{key}: not allowed", "remove it")
    keep = (tmp / "victim.txt", w.log_path)
    return Expect(run_out(sc, tmp / "out"), (2,), needles, keep=keep, absent=(tmp / "out",), cwd=tmp)


def log_as_output_file(w: World, tmp: Path) -> Expect:
    log = tmp / "drive.txt"
    shutil.copy(w.log_path, log)
    sc = scenario(tmp, f"dataset: {log}", f"ipopt: {{options: {{output_file: '{log}'}}}}\n")
    return Expect(run_out(sc, tmp / "out"), (2,), ("options.output_file",), keep=(log,))


def output_file_with_datasets(w: World, tmp: Path) -> Expect:
    extra = "ipopt: {options: {output_file: victim.txt}}\n"
    sc = scenario(tmp, f"datasets: [{w.log_path}, {w.second}]", extra)
    return Expect(
        run_out(sc, tmp / "out"), (2,), ("options.output_file",), cwd=tmp, absent=(tmp / "victim.txt",)
    )


FILE_OPTIONS = [
    ("output_file", "victim.txt"),
    ("output_file", "VICTIM.TXT"),
    ("file_print_level", "12"),
    ("file_append", "yes"),
    ("option_file_name", "victim.txt"),
    ("print_options_documentation", "yes"),
    ("hsllib", "/tmp/libevil.so"),
    ("pardisolib", "./victim.txt"),
]
IPOPT_CASES = [
    ("a stray ipopt.opt in the working folder", partial(stray_opt, False)),
    ("a stray ipopt.opt beside the scenario, in the working folder", partial(stray_opt, True)),
    *((f"ipopt.options.{key}: {value}", partial(file_option, key, value)) for key, value in FILE_OPTIONS),
    ("output_file naming the log itself", log_as_output_file),
    ("output_file in a scenario with datasets", output_file_with_datasets),
]

# ----------------------------------------------------------------------------- YAML 1.1 forms

AMBIGUOUS = "in YAML 1.1 but"


def yaml_refused(line: str, needles: tuple[str, ...], w: World, tmp: Path) -> Expect:
    sc = tmp / "case.yaml"
    sc.write_text(f"dataset: {w.log_path}\nsolvers: [gauss_newton]\n{line}\n")
    return Expect(run_out(sc, tmp / "out"), (2,), ("case.yaml", *needles), absent=(tmp / "out",))


def yaml_read_as(line: str, field: Callable[[Any], object], value: object, w: World, tmp: Path) -> Expect:
    sc = tmp / "case.yaml"
    horizon = "" if line.startswith("residual") else "residual: {horizon: 10}\n"
    sc.write_text(f"dataset: {w.log_path}\nsolvers: [gauss_newton]\n{horizon}{line}\n")

    def check(_: Outcome) -> None:
        assert field(load_scenario(sc)) == value

    return Expect(run_out(sc, tmp / "out"), (0,), check=check)


def robot_yaml_octal(w: World, tmp: Path) -> Expect:
    (tmp / "robot.yaml").write_text("encoder_ranges: {steering: 010000}\n")
    argv = import_bag(w.bags["ros1"], tmp / "out.txt", "--robot", str(tmp / "robot.yaml"))
    return Expect(argv, (2,), ("robot.yaml:1", "010000 is 4096 in YAML 1.1 but 10000"))


def sim_yaml(text: str, needle: str, w: World, tmp: Path) -> Expect:
    (tmp / "sim.yaml").write_text(text)
    argv = ["simulate", "--config", str(tmp / "sim.yaml"), "--out", str(tmp / "s.txt")]
    return Expect(argv, (2,), ("sim.yaml", needle), absent=(tmp / "s.txt",))


YAML_REFUSED = [
    ("residual: {horizon: 010}", ("case.yaml:3", "010 is 8 in YAML 1.1 but 10 in YAML 1.2", "plain decimal")),
    ("residual: {horizon: 1:30}", ("case.yaml:3", "1:30 is 90 in YAML 1.1 but the text '1:30'")),
    ("residual: {horizon: 1_0}", ("case.yaml:3", AMBIGUOUS)),
    ("residual: {horizon: 0b1010}", ("case.yaml:3", AMBIGUOUS)),
    ("residual:\n  horizon: -010", ("case.yaml:4", AMBIGUOUS)),
    ("residual: {horizon: '010'}", ("residual.horizon", "expected an integer, got '010'")),
    ("samples: {start: 010}", (AMBIGUOUS,)),
    ("samples: {start: 0, stop: 2:00}", ("2:00 is 120",)),
    ("robust: {kernel: huber, delta: 1:30.5}", (AMBIGUOUS,)),
    ("robust: {kernel: huber, delta: -.5e1}", ("robust.delta", "-5")),
    ("information: {translation: 1_000.0}", (AMBIGUOUS,)),
    ("alignment: {tracker_lag: 1:05}", (AMBIGUOUS,)),
    ("gauss_newton: {max_iterations: 0100}", (AMBIGUOUS,)),
    ("ipopt: {options: {max_iter: 0100}}", (AMBIGUOUS,)),
    ("ipopt: {max_iter: 1_000}", (AMBIGUOUS,)),
    ("strict: yes", ("strict", "expected true or false, got 'yes'")),
    ("strict: no", ("strict", "expected true or false, got 'no'")),
    ("strict: on", ("strict", "expected true or false, got 'on'")),
    ("strict: Off", ("strict", "expected true or false, got 'Off'")),
    ("strict: NO", ("strict", "expected true or false, got 'NO'")),
    ("on: true", ("case.yaml: on: unknown key",)),
    ("threads: 0x", ("threads", "expected an integer")),
]
YAML_READ = [
    ("residual: {horizon: 0x0A}", lambda sc: sc.objective.residual.horizon, 10),
    ("residual: {horizon: 0o12}", lambda sc: sc.objective.residual.horizon, 10),
    ("residual: {horizon: +10}", lambda sc: sc.objective.residual.horizon, 10),
    ("robust: {kernel: huber, delta: 1e-1}", lambda sc: sc.objective.robust.delta, 0.1),
    ("name: 2024-05-01", lambda sc: sc.name, "2024-05-01"),
    ("name: on", lambda sc: sc.name, "on"),
    ("samples: {start: 0, stop: ~}", lambda sc: sc.log.samples.stop, None),
    (
        "ipopt: {options: {mehrotra_algorithm: yes}}",
        lambda sc: dict(sc.options_for("ipopt").options),
        {"mehrotra_algorithm": "yes"},
    ),
]
YAML_CASES = [
    *((f"scenario {line!r}", partial(yaml_refused, line, needles)) for line, needles in YAML_REFUSED),
    *((f"scenario {line!r}", partial(yaml_read_as, line, get, value)) for line, get, value in YAML_READ),
    ("ROBOT.yaml encoder range 010000", robot_yaml_octal),
    ("simulation records: 0300", partial(sim_yaml, "records: 0300\n", "0300 is 192 in YAML 1.1 but 300")),
    ("simulation seed: 1_000", partial(sim_yaml, "seed: 1_000\n", "1_000 is 1000 in YAML 1.1")),
    ("simulation rate_hz: 1:40", partial(sim_yaml, "rate_hz: 1:40\n", "1:40 is 100 in YAML 1.1")),
]

# ----------------------------------------------------------------------------- aliasing

FIX_ALIAS = "none of the run's inputs"


def ros1_copy(w: World, tmp: Path) -> Path:
    shutil.copy(w.bags["ros1"], tmp / "B.bag")
    return tmp / "B.bag"


def ros2_copy(w: World, tmp: Path, fmt: str = "sqlite3") -> Path:
    shutil.copytree(w.bags[fmt], tmp / "BAG")
    return tmp / "BAG"


def hard_link(w: World, tmp: Path) -> tuple[Path, Path]:
    bag = ros1_copy(w, tmp)
    os.link(bag, tmp / "hard.bag")
    return bag, tmp / "hard.bag"


def soft_link(w: World, tmp: Path) -> tuple[Path, Path]:
    bag = ros1_copy(w, tmp)
    (tmp / "soft.bag").symlink_to(bag)
    return bag, tmp / "soft.bag"


def dotted(w: World, tmp: Path) -> tuple[Path, Path]:
    bag = ros1_copy(w, tmp)
    (tmp / "sub").mkdir()
    return bag, tmp / "sub" / ".." / "B.bag"


def storage_file(suffix: str, out_is_file: bool, w: World, tmp: Path) -> tuple[Path, Path]:
    folder = ros2_copy(w, tmp, "sqlite3" if suffix == ".db3" else "mcap")
    (data,) = folder.glob(f"*{suffix}")
    return (data if out_is_file else folder), data


def import_over(make: Callable[[World, Path], tuple[Path, Path]], needle: str, w: World, tmp: Path) -> Expect:
    bag, out = make(w, tmp)
    keep = (bag.parent if bag.suffix in (".db3", ".mcap") else bag,)
    return Expect(import_bag(bag, out, "--force"), (2,), (str(out), needle, FIX_ALIAS), keep=keep)


def command_over_input(
    command: str, victim: str, extra: tuple[str, ...], what: str, w: World, tmp: Path
) -> Expect:
    """``command --force`` into a folder that holds an input named like one of its outputs."""
    out = tmp / "out"
    out.mkdir()
    if what == "log":
        shutil.copy(w.log_path, out / victim)
        sc = scenario(tmp, f"dataset: {out / victim}")
    else:  # the scenario itself sits in --out under an output's name
        sc = scenario(out, f"dataset: {w.log_path}", name=victim)
    argv = [command, str(sc), "--out", str(out), "--force", *extra]
    return Expect(argv, (2,), (str(out / victim), FIX_ALIAS), keep=(out / victim,))


def simulate_over_config(config: str, out: str, w: World, tmp: Path) -> Expect:
    (tmp / config).write_text("records: 50\n")
    argv = ["simulate", "--config", str(tmp / config), "--out", str(tmp / out), "--force"]
    return Expect(argv, (2,), (config, FIX_ALIAS), keep=(tmp / config,))


def reserved_out(name: str, w: World, tmp: Path) -> Expect:
    sc = scenario(tmp, f"dataset: {w.log_path}")
    needles = (name.split("/")[0], "staging files", "choose another --out")
    return Expect(run_out(sc, tmp / name), (2,), needles, absent=(tmp / name,))


def reserved_scenario_name(w: World, tmp: Path) -> Expect:
    a = scenario(tmp, f"dataset: {w.log_path}", "name: .nlp_calib_staging.a\n", "a.yaml")
    b = scenario(tmp, f"dataset: {w.log_path}", "name: b\n", "b.yaml")
    argv = ["run", str(a), str(b), "--out", str(tmp / "out")]
    return Expect(argv, (2,), (".nlp_calib_staging.a", "staging files"))


def linked_subfolder(again: bool, w: World, tmp: Path) -> Expect:
    """A joint run's subfolder ``a`` replaced by a link to the user's folder; the next run writes
    ``a`` again (refused: not a folder) or no longer (its clean-up must not follow the link)."""
    for name in ("a", "b", "c"):
        shutil.copy(w.log_path, tmp / f"{name}.txt")
    out = tmp / "out"
    first = scenario(tmp, f"datasets: [{tmp / 'a.txt'}, {tmp / 'b.txt'}]", name="first.yaml")
    assert run_in_process(run_out(first, out), tmp).code == 0
    user = tmp / "user"
    user.mkdir()
    (user / "result.json").write_text("my own result\n")
    (user / "report.md").write_text("mine\n")
    shutil.rmtree(out / "a")
    (out / "a").symlink_to(user)
    second = scenario(tmp, f"datasets: {'[a.txt, b.txt]' if again else '[b.txt, c.txt]'}", name="second.yaml")
    codes, needles = ((2,), (str(out / "a"), "not a folder")) if again else ((0,), ())
    return Expect(run_out(second, out), codes, needles, keep=(user,))


def not_annotated(target: Path, _: Outcome) -> None:
    assert not target.exists() or "my annotation" not in target.read_text()


def written(w: World, tmp: Path, command: str, *flags: str) -> tuple[Path, Path]:
    """The first drive's scenario in ``tmp`` and ``tmp / "out"`` holding what ``command`` (with
    ``flags``) wrote over it: written once per world, then copied (the manifest names files
    relative to their folder and their digests, so a copy is what the command would write)."""
    sc = scenario(tmp, f"dataset: {w.log_path}")
    key = (command, *flags)
    if key not in w.written:
        folder = w.folder / f"written-{len(w.written)}"
        folder.mkdir()
        first = [command, str(scenario(folder, f"dataset: {w.log_path}")), "--out", str(folder / "out")]
        assert run_in_process([*first, *flags], folder).code == 0
        w.written[key] = folder / "out"
    shutil.copytree(w.written[key], tmp / "out", symlinks=True)
    return sc, tmp / "out"


def edited_output(
    command: str, name: str, second: tuple[str, ...], force: bool, w: World, tmp: Path
) -> Expect:
    """An output of ``command`` edited by the user, then ``command`` again (``second`` options)."""
    sc, out = written(w, tmp, command, *(["--report"] if name == "report.md" else []))
    target = out / name
    target.write_text(target.read_text() + "\nmy annotation\n")
    argv = [command, str(sc), "--out", str(out), *second, *(["--force"] if force else [])]
    if force:
        return Expect(argv, (0,), check=partial(not_annotated, target))
    needles = (str(target), "changed since nlp_calib wrote it", "move it away", "--force")
    return Expect(argv, (2,), needles, keep=(target,))


def output_replaced_by_link(w: World, tmp: Path) -> Expect:
    sc, out = written(w, tmp, "run")
    (tmp / "elsewhere.yaml").write_text("mine\n")
    (out / "calibration.yaml").unlink()
    (out / "calibration.yaml").symlink_to(tmp / "elsewhere.yaml")
    needles = ("calibration.yaml", "changed since nlp_calib wrote it")
    return Expect(run_out(sc, out), (2,), needles, keep=(tmp / "elsewhere.yaml", out / "calibration.yaml"))


_REPLACES, _INSIDE = "an input of this run", "is inside"
ALIAS_CASES = [
    (
        "import-bag B.bag --out B.bag --force",
        partial(import_over, lambda w, t: (ros1_copy(w, t),) * 2, _REPLACES),
    ),
    ("import-bag --out a hard link of the bag", partial(import_over, hard_link, _REPLACES)),
    ("import-bag --out a symbolic link to the bag", partial(import_over, soft_link, _REPLACES)),
    ("import-bag --out sub/../B.bag", partial(import_over, dotted, _REPLACES)),
    (
        "import-bag BAG --out BAG/metadata.yaml --force",
        partial(import_over, lambda w, t: (ros2_copy(w, t), t / "BAG" / "metadata.yaml"), _REPLACES),
    ),
    (
        "import-bag BAG --out BAG/new.txt",
        partial(import_over, lambda w, t: (ros2_copy(w, t), t / "BAG" / "new.txt"), _INSIDE),
    ),
    (
        "import-bag BAG/x.db3 --out BAG/x.db3 --force",
        partial(import_over, partial(storage_file, ".db3", True), _REPLACES),
    ),
    (
        "import-bag BAG --out BAG/x.mcap --force",
        partial(import_over, partial(storage_file, ".mcap", False), _REPLACES),
    ),
    ("run --force: a log named result.json", partial(command_over_input, "run", "result.json", (), "log")),
    (
        "run --force: a log named calibration.yaml",
        partial(command_over_input, "run", "calibration.yaml", (), "log"),
    ),
    (
        "run --force --report: a log named report.md",
        partial(command_over_input, "run", "report.md", ("--report",), "log"),
    ),
    (
        "run --force: the scenario named calibration.yaml",
        partial(command_over_input, "run", "calibration.yaml", (), "scenario"),
    ),
    (
        "odometry --force: a log named odometry.csv",
        partial(command_over_input, "odometry", "odometry.csv", (), "log"),
    ),
    (
        "validate --force: a log named validation.json",
        partial(command_over_input, "validate", "validation.json", (), "log"),
    ),
    (
        "codegen --force: a log named nlp_calib_residual.c",
        partial(command_over_input, "codegen", "nlp_calib_residual.c", (), "log"),
    ),
    (
        "simulate --config sim.yaml --out sim.yaml --force",
        partial(simulate_over_config, "sim.yaml", "sim.yaml"),
    ),
    ("simulate: the truth file is the config", partial(simulate_over_config, "s.truth.json", "s.txt")),
    ("--out .nlp_calib_staging.x", partial(reserved_out, ".nlp_calib_staging.x")),
    ("--out .nlp_calib_manifest.json", partial(reserved_out, ".nlp_calib_manifest.json")),
    ("--out inside a staging folder", partial(reserved_out, ".nlp_calib_staging.x/out")),
    ("a scenario named .nlp_calib_staging.a among two", reserved_scenario_name),
    ("a joint run's subfolder replaced by a link, then stale", partial(linked_subfolder, False)),
    ("a joint run's subfolder replaced by a link, then written", partial(linked_subfolder, True)),
    (
        "an annotated report.md, run again with --report",
        partial(edited_output, "run", "report.md", ("--report",), False),
    ),
    ("an annotated report.md, run again without it", partial(edited_output, "run", "report.md", (), False)),
    ("an annotated report.md, --force", partial(edited_output, "run", "report.md", ("--report",), True)),
    ("an edited result.json", partial(edited_output, "run", "result.json", (), False)),
    ("an edited calibration.yaml", partial(edited_output, "run", "calibration.yaml", (), False)),
    ("an edited example.c", partial(edited_output, "codegen", "example.c", (), False)),
    ("an edited example.c, --force", partial(edited_output, "codegen", "example.c", (), True)),
    ("an output replaced by a link to the user's file", output_replaced_by_link),
]

# ----------------------------------------------------------------------------- the corpus

CORPUS: list[Case] = [
    Case(cls, name, build)
    for cls, cases in [
        ("bags", [*KIND_CASES, *DAMAGE_CASES]),
        ("values", VALUE_CASES),
        ("datasets", DATASET_CASES),
        ("ipopt", IPOPT_CASES),
        ("yaml", YAML_CASES),
        ("aliasing", ALIAS_CASES),
    ]
    for name, build in cases
]
