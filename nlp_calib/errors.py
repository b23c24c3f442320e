"""The package's own exception types; each message says what went wrong and how to fix it."""

from __future__ import annotations


class NlpCalibError(Exception):
    """Base class of every error nlp_calib raises on purpose."""

    #: Process exit code the CLI uses: 2 for bad input (usage), 1 for runtime failures.
    exit_code: int = 1


class UsageError(NlpCalibError):
    """The user's input (command line, scenario, data file) cannot be used as given."""

    exit_code = 2


class DatasetError(UsageError):
    """A log file is malformed; the message names ``file:line`` and what was expected."""

    def __init__(self, path: str, line: int | None, problem: str) -> None:
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {problem}")
        self.path = path
        self.line = line
        self.problem = problem


class ScenarioError(UsageError):
    """A scenario file has an unknown key, a wrong type or inconsistent values."""


class ModelError(UsageError):
    """A kinematic model name or its inputs do not fit the data."""


class SolverError(NlpCalibError):
    """A solver could not run at all (as opposed to running and not converging)."""


class CodegenError(NlpCalibError):
    """C code could not be generated or compiled."""
