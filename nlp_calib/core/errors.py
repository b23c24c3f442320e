"""The package's own exception and warning types.

Library layers raise them in neutral words (what is wrong with a value, a log or a problem); the
scenario layer (:mod:`nlp_calib.pipeline`) adds the scenario key once, so a user reads where in
their file to fix it. Each message says what went wrong and how to fix it.
"""

from __future__ import annotations


class NlpCalibError(Exception):
    """Base class of every error nlp_calib raises on purpose."""

    #: Process exit code the CLI uses: 2 for bad input (usage), 1 for runtime failures.
    exit_code: int = 1


class UsageError(NlpCalibError):
    """The user's input (command line, configuration, data file) cannot be used as given."""

    exit_code = 2


#: Paths longer than this are shown cut in their middle: a message stays readable.
SHOWN_PATH = 200


def shown_path(path: object) -> str:
    """``path`` for a message: a very long one cut in its middle, its length said."""
    text = str(path)
    return text if len(text) <= SHOWN_PATH else f"{text[:100]}…{text[-60:]} ({len(text)} characters)"


class DatasetError(UsageError):
    """A log file is malformed; the message names ``file:line`` and what was expected.

    ``droppable`` marks a bad record that a non-strict read would have dropped.
    """

    def __init__(self, path: str, line: int | None, problem: str, *, droppable: bool = False) -> None:
        shown = shown_path(path)
        where = f"{shown}:{line}" if line is not None else shown
        super().__init__(f"{where}: {problem}")
        self.path = path
        self.line = line
        self.problem = problem
        self.droppable = droppable

    def with_hint(self, hint: str) -> DatasetError:
        """The same error with ``hint`` (how to fix it) appended in parentheses."""
        return DatasetError(self.path, self.line, f"{self.problem} ({hint})", droppable=self.droppable)


class ConfigError(UsageError):
    """A configuration file (scenario, simulation options) has an unknown key, a wrong type or an
    inconsistent value; the message names the file and the key."""


class ScenarioError(ConfigError):
    """A scenario does not fit its data or cannot be carried out; the message names the key."""


class ModelError(UsageError):
    """A kinematic model name or its inputs do not fit the data."""


class ProblemError(UsageError):
    """A calibration problem cannot be formed: an invalid horizon, kernel or fixed parameter, or
    too little data for the parameters."""


class OptionsError(UsageError):
    """A solver or backend option has a value outside its accepted range."""


class FieldError(OptionsError):
    """One option's value is not accepted. ``field`` names the option; whoever reads it from a
    file adds the file and the place (``scenario.yaml: residual.horizon: ...``)."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


class SolverError(NlpCalibError):
    """A solver could not run at all (as opposed to running and not converging)."""


class PreflightError(NlpCalibError):
    """The pre-flight found that a calibration from these data cannot succeed (a unit or sign the
    data get wrong, a parameter the drive does not determine); the message says why and what to
    do. ``exit_code`` is the pre-flight's (4: not enough, 5: check the data)."""

    def __init__(self, message: str, exit_code: int) -> None:
        super().__init__(message)
        self.exit_code = exit_code


class CodegenError(NlpCalibError):
    """C code could not be generated or compiled."""


class ResourceError(NlpCalibError):
    """The process lacks a resource the run needs (address space under ``ulimit -v``)."""


class NlpCalibWarning(UserWarning):
    """Something the user should know about a result that is still usable (the CLI prints it)."""
