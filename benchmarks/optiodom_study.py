"""Several real runs fitted together: the OptiOdom sessions (a differential drive and a tricycle).

    python benchmarks/optiodom_study.py [--root DIR] [--json FILE]

Every session folder under ``--root`` (``<robot>/<path type>/<session>/`` holding two or more
``*_run-NN.csv`` joint logs, each with its ``.tum`` beside it, as the shared data folder holds them)
is fitted as one ``datasets:`` calibration with the settings of the shipped scenario for that robot
(``scenarios/optiodom_diff_circular.yaml``, ``scenarios/optiodom_tricycle_circular.yaml``). Printed:
each session's verdict and why, and, per robot and path type, how each parameter scatters from
session to session against the σ each session reports. Nothing is written but ``--json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nlp_calib.pipeline import Calibration, Scenario, scenario_from_mapping

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"
SHARED = Path("/work/shared/data/real4/optiodom")
#: The shipped scenario whose settings each robot's sessions are fitted with.
TEMPLATE = {"diff": "optiodom_diff_circular", "tricyc": "optiodom_tricycle_circular"}


def session_scenario(folder: Path) -> Scenario:
    """The shipped scenario of the session's robot, on the session's runs."""
    robot = folder.parts[-3]
    raw = yaml.safe_load((SCENARIOS / f"{TEMPLATE[robot]}.yaml").read_text())
    entry = raw["datasets"][0]
    runs = sorted(folder.glob("*_run-*.csv"))
    raw["datasets"] = [
        {
            **entry,
            "joints": str(r),
            "poses": str(r.with_suffix(".tum")),
            "robot": str(SCENARIOS / entry["robot"]),
        }
        for r in runs
    ]
    raw["name"] = folder.name
    raw["solvers"] = ["gauss_newton"]
    return scenario_from_mapping(raw, folder.name, folder)


def sessions(root: Path) -> list[Path]:
    """Session folders with two runs or more, robot by robot and path type by path type."""
    found = [p.parent for p in root.glob("*/*/*/*_run-02.csv")]
    return sorted(set(found), key=lambda p: p.parts[-3:])


def fit(folder: Path) -> dict[str, Any]:
    """One session's joint fit, as the figures this study reports."""
    sc = session_scenario(folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    solver = run.chosen_solver()
    out: dict[str, Any] = {
        "session": "/".join(folder.parts[-3:]),
        "runs": len(run.logs) or 1,
        "verdict": run.verdict.level,
        "reasons": list(run.verdict.reasons),
        "gain": run.verdict.gain,
        "logs": [p.verdict.level for p in run.logs],
    }
    if solver is None:
        return out
    u = run.reports[solver].uncertainty
    params = run.reports[solver].result.param_dict()
    blocks = run.checks.crossval.std if run.checks.crossval is not None else np.full(len(u.names), np.nan)
    logs = run.checks.logs.std if run.checks.logs is not None else np.full(len(u.names), np.nan)
    check = run.checks.consistency
    out.update(
        params=params,
        std=run.std(solver),
        std_white=dict(zip(u.names, map(float, u.std))),
        std_blocks=dict(zip(u.names, map(float, blocks))),
        std_logs=dict(zip(u.names, map(float, logs))),
        moved=[n for n, m in zip(u.names, check.moved) if m] if check is not None else [],
        apart=bool(check is not None and check.significant),
    )
    return out


def group_key(session: str, by_day: bool) -> str:
    """A session's group: its robot and path type, and with ``by_day`` its day (a session's name
    starts with its date, DDMMYYYY)."""
    robot, path, name = session.split("/")
    return f"{robot}/{path}" + (f"/{name[:8]}" if by_day else "")


def spread_rows(results: list[dict[str, Any]], by_day: bool = False) -> list[str]:
    """Per robot and path type (``by_day``: and day), each parameter's session-to-session spread
    against its σ."""
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for r in results:
        if "params" in r:
            groups[group_key(r["session"], by_day)].append(r)
    rows = [
        f"| robot/path{'/day' if by_day else ''} | sessions | parameter | mean | "
        "spread (std over sessions) | median σ | spread / σ |",
        "|---|---|---|---|---|---|---|",
    ]
    for key, rs in groups.items():
        if len(rs) < 3:
            continue
        # The robot's parameters (each log's own clock offset is no session's to compare).
        for name in (n for n in rs[0]["params"] if all(n in r["params"] for r in rs)):
            values = np.array([r["params"][name] for r in rs])
            sigma = np.array([r["std"][name] for r in rs])
            if not np.any(sigma > 0):
                continue  # held
            spread = float(np.std(values, ddof=1))
            med = float(np.median(sigma))
            rows.append(
                f"| {key} | {len(rs)} | {name} | {np.mean(values):.6g} | {spread:.3g} | {med:.3g} | "
                f"{spread / med:.2f} |"
            )
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--root", type=Path, default=SHARED)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    t0 = time.perf_counter()
    results = []
    for folder in sessions(args.root):
        r = fit(folder)
        results.append(r)
        moved = ", ".join(r.get("moved", [])) or "-"
        print(
            f"{r['session']}: {r['runs']} runs, {r['verdict']} (logs: {', '.join(r['logs'])}; moved: {moved})"
        )
        if r["verdict"] == "not usable":
            print("   " + "; ".join(r["reasons"]))
        sys.stdout.flush()
    levels: dict[str, int] = defaultdict(int)
    for r in results:
        levels[r["verdict"]] += 1
    print("\nverdicts: " + ", ".join(f"{k} {v}" for k, v in levels.items()))
    print("\n".join(spread_rows(results)))
    print("\n".join(["", *spread_rows(results, by_day=True)]))
    print(f"\n_Study run time: {time.perf_counter() - t0:.0f} s._")
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
