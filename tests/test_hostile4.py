"""Hostile input, round four (issue 34): generated C, a shared compile cache, recordings that fit
well but are wrong, ``--urdf``, ``batch``, radians bags, ``check`` on a tampered calibration,
messages and the memory a large file costs.

Every case of the corpus (``hostile4_corpus.py``) is run as a user runs it, through the command
line (in this process, or in a child with a deadline and its own environment), and judged as in
round three: no hang, no file lost, no "internal error", an error is one line naming what and
where to fix; and, where the input is a recording that fits well but is wrong, the case checks
that the run refuses it, or ends with a verdict other than GOOD that names the likely cause and
writes no hand-off file, or gives the right answer.
"""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path

import pytest
from conftest import write_sim
from hostile3_corpus import run_in_process, snapshot
from hostile4_corpus import CLASSES, CORPUS, Case, World, judge, make_world, run_child

from nlp_calib.core.errors import NlpCalibError, NlpCalibWarning

#: (class, name) -> seconds, filled as the cases run and reported by the last test.
TIMINGS: dict[tuple[str, str], float] = {}


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    return make_world(tmp_path_factory.mktemp("world4"))


@pytest.mark.parametrize("case", CORPUS, ids=[f"{c.cls}: {c.name}" for c in CORPUS])
def test_hostile_case(case: Case, world: World, tmp_path: Path) -> None:
    expect = case.build(world, tmp_path)
    before = {p: snapshot(p) for p in expect.keep}
    t0 = time.perf_counter()
    if expect.child or expect.env:
        outcome = run_child(expect.argv, expect.cwd, expect.env)
    else:
        outcome = run_in_process(expect.argv, expect.cwd)
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
    assert set(counts) == set(CLASSES) and min(counts.values()) >= 8, counts
    assert len({(c.cls, c.name) for c in CORPUS}) == len(CORPUS)  # every case once
    print(f"\nround-four corpus: {len(CORPUS)} cases; " + ", ".join(f"{k} {counts[k]}" for k in CLASSES))
    if TIMINGS:
        worst = sorted(TIMINGS.items(), key=lambda kv: -kv[1])[:5]
        print("slowest: " + "; ".join(f"{name} ({cls}) {t:.2f} s" for (cls, name), t in worst))


# ----------------------------------------------------------------------------- units of the fixes


def test_a_large_log_is_said_to_be_so_before_it_is_read(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from nlp_calib.models import get_model
    from nlp_calib.sources import text

    log = write_sim(tmp_path, "drive.txt", records=100, seed=1)
    monkeypatch.setattr(text, "LARGE_LOG_BYTES", 1)
    with pytest.warns(NlpCalibWarning, match=r"drive.txt: 0 MB of records: a run of it holds about"):
        text.load_log(log, get_model("tricycle"))


@pytest.mark.parametrize(
    "tokens",
    [
        ["1700000000.123456789", "1700000001.000000001"],
        ["12", "13"],
        ["1.5", "2.5"],
        ["1.5", "2.x"],
        ["4100000000.5", "4100000000.6"],
        ["1.12345678912", "2.1"],
        ["1.1", "-2.2"],
        ["+5", "1_0", ".5", "-", "99999999999", "0.0000000019"],
    ],
)
def test_times_are_read_as_the_line_reader_reads_them(tokens: list[str]) -> None:
    from nlp_calib.logs.records import _NOT_A_TIME, _parse_time_ns
    from nlp_calib.logs.text_tables import times_of

    def one(token: str) -> int:
        try:
            return _parse_time_ns(token, "x", 1)
        except NlpCalibError:
            return _NOT_A_TIME

    assert times_of([t.encode() for t in tokens]).tolist() == [one(t) for t in tokens]


def test_a_table_with_comments_blanks_and_crlf_reads_as_its_lines(tmp_path: Path) -> None:
    from nlp_calib.logs.joint_log import read_joint_csv

    rows = [f"{1700000000 + k}.{k:09d},{k * 0.1!r},{-k * 0.2!r}" for k in range(5000)]
    rows[10] = "# a comment"
    rows[20] = ""
    rows[30] = rows[30].replace(",", " , ")
    text = "# made by hand\r\ntime,a,b\r\n" + "\r\n".join(rows) + "\r\n"
    path = tmp_path / "j.csv"
    path.write_bytes(text.encode())
    table = read_joint_csv(path)
    kept = [(k, r) for k, r in enumerate(rows) if r and not r.startswith("#")]
    assert table.line_numbers.tolist() == [k + 3 for k, _ in kept]
    assert table.positions.tolist() == [[float(v) for v in r.split(",")[1:]] for _, r in kept]
    assert table.time_ns.tolist() == [(1700000000 + k) * 10**9 + k for k, _ in kept]


def test_folder_names_stay_unique_whatever_plain_characters_and_case_make_of_them() -> None:
    from nlp_calib.fleet.jobs import job_names

    paths = [
        Path(p)
        for p in ("/d/a b.txt", "/d/a_b.txt", "/d/A_B.txt", "/d/ä.txt", "/d/ö.txt", "/d/..x.txt", "/d/x.txt")
    ]
    names = job_names(paths)
    assert len({n.lower() for n in names}) == len(paths), names
    assert names[:3] == ["a_b", "a_b-2", "A_B-3"]
    assert job_names([Path("/d/summary.csv.txt")]) == ["summary.csv-2"]


def test_a_mount_turned_upside_down_is_the_mirror_unless_given() -> None:
    from nlp_calib.sensors.mount import image_up, mirrored_mount

    truth = {"sensor_roll": -2.094, "sensor_pitch": 0.052, "sensor_yaw": -1.571}
    mirror = {"sensor_roll": 1.047, "sensor_pitch": -0.052, "sensor_yaw": -1.572}
    body = {"sensor_roll": 0.0, "sensor_pitch": 0.1, "sensor_yaw": 0.2}  # x forward, z up
    assert (image_up(truth), image_up(mirror), image_up(body)) == ("up", "down", "up")
    assert mirrored_mount(truth, None) == "" and "upside down" in mirrored_mount(mirror, None)
    assert mirrored_mount(mirror, mirror) == ""  # the user said the camera is so
