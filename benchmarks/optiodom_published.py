"""Each OptiOdom session's estimate against the calibrations the data set publishes, in the tool's σ.

    python benchmarks/optiodom_published.py STUDY_JSON PUBLISHED_CSV

``STUDY_JSON``: what ``benchmarks/optiodom_study.py --json`` writes; ``PUBLISHED_CSV``: the
published calibrations in nlp_calib's names (``sheet, directory, wheel_separation_or_wheelbase,
right_or_traction_radius, left_radius, steer_offset_rad``; the shared data folder's
``published.csv``). Printed: per method and parameter, how many sessions lie within 2σ and 3σ of
our estimate (σ: the σ each session's run reports), the largest differences, and how far the
published methods lie from each other in the same σ (they publish no σ of their own).
"""

from __future__ import annotations

import argparse
import csv
import json
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

#: The published columns as each robot's parameters.
NAMES = {
    "diff": {
        "wheel_separation_or_wheelbase": "wheel_separation",
        "right_or_traction_radius": "right_wheel_radius",
        "left_radius": "left_wheel_radius",
    },
    "tricyc": {
        "wheel_separation_or_wheelbase": "wheelbase",
        "right_or_traction_radius": "wheel_radius",
        "steer_offset_rad": "steer_offset",
    },
}


def pairs(
    study: dict[str, Any], rows: list[dict[str, str]]
) -> list[tuple[str, str, str, float, float, float]]:
    """(method, session, parameter, ours, published, our σ) for every published value of a fitted session."""
    out = []
    for row in rows:
        session = row["directory"]
        robot = session.split("/")[0]
        fit = study.get(session)
        if fit is None or "params" not in fit or robot not in NAMES:
            continue
        for column, name in NAMES[robot].items():
            if row[column]:
                out.append(
                    (row["sheet"], session, name, fit["params"][name], float(row[column]), fit["std"][name])
                )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("study", type=Path)
    ap.add_argument("published", type=Path)
    args = ap.parse_args()
    study = {r["session"]: r for r in json.loads(args.study.read_text())}
    with args.published.open() as f:
        found = pairs(study, list(csv.DictReader(f)))
    z: dict[tuple[str, str], list[float]] = defaultdict(list)
    for method, _, name, ours, theirs, sd in found:
        z[(method, name)].append((ours - theirs) / sd)
    print("method | parameter | sessions | within 2σ | within 3σ | z min | z median | z max")
    for (method, name), values in sorted(z.items()):
        v = np.array(values)
        print(
            f"{method} | {name} | {v.size} | {np.mean(abs(v) < 2):.0%} | {np.mean(abs(v) < 3):.0%} | "
            f"{v.min():+.1f} | {np.median(v):+.1f} | {v.max():+.1f}"
        )
    every = np.array([abs(ours - theirs) / sd for _, _, _, ours, theirs, sd in found])
    print(
        f"all: {every.size} comparisons, {np.mean(every < 2):.0%} within 2σ, "
        f"{np.mean(every < 3):.0%} within 3σ"
    )
    print("largest:")
    for method, session, name, ours, theirs, sd in sorted(found, key=lambda p: -abs(p[3] - p[4]) / p[5])[:8]:
        print(
            f"  {method} {session} {name}: ours {ours:.6g} ± {sd:.2g}, published {theirs:.6g}: "
            f"{abs(ours - theirs) / sd:.1f}σ ({100 * (ours - theirs) / theirs:+.2f} %)"
        )
    print("published methods against each other, per session (max − min over the methods, in our σ):")
    by: dict[tuple[str, str], list[float]] = defaultdict(list)
    for _, session, name, _, theirs, _ in found:
        by[(session, name)].append(theirs)
    spread: dict[tuple[str, str], list[float]] = defaultdict(list)
    for (session, name), values in by.items():
        if len(values) > 1:
            spread[(session.split("/")[0], name)].append(
                (max(values) - min(values)) / study[session]["std"][name]
            )
    for (robot, name), s in sorted(spread.items()):
        print(
            f"  {robot} {name}: {len(s)} sessions, median {np.median(s):.1f}σ, "
            f"range {min(s):.1f}–{max(s):.1f}σ"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
