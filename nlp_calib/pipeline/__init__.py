"""Pipeline layer: scenario configuration and the calibration as named steps.

The only layer that speaks scenario language: library errors from below are translated here into
messages that name the scenario key to fix.
"""

from nlp_calib.pipeline.calibration import Calibration, CalibrationRun, SolverReport
from nlp_calib.pipeline.scenario import Scenario, load_scenario, scenario_from_mapping

__all__ = [
    "Calibration",
    "CalibrationRun",
    "Scenario",
    "SolverReport",
    "load_scenario",
    "scenario_from_mapping",
]
