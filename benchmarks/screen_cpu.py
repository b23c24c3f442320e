"""The fault screen's CPU time on a scenario's log, and the report it gives, as a run screens it.

    python benchmarks/screen_cpu.py scenarios/demo.yaml --data LOG [--report OUT.pkl]

The scenario's log (``--data``: another, as ``run --data`` takes it) is prepared and its problem
built as ``run`` does (``pipeline.stages.align_log``'s stages before the screen); then the screen
stage runs once and its CPU time (``time.process_time``, every thread of this process) is printed
with the load average before and after, the process's peak RSS (the whole process: reading the
log included) and what it found. ``--report`` pickles the fault report, to compare two checkouts'
to the bit (run each with its own ``PYTHONPATH``). Logs at scale:
``nlp-calib simulate --records 1000000 --seed 7 --out LOG`` (the demo's), or
``nlp-calib simulate --config scenarios/data/camera_demo.sim.yaml --duration 20000 --out LOG.tum``
(10^6 camera poses).
"""

from __future__ import annotations

import argparse
import pickle
import resource
import time
import warnings
from pathlib import Path

from nlp_calib.pipeline.build import build_stage
from nlp_calib.pipeline.prepare import prepare
from nlp_calib.pipeline.scenario import load_scenario
from nlp_calib.pipeline.screen import screen


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenario", type=Path)
    parser.add_argument("--data", type=Path, help="the log to screen instead of the scenario's")
    parser.add_argument("--report", type=Path, help="pickle the fault report here")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    sc = load_scenario(args.scenario)
    sc = sc.with_dataset(args.data) if args.data is not None else sc
    prepared = prepare(sc, None)
    read, records = prepared.log, (prepared.start, prepared.stop)
    problem = build_stage(
        prepared.scenario,
        prepared.model,
        tuple(prepared.held),
        (read, prepared.start, prepared.split),
        tuple(sc.solvers),
        records[1] - records[0],
        gaps=prepared.gaps,
    )
    before, start = _load(), time.process_time()
    screening = screen(problem.binder, read, records, problem.start.x0)
    cpu, after = time.process_time() - start, _load()
    report = screening.findings.report
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024
    if args.report is not None:  # written first: a reader of the first line alone may close the pipe
        with args.report.open("wb") as f:
            pickle.dump(report, f)
    print(f"screen cpu {cpu:.2f} s; process peak RSS {peak} MB; load {before} -> {after}")
    print(f"{len(report.faults)} faults; stale {report.stale}; noise {report.noise}; lag {report.lag_s}")


if __name__ == "__main__":
    main()
