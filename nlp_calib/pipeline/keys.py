"""Library errors in the scenario's language: the one place a neutral error gains the key to fix."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from nlp_calib.core.errors import ModelError, OptionsError, ProblemError, ScenarioError
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.results import SolverResult

#: Return statuses with which a solver says its options, not the data, are at fault.
REJECTED_OPTIONS = ("Invalid_Option",)


@contextmanager
def scenario_key(sc: Scenario, key: str, hint: str = "") -> Iterator[None]:
    """Library errors raised inside become :class:`ScenarioError` naming the scenario's ``key``."""
    try:
        yield
    except (ProblemError, OptionsError, ModelError) as exc:
        raise ScenarioError(f"{sc.path or sc.name}: {key}: {exc}" + (f"; {hint}" if hint else "")) from None


def refuse_rejected_options(sc: Scenario, result: SolverResult) -> None:
    """A solver that stopped because it rejected its options is an input error, not a result."""
    status = result.trace.stats.get("return_status")
    if status not in REJECTED_OPTIONS:
        return
    options = sc.options_for(result.solver)
    linear = getattr(options, "options", {}).get("linear_solver", getattr(options, "linear_solver", None))
    hint = f"; is linear_solver {linear!r} installed? (mumps always is)" if linear is not None else ""
    raise ScenarioError(
        f"{sc.path or sc.name}: {result.solver}: the solver rejected its options when it started "
        f"({status}){hint}; check {result.solver}.linear_solver and {result.solver}.options"
    )
