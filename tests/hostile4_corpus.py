"""The round-four hostile corpus (issue 34): cases and what they share.

Classes: ``code`` (text from inputs reaching generated C; a compile cache others can write),
``verdicts`` (recordings that fit well but are wrong: a mirrored joint, quaternions in another
order, joints in degrees, late stamps, gaps; each must end in a refusal or a verdict that is not
GOOD naming the cause, or in a correct result), ``urdf`` (``--urdf`` descriptions a pattern
misreads), ``lost`` (results or messages dropped without a word), ``check`` (a tampered or foreign
calibration), ``messages`` (what the user is told) and ``memory`` (what reading a large file
costs). The harness is round three's (:mod:`hostile3_corpus`): a case builds its inputs in a fresh
folder and says what it runs and what must hold afterwards; :func:`hostile3_corpus.judge` applies
the rules every case shares.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from conftest import REPO
from hostile3_corpus import DEADLINE_S, Outcome, run_in_process
from hostile3_corpus import Expect as Expect3
from hostile3_corpus import judge as judge3

from nlp_calib.codegen import compiler
from nlp_calib.logs import Log
from nlp_calib.logs.text_tables import seconds

CLASSES = ("code", "verdicts", "urdf", "lost", "check", "messages", "memory")
CAMERA_ENCODERS = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
#: Exit codes of a run refused before any fit: the data (2), the pre-flight's stops (4, 5).
REFUSED = (2, 4, 5)
HANDOFF = ("calibration.yaml", "ros2_control.yaml", "robot.urdf", "sensor_mount.urdf.xml")


@dataclass
class Expect(Expect3):
    """Round three's :class:`~hostile3_corpus.Expect`, and ``env``: variables a child runs with;
    ``answers``: exit codes that are an answer, not an error (``check``'s DRIFTED and CANNOT TELL)."""

    env: dict[str, str] = field(default_factory=dict)
    answers: tuple[int, ...] = (0,)


def judge(expect: Expect, outcome: Outcome) -> None:
    """Round three's rules, an exit code in ``expect.answers`` read as an answer (its needles in the
    output), any other as an error (one line holding the needles)."""
    if outcome.code in expect.answers and outcome.code != 0:
        outcome = Outcome(0, outcome.out, outcome.err)
        expect = dataclasses.replace(expect, codes=(0,))
    judge3(expect, outcome)


#: A child that runs the command and writes its peak resident memory (kB) to ``$RSS_FILE``.
#: (VmHWM: ru_maxrss would carry over the forking parent's peak across exec on Linux.)
MEASURED = (
    "import os, re, sys\n"
    "from nlp_calib.cli import main\n"
    "code = main(sys.argv[1:])\n"
    "peak = re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read())[1]\n"
    "open(os.environ['RSS_FILE'], 'w').write(peak)\n"
    "sys.exit(code)\n"
)


def run_child(argv: Sequence[str], cwd: Path | None, env: dict[str, str]) -> Outcome:
    """The command in a child with a deadline and ``env`` added to this process's environment
    (with ``RSS_FILE`` in it: the child writes its peak resident memory there)."""
    full = dict(os.environ, PYTHONWARNINGS="ignore", PYTHONPATH=str(REPO), **env)
    command = [sys.executable, *(("-c", MEASURED) if "RSS_FILE" in env else ("-m", "nlp_calib")), *argv]
    try:
        proc = subprocess.run(
            command, cwd=cwd or REPO, env=full, capture_output=True, text=True, timeout=DEADLINE_S
        )
    except subprocess.TimeoutExpired:
        raise AssertionError(f"hang: nlp-calib {' '.join(argv)} did not end within {DEADLINE_S} s") from None
    return Outcome(proc.returncode, proc.stdout, proc.stderr)


@dataclass(frozen=True)
class World:
    """The shared inputs: a tricycle and a differential drive as text logs, a camera recording
    (TUM poses, CSV joints in radians, its truth) and a warm compile cache."""

    folder: Path
    tricycle: Path
    diff_drive: Path
    tricycle_log: Log
    camera: Path
    camera_truth: dict[str, float]
    cache: Path
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def camera_joints(self) -> Path:
        return self.camera.with_suffix(".joints.csv")


Build = Callable[[World, Path], Expect]


@dataclass(frozen=True)
class Case:
    cls: str
    name: str
    build: Build


def has_compiler() -> bool:
    return compiler.find_compiler() is not None


# ----------------------------------------------------------------------------- shared helpers


def quoted(path: Path | str) -> str:
    """A path as a YAML scalar (JSON's double-quoted strings are YAML)."""
    return json.dumps(str(path))


def text_scenario(
    folder: Path, log: Path, model: str = "tricycle", extra: str = "", name: str = "case.yaml"
) -> Path:
    path = folder / name
    path.write_text(
        f"dataset: {quoted(log)}\nmodel: {model}\nresidual: {{horizon: 10}}\nsolvers: [gauss_newton]\n"
        f"validation: {{blocks: 0}}\n{extra}"
    )
    return path


def camera_scenario(
    folder: Path,
    tum: Path,
    joints: Path,
    extra: str = "",
    encoders: dict[str, str] | None = None,
    name: str = "cam.yaml",
    block: str = "",
) -> Path:
    """A scenario of the camera demo's settings on ``tum`` and ``joints``."""
    enc = ", ".join(f"{k}: {v}" for k, v in (encoders or CAMERA_ENCODERS).items())
    path = folder / name
    path.write_text(
        "model: diff_drive\nsensor: 3d\n"
        f"dataset: {{poses: {quoted(tum)}, joints: {quoted(joints)}, encoders: {{{enc}}}{block}}}\n"
        "initial_guess: auto\nknown: {sensor_z: 0.30}\n"
        "alignment: {tracker_lag: auto, search: [-0.05, 0.05], step: 0.005}\n"
        "residual: {horizon_s: 0.25}\ninformation: {translation: 1.0e+6, rotation: 3.0e+5}\n"
        "robust: {kernel: huber, delta: 10.0}\nsolvers: [gauss_newton]\nvalidation: {blocks: 0}\n" + extra
    )
    return path


def c_run(out: Path, cwd: Path, flags: Sequence[str] = ()) -> subprocess.CompletedProcess[str]:
    """Build ``example.c`` of a C export in ``out`` as the docs say and run it in ``cwd``."""
    cc = compiler.find_compiler()
    assert cc is not None
    exe = out / "example"
    build = subprocess.run(
        [cc, "-O0", *flags, "-o", str(exe), "example.c", "nlp_calib_residual.c", "-lm"],
        cwd=out,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert build.returncode == 0, build.stderr[-2000:]
    return subprocess.run([str(exe)], cwd=cwd, capture_output=True, timeout=60, text=True, errors="replace")


# ----------------------------------------------------------------------------- code execution

#: What a name tries to make of generated C: a command, a printf format, the end of a comment.
PWN = 'x\n");system("touch PWNED");printf("x'


def example_runs_clean(out: Path, tmp: Path, shows: str, flags: Sequence[str], _: Outcome) -> None:
    proc = c_run(out, tmp, flags)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-500:])
    assert not (tmp / "PWNED").exists() and not (out / "PWNED").exists(), "the name ran as code"
    window = proc.stdout.split("\nparameters: ")[0]
    assert window.startswith("window: ") and shows in window, proc.stdout[:500]


def codegen_named(name: str, shows: str, flags: tuple[str, ...], w: World, tmp: Path) -> Expect:
    """``codegen`` on the tricycle's log copied under ``name``; example.c built and run."""
    log = tmp / name
    shutil.copy(w.tricycle, log)
    sc = text_scenario(tmp, tmp / "drive.txt")
    out = tmp / "c"
    argv = ["codegen", str(sc), "--out", str(out), "--data", str(log)]
    return Expect(argv, (0,), cwd=tmp, check=partial(example_runs_clean, out, tmp, shows, flags))


def codegen_scenario_named(scenario_name: str, w: World, tmp: Path) -> Expect:
    """A scenario ``name:`` that tries to end the banner's comment: every generated file compiles
    (with ``#error`` in the name, it would not if the comment ended)."""
    sc = text_scenario(tmp, w.tricycle, extra=f"name: {quoted(scenario_name)}\n")
    out = tmp / "c"
    check = partial(example_runs_clean, out, tmp, "drive", ())
    return Expect(["codegen", str(sc), "--out", str(out)], (0,), cwd=tmp, check=check)


def codegen_scenario_refused(scenario_name: str, w: World, tmp: Path) -> Expect:
    """A scenario ``name:`` holding a line break: refused on load, naming the file's line; no C."""
    sc = text_scenario(tmp, w.tricycle, extra=f"name: {quoted(scenario_name)}\n")
    out = tmp / "c"
    needles = (f"{sc}:6:", "line break or control character")
    return Expect(["codegen", str(sc), "--out", str(out)], (2,), needles, cwd=tmp, absent=(out,))


def codegen_camera_named(stem: str, w: World, tmp: Path) -> Expect:
    tum = tmp / f"{stem}.tum"
    shutil.copy(w.camera, tum)
    shutil.copy(w.camera_joints, tmp / f"{stem}.joints.csv")
    sc = camera_scenario(tmp, tum, tmp / f"{stem}.joints.csv")
    out = tmp / "c"
    check = partial(example_runs_clean, out, tmp, f"{stem}.tum", ())
    return Expect(["codegen", str(sc), "--out", str(out)], (0,), cwd=tmp, check=check)


def undecodable_name(w: World, tmp: Path) -> Expect:
    raw = os.fsdecode(b"drive\xff\xfe%n.txt")
    return codegen_named(raw, "drive", (), w, tmp)


CODEGEN_CASES = [
    (
        "codegen: a log named to run a command (the issue's case)",
        partial(codegen_named, PWN + ".txt", PWN, ()),
    ),
    (
        "codegen: a log named with printf formats",
        partial(codegen_named, "%s%n%s%n%p.txt", "%s%n%s%n%p.txt", ()),
    ),
    ("codegen: a log name ending in a backslash", partial(codegen_named, "drive\\", "drive\\", ())),
    (
        "codegen: trigraphs in the log name, built with -trigraphs",
        partial(codegen_named, "x??=??-??!.txt", "x??=??-??!.txt", ("-trigraphs",)),
    ),
    (
        "codegen: a log name with a tab, quotes and non-ASCII",
        partial(codegen_named, "a\t'b\"ä€.txt", "a\t'b\"ä€.txt", ()),
    ),
    ("codegen: a log name that is not UTF-8", undecodable_name),
    (
        # Round five (issue 40): a name holding a line break is refused on load, with its line.
        "codegen: a scenario name with lines of C",
        partial(codegen_scenario_refused, "x *\n#error injected\n* x"),
    ),
    (
        "codegen: a scenario name with trigraphs and a tab",
        partial(codegen_scenario_named, "x ??)\t??= #error"),
    ),
    (
        "codegen: a camera's TUM file named to run a command",
        partial(codegen_camera_named, 'cam");system("touch PWNED");printf("'),
    ),
    ("codegen: a camera's TUM file named with printf formats", partial(codegen_camera_named, "cam%n%s")),
]


# ----------------------------------------------------------------------------- the compile cache

_EVIL_C = (
    '#include <fcntl.h>\n__attribute__((constructor)) static void evil(void) { creat("PWNED", 0644); }\n'
)


def _plant(cache: Path, tmp: Path) -> list[Path]:
    """Every entry of ``cache`` replaced by a shared object whose constructor creates ``PWNED`` in
    the working folder, sealed with the entry's checksum (which anyone can compute)."""
    cc = compiler.find_compiler()
    assert cc is not None
    src = tmp / "evil.c"
    src.write_text(_EVIL_C)
    subprocess.run([cc, "-shared", "-fPIC", "-o", str(tmp / "evil.so"), str(src)], check=True, timeout=120)
    body = (tmp / "evil.so").read_bytes()
    entries = sorted(cache.glob("*.so"))
    for entry in entries:
        key = entry.stem.rsplit("-", 1)[1]
        entry.write_bytes(body + compiler._seal(key, body))
    return entries


def not_run(tmp: Path, _: Outcome) -> None:
    assert not (tmp / "PWNED").exists(), "a planted shared object ran"


def cache_case(arrange: Callable[[Path, Path], Path], warns: tuple[str, ...], w: World, tmp: Path) -> Expect:
    """A run of the warm cache's scenario with a copy of that cache, planted, then ``arrange``d:
    nothing planted runs; the run succeeds and warns naming the folder."""
    cache = tmp / "cache"
    shutil.copytree(w.cache, cache)
    _plant(cache, tmp)
    folder = arrange(cache, tmp)
    env = {"NLP_CALIB_CACHE": str(folder)}
    argv = ["run", str(w.extra["cache_scenario"]), "--out", str(tmp / "out")]
    return Expect(argv, (0,), (*warns,), cwd=tmp, child=True, check=partial(not_run, tmp), env=env)


def _chmod(mode: int, cache: Path, tmp: Path) -> Path:
    cache.chmod(mode)
    return cache


def _entries_chmod(mode: int, cache: Path, tmp: Path) -> Path:
    cache.chmod(0o755)
    for entry in cache.glob("*.so"):
        entry.chmod(mode)
    return cache


def _entries_chown(cache: Path, tmp: Path) -> Path:
    cache.chmod(0o755)
    for entry in cache.glob("*.so"):
        os.chown(entry, 65534, 65534)
        entry.chmod(0o644)
    return cache


def _folder_chown(cache: Path, tmp: Path) -> Path:
    cache.chmod(0o755)
    os.chown(cache, 65534, 65534)
    return cache


def _linked(cache: Path, tmp: Path) -> Path:
    cache.chmod(0o777)
    (tmp / "link").symlink_to(cache)
    return tmp / "link"


def _entry_links(cache: Path, tmp: Path) -> Path:
    """Entries replaced by links to planted files elsewhere (a folder the user owns)."""
    cache.chmod(0o755)
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir()
    for entry in cache.glob("*.so"):
        shutil.move(entry, elsewhere / entry.name)
        entry.symlink_to(elsewhere / entry.name)
    return cache


def _sticky(cache: Path, tmp: Path) -> Path:
    cache.chmod(0o1777)
    return cache


FOLDER_WARNS = ("compile cache", "not used", "NLP_CALIB_CACHE")
ENTRY_WARNS = ("compile cache", "never loaded")
CACHE_CASES = [
    (
        "cache: a planted entry in a folder writable by all",
        partial(cache_case, partial(_chmod, 0o777), ("writable by", *FOLDER_WARNS)),
    ),
    (
        "cache: a planted entry in a group-writable folder",
        partial(cache_case, partial(_chmod, 0o775), ("its group", *FOLDER_WARNS)),
    ),
    ("cache: a planted entry in a sticky folder like /tmp", partial(cache_case, _sticky, FOLDER_WARNS)),
    ("cache: a planted entry through a link to an open folder", partial(cache_case, _linked, FOLDER_WARNS)),
    (
        "cache: planted entries writable by others",
        partial(cache_case, partial(_entries_chmod, 0o666), ENTRY_WARNS),
    ),
    (
        "cache: planted entries writable by the group",
        partial(cache_case, partial(_entries_chmod, 0o775), ENTRY_WARNS),
    ),
    (
        "cache: planted entries that are links",
        partial(cache_case, _entry_links, ("compile cache", "not a regular file")),
    ),
]
if os.geteuid() == 0:  # only root can give a file to another user
    CACHE_CASES += [
        (
            "cache: planted entries owned by another user",
            partial(cache_case, _entries_chown, ("owned by user id 65534", *ENTRY_WARNS)),
        ),
        (
            "cache: a planted folder owned by another user",
            partial(cache_case, _folder_chown, ("owned by user id 65534", *FOLDER_WARNS)),
        ),
    ]


# ----------------------------------------------------------------------------- wrong but well-fitting


def _tum_rows(path: Path) -> list[list[str]]:
    return [ln.split() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]


def _csv_rows(path: Path) -> tuple[str, list[list[str]]]:
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    return lines[0], [ln.split(",") for ln in lines[1:]]


def _later(stamp: str, seconds: float) -> str:
    return str(Decimal(stamp) + Decimal(repr(seconds)))


def recording(
    w: World,
    tmp: Path,
    tum: Callable[[list[list[str]]], list[list[str]]] = lambda r: r,
    joints: Callable[[list[list[str]]], list[list[str]]] = lambda r: r,
) -> tuple[Path, Path]:
    """The camera recording, its TUM rows and joint rows edited, written into ``tmp``."""
    head, rows = _csv_rows(w.camera_joints)
    (tmp / "cam.tum").write_text("".join(" ".join(r) + "\n" for r in tum(_tum_rows(w.camera))))
    (tmp / "cam.joints.csv").write_text(head + "\n" + "".join(",".join(r) + "\n" for r in joints(rows)))
    return tmp / "cam.tum", tmp / "cam.joints.csv"


def _column(j: int, f: Callable[[float], float]) -> Callable[[list[list[str]]], list[list[str]]]:
    def edit(rows: list[list[str]]) -> list[list[str]]:
        return [[*r[:j], repr(f(float(r[j]))), *r[j + 1 :]] for r in rows]

    return edit


def _both(f: Callable[[float], float]) -> Callable[[list[list[str]]], list[list[str]]]:
    return lambda rows: _column(2, f)(_column(1, f)(rows))


def _w_first(rows: list[list[str]]) -> list[list[str]]:
    return [[*r[:4], r[7], *r[4:7]] for r in rows]


def _cut(t0: float, t1: float) -> Callable[[list[list[str]]], list[list[str]]]:
    def edit(rows: list[list[str]]) -> list[list[str]]:
        first = float(rows[0][0])
        return [r for r in rows if not t0 <= float(r[0]) - first < t1]

    return edit


def _shifted(seconds: float) -> Callable[[list[list[str]]], list[list[str]]]:
    return lambda rows: [[_later(r[0], seconds), *r[1:]] for r in rows]


def not_good(out: Path, outcome: Outcome) -> None:
    """Refused (by the reading or the pre-flight), or a verdict other than GOOD with no hand-off file."""
    if outcome.code in REFUSED:
        return
    doc = json.loads((out / "result.json").read_text())
    assert doc["verdict"]["level"] != "good", doc["verdict"]
    written = [n for n in HANDOFF if (out / n).exists()]
    assert not written, f"hand-off written for a wrong calibration: {written}"


def right_answer(out: Path, truth: dict[str, float], _: Outcome) -> None:
    """Every parameter within 4σ of the truth (and the σ believable: under 1 cm, 1 %, 0.01 rad)."""
    doc = json.loads((out / "result.json").read_text())
    g = doc["solvers"]["gauss_newton"]
    truth = {"tracker_lag": 0.0, **truth}  # the corpus' logs are simulated without latency
    off = {n: (g["params"][n] - truth[n]) / g["std"][n] for n in g["params"] if g["std"][n]}
    assert all(abs(z) < 4.0 for z in off.values()), off


def camera_case(edit: dict[str, Any], outcome: str, needles: tuple[str, ...], w: World, tmp: Path) -> Expect:
    """The camera recording with ``edit`` (TUM rows, joint rows, encoders), run: ``outcome`` is
    ``wrong`` (refused or not GOOD, naming ``needles``) or ``right`` (within 4σ, saying ``needles``)."""
    tum, joints = recording(w, tmp, edit.get("tum", lambda r: r), edit.get("joints", lambda r: r))
    sc = camera_scenario(tmp, tum, joints, encoders=edit.get("encoders"), extra=edit.get("extra", ""))
    out = tmp / "out"
    argv = ["run", str(sc), "--out", str(out)]
    if outcome == "wrong":
        return Expect(argv, (0, 1, *REFUSED), needles, check=partial(not_good, out), answers=(0, 1))
    return Expect(argv, (0,), needles, check=partial(right_answer, out, w.camera_truth))


def clock_case(edit: dict[str, Any], shift: float, w: World, tmp: Path) -> Expect:
    """Streams stamped seconds apart: refused, saying the shift to add to clock_offset (to 0.1 s:
    the tracker lag refines what remains; the recording's images are stamped 10 ms late)."""
    expect = camera_case(
        edit, "wrong", ("clock_offset", "late, which pairs poses with the wrong joints"), w, tmp
    )
    expect.codes, expect.answers = (2,), (0,)

    def said(outcome: Outcome) -> None:
        found = re.search(r"add ([+-][0-9.]+) s to clock_offset", outcome.err)
        assert found is not None and abs(float(found[1]) - shift) <= 0.1, outcome.err

    expect.check = said
    return expect


def text_case(
    model: str,
    edit: Callable[[list[str]], list[str]],
    outcome: str,
    needles: tuple[str, ...],
    w: World,
    tmp: Path,
    extra: str = "",
) -> Expect:
    """A simulated text log (counts) with its record lines edited by ``edit``."""
    src = w.tricycle if model == "tricycle" else w.diff_drive
    lines = src.read_text().splitlines()
    head = [ln for ln in lines if ln.startswith("#")]
    body = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
    log = tmp / "drive.txt"
    log.write_text("\n".join(head + edit(body)) + "\n")
    sc = text_scenario(tmp, log, model=model, extra=extra)
    out = tmp / "out"
    argv = ["run", str(sc), "--out", str(out)]
    if outcome == "wrong":
        return Expect(argv, (0, 1, *REFUSED), needles, check=partial(not_good, out), answers=(0, 1))
    truth = json.loads(src.with_suffix(".truth.json").read_text())["params"]
    return Expect(argv, (0,), needles, check=partial(right_answer, out, truth))


def _ticks(j: int, f: Callable[[int], int]) -> Callable[[list[str]], list[str]]:
    """Record lines with encoder column ``j`` mapped by ``f``."""

    def edit(body: list[str]) -> list[str]:
        out = []
        for ln in body:
            parts = ln.split()
            at = parts.index("ticks:") + 1 + j
            parts[at] = str(f(int(parts[at])))
            out.append(" ".join(parts))
        return out

    return edit


def _drop_seconds(t0: float, t1: float) -> Callable[[list[str]], list[str]]:
    def edit(body: list[str]) -> list[str]:
        first = float(body[0].split()[1])
        return [ln for ln in body if not t0 <= float(ln.split()[1]) - first < t1]

    return edit


REVERSED = lambda t: (-t) % (1 << 32)  # noqa: E731 (a counter counting backwards)
DEG = float(np.degrees(1.0))
VERDICT_CASES = [
    ("the camera recording as it is (a control)", partial(camera_case, {}, "right", ())),
    (
        "a right wheel joint with the opposite sign (the issue's case)",
        partial(camera_case, {"joints": _column(2, lambda v: -v)}, "wrong", ("backwards",)),
    ),
    (
        "a left wheel joint with the opposite sign",
        partial(camera_case, {"joints": _column(1, lambda v: -v)}, "wrong", ("backwards",)),
    ),
    (
        "both wheel joints with the opposite sign (the issue's case)",
        partial(camera_case, {"joints": _both(lambda v: -v)}, "wrong", ("upside down",)),
    ),
    (
        "the left and right joints swapped (the issue's case)",
        partial(
            camera_case,
            {"encoders": {"left_wheel": "right_wheel_joint", "right_wheel": "left_wheel_joint"}},
            "wrong",
            ("upside down",),
        ),
    ),
    (
        "joints logged in degrees (the issue's case)",
        partial(camera_case, {"joints": _both(lambda v: v * DEG)}, "wrong", ("degrees",)),
    ),
    (
        "joints logged in degrees, the right one reversed",
        partial(
            camera_case,
            {"joints": lambda r: _column(2, lambda v: -v)(_both(lambda v: v * DEG)(r))},
            "wrong",
            ("backwards",),
        ),
    ),
    (
        "TUM quaternions written w x y z (the issue's case)",
        partial(camera_case, {"tum": _w_first}, "wrong", ("cam.tum", "qw qx qy qz", "w to the end")),
    ),
    (
        "the camera losing tracking for 5 s (the issue's case)",
        partial(camera_case, {"tum": _cut(12.0, 17.0)}, "right", ("gap",)),
    ),
    (
        "the joints missing for 5 s (the issue's case)",
        partial(camera_case, {"joints": _cut(12.0, 17.0)}, "right", ("gap",)),
    ),
    (
        "the camera losing tracking twice for 2 s",
        partial(camera_case, {"tum": lambda r: _cut(20.0, 22.0)(_cut(6.0, 8.0)(r))}, "right", ("2 gap(s)",)),
    ),
    ("camera stamps 15 s late (the issue's case)", partial(clock_case, {"tum": _shifted(15.0)}, 15.01)),
    ("camera stamps 6 s early", partial(clock_case, {"tum": _shifted(-6.0)}, -5.99)),
    ("joint stamps 10 s late", partial(clock_case, {"joints": _shifted(10.0)}, -9.99)),
    (
        "a diff drive's right counter counting backwards",
        partial(text_case, "diff_drive", _ticks(1, REVERSED), "wrong", ("backwards",)),
    ),
    (
        "a diff drive's left and right counters swapped, started from the data",
        partial(
            text_case,
            "diff_drive",
            lambda b: _swap_ticks(b),
            "wrong",
            ("negative", "swapped"),
            extra="initial_guess: auto\n",
        ),
    ),
    (
        "a tricycle log with 2 s of records missing",
        partial(text_case, "tricycle", _drop_seconds(4.0, 6.0), "right", ("gap",)),
    ),
]


def other_camera(
    which: str, edit: dict[str, Any], outcome: str, needles: tuple[str, ...], w: World, tmp: Path
) -> Expect:
    """Another simulated camera of the world (``tricycle``: on a tricycle; ``upside_down``: a
    camera whose image is upside down), edited and run as :func:`camera_case` runs the first."""
    tum_src, truth, extra = w.extra[which]
    joints_src = tum_src.with_suffix(".joints.csv")
    head, rows = _csv_rows(joints_src)
    (tmp / "cam.tum").write_text(
        "".join(" ".join(r) + "\n" for r in edit.get("tum", lambda r: r)(_tum_rows(tum_src)))
    )
    (tmp / "cam.joints.csv").write_text(
        head + "\n" + "".join(",".join(r) + "\n" for r in edit.get("joints", lambda r: r)(rows))
    )
    model = "tricycle" if which == "tricycle" else "diff_drive"
    encoders = (
        {"steering": "steering_joint", "traction_wheel": "traction_wheel_joint"}
        if model == "tricycle"
        else None
    )
    sc = camera_scenario(
        tmp, tmp / "cam.tum", tmp / "cam.joints.csv", extra=extra + edit.get("extra", ""), encoders=encoders
    )
    text = sc.read_text().replace("model: diff_drive", f"model: {model}")
    sc.write_text(
        text.replace("initial_guess: auto\n", "", 1) if "initial_guess" in edit.get("extra", "") else text
    )
    out = tmp / "out"
    argv = ["run", str(sc), "--out", str(out)]
    if outcome == "wrong":
        return Expect(argv, (0, 1, *REFUSED), needles, check=partial(not_good, out), answers=(0, 1))
    return Expect(argv, (0,), needles, check=partial(right_answer, out, truth))


def optitrack_w_first(w: World, tmp: Path) -> Expect:
    """A real run (OptiOdom's differential drive under OptiTrack) with its TUM written w first."""
    run = REAL_RUN.with_suffix(".tum")
    rows = _tum_rows(run)
    (tmp / "run.tum").write_text("".join(" ".join(r) + "\n" for r in _w_first(rows)))
    shutil.copy(REAL_RUN.with_suffix(".csv"), tmp / "run.csv")
    sc = camera_scenario(tmp, tmp / "run.tum", tmp / "run.csv").read_text()
    sc = sc.replace("sensor: 3d\n", "").replace("known: {sensor_z: 0.30}\n", "")
    (tmp / "cam.yaml").write_text(sc)
    needles = ("run.tum", "qw qx qy qz", "w to the end")
    return Expect(["run", str(tmp / "cam.yaml"), "--out", str(tmp / "out")], (2,), needles)


REAL_RUN = Path("/work/shared/data/real4/optiodom/diff/circular/231220200134/231220200134_run-01.csv")
OTHER_CAMERAS = [
    (
        "a tricycle's steering joint logged in degrees",
        partial(
            other_camera,
            "tricycle",
            {"joints": _column(2, lambda v: v * DEG)},
            "wrong",
            ("steering", "degrees"),
        ),
    ),
    (
        "a tricycle's joints logged in degrees",
        partial(other_camera, "tricycle", {"joints": _both(lambda v: v * DEG)}, "wrong", ("degrees",)),
    ),
    ("a tricycle camera as it is (a control)", partial(other_camera, "tricycle", {}, "right", ())),
    (
        "a camera mounted upside down, its mount given (a control)",
        partial(
            other_camera,
            "upside_down",
            {
                "extra": "initial_guess: {sensor_roll: 1.05, sensor_pitch: -0.05, sensor_yaw: -1.57, "
                "sensor_x: 0.25, sensor_y: 0.06, sensor_z: 0.3, left_wheel_radius: 0.1, "
                "right_wheel_radius: 0.1, wheel_separation: 0.45}\n"
            },
            "right",
            (),
        ),
    ),
    (
        "a camera mounted upside down, nothing said of it",
        partial(other_camera, "upside_down", {}, "wrong", ("upside down", "initial guess")),
    ),
]
if REAL_RUN.is_file():
    OTHER_CAMERAS.append(("a real OptiTrack TUM written w x y z", optitrack_w_first))


def _swap_ticks(body: list[str]) -> list[str]:
    out = []
    for ln in body:
        parts = ln.split()
        at = parts.index("ticks:") + 1
        parts[at], parts[at + 1] = parts[at + 1], parts[at]
        out.append(" ".join(parts))
    return out


# ----------------------------------------------------------------------------- --urdf

ROBOT = """<?xml version="1.0"?>
<robot name="trike">
  <link name="base_link"/>
  <link name="chassis"/>
  <link name="laser"/>
  <link name="front_wheel"/>
  <joint name="base_to_chassis" type="fixed">
    <parent link="base_link"/>
    <child link="chassis"/>
    <origin xyz="0.2 0 0.1" rpy="0 0 0.1"/>
  </joint>
  <joint name="chassis_to_laser" type="fixed">
    <parent link="chassis"/><child link="laser"/>
    ORIGIN
  </joint>
  <joint name="steer" type="revolute">
    <parent link="base_link"/><child link="front_wheel"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>
  </joint>
</robot>
"""
LASER_ORIGIN = '<origin rpy="0.02 -0.05 0" xyz="1.2 0.05 0.4" />'


def urdf_run(w: World, tmp: Path, urdf: Path, link: str = "laser") -> list[str]:
    sc = text_scenario(tmp, w.tricycle)
    return ["run", str(sc), "--out", str(tmp / "out"), "--urdf", str(urdf), "--sensor-link", link]


def urdf_refused(text: bytes | str, needles: tuple[str, ...], w: World, tmp: Path) -> Expect:
    path = tmp / "robot.urdf"
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return Expect(urdf_run(w, tmp, path), (2,), ("robot.urdf", *needles), keep=(path,), absent=(tmp / "out",))


def _laser_in_base(robot: Path) -> np.ndarray:
    from urdf_parser_py.urdf import URDF

    model = URDF.from_xml_string(robot.read_bytes())
    joints = {j.child: j for j in model.joints}
    T, link = np.eye(4), "laser"
    while link != "base_link":
        j = joints[link]
        xyz, rpy = (j.origin.xyz, j.origin.rpy) if j.origin is not None else ([0, 0, 0], [0, 0, 0])
        from nlp_calib.outputs.urdf import _rotation

        A = np.eye(4)
        A[:3, :3], A[:3, 3] = _rotation(np.array(rpy, dtype=float)), xyz
        T, link = A @ T, j.parent
    return T


def re_posed(before: bytes, marker: bytes, tmp: Path, _: Outcome) -> None:
    """robot.urdf: the laser at the calibrated x, y, yaw as a URDF parser reads it, its height kept,
    and every byte outside the laser joint's origin tag the user's."""
    robot = tmp / "out" / "robot.urdf"
    after = robot.read_bytes()
    at = before.index(marker)
    end = before.index(b">", at + len(marker) - 1) + 1
    assert after.startswith(before[:at]) and after.endswith(before[end:]), after.decode(errors="replace")
    p = json.loads((tmp / "out" / "result.json").read_text())["solvers"]["gauss_newton"]["params"]
    T = _laser_in_base(robot)
    yaw = float(np.arctan2(T[1, 0], T[0, 0]))
    assert np.allclose([T[0, 3], T[1, 3], yaw], [p["sensor_x"], p["sensor_y"], p["sensor_theta"]], atol=1e-9)
    assert abs(T[2, 3] - 0.5) < 1e-9  # 0.1 of the chassis + 0.4 of the laser, kept


def urdf_edited(text: bytes, marker: bytes, w: World, tmp: Path) -> Expect:
    path = tmp / "robot.urdf"
    path.write_bytes(text)
    return Expect(urdf_run(w, tmp, path), (0,), keep=(path,), check=partial(re_posed, text, marker, tmp))


def robot(origin: str = LASER_ORIGIN, head: str = '<?xml version="1.0"?>\n', **replace: str) -> str:
    text = ROBOT.replace('<?xml version="1.0"?>\n', head).replace("ORIGIN", origin)
    for old, new in replace.items():
        text = text.replace(old.replace("_", " "), new)
    return text


ENTITY_JOINT = robot(
    head='<?xml version="1.0"?>\n<!DOCTYPE robot [\n<!ENTITY laser_joint \'<joint name="chassis_to_laser" '
    'type="fixed"><parent link="chassis"/><child link="laser"/><origin xyz="1.2 0.05 0.4" rpy="0 0 0"/>'
    "</joint>'>\n]>\n"
).replace(
    '<joint name="chassis_to_laser" type="fixed">\n    <parent link="chassis"/><child link="laser"/>\n    '
    f"{LASER_ORIGIN}\n  </joint>",
    "&laser_joint;",
)
TWO_ORIGINS = robot(origin=f'{LASER_ORIGIN}\n    <origin xyz="0 0 0" rpy="0 0 0"/>')
TWO_PARENTS = robot().replace(
    '<parent link="chassis"/>', '<parent link="chassis"/><parent link="base_link"/>'
)
TWO_CHILDREN = robot().replace('<child link="laser"/>', '<child link="laser"/><child link="front_wheel"/>')
SECOND_JOINT = robot().replace(
    "</robot>",
    '  <joint name="laser_again" type="fixed"><parent link="base_link"/><child link="laser"/>'
    '<origin xyz="0 0 0"/></joint>\n</robot>',
)
SAME_NAME = robot().replace('name="steer"', 'name="chassis_to_laser"')
UNDECLARED = robot().replace('  <link name="front_wheel"/>\n', "")
XACRO = robot().replace(
    '<robot name="trike">', '<robot name="trike" xmlns:xacro="http://www.ros.org/wiki/xacro">'
)
XACRO_TAG = robot().replace("</robot>", '<xacro:property name="r" value="0.1"/>\n</robot>')
NOT_ROBOT = robot().replace("<robot ", "<sdf ").replace("</robot>", "</sdf>")
VALUE_ENTITY = robot(head='<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY h "0.4">]>\n').replace(
    'xyz="0.2 0 0.1"', 'xyz="0.2 0 &h;"'
)
TRANSMISSION = (
    '<transmission name="t"><type>transmission_interface/SimpleTransmission</type>'
    '<joint name="chassis_to_laser">'
    "<hardwareInterface>hardware_interface/PositionJointInterface</hardwareInterface></joint>"
    '<actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>\n'
)
TRICK = '<origin rpy="0.02 -0.05 0" note=\'a xyz="9 9 9" &amp; b\' xyz="1.2 0.05 0.4" />'
URDF_REFUSED = [
    (
        "a UTF-16 URDF (the issue's case)",
        robot().replace('"1.0"?>', '"1.0" encoding="UTF-16"?>').encode("utf-16"),
        ("UTF-16", "UTF-8"),
    ),
    (
        "a UTF-16 URDF without a byte order mark",
        robot().replace('"1.0"?>', '"1.0" encoding="UTF-16"?>').encode("utf-16-le"),
        ("UTF-16",),
    ),
    ("a UTF-32 URDF", robot().encode("utf-32"), ("UTF-32",)),
    (
        "a joint defined through an internal entity (the issue's case)",
        ENTITY_JOINT.encode(),
        (":3", "entity 'laser_joint'", "does not expand"),
    ),
    ("an origin's value given by an entity", VALUE_ENTITY.encode(), ("entity 'h'",)),
    (
        "a joint with two <origin> elements (the issue's case)",
        TWO_ORIGINS.encode(),
        (":15", "2 <origin> elements (lines 14, 15)", "reads the first"),
    ),
    ("a joint with two <parent> elements", TWO_PARENTS.encode(), ("2 <parent> elements",)),
    ("a joint with two <child> elements", TWO_CHILDREN.encode(), ("2 <child> elements",)),
    (
        "two joints with one child link (the issue's case)",
        SECOND_JOINT.encode(),
        (":20", "'chassis_to_laser' (line 12) and 'laser_again'", "one parent"),
    ),
    ("two joints of one name", SAME_NAME.encode(), ("a second joint named 'chassis_to_laser'",)),
    ("a joint whose link is not declared", UNDECLARED.encode(), ("'front_wheel' is not declared",)),
    ("an unexpanded xacro file", XACRO.encode(), ("xacro",)),
    ("a xacro element in the URDF", XACRO_TAG.encode(), ("xacro:property", "run xacro")),
    ("a root that is not <robot>", NOT_ROBOT.encode(), ("<sdf>", "<robot>")),
]
URDF_EDITED = [
    (
        "an attribute whose value holds ' xyz=\"'",
        robot(origin=TRICK).encode(),
        b'<origin rpy="0.02 -0.05 0" note=',
    ),
    (
        "a UTF-8 byte order mark and CRLF lines",
        b"\xef\xbb\xbf" + robot().replace("\n", "\r\n").encode(),
        LASER_ORIGIN.encode(),
    ),
    (
        "a Latin-1 URDF with an accented comment",
        robot(head='<?xml version="1.0" encoding="ISO-8859-1"?>\n<!-- caméra -->\n').encode("latin-1"),
        LASER_ORIGIN.encode(),
    ),
    (
        "an origin written with an end tag",
        robot(origin='<origin xyz="1.2 0.05 0.4" rpy="0 0 0"></origin>').encode(),
        b'<origin xyz="1.2 0.05 0.4" rpy="0 0 0">',
    ),
    (
        "a commented-out origin before the real one",
        robot(origin=f'<!-- <origin xyz="7 7 7" rpy="0 0 0"/> -->\n    {LASER_ORIGIN}').encode(),
        LASER_ORIGIN.encode(),
    ),
    (
        "a transmission naming the sensor joint",
        robot().replace("</robot>", TRANSMISSION + "</robot>").encode(),
        LASER_ORIGIN.encode(),
    ),
]
URDF_CASES = [
    *((name, partial(urdf_refused, text, needles)) for name, text, needles in URDF_REFUSED),
    *((name, partial(urdf_edited, text, marker)) for name, text, marker in URDF_EDITED),
]


# ----------------------------------------------------------------------------- lost without a word


def batch_case(names: Sequence[str], w: World, tmp: Path) -> Expect:
    """``batch`` over logs named ``names`` (folders allowed): one folder each, each result the
    log's own, one summary row each pointing at its own folder."""
    logs = []
    for k, name in enumerate(names):
        path = tmp / "logs" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(w.tricycle if k % 2 == 0 else w.extra["fresh"], path)
        logs.append(path)
    out = tmp / "out"

    def one_each(_: Outcome) -> None:
        import csv

        rows = list(csv.DictReader((out / "summary.csv").open()))
        assert len(rows) == len(logs), rows
        folders = [r["folder"] for r in rows]
        assert len({f.lower() for f in folders}) == len(logs), folders
        for row in rows:
            doc = json.loads((out / row["folder"] / "result.json").read_text())
            assert Path(doc["dataset"]["path"]).resolve() == Path(row["source"]).resolve(), (
                row,
                doc["dataset"],
            )
        assert {Path(r["source"]).resolve() for r in rows} == {p.resolve() for p in logs}

    argv = ["batch", str(tmp / "logs"), "--out", str(out), *light(w), "--jobs", "1"]
    if any("/" in n for n in names):
        argv[1:2] = [str(p) for p in logs]
    return Expect(argv, (0,), check=one_each)


def _js_rows(w: World) -> tuple[tuple[str, ...], np.ndarray, np.ndarray]:
    from nlp_calib.logs.joint_log import read_joint_csv

    table = read_joint_csv(w.camera_joints)
    return table.names, table.time_ns, table.positions


def radians_messages(edit: Callable[[int, int, tuple[str, ...], list[float]], Any], w: World) -> list[Any]:
    """The camera recording as a bag's JointState (radians) and PoseStamped messages; ``edit(k, ns,
    names, positions)`` returns JointState message ``k``'s ``(ns, names, positions)`` or None."""
    from hostile3_corpus import pose_with_quaternion
    from test_bags import JS, POSE, joint_state

    from nlp_calib.logs.tum import read_tum

    names, stamps, positions = _js_rows(w)
    out = []
    for k, (ns, row) in enumerate(zip(stamps.tolist(), positions.tolist())):
        spec = (
            edit(k, int(stamps[k - 1]) if k else ns, names, row)
            if edit is _repeated
            else edit(k, ns, names, row)
        )
        spec = spec or (ns, names, row)
        out.append(("/joint_states", JS, ns, joint_state(spec[0], spec[1], spec[2])))
    tum = read_tum(w.camera)
    for ns, pose in zip(tum.time_ns.tolist(), tum.poses.tolist()):
        out.append(("/camera/pose", POSE, ns + 1000, pose_with_quaternion(ns, pose[:2], pose[3:])))
    return sorted(out, key=lambda m: m[2])


def radians_import(
    edit: Callable[..., Any],
    codes: tuple[int, ...],
    needles: tuple[str, ...],
    rows: int | None,
    w: World,
    tmp: Path,
    *extra: str,
) -> Expect:
    from test_bags import write_bag

    bag = write_bag(tmp / "bag", "mcap", radians_messages(edit, w))
    names = ",".join(CAMERA_ENCODERS.values())
    argv = [
        "import-bag",
        str(bag),
        "--out",
        str(tmp / "j.csv"),
        "--model",
        "diff_drive",
        "--joint-states",
        "/joint_states",
        "--joints",
        names,
        "--tracker",
        "/camera/pose",
        *extra,
    ]

    def counted(_: Outcome) -> None:
        if rows is not None:
            data = [ln for ln in (tmp / "j.csv").read_text().splitlines()[1:] if ln.strip()]
            assert len(data) == rows, len(data)
            assert not any(ln.startswith("0.") for ln in data), data[:3]

    return Expect(argv, codes, needles, check=counted)


def _short(k: int, ns: int, names: tuple[str, ...], row: list[float]) -> Any:
    return (ns, names, row[:1]) if k % 10 == 3 else None


def _zero(k: int, ns: int, names: tuple[str, ...], row: list[float]) -> Any:
    return (0, names, row) if k % 100 == 50 else None


def _partial(k: int, ns: int, names: tuple[str, ...], row: list[float]) -> Any:
    return (ns, names[:1], row[:1]) if k % 5 == 2 else None


def _equal(k: int, ns: int, names: tuple[str, ...], row: list[float]) -> Any:
    return (1_700_000_000 * 10**9, names, row)


def _repeated(k: int, ns: int, names: tuple[str, ...], row: list[float]) -> Any:
    return (ns, names, row) if k % 2 else None  # ns: the previous message's stamp


def _robot(text: str | None, w: World, tmp: Path) -> Expect:
    path = tmp / "robot.yaml"
    if text is not None:
        path.write_text(text)
    if text is None:
        return radians_import(lambda *a: None, (2,), ("robot.yaml",), None, w, tmp, "--robot", str(path))
    return radians_import(lambda *a: None, (0,), (f"robot: {path}",), None, w, tmp, "--robot", str(path))


N_JOINTS = 3100  # the camera recording's joint rows: 31 s at 100 Hz
LOST_CASES = [
    ("batch: 'a b.txt' and 'a_b.txt' (the issue's case)", partial(batch_case, ["a b.txt", "a_b.txt"])),
    ("batch: 'ä.txt' and 'ö.txt' (the issue's case)", partial(batch_case, ["ä.txt", "ö.txt"])),
    ("batch: '..x.txt' and 'x.txt' (the issue's case)", partial(batch_case, ["..x.txt", "x.txt"])),
    ("batch: 'A.txt' and 'a.txt'", partial(batch_case, ["A.txt", "a.txt"])),
    ("batch: d1/x.txt, d2/x.txt and d1_x.txt", partial(batch_case, ["d1/x.txt", "d2/x.txt", "d1_x.txt"])),
    ("batch: a log named like the summary", partial(batch_case, ["summary.csv.txt", "summary.md.txt"])),
    (
        "batch: three names that plain characters merge",
        partial(batch_case, ["r(1).txt", "r[1].txt", "r 1 .txt"]),
    ),
    (
        "radians bag: JointState arrays of mismatched length (the issue's case)",
        partial(
            radians_import,
            _short,
            (0,),
            ("310 JointState messages whose position and name lists differ",),
            N_JOINTS - 310,
        ),
    ),
    (
        "radians bag: zero stamps among good ones (the issue's case)",
        partial(radians_import, _zero, (0,), ("31 messages stamped 0",), N_JOINTS - 31),
    ),
    (
        "radians bag: a joint absent from some messages (the issue's case)",
        partial(
            radians_import,
            _partial,
            (0,),
            ("620 JointState messages holding only some of the joints",),
            N_JOINTS - 620,
        ),
    ),
    (
        "radians bag: every stamp equal (the issue's case)",
        partial(radians_import, _equal, (2,), ("carry one header stamp", "receive"), None),
    ),
    (
        "radians bag: every other stamp repeated",
        partial(radians_import, _repeated, (0,), ("1550 messages repeating",), N_JOINTS - 1550),
    ),
    ("import-bag --robot a missing file, joints in radians (the issue's case)", partial(_robot, None)),
    (
        "import-bag --robot, joints in radians",
        partial(
            _robot,
            "initial_guess: {left_wheel_radius: 0.1, right_wheel_radius: 0.1, wheel_separation: 0.45}\n",
        ),
    ),
]


# ----------------------------------------------------------------------------- messages


def short_lines(limit: int, outcome: Outcome) -> None:
    assert all(len(ln) <= limit for ln in outcome.err.splitlines()), [
        len(ln) for ln in outcome.err.splitlines()
    ]


def light(w: World) -> list[str]:
    """A batch's options that calibrate each tricycle log as the corpus's text scenarios do (one
    solver, no cross-validation): what a batch case checks is where each log's results go."""
    return ["--scenario", str(w.extra["light"])]


def batch_list(
    entries: Callable[[Path], dict[str, list[str]]], needles: tuple[str, ...], w: World, tmp: Path
) -> Expect:
    lists = entries(tmp)
    for name, items in lists.items():
        (tmp / name).write_text("".join(f"- {e}\n" for e in items))
    shutil.copy(w.tricycle, tmp / "drive.txt")
    argv = ["batch", str(tmp / next(iter(lists))), "--out", str(tmp / "out"), "--model", "tricycle"]
    return Expect(argv, (2,), needles, absent=(tmp / "out",))


def batch_glob(make: Callable[[World, Path], None], needles: tuple[str, ...], w: World, tmp: Path) -> Expect:
    """``batch 'data/*'`` over a folder holding one log and what ``make`` adds: one job only."""
    data = tmp / "data"
    data.mkdir()
    shutil.copy(w.tricycle, data / "drive.txt")
    make(w, tmp)
    out = tmp / "out"

    def one_job(_: Outcome) -> None:
        rows = (out / "summary.csv").read_text().splitlines()
        assert len(rows) == 2, rows

    argv = ["batch", str(data / "*"), "--out", str(out), *light(w), "--jobs", "1"]
    return Expect(argv, (0,), needles, check=one_job)


def _old_outputs(w: World, tmp: Path) -> None:
    outcome = run_in_process(
        [
            "batch",
            str(tmp / "data"),
            "--out",
            str(tmp / "data" / "previous"),
            *light(w),
            "--jobs",
            "1",
        ]
    )
    assert outcome.code == 0, outcome.err


def _other_files(w: World, tmp: Path) -> None:
    (tmp / "data" / "README.md").write_text("my notes\n")
    (tmp / "data" / "plot.png").write_bytes(b"\x89PNG")


def _run_output(w: World, tmp: Path) -> None:
    sc = text_scenario(tmp, tmp / "data" / "drive.txt")
    assert run_in_process(["run", str(sc), "--out", str(tmp / "data" / "run1")], tmp).code == 0


def partner(
    data: str, other: str, make: Callable[[Path], None], needles: tuple[str, ...], w: World, tmp: Path
) -> Expect:
    """``--data`` naming one file of a joint-log pair whose partner beside it is not a regular file."""
    shutil.copy(w.camera if data.endswith(".tum") else w.camera_joints, tmp / data)
    make(tmp / other)
    sc = camera_scenario(tmp, w.camera, w.camera_joints)
    argv = ["run", str(sc), "--out", str(tmp / "out"), "--data", str(tmp / data)]
    return Expect(argv, (2,), (data, other, *needles), child=True, absent=(tmp / "out",))


def non_ascii(utf8_mode: str, w: World, tmp: Path) -> Expect:
    """A log and folder named in non-ASCII, given in the scenario, under ``LC_ALL=C``."""
    folder = tmp / "dätä"
    folder.mkdir()
    shutil.copy(w.tricycle, folder / "fährt.txt")
    sc = text_scenario(tmp, Path("dätä") / "fährt.txt")
    env = {"LC_ALL": "C", "PYTHONUTF8": utf8_mode, "PYTHONIOENCODING": ""}
    argv = ["run", str(sc), "--out", str(tmp / "out")]
    if utf8_mode == "1":
        return Expect(argv, (0,), cwd=tmp, env=env)
    return Expect(argv, (2,), ("f\\xe4hrt.txt", "file system encoding", "LC_ALL=C.UTF-8"), cwd=tmp, env=env)


def long_cache(w: World, tmp: Path) -> Expect:
    env = {"NLP_CALIB_CACHE": str(tmp / ("c" * 5000))}
    argv = ["run", str(w.extra["cache_scenario"]), "--out", str(tmp / "out")]
    return Expect(
        argv, (2,), ("compile cache", "NLP_CALIB_CACHE", "5"), env=env, check=partial(short_lines, 600)
    )


def long_name(where: str, w: World, tmp: Path) -> Expect:
    name = "x" * 300
    sc = text_scenario(tmp, w.tricycle)
    argv = (
        ["run", str(sc), "--out", str(tmp / name)]
        if where == "out"
        else ["run", str(sc), "--out", str(tmp / "out"), "--data", str(tmp / f"{name}.txt")]
    )
    return Expect(argv, (1, 2), ("File name too long",), check=partial(short_lines, 600))


def frozen(which: str, w: World, tmp: Path) -> Expect:
    """Joints (or a counter) that never change while the robot drives: one line naming it, and no
    library's warnings."""
    if which == "camera":
        tum, joints = recording(w, tmp, joints=lambda r: [[x[0], "1.0", "2.0"] for x in r])
        sc = camera_scenario(tmp, tum, joints)
        needles: tuple[str, ...] = ("cam.joints.csv", "left_wheel", "never turns", "dataset.encoders")
    else:
        lines = w.diff_drive.read_text().splitlines()
        body = [ln for ln in lines if ln.strip() and not ln.startswith("#")]
        log = tmp / "dd.txt"
        log.write_text(
            "\n".join([ln for ln in lines if ln.startswith("#")] + _ticks(1, lambda t: 7)(body)) + "\n"
        )
        sc = text_scenario(tmp, log, model="diff_drive")
        needles = ("dd.txt", "right_wheel", "never turns")

    def quiet(outcome: Outcome) -> None:
        assert "warning" not in outcome.err, outcome.err

    return Expect(["run", str(sc), "--out", str(tmp / "out")], (2,), needles, check=quiet)


def _fifo(path: Path) -> None:
    os.mkfifo(path)


MESSAGE_CASES = [
    (
        "a batch list naming itself (the issue's case)",
        partial(
            batch_list,
            lambda t: {"list.yaml": ["drive.txt", "list.yaml"]},
            ("list.yaml", "entry 2", "names itself"),
        ),
    ),
    (
        "two batch lists naming each other",
        partial(
            batch_list,
            lambda t: {"a.yaml": ["b.yaml"], "b.yaml": ["drive.txt", "a.yaml"]},
            ("b.yaml", "leads back"),
        ),
    ),
    (
        "batch outputs globbed as logs (the issue's case)",
        partial(batch_glob, _old_outputs, ("left out", "written by nlp_calib")),
    ),
    (
        "a run's outputs globbed as logs",
        partial(batch_glob, _run_output, ("left out", "written by nlp_calib")),
    ),
    (
        "a pattern matching notes and pictures",
        partial(batch_glob, _other_files, ("left out 2", "neither logs nor scenarios", "README.md")),
    ),
    (
        "--data x.tum with x.joints.csv a folder (the issue's case)",
        partial(partner, "x.tum", "x.joints.csv", lambda p: p.mkdir(), ("a folder",)),
    ),
    (
        "--data x.tum with x.csv a FIFO (the issue's case)",
        partial(partner, "x.tum", "x.csv", _fifo, ("a FIFO",)),
    ),
    (
        "--data x.csv with x.tum a folder",
        partial(partner, "x.csv", "x.tum", lambda p: p.mkdir(), ("a folder",)),
    ),
    ("a non-ASCII path under LC_ALL=C (the issue's case)", partial(non_ascii, "0")),
    ("a non-ASCII path under LC_ALL=C, UTF-8 mode", partial(non_ascii, "1")),
    ("a 5,000-character compile cache path (the issue's case)", long_cache),
    ("an output folder name of 300 characters", partial(long_name, "out")),
    ("a log name of 300 characters", partial(long_name, "data")),
    ("joints that never move (the issue's case)", partial(frozen, "camera")),
    ("a wheel counter that never moves", partial(frozen, "text")),
]


# ----------------------------------------------------------------------------- check


def stored_calibration(w: World) -> Path:
    """``calibration.yaml`` of a run on the tricycle log through an absolute scenario path."""
    return Path(w.extra["calibration"])


def tampered(edit: Callable[[dict[str, Any]], None], w: World, tmp: Path) -> Path:
    doc = yaml.safe_load(stored_calibration(w).read_text())
    edit(doc)
    path = tmp / "calibration.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _set(key: str, name: str, value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(doc: dict[str, Any]) -> None:
        doc[key][name] = value

    return edit


def check_refused(
    edit: Callable[[dict[str, Any]], None], needles: tuple[str, ...], w: World, tmp: Path
) -> Expect:
    cal = tampered(edit, w, tmp)
    argv = ["check", str(cal), str(w.extra["fresh"]), "--out", str(tmp / "out")]
    return Expect(argv, (2,), ("calibration.yaml", *needles), absent=(tmp / "out",))


def relative_scenario(w: World, tmp: Path) -> Expect:
    """A calibration recording its scenario as ``case.yaml`` (relative) checked from a folder that
    holds another ``case.yaml`` (another formulation, a few samples): that file is not used."""
    cal = tampered(lambda d: d["scenario"].update(path="case.yaml"), w, tmp)
    (tmp / "case.yaml").write_text(
        f"dataset: {quoted(w.tricycle)}\nmodel: tricycle\nresidual: {{horizon: 1}}\n"
        "samples: {start: 0, stop: 40}\n"
    )
    out = tmp / "out"

    def whole(_: Outcome) -> None:
        doc = json.loads((out / "result.json").read_text())
        assert doc["residual"]["horizon"] == 10 and doc["dataset"]["used"][1] == 300, doc["residual"]

    argv = ["check", str(cal), str(w.extra["fresh"]), "--out", str(out)]
    needles = ("recorded relative to the folder it ran in",)
    return Expect(argv, (0, 3, 4), needles, cwd=tmp, check=whole, answers=(0, 3, 4))


def samples_on_a_new_log(same: bool, w: World, tmp: Path) -> Expect:
    """A calibration made on records [50, 250) checked on a new log (whole, said) or the same log
    (the same records)."""
    out = tmp / "out"
    log = w.tricycle if same else w.extra["fresh"]

    def used(_: Outcome) -> None:
        doc = json.loads((out / "result.json").read_text())
        # Whole: from the first record whose encoders the fitted lag can read (t − lag in the log).
        t = np.array([float(ln.split()[1]) for ln in log.read_text().splitlines() if ln.startswith("time:")])
        lag = doc["alignment"]["tracker_lag_s"]
        first = int(np.flatnonzero(t - lag >= t[0])[0])
        assert doc["dataset"]["used"] == ([50, 250] if same else [first, 300]), doc["dataset"]

    needles = () if same else ("selects samples [50, 250)", "checked whole")
    argv = ["check", str(w.extra["sampled"]), str(log), "--out", str(out)]
    return Expect(argv, (0, 3, 4), needles, check=used, answers=(0, 3, 4))


NOT_OURS = "give the calibration.yaml nlp_calib wrote"
CHECK_CASES = [
    (
        "a σ of 1e300 (the issue's case)",
        partial(check_refused, _set("std", "sensor_x", 1e300), ("std.sensor_x", "1e+300", NOT_OURS)),
    ),
    (
        "a σ of ten turns",
        partial(check_refused, _set("std", "sensor_theta", 62.8), ("std.sensor_theta", "62.8")),
    ),
    (
        "a negative σ (the issue's case)",
        partial(check_refused, _set("std", "k_steer", -0.002), ("std.k_steer", "negative")),
    ),
    (
        "a negative white-noise σ",
        partial(
            check_refused,
            _set("std_white_noise", "axis_length", -1.0),
            ("std_white_noise.axis_length", "negative"),
        ),
    ),
    (
        "a σ that is not a number",
        partial(check_refused, _set("std", "k_traction", float("nan")), ("std.k_traction", "finite")),
    ),
    (
        "axis_length 1e300 (the issue's case)",
        partial(
            check_refused, _set("parameters", "axis_length", 1e300), ("parameters.axis_length", "1e+300")
        ),
    ),
    (
        "a negative k_steer",
        partial(check_refused, _set("parameters", "k_steer", -0.55), ("parameters.k_steer",)),
    ),
    (
        "a sensor_theta of 100 rad",
        partial(check_refused, _set("parameters", "sensor_theta", 100.0), ("parameters.sensor_theta",)),
    ),
    (
        "a parameter given as text",
        partial(
            check_refused, _set("parameters", "sensor_x", "1.6 m"), ("parameters.sensor_x", "finite number")
        ),
    ),
    ("a scenario path relative to another folder (the issue's case)", relative_scenario),
    ("a recorded sample range on a new log (the issue's case)", partial(samples_on_a_new_log, False)),
    ("a recorded sample range on the same log", partial(samples_on_a_new_log, True)),
]


# ----------------------------------------------------------------------------- memory

#: What reading a file may hold beyond a run of a small file like it, per byte of the file.
MEMORY_FACTOR = 3.0


def peak_kb(argv: Sequence[str], cwd: Path) -> int:
    """The peak resident memory (kB) of the command in a child."""
    rss = cwd / f"rss-{len(list(cwd.glob('rss-*')))}.txt"
    outcome = run_child(argv, cwd, {"RSS_FILE": str(rss)})
    assert "Traceback" not in outcome.err, outcome.err
    return int(rss.read_text())


def within_memory(
    big: Path, small_argv: Sequence[str], tmp: Path, _: Outcome, bases: dict[str, int] | None = None
) -> None:
    """The command's peak (its ``RSS_FILE``) exceeds the same command's on ``small_argv`` by at
    most :data:`MEMORY_FACTOR` times the size of ``big``. ``bases``: the small command's peak kept
    for the cases that run the same command on the same small inputs (measured once)."""
    peak = int((tmp / "rss.txt").read_text())
    bases = {} if bases is None else bases
    if "base" not in bases:
        bases["base"] = peak_kb(small_argv, tmp)
    base = bases["base"]
    extra, size = (peak - base) * 1024, big.stat().st_size
    mb = f"{size / 1e6:.0f} MB, peak {peak / 1024:.0f} MB, base {base / 1024:.0f} MB"
    print(f"\n{big.name}: {mb}: {extra / size:.2f}× the file")
    assert extra <= MEMORY_FACTOR * size, (extra / size, peak, base)


def _long_rows(before_s: int, w: World) -> tuple[np.ndarray, str, list[str]]:
    """Six minutes of the camera's joints at 1 kHz, ``before_s`` of them before its 30 s (held at
    its first values, then at its last): their stamps, the CSV's header and each row after its
    stamp, formatted once per world for the cases that shift or annotate the same rows."""
    from nlp_calib.logs.joint_log import format_joint_csv, read_joint_csv

    key = f"long_rows_{before_s}"
    if key not in w.extra:
        table = read_joint_csv(w.camera_joints)
        t = table.time_ns
        before, after, step = before_s * 10**9, (360 - before_s) * 10**9, 10**6
        pad_a = np.arange(t[0] - before, t[0], step)
        pad_b = np.arange(t[-1] + step, t[-1] + after, step)
        fine = np.arange(t[0], t[-1], step)
        columns = [np.interp(fine, t, table.positions[:, j]) for j in range(table.positions.shape[1])]
        q = np.column_stack(columns)
        times = np.concatenate([pad_a, fine, pad_b])
        values = np.vstack([np.repeat(q[:1], pad_a.size, 0), q, np.repeat(q[-1:], pad_b.size, 0)])
        head, *rows = format_joint_csv(np.zeros_like(times), table.names, values).splitlines(keepends=True)
        stamp = len(seconds(0))  # every row's stamp, 0 here, before its first comma
        w.extra[key] = (times, head, [r[stamp:] for r in rows])
    found: tuple[np.ndarray, str, list[str]] = w.extra[key]
    return found


def long_joints(where: str, w: World, tmp: Path) -> Expect:
    """Six minutes of a joint log at 1 kHz (a scaled-down two hours) of which the camera's 30 s pair
    with ``where`` (the middle, the start, the end, or a clock offset given): only what pairs is
    kept, said, and the calibration is the right one."""
    times, head, rows = _long_rows({"end": 360}.get(where, 180), w)
    shift = {"offset": 500, "earlier": 900}.get(where, 0) * 10**9
    stamps = (times - shift).tolist()
    big = tmp / "long.csv"
    with big.open("w") as fh:
        fh.write(head + seconds(stamps[0]) + rows[0])
        step_rows = 10_000 if where == "comments" else 100_000
        for k in range(1, len(stamps), step_rows):
            chunk = zip(stamps[k : k + step_rows], rows[k : k + step_rows])
            fh.write("".join(seconds(t) + row for t, row in chunk))
            fh.write("# a note from the logger\n" if where == "comments" else "")
    extra = "" if where != "offset" else ", clock_offset: 500.0"
    sc = camera_scenario(tmp, w.camera, big, block=extra)
    small = camera_scenario(tmp, w.camera, w.camera_joints, name="small.yaml")
    out = tmp / "out"

    def check(outcome: Outcome) -> None:
        small_argv = ["run", str(small), "--out", str(tmp / "small")]
        within_memory(big, small_argv, tmp, outcome, w.extra.setdefault("camera_base_kb", {}))
        if where != "earlier":
            right_answer(out, w.camera_truth, outcome)

    argv = ["run", str(sc), "--out", str(out)]
    env = {"RSS_FILE": str(tmp / "rss.txt")}
    if where == "earlier":  # the joints end minutes before the poses begin: refused, naming both spans
        return Expect(
            argv, (2,), ("long.csv", "do not overlap", "clock_offset"), cwd=tmp, env=env, check=check
        )
    return Expect(argv, (0,), ("long.csv", "were kept"), cwd=tmp, env=env, check=check)


def read_then_refused(kind: str, w: World, tmp: Path) -> Expect:
    """A large file read whole, then the scenario's samples refused (beyond its records): the
    reading alone, measured."""
    from conftest import write_sim

    if kind in ("text", "crlf"):
        # The small log fills a block of the reader (4 MB): what grows with the file is measured.
        # Both kinds read the same simulated logs (simulated once, copied).
        for name, records in (("big.txt", 200_000), ("little.txt", 30_000)):
            if not (w.folder / name).exists():
                write_sim(w.folder, name, records=records, rate_hz=1000.0, seed=4)
            shutil.copyfile(w.folder / name, tmp / name)
        big, little = tmp / "big.txt", tmp / "little.txt"
        if kind == "crlf":
            for path in (big, little):
                path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
        sc = text_scenario(tmp, big, extra="samples: {start: 0, stop: 999999999}\n")
        small = text_scenario(tmp, little, extra="samples: {start: 0, stop: 999999999}\n", name="small.yaml")
    else:  # a camera at 1 kHz: a long TUM file with its joints
        from nlp_calib.simulation.camera import (
            CameraNoise,
            CameraSimulationOptions,
            simulate_camera,
            write_camera_simulation,
        )

        sim = simulate_camera(
            CameraSimulationOptions(
                model="diff_drive",
                duration_s=180.0,
                seed=9,
                image_rate_hz=1000.0,
                noise=CameraNoise(0.001, 0.0017),
            )
        )
        big, joints, _ = write_camera_simulation(sim, tmp / "fast.tum")
        extra = "samples: {start: 0, stop: 999999999}\n"
        sc = camera_scenario(tmp, big, joints, extra=extra)
        small = camera_scenario(tmp, w.camera, w.camera_joints, extra=extra, name="small.yaml")
    argv = ["run", str(sc), "--out", str(tmp / "out")]
    small_argv = ["run", str(small), "--out", str(tmp / "small")]
    return Expect(
        argv,
        (2,),
        ("samples",),
        cwd=tmp,
        env={"RSS_FILE": str(tmp / "rss.txt")},
        check=partial(within_memory, big, small_argv, tmp),
    )


MEMORY_CASES = [
    (
        "a long joint log, the camera's 30 s in its middle (the issue's case, scaled)",
        partial(long_joints, "middle"),
    ),
    ("a long joint log, the camera's 30 s at its end", partial(long_joints, "end")),
    ("a long joint log on another clock, clock_offset given", partial(long_joints, "offset")),
    (
        "a text log of 200,000 records at 1 kHz, read (the issue's case, scaled)",
        partial(read_then_refused, "text"),
    ),
    ("a TUM file of 180,000 poses at 1 kHz, read", partial(read_then_refused, "tum")),
    ("a long joint log with a comment every 10,000 rows", partial(long_joints, "comments")),
    ("a long joint log that ends before the poses begin", partial(long_joints, "earlier")),
    ("a text log of 200,000 records with CRLF line ends, read", partial(read_then_refused, "crlf")),
]


# ----------------------------------------------------------------------------- the world


def make_world(folder: Path) -> World:
    """Simulate the shared inputs and fill a compile cache with one run's compiled code."""
    from conftest import write_sim

    from nlp_calib.models import get_model, load_log
    from nlp_calib.simulation.camera import (
        CameraNoise,
        CameraSimulationOptions,
        simulate_camera,
        write_camera_simulation,
    )

    tricycle = write_sim(folder, "drive.txt", records=300, seed=5)
    diff_drive = write_sim(folder, "dd.txt", records=600, seed=2, model="diff_drive")
    options = CameraSimulationOptions(
        model="diff_drive",
        duration_s=30.0,
        seed=7,
        image_rate_hz=30.0,
        joint_rate_hz=100.0,
        stamp_offset_s=0.01,
        noise=CameraNoise(position=0.001, rotation=0.0017),
    )
    names = {
        "k_left": "left_wheel_radius",
        "k_right": "right_wheel_radius",
        "baseline": "wheel_separation",
        "axis_length": "wheelbase",
    }
    cameras = {}
    for name, model, mount in (
        ("cam", "diff_drive", {}),
        ("tricycle", "tricycle", {}),
        ("upside_down", "diff_drive", {"sensor_roll": float(np.radians(60.0))}),
    ):
        sim = simulate_camera(dataclasses.replace(options, model=model, truth=mount))
        tum, _, _ = write_camera_simulation(sim, folder / f"{name}.tum")
        truth = {names.get(n, n): float(v) for n, v in sim.truth.items()}
        truth["tracker_lag"] = options.stamp_offset_s  # the images stamped late: the lag to find
        if model == "tricycle":
            truth["wheel_radius"] = truth.pop("k_traction") / (2 * np.pi)
        cameras[name] = (tum, truth, "")
    camera, truth = cameras["cam"][0], cameras["cam"][1]
    cache = folder / "cache"
    cache_scenario = text_scenario(folder, tricycle, name="cached.yaml")
    if has_compiler():
        proc = run_child(
            ["run", str(cache_scenario), "--out", str(folder / "cached")],
            folder,
            {"NLP_CALIB_CACHE": str(cache)},
        )
        assert proc.code == 0, proc.err
    w = World(folder, tricycle, diff_drive, load_log(tricycle, get_model("tricycle")), camera, truth, cache)
    w.extra["cache_scenario"] = cache_scenario
    w.extra["light"] = text_scenario(folder, tricycle, name="light.yaml")
    w.extra.update(cameras)
    w.extra["fresh"] = write_sim(folder, "fresh.txt", records=300, seed=8)
    for name, extra in (("calibration", ""), ("sampled", "samples: {start: 50, stop: 250}\n")):
        sc = text_scenario(folder, tricycle, extra=extra, name=f"{name}.yaml")
        outcome = run_in_process(["run", str(sc), "--out", str(folder / name)], folder)
        assert outcome.code == 0, outcome.err
        w.extra[name] = folder / name / "calibration.yaml"
    return w


# ----------------------------------------------------------------------------- the corpus

_CODE = [*CODEGEN_CASES, *CACHE_CASES] if has_compiler() else []

CORPUS: list[Case] = [
    Case(cls, name, build)
    for cls, cases in [
        ("code", _CODE),
        ("verdicts", [*VERDICT_CASES, *OTHER_CAMERAS]),
        ("urdf", URDF_CASES),
        ("check", CHECK_CASES),
        ("lost", LOST_CASES),
        ("messages", MESSAGE_CASES),
        ("memory", MEMORY_CASES),
    ]
    for name, build in cases
]
