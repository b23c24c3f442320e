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
from hostile3_corpus import run_in_process, snapshot
from hostile4_corpus import CLASSES, CORPUS, Case, World, judge, make_world, run_child

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
