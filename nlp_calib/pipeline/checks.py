"""Plug-in checks: each one function from a run's result (and what its log's source knows) to a
generic :class:`~nlp_calib.results.checks.CheckResult`, and one registry line.

A check here runs after the run is assembled and before its verdict: what it finds is stored
with the run (``checks.more``), printed in its one wording by the terminal, the report and the
summary, and, at the :data:`~nlp_calib.results.checks.CAVEAT` level, named among the verdict's
caveats. Adding one touches nothing else.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from nlp_calib.models import KinematicModel
from nlp_calib.pipeline import (
    consistency_check,
    determinacy_check,
    direction_check,
    drift_check,
    fault_check,
    held_check,
    leverage_check,
    profile_check,
    rival,
    slip_check,
    truth,
)
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.pipeline.stored import StoredCalibration
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CheckResult


@dataclass(frozen=True)
class CheckContext:
    """What a check may read besides the run: its log source's files, the scenario, and the conversion of
    parameter values from the simulator's names and units into the run's (``convert``)."""

    files: Sequence[Path] = ()
    convert: Callable[[Mapping[str, float]], dict[str, float]] = field(default=dict)
    #: The scenario the run fitted (None: not known).
    scenario: Scenario | None = None
    #: The model the run fitted (None: the scenario's, by name).
    model: KinematicModel | None = None
    #: A stored calibration the run checks (``nlp-calib check``; None: none).
    against: StoredCalibration | None = None
    #: The run's fit: its evaluator bound to the windows it fitted (None: not at hand).
    fit: Fit | None = None


#: A check: the run and its context to a result, or None when it has nothing to say.
RunCheck = Callable[[CalibrationRun, CheckContext], "CheckResult | None"]

#: The plug-in checks, by name, in the order they run: the order the terminal, the report, the
#: summary and the verdict's reasons name them in.
RUN_CHECKS: dict[str, RunCheck] = {
    # Its σ of the slip is part of the σ to believe every other check reads (WIDENING).
    slip_check.NAME: lambda run, ctx: slip_check.check(run, ctx.model, ctx.fit),
    determinacy_check.NAME: lambda run, ctx: determinacy_check.check(run, ctx.model),
    "faults": lambda run, ctx: fault_check.check(run),
    "direction": lambda run, ctx: direction_check.check(run),
    "consistency": lambda run, ctx: consistency_check.check(run),
    leverage_check.NAME: lambda run, ctx: leverage_check.check(run),
    profile_check.NAME: lambda run, ctx: profile_check.check(run, ctx.scenario, ctx.model, ctx.fit),
    # Run after the slip check (WIDENING): a held value's shift is weighed against its σ.
    held_check.NAME: lambda run, ctx: held_check.check(run, ctx.fit),
    "truth": lambda run, ctx: truth.check(run, ctx.files, ctx.convert),
    "model": lambda run, ctx: rival.check(run, ctx.scenario),
    "drift": lambda run, ctx: drift_check.check(run, ctx.against, ctx.model),
}


#: The checks whose records widen the σ to believe (:meth:`~nlp_calib.results.run.Checks.shifts`
#: reads their ``std_slip`` and ``std_held``), in the order they run: before every other check, so
#: that each σ another check words ("known only to ±σ", "Nσ by its σ") or weighs against is the one
#: the run finally states (calibration.yaml's, result.json's ``std``). Worded before the held check
#: widened it, a real car's lag read ±6.7 ms in the verdict and ±31 ms in every file.
WIDENING: tuple[str, ...] = (slip_check.NAME, held_check.NAME)


def run_checks(run: CalibrationRun, context: CheckContext) -> tuple[CheckResult, ...]:
    """Every registered check's result on ``run`` (those with something to say), in registry
    order; the :data:`WIDENING` checks run first, every other reading the run with their results
    and those of the checks before it in the registry."""
    order = [*WIDENING, *(name for name in RUN_CHECKS if name not in WIDENING)]
    found: dict[str, CheckResult] = {}
    for name in order:
        seen = dataclasses.replace(run, checks=dataclasses.replace(run.checks, more=tuple(found.values())))
        result = RUN_CHECKS[name](seen, context)
        if result is not None:
            found[name] = result
    return tuple(found[name] for name in RUN_CHECKS if name in found)
