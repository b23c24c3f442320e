"""CPU of the trajectory figures alone on a simulated drive of N records (the predicted steps left out).

    python benchmarks/metrics_cpu.py                       # this checkout, 10^6 records
    python benchmarks/metrics_cpu.py --repo ../main --records 1000000 --faults --out A.pkl

What a run of the demo's scenario scores: four parameter sets over every record (the two solvers',
the initial guess, the nominal robot), then two on each of ten blocks (each fold's estimate and
the full fit's on the block it left out). Each set's predicted steps are computed before the
clock starts (in a run a compiled Function's evaluation, timed elsewhere): what is printed
(``time.process_time``) is the figures' arithmetic. ``--faults``: 20 bad intervals and 50 bad
tracker poses at random (a segment ATE per part). ``--out``: the figures pickled, to compare two
checkouts' bits (``repr`` of the lists).
"""

from __future__ import annotations

import argparse
import itertools
import pickle
import sys
import time
from pathlib import Path
from typing import Any


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[1]))
    ap.add_argument("--records", type=int, default=1_000_000)
    ap.add_argument("--faults", action="store_true")
    ap.add_argument("--out")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(args.repo).resolve()))
    import numpy as np

    from nlp_calib.analysis import metrics
    from nlp_calib.models import get_model
    from nlp_calib.problem import ProblemSpec, build

    n = args.records
    fns = build(get_model("tricycle"), ProblemSpec(horizon=1))
    p = np.array([0.5, 0.01, 1.5, 0.0, 1.0, 0.0, 0.0])
    rng = np.random.default_rng(3)
    inputs = np.vstack([rng.uniform(0.0, 0.05, n - 1), rng.uniform(-0.3, 0.3, n - 1)])
    ref = metrics.integrate(fns, p, inputs, np.zeros(3)) + rng.normal(0.0, 0.01, (n, 3))
    bad_i, bad_r = np.zeros(n - 1, dtype=bool), np.zeros(n, dtype=bool)
    if args.faults:
        bad_i[rng.integers(0, n - 1, 20)] = True
        bad_r[rng.integers(0, n, 50)] = True
    kw: dict[str, Any] = {"rpe_window": 25, "bad_intervals": bad_i, "bad_records": bad_r}
    steps, cache = metrics.steps, {}

    def cached(fns_: Any, params: np.ndarray, inputs_: np.ndarray) -> np.ndarray:
        key = (np.asarray(params).tobytes(), inputs_.shape[1], inputs_[:, :1].tobytes())
        if key not in cache:
            cache[key] = steps(fns_, params, inputs_)
        return cache[key]

    metrics.steps = cached  # type: ignore[assignment]
    edges = np.linspace(0, n, 11).astype(int)

    def run() -> list:
        return metrics.each_metrics(fns, [p * 1.001, p * 0.999, p * 1.01, p], inputs, ref, **kw)

    def folds() -> list:
        sets = [p * 1.002, p * 1.001]
        return [
            metrics.each_metrics(fns, sets, inputs, ref, start=a, stop=b, **kw)
            for a, b in itertools.pairwise(edges)
        ]

    run(), folds()  # the steps, and the first touch of the arrays
    t0 = time.process_time()
    out = run()
    t1 = time.process_time()
    blocks = folds()
    t2 = time.process_time()
    print(f"{n} records: the run's 4 sets {t1 - t0:.3f} s, the folds' 10 x 2 {t2 - t1:.3f} s (CPU)")
    if args.out:
        with open(args.out, "wb") as f:
            pickle.dump((out, blocks), f)


if __name__ == "__main__":
    main()
