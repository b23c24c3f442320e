"""Hostile input, round three (issue 24): bags, several logs, IPOPT's own files, YAML 1.1 forms,
aliasing.

Every case of the corpus (``hostile3_corpus.py``) is a hostile input run as a user runs it, through
the command line (in this process, or in a child with a deadline where the point is that nothing
blocks), and judged the same way: no hang, no file lost (the files a case protects are byte for
byte the same afterwards, and files IPOPT could write do not appear), no silent result (the case
says what must be refused, dropped with a count, or read exactly, and checks it), and no "internal
error": an error is one line that names the file (or the key in it) and says what to do.

The parts that belong to the pipeline (one log is one log, per-log folders, a mirrored fit) are
the tests at the end.
"""

from __future__ import annotations

import json
import os
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import pytest
from conftest import write_sim
from hostile3_corpus import (
    CLASSES,
    CORPUS,
    T0_NS,
    Case,
    Expect,
    Outcome,
    World,
    bag_mapping,
    judge,
    run_child,
    run_in_process,
    scenario,
    snapshot,
)
from test_bags import drive_messages, write_bag

from nlp_calib.core.config import parse_yaml
from nlp_calib.logs.writer import format_time
from nlp_calib.models import get_model, load_log
from nlp_calib.solvers.ipopt import Ipopt, IpoptOptions

#: (class, name) -> seconds, filled as the cases run and reported by the last test.
TIMINGS: dict[tuple[str, str], float] = {}


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    folder = tmp_path_factory.mktemp("world")
    path = write_sim(folder, "drive.txt", records=300, seed=5)
    second = write_sim(folder, "second.txt", records=300, seed=6)
    w = World(folder, path, second, load_log(path, get_model("tricycle")))
    for fmt in ("ros1", "sqlite3", "mcap"):
        w.bags[fmt] = write_bag(folder / f"drive_{fmt}", fmt, w.messages())
    return w


@pytest.mark.parametrize("case", CORPUS, ids=[f"{c.cls}: {c.name}" for c in CORPUS])
def test_hostile_case(case: Case, world: World, tmp_path: Path) -> None:
    expect = case.build(world, tmp_path)
    before = {p: snapshot(p) for p in expect.keep}
    t0 = time.perf_counter()
    outcome = (run_child if expect.child else run_in_process)(expect.argv, expect.cwd)
    TIMINGS[(case.cls, case.name)] = time.perf_counter() - t0
    judge(expect, outcome)
    for path, was in before.items():
        assert snapshot(path) == was, f"lost: {path}"
    for path in expect.absent:
        assert not path.exists(), f"written: {path}"
    if expect.check is not None:
        expect.check(outcome)


def test_the_corpus_covers_every_class() -> None:
    counts = Counter(c.cls for c in CORPUS)
    assert set(counts) == set(CLASSES) and min(counts.values()) >= 10, counts
    assert len({(c.cls, c.name) for c in CORPUS}) == len(CORPUS)  # every case once
    print(f"\nround-three corpus: {len(CORPUS)} cases; " + ", ".join(f"{k} {counts[k]}" for k in CLASSES))
    if TIMINGS:
        worst = sorted(TIMINGS.items(), key=lambda kv: -kv[1])[:5]
        print("slowest: " + "; ".join(f"{name} ({cls}) {t:.2f} s" for (cls, name), t in worst))


# ----------------------------------------------------------------------------- units of the fixes


def test_negative_stamps_are_written_as_they_are_read() -> None:
    for ns in (-1_500_000_000, -500_000_000, -1, 0, 1, 1_700_000_000_123_456_789):
        text = format_time(ns)
        sec, frac = text.lstrip("-").split(".")
        assert (-1 if text.startswith("-") else 1) * (int(sec) * 10**9 + int(frac)) == ns, text


@pytest.mark.parametrize(
    ("text", "value"),
    [
        ("0x1F", 31),
        ("0o17", 15),
        ("08", 8),
        ("00", 0),
        ("yes", "yes"),
        ("Off", "Off"),
        ("~", None),
        ("1e3", 1e3),
    ],
)
def test_yaml_is_read_as_yaml_1_2(text: str, value: object) -> None:
    assert parse_yaml(f"v: {text}\n", "x") == {"v": value}


def test_ipopt_is_told_to_read_no_options_file() -> None:
    solver = Ipopt.__new__(Ipopt)
    solver.options = IpoptOptions()
    assert solver._ipopt_options()["ipopt.option_file_name"] == ""


# ------------------------------------------------------------------------ one log, one answer
# What these ask belongs to the pipeline's stages: the scenario's check of the logs, the per-log
# folders and the verdict that holds back a mirror image.


def _joint_run(world: World, tmp: Path, entries: Sequence[str]) -> Outcome:
    sc = scenario(tmp, "datasets:\n" + "".join(f"  - {e}\n" for e in entries))
    return run_in_process(["run", str(sc), "--out", str(tmp / "out")], tmp)


def test_the_same_log_through_a_hard_link_is_one_log(world: World, tmp_path: Path) -> None:
    os.link(world.log_path, tmp_path / "again.txt")
    outcome = _joint_run(world, tmp_path, [str(world.log_path), str(tmp_path / "again.txt")])
    judge(Expect([], (2,), ("datasets[1]", "again.txt", "the same log as datasets[0]")), outcome)


def test_a_bag_folder_and_its_own_db3_are_one_log(world: World, tmp_path: Path) -> None:
    folder = world.bags["sqlite3"]
    (db3,) = folder.glob("*.db3")
    outcome = _joint_run(world, tmp_path, [bag_mapping(folder), bag_mapping(db3)])
    judge(Expect([], (2,), ("datasets[1]", "the same log as datasets[0]")), outcome)


def test_per_log_folders_are_unique_and_name_their_logs(world: World, tmp_path: Path) -> None:
    paths = [tmp_path / "a" / "drive.txt", tmp_path / "b" / "drive.txt", tmp_path / "c" / "1_drive.txt"]
    for k, path in enumerate(paths):
        path.parent.mkdir()
        write_sim(path.parent, path.name, records=300, seed=10 + k)
    outcome = _joint_run(world, tmp_path, [str(p) for p in paths])
    judge(Expect([], (0,)), outcome)
    results = sorted((tmp_path / "out").glob("*/result.json"))
    datasets = {json.loads(r.read_text())["dataset"]["path"] for r in results}
    assert len(results) == 3 and datasets == {str(p) for p in paths}, results


def test_swapped_wheel_joints_name_the_cause_and_write_no_hand_off(tmp_path: Path) -> None:
    path = write_sim(tmp_path, "dd.txt", records=400, seed=2, model="diff_drive")
    log = load_log(path, get_model("diff_drive"))
    bag = write_bag(tmp_path / "dd", "mcap", drive_messages(log, T0_NS, joints=("left", "right")))
    sc = tmp_path / "swapped.yaml"
    sc.write_text(
        f"dataset: {{bag: {bag}, joint_states: /joint_states, joints: [right, left], "
        "tracker: /tracker/pose, joint_units: counts}\n"
        "model: diff_drive\ninitial_guess: auto\nsolvers: [gauss_newton]\n"
        "validation: {blocks: 0}\n"
    )
    outcome = run_in_process(["run", str(sc), "--out", str(tmp_path / "out")], tmp_path)
    assert "Traceback" not in outcome.err and "internal error" not in outcome.err
    said = outcome.out + outcome.err
    assert outcome.code != 0 and all(w in said for w in ("negative", "joints", "swapped")), said[-2000:]
    assert not (tmp_path / "out" / "calibration.yaml").exists()
