"""nlp_calib: joint calibration of a wheeled robot's kinematics and its sensor's mounting pose.

The problem is written once, symbolically, in CasADi (:mod:`nlp_calib.problem`); Gauss-Newton
and IPOPT solve it from the same Functions. Typical use::

    from nlp_calib import Calibration, load_scenario
    run = Calibration.setup(load_scenario("scenarios/demo.yaml")).run()
    print(run.reports["gauss_newton"].result.param_dict())

Layers, from inputs to outputs (each imports only from the ones before it): ``core``,
``symbolic`` and ``logs``, ``models``, ``problem`` and ``simulation``, ``codegen``, ``solvers``,
``analysis``, ``pipeline``, ``outputs``, ``cli``.
"""

from __future__ import annotations

from nlp_calib.core.errors import (
    CodegenError,
    ConfigError,
    DatasetError,
    ModelError,
    NlpCalibError,
    NlpCalibWarning,
    OptionsError,
    ProblemError,
    ScenarioError,
    SolverError,
    UsageError,
)
from nlp_calib.core.version import __version__
from nlp_calib.logs import Log, LogHeader, read_log
from nlp_calib.models import MODELS, KinematicModel, get_model, load_log
from nlp_calib.pipeline import (
    Calibration,
    CalibrationRun,
    Scenario,
    SolverReport,
    load_scenario,
    scenario_from_mapping,
)
from nlp_calib.problem import ProblemFunctions, ProblemSpec, build
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation
from nlp_calib.solvers import SOLVERS, Solver, SolverResult, get_solver

__all__ = [
    "MODELS",
    "SOLVERS",
    "Calibration",
    "CalibrationRun",
    "CodegenError",
    "ConfigError",
    "DatasetError",
    "KinematicModel",
    "Log",
    "LogHeader",
    "ModelError",
    "NlpCalibError",
    "NlpCalibWarning",
    "OptionsError",
    "ProblemError",
    "ProblemFunctions",
    "ProblemSpec",
    "Scenario",
    "ScenarioError",
    "SimulationOptions",
    "Solver",
    "SolverError",
    "SolverReport",
    "SolverResult",
    "UsageError",
    "__version__",
    "build",
    "get_model",
    "get_solver",
    "load_log",
    "load_scenario",
    "read_log",
    "scenario_from_mapping",
    "simulate",
    "write_simulation",
]
