"""Does re-sampling a simulated log's encoders at a lag move the data as much as the lag says?

    python benchmarks/lag_resample_study.py LOG --model MODEL [--horizon 1] [--lags -1e-4,-3e-4]

LOG is a simulated log with its ``<stem>.truth.json`` beside it (``nlp-calib simulate``), its true
lag 0. For each lag τ₀ it prints how many of each encoder's readings the re-sampling at τ₀ changes,
and the Gauss-Newton step from the truth with the lag started at τ₀ on the encoders re-sampled
there: the lag that fit reports and g(τ₀) = that lag − τ₀, whose root the alignment's re-samplings
look for (``pipeline/align.py``). Where the re-sampling changes no reading, the fit sees the logged
data whatever τ₀ and g is the same at every τ₀: no root there, and each re-sampling moves the lag
by that much again until the readings change.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from nlp_calib.logs import Log, resample_encoders
from nlp_calib.models import get_model, load_log
from nlp_calib.problem import ProblemSpec, build, build_residual_data
from nlp_calib.problem.windows import ResidualOptions
from nlp_calib.solvers import ProblemEvaluator

LAGS = "0,-1e-5,-1e-4,-2e-4,-3e-4,-4.5e-4,-1e-3,1e-4,3e-4"


def fitted_lag(log: Log, model_name: str, horizon: int, truth: dict[str, float], lag_s: float) -> float:
    """The lag of one Gauss-Newton step from the truth (the lag at ``lag_s``) on ``log``'s encoders
    re-sampled at ``lag_s`` (no robust kernel, unit weights)."""
    model = get_model(model_name)
    fns = build(model, ProblemSpec(horizon=horizon, lags=1))
    shifted = resample_encoders(log, lag_s, model.encoder_kinds)[0]
    data = build_residual_data(fns, shifted, ResidualOptions(horizon=horizon))
    ev = ProblemEvaluator(fns, data, x_fixed=np.zeros(0), omega=np.ones(3), delta=1e9)
    x = np.array([*(truth.get(n, 0.0) for n in fns.names[:-1]), lag_s])
    ne = ev.normal_equations(x)
    return lag_s + float(-np.linalg.solve(ne.H, ne.g)[-1])


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("log", type=Path)
    parser.add_argument("--model", required=True)
    parser.add_argument("--horizon", type=int, default=1)
    parser.add_argument("--lags", default=LAGS, help="comma-separated lags τ₀ (s)")
    args = parser.parse_args()
    truth = json.loads(args.log.with_suffix(".truth.json").read_text())["params"]
    log = load_log(args.log, get_model(args.model))
    print(f"encoders: {', '.join(log.header.encoder_names)}")
    for lag in (float(v) for v in args.lags.split(",")):
        shifted = resample_encoders(log, lag, get_model(args.model).encoder_kinds)[0]
        changed = np.sum(shifted.ticks != log.ticks, axis=0).tolist()
        fit = fitted_lag(log, args.model, args.horizon, truth, lag)
        print(
            f"τ₀ {1e6 * lag:+8.1f} µs: readings changed {changed} of {log.n_records}; "
            f"fitted lag {1e6 * fit:+8.1f} µs, g {1e6 * (fit - lag):+8.1f} µs"
        )


if __name__ == "__main__":
    main()
