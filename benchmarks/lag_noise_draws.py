"""Is one lag error a tail of its σ, a bias or a σ too small? Its drive, the tracker's noise drawn again.

    nice -n 10 python3 benchmarks/lag_noise_draws.py --model diff_drive --seed 501 --draws 40
    nice -n 10 python3 benchmarks/lag_noise_draws.py --seed 501 --draws 0 --own-scales 0.5 -1
    nice -n 10 python3 benchmarks/lag_noise_draws.py --seed 501 --draws 0 --jitter 0 --fine 10 --lag 0.04

A simulated text log (``SimulationOptions`` defaults but the seed: s-curves, 1500 records at
25 Hz), the tracker late by ``--lag`` (default: the 0–30 ms ``benchmarks/gate_study.py`` draws for
the seed), fitted with ``tracker_lag: auto`` as that study does. The log is simulated once without
tracker noise; each draw adds white noise of the simulator's size times ``--scale`` to the poses
(``--draws`` draws, their own generator), so the stamps, the encoders and the drive are the seed's
in every draw. Printed: the seed's own log (the simulator's draw of the noise), the noise-free log
(the estimator's bias on this drive), the seed's own noise times each of ``--own-scales`` (is the
error linear in it?), each draw, and over the draws the errors' mean and standard
deviation beside the mean white σ and σ to believe (``run.std``) and the RMS z. A σ that is right
on this drive has the errors' spread near it and the RMS z near 1; then the seed's own z against
that spread says how far in the tail its draw lies. ``--jitter`` sets the stamps' jitter and
``--fine N`` divides the wheel counters' gains by N (finer ticks): the noise-free fit without either
isolates what the re-sampling between records does. Nothing here tunes anything.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

#: This checkout (its code, not an installed one's, is what runs).
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from nlp_calib import Calibration, scenario_from_mapping  # noqa: E402
from nlp_calib.core.numeric import wrap_angle  # noqa: E402
from nlp_calib.simulation import SimulatedLog, SimulationOptions, simulate, write_simulation  # noqa: E402
from nlp_calib.simulation.options import Sampling, TrackerSim  # noqa: E402

#: The simulator's tracker noise (m, rad), which ``--scale`` multiplies.
NOISE = (TrackerSim().tracker_noise_xy, TrackerSim().tracker_noise_theta)
#: The wheel counters' gains (m per tick) that ``--fine`` divides.
COUNTER_GAINS = ("k_left", "k_right", "k_traction")
#: The draws' generators start here (apart from any simulation seed's own).
DRAW_SEED = 20_000


def options(model: str, seed: int, jitter: float, fine: float, lag: float) -> SimulationOptions:
    """The seed's simulation of ``model``, the stamps' jitter ``jitter`` and gains / ``fine``."""
    default = SimulationOptions(seed=seed, model=model)
    truth, guess = (
        {n: v / fine if n in COUNTER_GAINS else v for n, v in d.items()}
        for d in (default.truth, default.guess)
    )
    return replace(
        default,
        sampling=Sampling(jitter_s=jitter),
        tracker=TrackerSim(latency_s=lag),
        truth=truth,
        guess=guess,
    )


def fitted(sim: SimulatedLog, folder: Path, name: str, lag: float) -> tuple[float, float, float]:
    """The lag's error, white σ and σ to believe of ``sim`` fitted as ``gate_study.py`` fits it."""
    log, _ = write_simulation(sim, folder / f"{name}.txt")
    doc: dict[str, Any] = {"dataset": str(log), "model": sim.options.model, "initial_guess": "from_file"}
    doc |= {"solvers": ["gauss_newton"], "alignment": {"tracker_lag": "auto"}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(scenario_from_mapping(doc, name, folder)).run(["gauss_newton"])
    report = run.reports["gauss_newton"]
    u = report.uncertainty
    error = report.result.param_dict()["tracker_lag"] - lag
    return error, float(u.std[u.names.index("tracker_lag")]), run.std("gauss_newton")["tracker_lag"]


def noisy(clean: SimulatedLog, scale: float, rng: np.random.Generator) -> SimulatedLog:
    """``clean``'s tracker poses with white noise of the simulator's size times ``scale``."""
    poses = np.array(clean.T_world_sensor, dtype=float)
    n = poses.shape[0]
    poses[:, :2] += rng.normal(0.0, scale * NOISE[0], (n, 2))
    poses[:, 2] = wrap_angle(poses[:, 2] + rng.normal(0.0, scale * NOISE[1], n))
    return replace(clean, T_world_sensor=poses)


def scaled_own(own: SimulatedLog, clean: SimulatedLog, scale: float) -> SimulatedLog:
    """``clean`` with the seed's own tracker noise (``own``'s poses less ``clean``'s) times ``scale``."""
    noise = np.array(own.T_world_sensor, dtype=float) - clean.T_world_sensor
    noise[:, 2] = wrap_angle(noise[:, 2])
    poses = np.array(clean.T_world_sensor, dtype=float) + scale * noise
    poses[:, 2] = wrap_angle(poses[:, 2])
    return replace(clean, T_world_sensor=poses)


def line(label: str, error: float, white: float, told: float) -> str:
    return (
        f"{label:14s} error {1e3 * error:+7.2f} ms  σ white {1e3 * white:5.2f}  told {1e3 * told:5.2f} ms"
        f"  z {error / told:+6.2f}"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="diff_drive")
    ap.add_argument("--seed", type=int, default=501)
    ap.add_argument("--draws", type=int, default=20)
    ap.add_argument("--scale", type=float, default=1.0, help="the noise, in the simulator's")
    ap.add_argument("--lag", type=float, default=None, help="s (default: gate_study.py's for the seed)")
    ap.add_argument("--jitter", type=float, default=Sampling().jitter_s, help="the stamps' jitter (s)")
    ap.add_argument("--fine", type=float, default=1.0, help="the encoders' gains divided by this")
    ap.add_argument("--own-scales", type=float, nargs="*", default=[], help="the seed's noise times these")
    args = ap.parse_args()
    lag = float(np.random.default_rng(args.seed).uniform(0.0, 0.03)) if args.lag is None else args.lag
    opts = options(args.model, args.seed, args.jitter, args.fine, lag)
    own = simulate(opts)
    clean = simulate(
        replace(opts, tracker=TrackerSim(latency_s=lag, tracker_noise_xy=0.0, tracker_noise_theta=0.0))
    )
    print(
        f"{args.model} seed {args.seed}, lag {1e3 * lag:+.2f} ms, jitter {1e3 * args.jitter:g} ms, "
        f"gains / {args.fine:g}",
        flush=True,
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print(line("seed's own", *fitted(own, folder, "own", lag)), flush=True)
        print(line("noise-free", *fitted(clean, folder, "clean", lag)), flush=True)
        for k, scale in enumerate(args.own_scales):
            print(
                line(f"own × {scale:g}", *fitted(scaled_own(own, clean, scale), folder, f"s{k}", lag)),
                flush=True,
            )
        for d in range(args.draws):
            rows.append(
                fitted(noisy(clean, args.scale, np.random.default_rng(DRAW_SEED + d)), folder, f"d{d}", lag)
            )
            print(line(f"draw {d}", *rows[-1]), flush=True)
    if len(rows) > 1:
        err, white, told = (np.array(c) for c in zip(*rows))
        print(
            f"{len(rows)} draws (noise ×{args.scale:g}): error mean {1e3 * err.mean():+.2f} ms, "
            f"sd {1e3 * err.std(ddof=1):.2f} ms; mean σ white {1e3 * white.mean():.2f}, told "
            f"{1e3 * told.mean():.2f} ms; RMS z white {np.sqrt(np.mean((err / white) ** 2)):.2f}, "
            f"told {np.sqrt(np.mean((err / told) ** 2)):.2f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
