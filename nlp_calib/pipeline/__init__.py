"""Pipeline layer: scenario configuration and the calibration as named steps.

The only layer that speaks scenario language: library errors from below are translated here into
messages that name the scenario key to fix.
"""

from nlp_calib.pipeline.calibration import Calibration, CalibrationRun, SolverReport
from nlp_calib.pipeline.joint import JointCalibration, JointRun
from nlp_calib.pipeline.scenario import LogEntry, Scenario, load_scenario, scenario_from_mapping

__all__ = [
    "Calibration",
    "CalibrationRun",
    "JointCalibration",
    "JointRun",
    "LogEntry",
    "Scenario",
    "SolverReport",
    "load_scenario",
    "scenario_from_mapping",
]
