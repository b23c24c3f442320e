"""How often white noise alone makes a drive's blocks disagree (the block scatter's false alarms).

    python3 benchmarks/block_scatter_study.py OUTDIR [--seeds 7100-7129] [--model tricycle]

Simulates one log per seed (white tracker and encoder noise, nothing else), fits it with
Gauss-Newton and prints, per run, each free parameter's blocks' χ² about their weighted mean with
its degrees of freedom, and which parameters' σ the blocks widen (Birge ratio): under white noise
that should almost never happen (``nlp_calib.analysis.block_scatter.LEVEL`` per parameter); with
each, and for the worst parameter, the estimate's distance from the truth in the σ before the
widening (the larger of the white-noise σ and the residuals' own).
"""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from nlp_calib import Calibration
from nlp_calib.analysis import uncertainty as unc
from nlp_calib.pipeline import scenario_from_mapping
from nlp_calib.simulation.options import SimulationOptions
from nlp_calib.simulation.simulate import simulate_to_file


def one(out: Path, seed: int, model: str, sim: dict[str, float]) -> tuple[int, int]:
    opts = SimulationOptions.of(seed=seed, model=model, **sim)
    log, truth_path = simulate_to_file(opts, out / f"{model}_{seed}.txt")
    sc = scenario_from_mapping(
        {"dataset": str(log), "model": model, "initial_guess": "from_file", "solvers": ["gauss_newton"]},
        "sim",
        out,
    )
    cal = Calibration.setup(sc)
    r = cal.solve("gauss_newton")
    noise = cal.stages.windows.input_noise
    ranges = unc.range_std(cal.start.lower, cal.start.upper, cal.fns.n_free)
    u = unc.estimate(cal.evaluator, r.x, cal.data, noise[0], ranges, noise[1])
    chi2, dof = u.block_chi2 if u.block_chi2 is not None else (np.full(1, np.nan),) * 2
    truth, values = json.loads(truth_path.read_text())["params"], r.param_dict()
    floor = dict(zip(u.names, np.fmax(u.std, u.residual_spread())))
    z = {n: (values[n] - truth[n]) / floor[n] for n in u.free if n in truth and floor[n] > 0}
    fired = [f"{n} (z {z.get(n, np.nan):+.1f})" for n, s in zip(u.names, u.block_spread()) if np.isfinite(s)]
    judged = [f"{n} {c:.1f}/{d:.0f}" for n, c, d in zip(u.names, chi2, dof) if d > 0]
    worst = max(z, key=lambda n: abs(z[n]))
    print(
        f"seed {seed}: {', '.join(judged)}; widened: {', '.join(fired) or 'none'}; largest |estimate − "
        f"truth| / σ: {worst} {z[worst]:+.1f}",
        flush=True,
    )
    return len(fired), len(judged)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--seeds", default="7100-7129")
    ap.add_argument("--model", default="tricycle")
    ap.add_argument("--sim", nargs="*", default=[], help="simulation options NAME=VALUE (flat names)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    lo, hi = map(int, args.seeds.split("-"))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    fired = judged = runs = 0
    for seed in range(lo, hi + 1):
        f, j = one(out, seed, args.model, {k: float(v) for k, v in (a.split("=") for a in args.sim)})
        fired, judged, runs = fired + f, judged + j, runs + (f > 0)
    print(f"{args.model}: widened {fired} of {judged} parameters judged; {runs} of {hi - lo + 1} runs")


if __name__ == "__main__":
    main()
