"""The check stage: a stored calibration scored and refitted on a new log, and each parameter's
change judged in the combined σ (:mod:`nlp_calib.analysis.drift`).

The new log (or logs, fitted jointly) goes through every stage of a calibration as a run does
them, its fit started from the stored values: its fair figures with the stored values are the
run's baseline, the refit's beside them, and the run's ``drift`` plug-in check
(:mod:`nlp_calib.pipeline.drift_check`) carries the comparison (``checks.drift``). The refit uses
the formulation the calibration was made with: its scenario file when it still exists, else the
model's defaults with the residual and robust options the calibration recorded.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nlp_calib.core.config import from_mapping
from nlp_calib.core.errors import NlpCalibWarning, UsageError
from nlp_calib.logs import Log
from nlp_calib.pipeline.analyse import Wanted
from nlp_calib.pipeline.calibration import Calibration
from nlp_calib.pipeline.options import RobustOptions
from nlp_calib.pipeline.scenario import Scenario, load_scenario
from nlp_calib.pipeline.stored import StoredCalibration
from nlp_calib.problem import ResidualOptions
from nlp_calib.results import CalibrationRun

#: File names taken for scenarios (anything else is a log: a text log or a bag).
SCENARIO_SUFFIXES = (".yaml", ".yml")


def _recorded(stored: StoredCalibration, log: Path) -> Scenario:
    """The log with the scenario the calibration was made with, or the model's defaults with the
    residual and robust options it recorded."""
    if stored.scenario is not None:
        return _whole(load_scenario(stored.scenario).with_dataset(log), stored)
    if stored.recorded is not None:
        why = (
            "is not there"
            if Path(stored.recorded).is_absolute()
            else "is recorded relative to the folder it ran in"
        )
        warnings.warn(
            f"the scenario {stored.path} was made with ({stored.recorded}) {why}; the log is read with the "
            "model's defaults and the residual and kernel the calibration recorded; give the scenario as "
            "SCENARIO to use it",
            NlpCalibWarning,
            stacklevel=3,
        )
    sc = Scenario.of(log.stem or "check", log, model=stored.model)
    objective = stored.objective or {}
    where = f"{stored.path}: objective"
    if "residual" in objective:
        sc = sc.with_options(
            residual=from_mapping(ResidualOptions, objective["residual"], f"{where}.residual")
        )
    if "robust" in objective:
        sc = sc.with_options(robust=from_mapping(RobustOptions, objective["robust"], f"{where}.robust"))
    return sc


def _whole(sc: Scenario, stored: StoredCalibration) -> Scenario:
    """The recorded scenario on a new log, all of it: its ``samples`` chose records of the log it
    calibrated, which mean nothing on another (said in a warning when it had a range)."""
    samples = sc.log.samples
    if (samples.start == 0 and samples.stop is None) or _same_file(stored.dataset, sc.dataset):
        return sc
    warnings.warn(
        f"the scenario {stored.path} was made with selects samples [{samples.start}, {samples.stop}) of the "
        "log it calibrated; the new log is checked whole (give a scenario with samples for it as SCENARIO "
        "to choose)",
        NlpCalibWarning,
        stacklevel=4,
    )
    return sc.with_options(samples=dataclasses.replace(samples, start=0, stop=None))


def _same_file(recorded: str | None, path: Path) -> bool:
    """Whether ``path`` is the log the calibration recorded (the same file, by any name)."""
    try:
        return recorded is not None and Path(recorded).is_absolute() and os.path.samefile(recorded, path)
    except OSError:
        return False


def _same_formulation(stored: StoredCalibration, sc: Scenario) -> None:
    """Warn when the scenario fits another residual or kernel than the calibration did: the
    parameters would then differ by the formulation alone."""
    recorded = stored.objective or {}
    used: dict[str, Any] = {"residual": sc.objective.residual, "robust": sc.objective.robust}
    for key, options in used.items():
        if key in recorded and _formulation(dict(recorded[key])) != _formulation(dataclasses.asdict(options)):
            warnings.warn(
                f"{sc.path or sc.name} fits {key} {dataclasses.asdict(options)}, the calibration "
                f"{recorded[key]}: the parameters may differ by the formulation alone; check with the "
                "scenario the calibration was made with",
                NlpCalibWarning,
                stacklevel=3,
            )


def _formulation(options: dict[str, Any]) -> dict[str, Any]:
    """Residual or robust options as a formulation: with windows given in seconds
    (``horizon_s``) the record horizon is what each log's rate makes of them, recorded resolved
    by a run and unresolved in its scenario file, so it is no part of the formulation."""
    return (
        {k: v for k, v in options.items() if k != "horizon"}
        if options.get("horizon_s") is not None
        else options
    )


def check_scenario(stored: StoredCalibration, target: Path) -> Scenario:
    """The scenario a check runs: ``target`` when it is a scenario file, else the log ``target``
    with the calibration's own formulation, with its solver (:func:`check` starts its fit from the
    stored values)."""
    sc = load_scenario(target) if target.suffix in SCENARIO_SUFFIXES else _recorded(stored, target)
    if sc.model != stored.model:
        raise UsageError(
            f"{target}: the scenario's model is {sc.model}, the calibration's ({stored.path}) is "
            f"{stored.model}; check with a scenario of the same model"
        )
    _same_formulation(stored, sc)
    return sc.with_options(solvers=(stored.solver,))


def check(
    stored: StoredCalibration, scenario: Scenario, logs: Log | Sequence[Log] | None = None
) -> CalibrationRun:
    """The calibration of ``scenario``'s log or logs (read, or ``logs``; several fitted jointly,
    as a run fits them) from the stored values, with the comparison against them (the ``drift``
    plug-in: ``checks.drift``). Every stage before the fit (the screen, the lag, the windows) is
    done as a run of ``scenario`` does it: on a run's own data the check tests what it fitted."""
    calib = Calibration(scenario, logs, (stored.solver,), start=stored.start())
    return calib.run((stored.solver,), Wanted(against=stored))
