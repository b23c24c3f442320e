"""A check of a stored calibration on a new log, as text and as ``check.json``."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.outputs.results import finite_or_null
from nlp_calib.results import CalibrationRun
from nlp_calib.results.check import DriftCheck


def drift_of(run: CalibrationRun) -> DriftCheck:
    """The run's check against a stored calibration."""
    if run.checks.drift is None:
        raise UsageError(f"the result of {run.scenario.name} holds no check of a stored calibration")
    return run.checks.drift


def _number(v: float, form: str = ".6g") -> str:
    return f"{v:{form}}" if math.isfinite(v) else "-"


def check_text(run: CalibrationRun) -> str:
    """The figures of the stored calibration and of the refit on the new log, each parameter's
    change in its combined σ, and the verdict."""
    drift = drift_of(run)
    refit = run.reports[drift.solver].metrics.fair_figures()
    on = "these logs" if run.logs else "this log"
    lines = [
        f"check of {drift.calibration} on {run.log.path} ({run.scenario.name}, {drift.solver})",
        "",
        *(
            [
                f"{'fair figures on ' + on:<26}{'stored':>12}{'refit':>12}",
                *(
                    f"  {k:<24}{_number(v):>12}{_number(refit.get(k, math.nan)):>12}"
                    for k, v in run.baseline.fair_figures().items()
                ),
            ]
            if run.scenario.sensor.positions
            else [f"fair figures on {on}: none in metres ({run.scenario.sensor.no_position})"]
        ),
        "",
        f"{'parameter':<16}{'stored':>13}{'refit':>13}{'change':>12}{'σ comb.':>10}{'z':>7}{'limit':>7}"
        "  unit",
    ]
    for c in drift.changes:
        # The σ the change was judged in (without held values' parts both fits share: its z's).
        sigma = (
            abs(c.change / c.z) if math.isfinite(c.z) and c.z != 0 else math.hypot(c.std_stored, c.std_refit)
        )
        mark = (
            (" <- moved" + ("" if c.confirmed else " (not confirmed)"))
            if c.drifted
            else (" (not tested)" if c.untested else "")
        )
        lines.append(
            f"{c.name:<16}{_number(c.stored):>13}{_number(c.refit):>13}{_number(c.change, '+.3g'):>12}"
            f"{_number(sigma, '.2g'):>10}{_number(c.z, '+.1f'):>7}{_number(c.threshold, '.1f'):>7}"
            f"  {c.unit}{mark}"
        )
    lines += [
        "",
        f"z: the change over σ comb. = √(σ_stored² + σ_refit²), the σ to believe of each (without what "
        "values both fits hold move them by alike); limit: the Student-t "
        f"quantile that an unchanged robot passes with probability {1 - drift.false_alarm:.0%} over "
        f"all {sum(not c.untested for c in drift.changes)} parameters tested",
        f"verdict: {drift.line()}",
    ]
    return "\n".join(lines)


def check_document(run: CalibrationRun) -> dict[str, Any]:
    """The ``check.json`` document."""
    drift = drift_of(run)
    params = {
        c.name: {
            "unit": c.unit,
            "stored": c.stored,
            "refit": c.refit,
            "change": c.change,
            "std_stored": c.std_stored,
            "std_refit": c.std_refit,
            "z": c.z,
            "z_shared": finite_or_null(c.z_shared),
            "dof": c.dof,
            "threshold": c.threshold,
            "drifted": c.drifted,
            "untested": c.untested or None,
        }
        for c in drift.changes
    }
    return {
        "tool": {"name": "nlp_calib", "version": __version__},
        "calibration": drift.calibration,
        "scenario": run.scenario.name,
        "dataset": run.log.path,
        "solver": drift.solver,
        "verdict": drift.verdict,
        "exit_code": drift.exit_code,
        "reasons": list(drift.reasons),
        "hint": drift.hint or None,
        "false_alarm": drift.false_alarm,
        "figures": {
            "stored": run.baseline.fair_figures(),
            "refit": run.reports[drift.solver].metrics.fair_figures(),
        },
        "parameters": params,
    }


def write_check(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Write ``check.json`` (only for a run that checked a stored calibration)."""
    if run.checks.drift is None:
        return []
    text = json.dumps(finite_or_null(check_document(run)), indent=2, allow_nan=False)
    atomic_write_text(folder / name, text + "\n")
    return [folder / name]
