"""nlp_calib: joint calibration of a wheeled robot's kinematics and its sensor's mounting pose.

The problem is written once, symbolically, in CasADi (:mod:`nlp_calib.problem`); Gauss-Newton
and IPOPT solve it from the same Functions. Typical use::

    from nlp_calib import Calibration, load_scenario
    run = Calibration.setup(load_scenario("scenarios/demo.yaml")).run()
    print(run.reports["gauss_newton"].result.param_dict())
    write_run(run, "out/demo")  # what ``nlp-calib run`` writes: calibration.yaml, robot.urdf, ...

Layers, from inputs to outputs (each imports only from the ones before it): ``core``,
``symbolic`` and ``logs``, ``models``, ``problem`` and ``simulation``, ``codegen``, ``solvers``,
``analysis``, ``pipeline``, ``outputs``, ``fleet``, ``cli``.
"""

from __future__ import annotations

import sys


def _started_as_the_command() -> bool:
    """``python -m nlp_calib`` (while the module is located, ``sys.argv[0]`` is ``-m``) or the
    ``nlp-calib`` script."""
    argv0 = sys.argv[0] if sys.argv else ""
    line = " ".join(getattr(sys, "orig_argv", ())) + " "
    as_module = argv0 == "-m" and (" -m nlp_calib " in line or " -mnlp_calib " in line)
    return as_module or argv0.replace("\\", "/").rsplit("/", 1)[-1] in ("nlp-calib", "nlp-calib.exe")


# The command's first instruction: a signal from here on ends it quietly (core/interrupts.py).
if _started_as_the_command():
    from nlp_calib.core import interrupts as _interrupts
    from nlp_calib.core import threads as _threads

    _interrupts.install()
    # Before numpy loads: its BLAS reads the environment once.
    _threads.native_one_thread_by_default()

from typing import TYPE_CHECKING  # noqa: E402

from nlp_calib.core import lazy  # noqa: E402
from nlp_calib.core.version import __version__  # noqa: E402

if TYPE_CHECKING:
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
    from nlp_calib.fleet import BatchOptions, batch_jobs, run_job, write_summary
    from nlp_calib.logs import Log, LogHeader, read_log
    from nlp_calib.models import MODELS, KinematicModel, get_model
    from nlp_calib.outputs.summary import summary_lines
    from nlp_calib.outputs.write import output_options, write_run
    from nlp_calib.pipeline import (
        Calibration,
        Scenario,
        Wanted,
        load_scenario,
        scenario_from_mapping,
    )
    from nlp_calib.problem import ProblemFunctions, ProblemSpec, build
    from nlp_calib.results import CalibrationRun, SolverReport, Verdict
    from nlp_calib.simulation import SimulationOptions, simulate, write_simulation
    from nlp_calib.solvers import SOLVERS, Solver, SolverResult, get_solver
    from nlp_calib.sources import load_log

# The public API is imported when first used, not with the package: ``python -m nlp_calib``
# installs its signal handlers before numpy and CasADi load, and light tools stay light.
_EXPORTS: dict[str, str] = {
    "BatchOptions": "nlp_calib.fleet",
    "batch_jobs": "nlp_calib.fleet",
    "run_job": "nlp_calib.fleet",
    "write_summary": "nlp_calib.fleet",
    "Calibration": "nlp_calib.pipeline",
    "CalibrationRun": "nlp_calib.results",
    "CodegenError": "nlp_calib.core.errors",
    "ConfigError": "nlp_calib.core.errors",
    "DatasetError": "nlp_calib.core.errors",
    "KinematicModel": "nlp_calib.models",
    "Log": "nlp_calib.logs",
    "LogHeader": "nlp_calib.logs",
    "MODELS": "nlp_calib.models",
    "ModelError": "nlp_calib.core.errors",
    "NlpCalibError": "nlp_calib.core.errors",
    "NlpCalibWarning": "nlp_calib.core.errors",
    "OptionsError": "nlp_calib.core.errors",
    "ProblemError": "nlp_calib.core.errors",
    "ProblemFunctions": "nlp_calib.problem",
    "ProblemSpec": "nlp_calib.problem",
    "SOLVERS": "nlp_calib.solvers",
    "Scenario": "nlp_calib.pipeline",
    "ScenarioError": "nlp_calib.core.errors",
    "SimulationOptions": "nlp_calib.simulation",
    "Solver": "nlp_calib.solvers",
    "SolverError": "nlp_calib.core.errors",
    "SolverReport": "nlp_calib.results",
    "SolverResult": "nlp_calib.solvers",
    "UsageError": "nlp_calib.core.errors",
    "Verdict": "nlp_calib.results",
    "Wanted": "nlp_calib.pipeline",
    "build": "nlp_calib.problem",
    "get_model": "nlp_calib.models",
    "get_solver": "nlp_calib.solvers",
    "load_log": "nlp_calib.sources",
    "load_scenario": "nlp_calib.pipeline",
    "read_log": "nlp_calib.logs",
    "scenario_from_mapping": "nlp_calib.pipeline",
    "simulate": "nlp_calib.simulation",
    "summary_lines": "nlp_calib.outputs.summary",
    "output_options": "nlp_calib.outputs.write",
    "write_run": "nlp_calib.outputs.write",
    "write_simulation": "nlp_calib.simulation",
}


__getattr__, __dir__ = lazy.exports(__name__, _EXPORTS)

__all__ = [
    "MODELS",
    "SOLVERS",
    "BatchOptions",
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
    "Verdict",
    "Wanted",
    "__version__",
    "batch_jobs",
    "build",
    "get_model",
    "get_solver",
    "load_log",
    "load_scenario",
    "output_options",
    "read_log",
    "run_job",
    "scenario_from_mapping",
    "simulate",
    "summary_lines",
    "write_run",
    "write_simulation",
    "write_summary",
]
