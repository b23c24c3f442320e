"""Hostile input, round five (issue 40): output paths, text that becomes settings, mounts and
units that cannot be right, ordinary faults as one-line errors, and the memory a large file costs.

Each class's members are generated here (a lidar bag with one thing wrong, a name with each kind of
line break, each address form ``--dask`` must refuse) and run as a user runs them, through the
command line in this process: a refusal is exit 2 with one line naming the cause, never an
internal error, a replaced file or a hand-off of what cannot be right.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import re
import subprocess
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from conftest import REPO

from nlp_calib.cli import main
from nlp_calib.simulation.lidar import LidarSimulationOptions, simulate_lidar
from nlp_calib.simulation.rosbag import LASER_SCAN, header, joint_state, tf_static, write_bag

T0 = 1_700_000_000 * 10**9


def run(argv: Sequence[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(err: str, *needles: str) -> str:
    """The one ``error:`` line of ``err``, holding every needle and no internal error."""
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    assert "internal error" not in lines[0], lines[0]
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


# ----------------------------------------------------------------------------- lidar bags


@pytest.fixture(scope="module")
def lidar_sim() -> Any:
    return simulate_lidar(LidarSimulationOptions(duration_s=6.0, beams=180, degraded_fraction=0.0, seed=2))


def scan_message(ns: int, ranges: np.ndarray, **fields: Any) -> Any:
    """A LaserScan of 180 beams over the full turn (``fields`` override the message's values)."""
    n = max(ranges.size, 1)
    values = {
        "angle_min": -math.pi,
        "angle_max": -math.pi + 2 * math.pi * (n - 1) / n,
        "angle_increment": 2 * math.pi / n,
        "time_increment": 0.0,
        "scan_time": 0.1,
        "range_min": 0.05,
        "range_max": 15.0,
    }
    values.update(fields)
    frame = values.pop("frame", "laser")
    stamp = values.pop("stamp", ns)

    def build(ts: Any) -> Any:
        return ts.types[LASER_SCAN](
            header=header(ts, stamp, frame),
            ranges=np.asarray(ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
            **{k: float(v) for k, v in values.items()},
        )

    return ("/scan", LASER_SCAN, ns, build)


Mutate = Callable[[int, int, np.ndarray], list[Any]]


def lidar_bag(
    sim: Any, folder: Path, mutate: Mutate | None = None, tf: tuple[float, ...] = (0.2, 0.0, 0.3)
) -> Path:
    """The simulated drive as a bag, each scan ``k`` (stamp ``ns``, ranges) made into the messages
    ``mutate`` returns (default: the scan as it is)."""
    ns = [round(t * 1e9) for t in sim.scan_time_s]
    out = [tf_static(round(sim.joint_time_s[0] * 1e9), "base_link", "laser", tf, 0.0)]
    out += [
        joint_state(round(t * 1e9), sim.joint_names, r) for t, r in zip(sim.joint_time_s, sim.joint_positions)
    ]
    for k, (stamp, r) in enumerate(zip(ns, sim.ranges)):
        out += mutate(k, stamp, r) if mutate else [scan_message(stamp, r)]
    return write_bag(folder / "bag", out)


def lidar_scenario(bag: Path) -> Path:
    sc = bag.parent / "lidar.yaml"
    sc.write_text(
        f"name: lidar\nmodel: diff_drive\ndataset: {{bag: {json.dumps(str(bag))}, "
        "joint_states: /joint_states, joints: [left_wheel_joint, right_wheel_joint], scan: /scan}\n"
        "initial_guess: auto\n"
        "solvers: [gauss_newton]\nvalidation: {blocks: 0}\n"
    )
    return sc


LIDAR_FAULTS: dict[str, tuple[Mutate, tuple[str, ...]]] = {
    "every range NaN": (
        lambda k, ns, r: [scan_message(ns, np.full_like(r, np.nan))],
        ("no valid lidar returns", "NaN"),
    ),
    "every range inf": (
        lambda k, ns, r: [scan_message(ns, np.full_like(r, np.inf))],
        ("no valid lidar returns",),
    ),
    "every range negative": (lambda k, ns, r: [scan_message(ns, -r)], ("no valid lidar returns", "negative")),
    "range_max tiny": (
        lambda k, ns, r: [scan_message(ns, r, range_max=0.06)],
        ("no valid lidar returns", "beyond"),
    ),
    "range_max below range_min": (
        lambda k, ns, r: [scan_message(ns, r, range_max=0.01)],
        ("admit no return",),
    ),
    "empty ranges": (lambda k, ns, r: [scan_message(ns, r[:0], angle_max=-math.pi)], ("holds no ranges",)),
    "angle_min inf": (lambda k, ns, r: [scan_message(ns, r, angle_min=math.inf)], ("not finite",)),
    "angle_increment NaN": (
        lambda k, ns, r: [scan_message(ns, r, angle_increment=math.nan)],
        ("not finite",),
    ),
    "increment does not fit the count": (
        lambda k, ns, r: [scan_message(ns, r, angle_increment=2 * math.pi / 180 * 0.38)],
        ("beam geometry does not fit", "180 ranges"),
    ),
    "angle_max does not fit the count": (
        lambda k, ns, r: [scan_message(ns, r, angle_max=0.5)],
        ("beam geometry does not fit",),
    ),
    "zero increment": (lambda k, ns, r: [scan_message(ns, r, angle_increment=0.0)], ("beam geometry",)),
    "all scans one stamp": (
        lambda k, ns, r: [scan_message(ns, r, stamp=T0)],
        ("carry one stamp", "stamps: receive"),
    ),
    "scans 1 ns apart": (
        lambda k, ns, r: [scan_message(ns, r, stamp=T0 + k)],
        ("faster than any lidar sweeps", "stamps: receive"),
    ),
    "frame_id is the base": (
        lambda k, ns, r: [scan_message(ns, r, frame="base_link")],
        ("base frame", "base_link"),
    ),
}


@pytest.mark.parametrize("fault", list(LIDAR_FAULTS))
def test_a_lidar_bag_that_cannot_be_right_is_refused_naming_the_cause(
    fault: str, lidar_sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mutate, needles = LIDAR_FAULTS[fault]
    sc = lidar_scenario(lidar_bag(lidar_sim, tmp_path, mutate))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    one_line_error(err, *needles)
    assert not (tmp_path / "out").exists()


def test_a_nan_on_tf_static_is_refused(
    lidar_sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = lidar_scenario(lidar_bag(lidar_sim, tmp_path, tf=(0.2, math.nan, 0.3)))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    one_line_error(err, "/tf_static", "'laser' in 'base_link' is not finite")


@pytest.mark.parametrize("how", ["twice", "duplicate stamps"])
def test_scans_sharing_a_stamp_are_dropped_counted_and_said(how: str, lidar_sim: Any, tmp_path: Path) -> None:
    from nlp_calib.core.errors import NlpCalibWarning
    from nlp_calib.logs.scans import read_scans

    def doubled(k: int, ns: int, r: np.ndarray) -> list[Any]:
        again = r if how == "twice" else r + 0.01
        return [scan_message(ns, r), *([scan_message(ns, again)] if k % 4 == 1 else [])]

    bag = lidar_bag(lidar_sim, tmp_path, doubled)
    n = lidar_sim.scan_time_s.size
    extra = len(range(1, n, 4))
    with pytest.warns(
        NlpCalibWarning, match=rf"{extra} of {n + extra} scans .* carry the stamp of the scan before"
    ):
        scans = read_scans(bag, "/scan")
    assert scans.n == n and np.all(np.diff(scans.stamp_ns) > 0)
    assert np.allclose(scans.ranges, lidar_sim.ranges.astype(np.float32), equal_nan=True)


# ----------------------------------------------------------------------------- output paths


@pytest.fixture(scope="module")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from conftest import write_sim

    return write_sim(tmp_path_factory.mktemp("log5"), "drive.txt", records=400, seed=1)


def _special(kind: str, path: Path, tmp: Path) -> Path:
    """``path`` made into ``kind``: a user's file, links to one (or to nothing), a FIFO, a device."""
    if kind == "user file":
        path.write_text("mine\n")
    elif kind == "link to a user file":
        (tmp / "mine.txt").write_text("mine\n")
        path.symlink_to(tmp / "mine.txt")
    elif kind == "dangling link":
        path.symlink_to(tmp / "nowhere")
    elif kind == "FIFO":
        os.mkfifo(path)
    elif kind == "device":
        return Path("/dev/null")
    return path


OUTPUT_KINDS = ["user file", "link to a user file", "dangling link", "FIFO", "device"]


@pytest.mark.parametrize("force", [False, True])
@pytest.mark.parametrize("kind", OUTPUT_KINDS)
@pytest.mark.parametrize("command", ["preflight --json", "init --out"])
def test_a_single_output_file_never_replaces_what_is_not_ours(
    command: str, kind: str, force: bool, small_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = _special(kind, tmp_path / ("report.json" if "json" in command else "drafted.yaml"), tmp_path)
    before = (target.is_symlink(), os.readlink(target) if target.is_symlink() else None)
    mine = (tmp_path / "mine.txt").read_text() if (tmp_path / "mine.txt").exists() else None
    verb, flag = command.split()
    argv = [verb, small_log, flag, target, *(["--force"] if force else [])]
    code, _, err = run(argv, capsys)
    if kind == "user file" and force:
        # Any verdict's exit code (the 400-record drive never turns: NOT ENOUGH, 4): the file is written.
        assert code in (0, 3, 4), err
        assert target.read_text() != "mine\n"
        return
    assert code == 2, err
    line = one_line_error(err, str(target))
    assert ("symbolic link" in line) if "link" in kind else True
    special = kind == "FIFO" or (kind == "device" and command.startswith("preflight"))
    assert ("not a regular file" in line) if special else True  # init: /dev/null is no .yaml
    assert (target.is_symlink(), os.readlink(target) if target.is_symlink() else None) == before
    if mine is not None:
        assert (tmp_path / "mine.txt").read_text() == mine
    if kind == "user file":
        assert target.read_text() == "mine\n"


def test_a_link_in_an_output_folder_is_refused_even_with_force(
    small_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = tmp_path / "s.yaml"
    sc.write_text(
        f"dataset: {json.dumps(str(small_log))}\nmodel: tricycle\nsolvers: [gauss_newton]\n"
        "validation: {blocks: 0}\n"
    )
    out = tmp_path / "out"
    out.mkdir()
    (tmp_path / "elsewhere.json").write_text("mine\n")
    (out / "result.json").symlink_to(tmp_path / "elsewhere.json")
    code, _, err = run(["run", sc, "--out", out, "--force"], capsys)
    assert code == 2, err
    one_line_error(err, str(out / "result.json"), "symbolic link")
    assert (tmp_path / "elsewhere.json").read_text() == "mine\n" and (out / "result.json").is_symlink()


# ----------------------------------------------------------------------------- text that becomes settings

#: Every character YAML or a terminal reads as more than text.
BREAKS = ["\n", "\r", "\r\n", "\x85", "\u2028", "\u2029", "\x1b[31m", "\x00", "\u202e", "\x0b", "\x7f"]


@pytest.mark.parametrize("brk", BREAKS, ids=[repr(b) for b in BREAKS])
def test_a_scenario_name_that_is_not_one_line_is_refused_with_its_line(
    brk: str, small_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = tmp_path / "s.yaml"
    name = json.dumps(f"map{brk}known: {{wheel_separation: 0.9}}")
    sc.write_text(f"model: tricycle\ndataset: {json.dumps(str(small_log))}\nname: {name}\n")
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    line = one_line_error(err, f"{sc}:3:")
    assert brk not in line and "\x1b" not in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("brk", ["\x1b", "\x85", "\x7f"], ids=repr)
def test_a_raw_control_character_in_a_scenario_is_refused_with_its_line(
    brk: str, small_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = tmp_path / "s.yaml"
    sc.write_bytes(f"model: tricycle\ndataset: {json.dumps(str(small_log))}\nname: a{brk}b\n".encode())
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 2, err
    assert brk not in one_line_error(err, f"{sc}:")  # U+0085 is a line break to YAML: a line later


@pytest.mark.parametrize("brk", BREAKS, ids=[repr(b) for b in BREAKS])
def test_hand_off_files_read_back_as_written_whatever_the_names(brk: str) -> None:
    from nlp_calib.outputs.handoff import _comment_text, calibration_yaml

    name = f"robot{brk}known: {{x: 1}}"
    doc = {
        "tool": {"version": "0"},
        "scenario": {"name": name},
        "solver": "gauss_newton",
        "solver_choice": "only",
        "frames": {"sensor": f"laser{brk}", "parent": "base_link"},
        "sensor": {"params": ["sensor_x"]},
        "parameters": {"note": name},
    }
    text = calibration_yaml(doc)
    assert yaml.safe_load(text) == {k: v for k, v in doc.items()}
    assert all(line.startswith("#") for line in text.splitlines()[:5])
    comment = _comment_text(f"scenario {name} -- end-")
    assert "--" not in comment and not comment.endswith("-") and brk not in comment


@pytest.mark.parametrize("brk", ["\x1b[2J", "\u2028", "\x85", "\u202e"], ids=repr)
def test_init_refuses_a_joint_name_that_is_not_one_line(
    brk: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from nlp_calib.logs.joint_log import format_joint_csv

    t = np.arange(200) * 10_000_000 + T0
    names = ("left_wheel_joint", f"right_wheel_joint{brk}known")
    (tmp_path / "d.csv").write_text(format_joint_csv(t, names, np.zeros((200, 2))))
    (tmp_path / "d.tum").write_text("".join(f"{k / 100 + 1.7e9:.6f} 0 0 0 0 0 0 1\n" for k in range(200)))
    code, _, err = run(["init", tmp_path / "d.csv", "--out", tmp_path / "d.yaml"], capsys)
    assert code == 2, err
    line = one_line_error(err, "line break or control character", "right_wheel_joint")
    assert brk not in line
    assert not (tmp_path / "d.yaml").exists()


# ----------------------------------------------------------------------------- --dask addresses


@pytest.mark.parametrize(
    "address",
    [
        "",
        "/tmp/scheduler",
        "file:///tmp/scheduler",
        "inproc://scheduler",
        "tcp://host:99999999999999999999",
        "tcp://host:0",
        "tcp://host\n:8786",
        "tcp://" + "a" * 100_000 + ":8786",
        "tcp://bob:hunter2@host:8786",
        "bob:hunter2@host:8786",
        "localhost",
        "tcp://localhost",
        "tcp://host:87a6",
        "tcp://ho st:8786",
        "tcp://host:8786/path",
    ],
    ids=lambda a: repr(a[:40]),
)
def test_a_dask_address_is_checked_before_dask_sees_it(
    address: str, small_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(
        [
            "batch",
            small_log,
            "--scenario",
            REPO / "scenarios" / "demo.yaml",
            "--out",
            tmp_path / "b",
            "--dask",
            address,
        ],
        capsys,
    )
    assert code == 2, err
    line = one_line_error(err, "--dask", "tcp://HOST:PORT")
    assert "hunter2" not in err + out and len(line) < 400
    assert not (tmp_path / "b").exists()


def test_the_dask_address_forms_it_takes() -> None:
    from nlp_calib.cli.parser import dask_address

    for ok in ("tcp://10.0.0.5:8786", "scheduler.local:8786", "tls://a-b.example.org:8786", "[::1]:8786"):
        assert dask_address(ok) == ok


# ----------------------------------------------------------------------------- motions rows


def _motions(tmp: Path, rows: list[str]) -> Path:
    p = tmp / "m.csv"
    p.write_text("t_start,t_end,x,y,theta\n" + "".join(r + "\n" for r in rows))
    return p


def test_motions_rows_written_twice_are_kept_once_and_said(tmp_path: Path) -> None:
    from nlp_calib.core.errors import NlpCalibWarning
    from nlp_calib.logs.motions import read_motions

    rows = [f"1700000000.{k:03d},1700000000.{k + 1:03d},0.01,0.0,{k * 1e-3!r}" for k in range(100)]
    twice = [r for r in rows for _ in range(2)]
    with pytest.warns(
        NlpCalibWarning, match=r"100 of 200 rows repeat the interval of an earlier row \(first on line 3\)"
    ):
        table = read_motions(_motions(tmp_path, twice))
    assert table.n == 100 and table.line_numbers.tolist() == list(range(2, 202, 2))
    assert np.allclose(table.z[:, 2], np.arange(100) * 1e-3)


def test_motions_rows_lost_from_a_chain_are_said(tmp_path: Path) -> None:
    from nlp_calib.core.errors import NlpCalibWarning
    from nlp_calib.logs.motions import read_motions

    rows = [f"1700000000.{k:03d},1700000000.{k + 1:03d},0.01,0.0,0.0" for k in range(100) if k % 20 != 7]
    with pytest.warns(NlpCalibWarning, match=r"5 links are missing \(first before line 9"):
        assert read_motions(_motions(tmp_path, rows)).n == 95


@pytest.mark.parametrize("end", ["1700000000.5", "1700000000.4"])
def test_a_motions_row_that_does_not_run_forward_is_refused_with_its_line(end: str, tmp_path: Path) -> None:
    from nlp_calib.core.errors import DatasetError
    from nlp_calib.logs.motions import read_motions

    rows = ["1700000000.1,1700000000.2,0,0,0", f"1700000000.5,{end},0,0,0"]
    with pytest.raises(DatasetError, match=r"m.csv:3: t_end .* is not after t_start"):
        read_motions(_motions(tmp_path, rows))


# ----------------------------------------------------------------------------- memory


#: What reading a block costs whatever the file's size (its tokens as Python objects).
BLOCK_COST = 32 * 2**20


def _peak_kb(code: str) -> int:
    script = (
        code + "\nimport re\nprint(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read())[1])\n"
    )
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300, check=True
    )
    return int(proc.stdout.split()[-1])


@pytest.mark.parametrize("what", ["vendor", "motions"])
def test_a_large_file_costs_less_than_two_bytes_per_byte(what: str, tmp_path: Path) -> None:
    """300,000 rows (about 15 MB): the read's peak above the interpreter's, per byte of file."""
    n = 300_000
    t = 1_700_000_000 + np.arange(n) / 1000
    if what == "vendor":
        path = tmp_path / "odom.txt"
        body = np.column_stack([t, np.sin(t), np.cos(t), t % 1])
        np.savetxt(path, body, fmt=["%.3f", "%.6f", "%.6f", "%.6f"])
        call = (
            f"from nlp_calib.logs.vendor import read_odometry as r; x = r({str(path)!r}); "
            f"assert x.time_ns.size == {n}"
        )
    else:
        path = tmp_path / "m.csv"
        body = np.column_stack([t, t + 0.001, np.sin(t), np.cos(t), t % 1])
        np.savetxt(
            path,
            body,
            fmt=["%.3f", "%.3f", "%.5f", "%.5f", "%.5f"],
            delimiter=",",
            header="t_start,t_end,x,y,theta",
            comments="",
        )
        call = (
            f"from nlp_calib.logs.motions import read_motions as r; x = r({str(path)!r}); assert x.n == {n}"
        )
    imports = "import numpy, nlp_calib.logs.vendor, nlp_calib.logs.motions"
    base = _peak_kb(imports)
    peak = _peak_kb(imports + "\n" + call)
    size = path.stat().st_size
    # Two bytes per byte of file, and the fixed cost of a block being parsed (its tokens).
    assert (peak - base) * 1024 <= 2 * size + BLOCK_COST, (
        f"{(peak - base) / 1024:.0f} MB for a {size / 1e6:.0f} MB file"
    )


# ----------------------------------------------------------------------------- round five, the rest


def _joints_as(joints: Path, form: str, factor: float = 1.0, lost: float = 0.0, seed: int = 0) -> None:
    """Rewrite a joint CSV of positions as ``form``: speeds (times ``factor``, a unit's), or
    increments per cycle with a share ``lost`` of the rows dropped (stamps and all)."""
    from nlp_calib.logs.joint_log import format_joint_csv, read_joint_csv

    table = read_joint_csv(joints)
    t, pos = table.time_ns, np.asarray(table.positions, dtype=float)
    if form == "speeds":
        values = np.gradient(pos, t * 1e-9, axis=0) * factor
    else:
        values = np.vstack([np.zeros((1, pos.shape[1])), np.diff(pos, axis=0)])
        keep = np.random.default_rng(seed).random(t.size) >= lost
        keep[0] = True
        t, values = t[keep], values[keep]
    joints.write_text(format_joint_csv(t, table.names, values))


def _motions_scenario(folder: Path, form: str = "positions", seed: int = 5, duration: float = 30.0) -> Path:
    from test_references import recording

    joints, motions, truth = recording(folder, seed, duration=duration)
    (folder / "truth.json").write_text(json.dumps(truth))
    sc = folder / "m.yaml"
    sc.write_text(
        f"name: m\nmodel: diff_drive\ndataset: {{joints: {json.dumps(str(joints))}, motions: "
        f"{json.dumps(str(motions))}, form: {form}, sensor_frame: laser, encoders: "
        "{left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}\ninitial_guess: auto\n"
        "information: {translation: 1.0e6, rotation: 4.0e6}\nrobust: {kernel: huber, delta: 3.0}\n"
        "solvers: [gauss_newton]\n"
    )
    return sc


@pytest.mark.parametrize(("unit", "factor"), [("rpm", 60 / (2 * math.pi)), ("deg/s", 180 / math.pi)])
def test_wheel_speeds_in_another_unit_are_named_with_the_fix(
    unit: str, factor: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = _motions_scenario(tmp_path, "speeds")
    _joints_as(tmp_path / "drive.csv", "speeds", factor)
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 5, err  # the pre-flight's CHECK THE DATA
    line = one_line_error(err, f"speeds look like {unit}", "give them in rad/s")
    # The wheel the unit makes of the data: the truth's 0.1 m radius, to the percent.
    radius = float(line.split(f"read as {unit}, one of ")[1].split(" mm")[0])
    assert abs(radius / 100.0 - 1.0) < 0.02, line
    assert not (tmp_path / "out").exists()


def test_wheel_speeds_in_rad_s_raise_no_unit_finding(tmp_path: Path) -> None:
    from nlp_calib.pipeline import load_scenario
    from nlp_calib.pipeline.preflight import preflight

    sc = _motions_scenario(tmp_path, "speeds")
    _joints_as(tmp_path / "drive.csv", "speeds")
    with warnings_ignored():
        report = preflight(load_scenario(sc))
    assert report.units == ()


def test_a_bags_joint_velocities_in_rpm_are_named(
    lidar_sim: Any, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from nlp_calib.simulation.rosbag import JOINT_STATE

    t = lidar_sim.joint_time_s
    rpm = np.gradient(lidar_sim.joint_positions, t, axis=0) * 60 / (2 * math.pi)

    def velocity(ns: int, v: np.ndarray) -> Any:
        def build(ts: Any) -> Any:
            return ts.types[JOINT_STATE](
                header=header(ts, ns, ""),
                name=list(lidar_sim.joint_names),
                position=np.zeros(0),
                velocity=np.asarray(v, float),
                effort=np.zeros(0),
            )

        return ("/joint_states", JOINT_STATE, ns, build)

    out = [tf_static(round(t[0] * 1e9), "base_link", "laser", (0.2, 0.0, 0.3), 0.0)]
    out += [velocity(round(s * 1e9), v) for s, v in zip(t, rpm)]
    out += [scan_message(round(s * 1e9), r) for s, r in zip(lidar_sim.scan_time_s, lidar_sim.ranges)]
    sc = lidar_scenario(write_bag(tmp_path / "bag", out))
    code, _, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code == 5, err
    one_line_error(err, "speeds look like rpm")


@contextlib.contextmanager
def warnings_ignored() -> Any:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def test_the_intervals_a_break_in_the_joints_overlaps() -> None:
    from nlp_calib.logs.log import JointStream

    stream = JointStream(np.arange(10.0), np.zeros((10, 1)), (0.0,), (), np.array([[2.0, 3.0], [6.0, 7.0]]))
    t = np.array([0.0, 1.5, 2.5, 2.8, 3.0, 5.0, 6.0, 7.5, 9.0])
    want = [any(a < b1 and b > a1 for a1, b1 in ((2.0, 3.0), (6.0, 7.0))) for a, b in itertools.pairwise(t)]
    assert stream.broken(t).tolist() == want == [False, True, True, True, False, False, True, False]


def test_increment_rows_lost_are_found_from_their_stamps_and_no_window_crosses_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """5 % of the rows of wheel increments per cycle lost: the radii came out 3σ long with GOOD."""
    sc = _motions_scenario(tmp_path, "increments", duration=60.0)
    _joints_as(tmp_path / "drive.csv", "increments", lost=0.05, seed=105)
    code, out, err = run(["run", sc, "--out", tmp_path / "out"], capsys)
    assert code in (0, 3), err
    assert re.search(r"drive.csv: \d+ of \d+ rows follow the row before by more than 1.5 cycles", err), err
    assert "nan" not in out
    result = json.loads((tmp_path / "out" / "result.json").read_text())["solvers"]["gauss_newton"]
    truth = json.loads((tmp_path / "truth.json").read_text())
    for name, value in truth.items():
        assert abs(result["params"][name] - value) < 3 * result["std"][name], (name, result["params"][name])


def test_every_motions_row_twice_gives_the_sigma_of_once(tmp_path: Path) -> None:
    from nlp_calib.pipeline import Calibration, load_scenario

    stds = []
    for twice in (False, True):
        folder = tmp_path / str(twice)
        folder.mkdir()
        sc = _motions_scenario(folder, duration=20.0)
        if twice:
            head, *rows = (folder / "drive.motions.csv").read_text().splitlines()
            (folder / "drive.motions.csv").write_text(
                "\n".join([head, *(r for r in rows for _ in "ab")]) + "\n"
            )
        with warnings_ignored():
            calibration = Calibration(load_scenario(sc))
            stds.append(calibration.run().std("gauss_newton"))
    assert stds[0] == pytest.approx(stds[1], rel=1e-9)


def test_motions_of_the_opposite_sign_name_the_references_sign_convention(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = _motions_scenario(tmp_path, duration=20.0)
    head, *rows = (tmp_path / "drive.motions.csv").read_text().splitlines()
    mirrored = [
        ",".join([*f[:3], repr(-float(f[3])), repr(-float(f[4])), *f[5:]])
        for f in (r.split(",") for r in rows)
    ]
    (tmp_path / "drive.motions.csv").write_text("\n".join([head, *mirrored]) + "\n")
    _, out, _ = run(["run", sc, "--out", tmp_path / "out"], capsys)
    verdict = next(line for line in out.splitlines() if "verdict:" in line)
    assert "NOT DETERMINED" in verdict and "the reference's sign convention is mirrored" in verdict


@pytest.mark.parametrize("model", ["diff_drive", "tricycle"])
@pytest.mark.parametrize("fault", ["theta in degrees", "model in mm", "as it is"])
def test_vendor_odometry_in_the_wrong_units_is_named(model: str, fault: str) -> None:
    from nlp_calib.core.errors import ConfigError, DatasetError
    from nlp_calib.models import get_model
    from nlp_calib.models.radians import in_units
    from nlp_calib.simulation.camera import base_motion
    from nlp_calib.simulation.vendor import VendorSimulationOptions
    from nlp_calib.sources.vendor import check_arcs, vendor_readings

    opts = VendorSimulationOptions(model=model, duration_s=30.0, seed=3)
    t = np.arange(0.0, 30.0, 0.02)
    base, _ = base_motion(model, opts.truth, opts.drive, np.random.default_rng(3), t)
    vendor = opts.vendor_in_radians()
    m = in_units(get_model(model), "radians")
    if fault == "theta in degrees":
        odometry = base.copy()
        odometry[:, 2] = np.degrees(np.angle(np.exp(1j * base[:, 2])))
        with pytest.raises(DatasetError, match=r"its θ is in degrees; give it in radians"):
            check_arcs("odom.txt", odometry)
    elif fault == "model in mm":
        mm = {n: v * 1000 if m.units[n] == "m" else v for n, v in vendor.items()}
        with pytest.raises(ConfigError, match=r"looks given in millimetres; give its lengths in metres"):
            vendor_readings(m, base, mm)
    else:
        check_arcs("odom.txt", base)
        assert set(vendor_readings(m, base, vendor)) == set(m.encoder_kinds)


@pytest.mark.parametrize("brk", [b for b in BREAKS if "\n" not in b], ids=repr)
def test_stdout_spells_what_is_not_text(brk: str, capsys: pytest.CaptureFixture[str]) -> None:
    """A name in a table holding a control character: spelled, the table's lines kept (a line feed
    is the tool's own: a name holding one is refused where it is read)."""
    from nlp_calib.cli.streams import guarded
    from nlp_calib.core.text import escaped

    with guarded():
        print(f"joint   right{brk}wheel   0.1\nnext line")
    out = capsys.readouterr().out
    assert out == f"joint   right{escaped(brk)}wheel   0.1\nnext line\n" and brk not in out


@pytest.mark.parametrize("beams", [5, 30])
def test_a_narrow_field_of_view_is_named(beams: int, lidar_sim: Any, tmp_path: Path) -> None:
    from nlp_calib.core.errors import NlpCalibWarning
    from nlp_calib.logs.bag_files import BagError
    from nlp_calib.logs.scans import read_scans

    inc = 2 * math.pi / 180
    a = 90 - beams // 2

    def narrow(k: int, ns: int, r: np.ndarray) -> list[Any]:
        return [
            scan_message(
                ns,
                r[a : a + beams],
                angle_min=-math.pi + a * inc,
                angle_max=-math.pi + (a + beams - 1) * inc,
                angle_increment=inc,
            )
        ]

    bag = lidar_bag(lidar_sim, tmp_path, narrow)
    if beams < 10:
        with pytest.raises(BagError, match=r"holds 5 beams over 10° \(its field of view\)"):
            read_scans(bag, "/scan")
    else:
        with pytest.warns(NlpCalibWarning, match=r"the scans cover 60° \(30 beams\): a narrow field of view"):
            read_scans(bag, "/scan")


VENDOR_BLOCKS = {
    "diff_drive": "{left_wheel_radius: 0.1, right_wheel_radius: 0.1, wheel_separation: 0.45}",
    "tricycle": "{k_steer: 0.5, wheel_radius: 0.078, wheelbase: 1.45, steer_offset: 0.0}",
}


@pytest.mark.parametrize(
    ("robot", "declared"),
    [("diff_drive", "tricycle"), ("tricycle", "diff_drive"), ("diff_drive", "diff_drive")],
)
def test_vendor_odometry_of_another_model_is_said(robot: str, declared: str, tmp_path: Path) -> None:
    """Any model that turns odometry back reproduces any arcs, so the declared model's fit cannot
    tell it is the wrong one: the other models fitted to the same odometry and reference name the
    robot's own (a caveat with each model's cost per residual); the right one declared is fine."""
    from nlp_calib.pipeline.calibration import Calibration
    from nlp_calib.pipeline.scenario import load_scenario
    from nlp_calib.results.checks import CAVEAT, FINE
    from nlp_calib.results.run import CAVEATS
    from nlp_calib.simulation.vendor import VendorSimulationOptions, write_vendor_simulation

    odo, tum, _ = write_vendor_simulation(
        VendorSimulationOptions(model=robot, duration_s=40.0, seed=5), tmp_path / "odom.txt"
    )
    sc = tmp_path / "v.yaml"
    sc.write_text(
        f"name: v\nmodel: {declared}\ndataset: {{odometry: {odo.name}, poses: {tum.name}, "
        f"vendor: {VENDOR_BLOCKS[declared]}}}\nresidual: {{horizon_s: 0.5}}\nsolvers: [gauss_newton]\n"
    )
    run = Calibration(load_scenario(sc)).run()
    found = next(c for c in run.checks.more if c.name == "model")
    costs = found.table["cost_per_residual"]
    assert set(costs) == {"diff_drive", "tricycle"}
    if robot == declared:
        assert found.level == FINE and min(costs, key=lambda n: costs[n]) == robot
        return
    assert found.level == CAVEAT and found.about["likely"] == robot, found.words
    assert costs[declared] > 1.03 * costs[robot]
    assert f"looks integrated by a {robot} controller, not the declared {declared}" in found.words
    assert run.verdict.level == CAVEATS and found.words in run.verdict.reasons, run.verdict
    solver = run.chosen_solver()
    assert solver is not None
    assert set(run.verdict.concerns) == set(run.reports[solver].result.names)  # none handed off as calibrated


def test_a_table_that_grows_while_read_keeps_every_row(tmp_path: Path) -> None:
    """The columns are allocated for the lines counted when the file is opened; rows beyond them
    (a file appended to while read) are kept in order, none lost."""
    from nlp_calib.logs.text_tables import _Columns

    cols = _Columns(3, 2)
    blocks = [(np.arange(k, k + 2), np.full((2, 2), float(k)), np.arange(k, k + 2) + 10) for k in (0, 2, 4)]
    for block in blocks:
        cols.add(*block)
    time_ns, values, lines = cols.filled()
    for got, i in ((time_ns, 0), (values, 1), (lines, 2)):
        np.testing.assert_array_equal(got, np.concatenate([b[i] for b in blocks]))


@pytest.mark.parametrize("frame", ["base_link", "/base_link"])
def test_a_sensor_frame_that_is_the_base_is_refused_for_every_source(frame: str, tmp_path: Path) -> None:
    """A CSV source's sensor_frame equal to base_link handed off a joint from base_link to itself
    (a bag's frame_id and a lidar's were refused already): refused where every source is read."""
    from nlp_calib.core.errors import DatasetError
    from nlp_calib.pipeline.prepare import read_checked
    from nlp_calib.pipeline.scenario import load_scenario

    sc = _motions_scenario(tmp_path)
    sc.write_text(sc.read_text().replace("sensor_frame: laser", f"sensor_frame: {json.dumps(frame)}"))
    with pytest.raises(
        DatasetError, match="the sensor's frame is 'base_link', the frame its mount is calibrated in"
    ):
        read_checked(load_scenario(sc))
    sc.write_text(sc.read_text().replace(f"sensor_frame: {json.dumps(frame)}", "sensor_frame: base_laser"))
    assert read_checked(load_scenario(sc)).header.sensor_frame == "base_laser"
