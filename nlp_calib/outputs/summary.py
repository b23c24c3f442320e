"""The closing summary of a run: what was found, the verdict and what to do next.

The verdict itself is decided by the analyse stage (:mod:`nlp_calib.analysis.verdict`) and carried
in the result; this module only phrases it.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence

import numpy as np

from nlp_calib.results import CalibrationRun
from nlp_calib.results.run import CAVEATS, NOT_USABLE, UNDETERMINED


def _accuracy_line(run: CalibrationRun, solver: str) -> str:
    if reason := run.scenario.sensor.no_position:
        return f"no trajectory figure in metres ({reason}); the checks below judge the fit"
    m, b = run.reports[solver].metrics, run.baseline
    rpe5, base5 = m.rpe_distance[5.0].mean, b.rpe_distance[5.0].mean
    start = "data-driven start" if run.scenario.initial_guess == "auto" else "initial guess"
    nominal = run.checks.nominal
    also = f", nominal robot {nominal.metrics.segment_ate.mean:.3g} m" if nominal is not None else ""
    text = f"segment ATE {m.segment_ate.mean:.3g} m ({start} {b.segment_ate.mean:.3g} m{also})"
    if np.isfinite(rpe5):
        text += (
            f", RPE over 5 m {rpe5:.3g} m = {100 * rpe5 / 5:.2g} % of the distance "
            f"({start} {100 * base5 / 5:.2g} %)"
        )
    cv = run.checks.crossval
    if cv is not None and cv.available:
        ate = "segment ATE mean [m]"
        text += (
            f"; over the same {len(cv.folds)} blocks, segment ATE {cv.heldout_mean(ate):.3g} m held out "
            f"vs {cv.insample_mean(ate):.3g} m in-sample"
        )
    return text


def _next_steps(run: CalibrationRun, level: str, files: Sequence[str]) -> list[str]:
    steps = list(files)
    if level != UNDETERMINED and run.scenario.path is not None:
        steps.append(
            "C code of the residual and its Jacobian: nlp-calib codegen "
            f"{shlex.quote(run.scenario.path)} --out DIR"  # a command to paste: the path quoted
        )
    plan = run.checks.plan
    planned = plan is not None and plan.best is not None
    if level in (UNDETERMINED, NOT_USABLE):
        obs = run.checks.observability
        hints = [w for w in obs.warnings if "drive" in w] if obs is not None else []
        if planned:
            assert plan is not None
            steps.insert(0, f"{plan.line()}; plan.md ranks {len(plan.ranked)} manoeuvres")
        steps.append(hints[0] if hints else _verdicts_next(run) or _run_again(run))
    elif level == CAVEATS:
        steps.insert(0, "read the caveats above before using the result")
        if planned:
            assert plan is not None
            steps.insert(1, f"to know {plan.target} better, {plan.line()}")
    return steps


def _verdicts_next(run: CalibrationRun) -> str:
    """The next step a reason of the verdict already names ('next: ...'): the summary says that
    one, not another."""
    said = [r.split("next: ", 1)[1] for r in run.verdict.reasons if "next: " in r]
    return said[0] if said else ""


def _run_again(run: CalibrationRun) -> str:
    """What to try when nothing names a next step: the data-driven start, unless it was used."""
    if run.scenario.initial_guess == "auto":
        return "check the log (units, signs, which joint is which) and the model, then run again"
    return "check the initial guess (or use initial_guess: auto) and the log, then run again"


def _travelled(run: CalibrationRun) -> str:
    """How far the sensor went: its path in metres, or for a reference without positions (a gyro)
    the span of the heading it saw."""
    if run.scenario.sensor.positions:
        return f"the sensor travelled {run.baseline.distance_m:.1f} m (tracker path)"
    obs = run.checks.observability
    spanned = f"the heading spanned {obs.heading_range_rad:.2f} rad; " if obs is not None else ""
    return f"{spanned}no distance: {run.scenario.sensor.no_position}"


def summary_lines(run: CalibrationRun, files: Sequence[str] = ()) -> list[str]:
    """The closing summary of a run: one line per solver, accuracy, faults, observability, verdict
    and next steps; ``files`` say what each file the run wrote is for (``name: what``)."""
    used, sc = run.data.used, run.scenario
    name = f"the joint fit of {len(sc.datasets)} logs ({sc.name})" if sc.datasets else sc.name
    lines = [
        f"summary of {name}: model {sc.model}, {used[1] - used[0]} records over "
        f"{run.log.duration_s:.1f} s; {_travelled(run)}"
    ]
    chosen = run.chosen_solver()
    for s in run.solver_order():
        res = run.reports[s].result
        if not res.converged:
            lines.append(f"  {s}: did not converge ({res.reason}); not used")
            continue
        state = f"converged in {res.iterations} iterations, {1e3 * res.time_s:.0f} ms"
        if s == chosen:
            state += f"; the result written (first converged of {', '.join(run.solver_order())})"
        else:
            state += f"; agrees with {chosen} to {run.relative_difference(chosen, s):.1e}" if chosen else ""
        lines.append(f"  {s}: {state}")
    if chosen is not None:
        lines.append(f"  accuracy ({chosen}): {_accuracy_line(run, chosen)}")
    lines += [f"  {r.name}: {r.words}" for r in run.checks.more]
    v = run.verdict
    lines.append(f"  verdict: {v.line()}")
    for i, step in enumerate(_next_steps(run, v.level, files)):
        lines.append(f"  {'next: ' if i == 0 else '      '}{step}")
    return lines
