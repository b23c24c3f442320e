"""The passes over the windows a run makes, and what recalling a Gauss-Newton run's costs.

    python benchmarks/recall_cpu.py LOG                  # this checkout, the seed scenario
    python benchmarks/recall_cpu.py LOG --repo ../main   # another checkout's, for before/after

Prints every per-window Function evaluation ``nlp-calib run SCENARIO --data LOG`` made, counted
by name (``ProblemEvaluator._call``: one pass over an evaluator's windows each), and, where the
checkout has ``ProblemEvaluator.contents``, the CPU (``time.process_time``) of hashing an
evaluator's contents against one normal-equations pass on the fit's windows. Logs:
``nlp-calib simulate --records N --seed 11 --out LOG``.
"""

from __future__ import annotations

import argparse
import collections
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[1]))
    ap.add_argument("--scenario", default="scenarios/real_tricycle_seed.yaml")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    repo = Path(args.repo).resolve()
    sys.path.insert(0, str(repo))
    import nlp_calib.solvers.evaluation as evaluation
    from nlp_calib import Calibration, load_scenario
    from nlp_calib.cli.main import main as cli

    calls: collections.Counter[str] = collections.Counter()
    call = evaluation.ProblemEvaluator._call

    def counted(self, name, x):  # type: ignore[no-untyped-def]
        calls[name] += 1
        return call(self, name, x)

    scenario = str(repo / args.scenario)
    evaluation.ProblemEvaluator._call = counted  # type: ignore[method-assign]
    with tempfile.TemporaryDirectory() as out:
        cli(["run", scenario, "--data", args.log, "--out", out, "--force"])
    evaluation.ProblemEvaluator._call = call  # type: ignore[method-assign]
    print("calls", dict(calls))
    if not hasattr(evaluation.ProblemEvaluator, "contents"):
        return
    cal = Calibration(load_scenario(scenario).with_dataset(args.log))
    ev, x = cal.evaluator, cal.x0
    ev.normal_equations(x)
    for k in range(args.repeats):
        t = time.process_time()
        ev.contents()
        hashed = time.process_time() - t
        t = time.process_time()
        ev.normal_equations(x * (1.0 + 1e-7 * (k + 1)))
        passed = time.process_time() - t
        pass_s = f"one normal-equations pass {passed:.4f} s CPU"
        print(f"windows {ev.n_residuals} contents() {hashed:.4f} s CPU, {pass_s}")


if __name__ == "__main__":
    main()
