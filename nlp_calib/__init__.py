"""nlp_calib: joint calibration of a wheeled robot's kinematics and its sensor's mounting pose.

The problem is written once, symbolically, in CasADi (:mod:`nlp_calib.symbolic`); Gauss-Newton
and IPOPT solve it from the same Functions. Typical use::

    from nlp_calib import Calibration, load_scenario
    run = Calibration.setup(load_scenario("scenarios/demo.yaml")).run()
"""

from __future__ import annotations

__version__ = "0.1.0"

from nlp_calib.calibration import Calibration, CalibrationRun, SolverReport
from nlp_calib.errors import (
    CodegenError,
    DatasetError,
    ModelError,
    NlpCalibError,
    ScenarioError,
    SolverError,
    UsageError,
)
from nlp_calib.io.logfile import Dataset, LogHeader, read_log
from nlp_calib.io.scenario import Scenario, load_scenario
from nlp_calib.models import KinematicModel, get_model
from nlp_calib.solvers.result import SolverResult
from nlp_calib.symbolic.builder import ProblemFunctions, ProblemSpec, build

__all__ = [
    "Calibration",
    "CalibrationRun",
    "CodegenError",
    "Dataset",
    "DatasetError",
    "KinematicModel",
    "LogHeader",
    "ModelError",
    "NlpCalibError",
    "ProblemFunctions",
    "ProblemSpec",
    "Scenario",
    "ScenarioError",
    "SolverError",
    "SolverReport",
    "SolverResult",
    "UsageError",
    "__version__",
    "build",
    "get_model",
    "load_scenario",
    "read_log",
]
