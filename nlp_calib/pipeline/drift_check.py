"""The drift check as a plug-in: a stored calibration against the refit of a new log started from
it (:func:`nlp_calib.analysis.drift.check_drift`: each parameter's change in the combined σ), in
its one wording (:meth:`~nlp_calib.results.check.DriftCheck.line`).

It runs only when the run checks a stored calibration (``nlp-calib check``). Always at the fine
level: what it judges is the stored calibration, not the refit the run's verdict is about; its own
verdict is the check's exit code.
"""

from __future__ import annotations

from nlp_calib.analysis.drift import check_drift
from nlp_calib.models import KinematicModel, get_model
from nlp_calib.pipeline.stored import StoredCalibration
from nlp_calib.results import CalibrationRun, codec
from nlp_calib.results.checks import FINE, CheckResult


def check(
    run: CalibrationRun, stored: StoredCalibration | None, model: KinematicModel | None
) -> CheckResult | None:
    """The stored calibration's drift on the run's log (None: the run checks none)."""
    if stored is None:
        return None
    fitted = model if model is not None else get_model(run.scenario.model)
    found = check_drift(
        run,
        fitted,
        stored.stats(),
        str(stored.path),
        stored.solver,
        stored.uncalibrated(),
        stored.std_shared or None,
        (stored.spreads.held, stored.spreads.held_values),
    )
    return CheckResult(
        "drift",
        FINE,
        found.line(),
        about={"calibration": found.calibration, "solver": found.solver},
        record=codec.to_data(found),
    )
