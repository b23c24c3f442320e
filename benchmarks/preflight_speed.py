"""How long ``nlp-calib preflight`` takes on 10^5 records, and what it says, as a user runs it.

    python benchmarks/preflight_speed.py                  # 3 runs of each, medians
    python benchmarks/preflight_speed.py --repeats 1      # a quick look

Drives (written into a temporary folder): a simulated tricycle driving straight (``simulate
--trajectory straight``, 10^5 records, a lag search) and the same on S-curves (the demo's drive),
a camera on a differential drive whose wheels turn at 2·cos t and 2·sin t rad/s (10^5 camera
poses at 50 Hz, joints at 100 Hz: the drive of tests/test_clock.py, longer), and the circle-only
session of a real tricycle where it lies (OptiOdom, ``shared/data/real4``; 3,837 records). Each
is checked by ``python -m nlp_calib preflight`` in a fresh process; printed: the wall time, the
child's CPU time, the pre-flight's own time in its report, the verdict and what it names; then, in
this process, the CPU time of reading the log and of the pre-flight's analysis once it is read
(its first call: building the problem's Functions included). The machine's load is printed too:
on a shared machine, CPU time is the fairer figure.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nlp_calib.core import poses3d

REPO = Path(__file__).resolve().parents[1]


def _sinusoids(folder: Path, poses: int) -> Path:
    """The two-sinusoid camera drive with ``poses`` camera poses (see the module docstring)."""
    r, b, dt, mount = 0.1, 0.57, 0.01, (0.36, 0.06, 0.10, -1.58, 0.012, -1.55)
    t = np.arange(2 * poses + 1) * dt
    wl, wr = 2.0 * np.cos(t[:-1]), 2.0 * np.sin(t[:-1])
    travel, turn = 0.5 * r * (wl + wr) * dt, r * (wr - wl) / b * dt
    theta = np.concatenate([[0.0], np.cumsum(turn)])
    c = np.sinc(turn / (2 * np.pi)) * travel
    x = np.concatenate([[0.0], np.cumsum(c * np.cos(theta[:-1] + turn / 2))])
    y = np.concatenate([[0.0], np.cumsum(c * np.sin(theta[:-1] + turn / 2))])
    planar = np.column_stack([x, y, theta])
    cam = poses3d.compose(poses3d.from_planar(planar), poses3d.mount_pose(np.array(mount)))
    images = np.arange(0, t.size, 2)
    rows = np.column_stack([1e9 + t[images] + 0.01, cam[images]])
    np.savetxt(folder / "cam.tum", rows, fmt="%.6f")
    joints = np.column_stack(
        [1e9 + t, np.concatenate([[0], np.cumsum(wl * dt)]), np.concatenate([[0], np.cumsum(wr * dt)])]
    )
    np.savetxt(
        folder / "cam.joints.csv",
        joints,
        fmt="%.6f",
        delimiter=",",
        header="time,left_wheel_joint,right_wheel_joint",
        comments="",
    )
    path = folder / "sinusoids.yaml"
    path.write_text(
        "name: sinusoids\nmodel: diff_drive\nsensor: 3d\ninitial_guess: auto\nknown: {sensor_z: 0.10}\n"
        "dataset: {poses: cam.tum, joints: cam.joints.csv,\n"
        "          encoders: {left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}\n"
        "alignment: {tracker_lag: auto, search: [-0.05, 0.05]}\nresidual: {horizon_s: 0.25}\n"
        "information: {translation: 1.0e+6, rotation: 3.0e+5}\nrobust: {kernel: huber, delta: 10.0}\n"
    )
    return path


def _simulated(folder: Path, name: str, trajectory: str, records: int) -> Path:
    log = folder / f"{name}.txt"
    subprocess.run(
        [sys.executable, "-m", "nlp_calib", "simulate", "--out", str(log), "--records", str(records),
         "--seed", "3", "--trajectory", trajectory, "--force"],
        check=True, capture_output=True,
    )  # fmt: skip
    path = folder / f"{name}.yaml"
    path.write_text(
        f"name: {name}\nmodel: tricycle\ndataset: {log.name}\ninitial_guess: from_file\n"
        "residual: {horizon: 10}\nalignment: {tracker_lag: auto, search: [-0.1, 0.1]}\n"
    )
    return path


def _circles(folder: Path) -> Path | None:
    for parent in REPO.parents:
        session = parent / "shared" / "data" / "real4" / "optiodom" / "tricyc" / "circular" / "140120211440"
        if session.is_dir():
            break
    else:
        return None
    entries = "\n".join(
        f"  - {{joints: {r}, poses: {r.with_suffix('.tum')}, encoders: {{steering: steer_joint, "
        "traction_wheel: traction_joint}}"
        for r in sorted(session.glob("*_run-*.csv"))
    )
    path = folder / "circles.yaml"
    path.write_text(
        f"name: circles\nmodel: tricycle\ndatasets:\n{entries}\ninitial_guess: auto\n"
        "residual: {horizon_s: 0.5}\nalignment: {tracker_lag: auto, search: [-0.1, 0.1]}\n"
    )
    return path


def _timed(scenario: Path) -> tuple[float, float, dict[str, object]]:
    """Wall and CPU seconds of one ``preflight`` in a fresh process, and its JSON report."""
    report = scenario.with_suffix(".preflight.json")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "nlp_calib", "preflight", str(scenario), "--json", str(report)],
        capture_output=True, env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, json.loads(report.read_text())


def _in_process(scenario: Path) -> tuple[float, float]:
    """CPU seconds of reading the scenario's logs, and of the pre-flight once they are read."""
    from nlp_calib.pipeline import load_scenario
    from nlp_calib.pipeline.preflight import preflight
    from nlp_calib.pipeline.prepare import read

    sc = load_scenario(scenario)
    t0 = time.process_time()
    logs = [read(s)[1] for s in sc.per_log()]
    t1 = time.process_time()
    preflight(sc, logs)
    return t1 - t0, time.process_time() - t1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        drives = {
            "straight, 10^5 records": _simulated(folder, "straight", "straight", 100_000),
            "S-curves, 10^5 records": _simulated(folder, "s_curves", "s_curves", 100_000),
            "two sinusoids, 10^5 camera poses": _sinusoids(folder, 100_000),
        }
        circles = _circles(folder)
        if circles is not None:
            drives["OptiOdom circles, 3837 records"] = circles
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
        print(
            f"{'drive':34s} {'wall [s]':>9s} {'CPU [s]':>8s} {'own [s]':>8s} {'read':>6s} {'check':>6s}  "
            "verdict: named"
        )
        for label, scenario in drives.items():
            runs = [_timed(scenario) for _ in range(args.repeats)]
            wall, cpu = (float(np.median([r[i] for r in runs])) for i in (0, 1))
            doc = runs[-1][2]
            own = float(np.median([float(r[2]["time_s"]) for r in runs]))  # type: ignore[arg-type]
            named = [p["name"] for p in doc["parameters"] if p["status"] != "determined"]  # type: ignore[attr-defined]
            reading, checking = _in_process(scenario)
            print(
                f"{label:34s} {wall:9.2f} {cpu:8.2f} {own:8.2f} {reading:6.2f} {checking:6.2f}  "
                f"{doc['verdict']}: {', '.join(named) or '-'}"
            )


if __name__ == "__main__":
    main()
