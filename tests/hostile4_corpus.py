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
from hostile3_corpus import DEADLINE_S, Outcome
from hostile3_corpus import Expect as Expect3

from nlp_calib.codegen import compiler
from nlp_calib.logs import Log

CLASSES = ("code", "verdicts", "urdf", "lost", "check", "messages", "memory")
CAMERA_ENCODERS = {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"}
HANDOFF = ("calibration.yaml", "ros2_control.yaml", "robot.urdf", "sensor_mount.urdf.xml")


@dataclass
class Expect(Expect3):
    """Round three's :class:`~hostile3_corpus.Expect`, and ``env``: variables a child runs with."""

    env: dict[str, str] = field(default_factory=dict)


def run_child(argv: Sequence[str], cwd: Path | None, env: dict[str, str]) -> Outcome:
    """The command in a child with a deadline and ``env`` added to this process's environment."""
    full = dict(os.environ, PYTHONWARNINGS="ignore", PYTHONPATH=str(REPO), **env)
    command = [sys.executable, "-m", "nlp_calib", *argv]
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


def text_scenario(folder: Path, log: Path, model: str = "tricycle", extra: str = "", name: str = "case.yaml") -> Path:
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
    ("codegen: a log named to run a command (the issue's case)", partial(codegen_named, PWN + ".txt", PWN, ())),
    ("codegen: a log named with printf formats", partial(codegen_named, "%s%n%s%n%p.txt", "%s%n%s%n%p.txt", ())),
    ("codegen: a log name ending in a backslash", partial(codegen_named, "drive\\", "drive\\", ())),
    ("codegen: trigraphs in the log name, built with -trigraphs", partial(codegen_named, "x??=??-??!.txt", "x??=??-??!.txt", ("-trigraphs",))),
    ("codegen: a log name with a tab, quotes and non-ASCII", partial(codegen_named, "a\t'b\"ä€.txt", "a\t'b\"ä€.txt", ())),
    ("codegen: a log name that is not UTF-8", undecodable_name),
    ("codegen: a scenario name with lines of C", partial(codegen_scenario_named, "x *\n#error injected\n* x")),
    ("codegen: a scenario name with trigraphs and a tab", partial(codegen_scenario_named, "x ??)\t??= #error")),
    ("codegen: a camera's TUM file named to run a command", partial(codegen_camera_named, 'cam");system("touch PWNED");printf("')),
    ("codegen: a camera's TUM file named with printf formats", partial(codegen_camera_named, "cam%n%s")),
]


# ----------------------------------------------------------------------------- the compile cache

_EVIL_C = '#include <fcntl.h>\n__attribute__((constructor)) static void evil(void) { creat("PWNED", 0644); }\n'


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


def cache_case(
    arrange: Callable[[Path, Path], Path], warns: tuple[str, ...], w: World, tmp: Path
) -> Expect:
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
    ("cache: a planted entry in a folder writable by all", partial(cache_case, partial(_chmod, 0o777), ("writable by", *FOLDER_WARNS))),
    ("cache: a planted entry in a group-writable folder", partial(cache_case, partial(_chmod, 0o775), ("its group", *FOLDER_WARNS))),
    ("cache: a planted entry in a sticky folder like /tmp", partial(cache_case, _sticky, FOLDER_WARNS)),
    ("cache: a planted entry through a link to an open folder", partial(cache_case, _linked, FOLDER_WARNS)),
    ("cache: planted entries writable by others", partial(cache_case, partial(_entries_chmod, 0o666), ENTRY_WARNS)),
    ("cache: planted entries writable by the group", partial(cache_case, partial(_entries_chmod, 0o775), ENTRY_WARNS)),
    ("cache: planted entries that are links", partial(cache_case, _entry_links, ("compile cache", "not a regular file"))),
]
if os.geteuid() == 0:  # only root can give a file to another user
    CACHE_CASES += [
        ("cache: planted entries owned by another user", partial(cache_case, _entries_chown, ("owned by user id 65534", *ENTRY_WARNS))),
        ("cache: a planted folder owned by another user", partial(cache_case, _folder_chown, ("owned by user id 65534", *FOLDER_WARNS))),
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
    sim = simulate_camera(options)
    camera, _, _ = write_camera_simulation(sim, folder / "cam.tum")
    names = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
    truth = {names.get(n, n): float(v) for n, v in sim.truth.items()}
    cache = folder / "cache"
    cache_scenario = text_scenario(folder, tricycle, name="cached.yaml")
    if has_compiler():
        proc = run_child(["run", str(cache_scenario), "--out", str(folder / "cached")], folder, {"NLP_CALIB_CACHE": str(cache)})
        assert proc.code == 0, proc.err
    w = World(folder, tricycle, diff_drive, load_log(tricycle, get_model("tricycle")), camera, truth, cache)
    w.extra["cache_scenario"] = cache_scenario
    return w


# ----------------------------------------------------------------------------- the corpus

_CODE = [*CODEGEN_CASES, *CACHE_CASES] if has_compiler() else []

CORPUS: list[Case] = [
    Case(cls, name, build)
    for cls, cases in [
        ("code", _CODE),
    ]
    for name, build in cases
]
