"""The pre-flight gate against the fit: does it refuse only what the fit then cannot determine?

    python3 benchmarks/gate_study.py --first 500 --seeds 4          # every model, seeds 500-503
    python3 benchmarks/gate_study.py --real ../shared/data/dataset.txt   # parts of a real log

Simulated text logs (``SimulationOptions`` defaults but the seed: s-curves, 1500 records at 25 Hz)
of every model in the registry, the tracker's stamps late by a lag drawn in 0–30 ms per seed (the
simulator stamps late, never early), run with the scenario a user writes first (``initial_guess:
from_file``, the lag fitted: ``alignment: {tracker_lag: auto}``, everything else the default);
``--straight`` adds one straight drive per model, which the gate must stop.
``--real LOG`` runs the parts of a real log the issue names (first 60 %, last 40 %, middle 60 %,
each leave-one-of-five-blocks-out part). For each: the gate's exit code (0 enough, 3 weak, 4 not
enough, 5 check the data), the fit's verdict, the largest |estimate − truth| in σ and the lag's
(simulated logs). Counted: false refusals (the gate stops, exit 4/5, a run the fit determines: its
verdict is not NOT DETERMINED) and misses (the gate lets through a run the fit says NOT DETERMINED),
and the lag's σ coverage. Nothing here tunes anything: the seeds are whatever the arguments say.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib import Calibration, scenario_from_mapping
from nlp_calib.models import MODELS
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.results.run import UNDETERMINED
from nlp_calib.simulation import SimulationOptions, simulate_to_file
from nlp_calib.simulation.options import DriveShape, TrackerSim

STOPS = (4, 5)


def judge(doc: dict[str, Any], name: str, folder: Path) -> tuple[int, str, dict[str, float]]:
    """The gate's exit code, the fit's verdict and |z| against the truth (empty: no truth)."""
    sc = scenario_from_mapping(doc, name, folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = preflight(sc).exit_code
        run = Calibration(sc).run(["gauss_newton"])
    truth = run.checks.truth
    z = {} if truth is None else {n: float(abs(v)) for n, v in zip(truth.names, truth.z) if np.isfinite(v)}
    return code, run.verdict.level, z


def simulated(folder: Path, model: str, seed: int, trajectory: str) -> tuple[dict[str, Any], str]:
    """A simulated log of ``model`` and the scenario a user writes first for it."""
    lag = float(np.random.default_rng(seed).uniform(0.0, 0.03))
    opts = SimulationOptions(
        seed=seed, model=model, drive=DriveShape(trajectory=trajectory), tracker=TrackerSim(latency_s=lag)
    )
    log, _ = simulate_to_file(opts, folder / f"{model}_{trajectory}_{seed}.txt")
    doc: dict[str, Any] = {"dataset": str(log), "model": model, "initial_guess": "from_file"}
    doc["solvers"] = ["gauss_newton"]
    doc["alignment"] = {"tracker_lag": "auto"}
    return doc, f"{model} {trajectory} seed {seed} (lag {1e3 * lag:+.1f} ms)"


def real_parts(path: Path) -> list[tuple[dict[str, Any], str]]:
    """The parts of a real log the gate must let through, as ``samples`` ranges of its records."""
    n = sum(1 for line in path.read_text().splitlines() if line.strip() and not line.startswith("#"))
    parts = {"first 60 %": [(0, int(0.6 * n))], "last 40 %": [(int(0.6 * n), n)]}
    parts["middle 60 %"] = [(int(0.2 * n), int(0.8 * n))]
    base: dict[str, Any] = {"dataset": str(path.resolve()), "model": "tricycle", "initial_guess": "from_file"}
    base["alignment"] = {"tracker_lag": "auto", "search": [-0.2, 0.2]}  # the shipped scenario's
    out = [({**base, "samples": {"start": a, "stop": b}}, f"real {k}") for k, [(a, b)] in parts.items()]
    cuts = np.linspace(0, n, 6).round().astype(int)
    for i in range(5):
        keep = [(int(a), int(b)) for j, (a, b) in enumerate(itertools.pairwise(cuts)) if j != i]
        doc = {
            **base,
            "datasets": [{"path": base["dataset"], "samples": {"start": a, "stop": b}} for a, b in keep],
        }
        del doc["dataset"]
        out.append((doc, f"real without block {i + 1} of 5"))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=500)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--models", nargs="+", default=list(MODELS))
    ap.add_argument("--straight", action="store_true", help="one straight drive per model, to be stopped")
    ap.add_argument("--real", type=Path, default=None)
    args = ap.parse_args()
    false_refusals = misses = cases = 0
    lag_z: list[float] = []
    drive_z: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        seeds = range(args.first, args.first + args.seeds)
        jobs = [simulated(folder, m, s, "s_curves") for m in args.models for s in seeds]
        # One model per seed (in turn, as benchmarks/lag_coverage.py takes them): its lag's z is
        # that drive's one independent draw.
        own = {f"{args.models[s % len(args.models)]} s_curves seed {s} " for s in seeds}
        if args.straight:
            jobs += [simulated(folder, m, args.first, "straight") for m in args.models]
        if args.real is not None:
            jobs += real_parts(args.real)
        for i, (doc, label) in enumerate(jobs):
            code, level, z = judge(doc, f"case{i}", folder)
            stopped, determined = code in STOPS, level != UNDETERMINED
            cases += 1
            false_refusals += stopped and determined
            misses += not stopped and not determined
            if "tracker_lag" in z:
                lag_z.append(z["tracker_lag"])
                if any(label.startswith(o) for o in own):
                    drive_z.append(z["tracker_lag"])
            worst = max(z.values(), default=float("nan"))
            lz = z.get("tracker_lag", float("nan"))
            print(
                f"{label}: gate exit {code}, verdict {level}, worst |z| {worst:.2f}, lag |z| {lz:.2f}",
                flush=True,
            )
    lags = np.array(lag_z)
    print(f"gate: {false_refusals} false refusals, {misses} misses over {cases} runs")
    if lags.size:
        within = f"{np.mean(lags <= 1):.3f} within 1σ, {np.mean(lags <= 2):.3f} within 2σ"
        # One seed's models share its drive's stamps and tracker noise: their lags' z are one draw,
        # not several (seed 501's seven all lie 1.7-3.2σ low: that drive's noise, a 2.6σ draw by
        # benchmarks/lag_noise_draws.py); benchmarks/lag_coverage.py gives each log its own seed.
        print(f"the lag: {within} ({lags.size} logs, {args.seeds} independent drives)")
        if drive_z:
            one = np.array(drive_z)
            print(
                f"the lag, one model per drive: {np.mean(one <= 1):.3f} within 1σ, "
                f"{np.mean(one <= 2):.3f} within 2σ ({one.size} drives)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
