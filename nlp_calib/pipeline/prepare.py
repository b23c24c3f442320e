"""The prepare stage: a log read from its source, its records selected and checked, once.

What costs nothing to check (the record range, windows enough for the parameters, parameters the
drive cannot determine at all) is checked here, before anything is built, so several scenarios
are all checked before the first is solved.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass

from nlp_calib.core.errors import DatasetError, ModelError, NlpCalibWarning, ScenarioError
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel, get_model, param_names
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.scenario import Scenario


@dataclass(frozen=True)
class PreparedLog:
    """One log ready for the later stages: its single-log ``scenario``, the model, the records as
    read, the selected range ``[start, stop)``, the first hold-out record ``split`` and the free
    parameters the selection cannot determine at all (``held``, with the reason)."""

    scenario: Scenario
    model: KinematicModel
    log: Log
    start: int
    stop: int
    split: int
    held: Mapping[str, str]


def read(sc: Scenario, log: Log | None = None) -> tuple[KinematicModel, Log]:
    """The scenario's model, in the form the log's encoder units call for, and its (first) log read
    from its source (or ``log`` as given)."""
    with scenario_key(sc, "model"):
        get_model(sc.model)
    model, log = _read(sc, log)
    return in_units(model, log.header.encoder_units), log


def _read(sc: Scenario, log: Log | None) -> tuple[KinematicModel, Log]:
    model = sc.model_form()
    if log is not None:
        if log.header.kinematic_model not in model.log_names:
            raise ModelError(
                f"{log.path}: the log is of kind {log.header.kinematic_model!r}, but the scenario's "
                f"model {model.name!r} reads {', '.join(model.log_names)}"
            )
        return model, log
    try:
        return model, sc.log.source.read(model, strict=sc.data.strict)
    except DatasetError as exc:
        if exc.droppable:
            raise exc.with_hint("set 'strict: false' in the scenario to drop such records") from None
        if exc.line is None and exc.problem == "no such file":
            key = sc.origin or "dataset"
            raise exc.with_hint(f"pass the log with --data or fix '{key}' in the scenario") from None
        raise


def select(sc: Scenario, log: Log) -> tuple[int, int]:
    """The record range ``[start, stop)`` the scenario's ``samples`` ask for."""
    n = log.n_records
    samples = sc.log.samples
    start = samples.start
    stop = n if samples.stop is None else samples.stop
    if stop > n or start >= stop - 1:
        raise ScenarioError(f"samples: the range [{start}, {stop}) does not fit the log's {n} records")
    check_windows(sc, start, stop)
    return start, stop


def check_windows(sc: Scenario, start: int, stop: int) -> None:
    """Refuse, before anything is built, a horizon that leaves fewer windows than parameters."""
    H, stride = sc.objective.residual.horizon, sc.objective.residual.stride
    fit_stop = split(sc, start, stop)
    intervals = fit_stop - start - 1
    windows = 0 if intervals < H else (intervals - H) // stride + 1
    n_free = len(param_names(get_model(sc.model))) - len(set(sc.parameters.fixed))
    if windows >= n_free:
        return
    longest = intervals - (n_free - 1) * stride
    fix = f"shorten residual.horizon to at most {longest}" if longest >= 1 else "select more samples"
    part = f"{sc.origin} ({sc.dataset.name}): " if sc.origin else ""
    raise ScenarioError(
        f"{sc.path or sc.name}: {part}residual.horizon {H} (stride {stride}) leaves {windows} residual "
        f"window(s) in the {fit_stop - start} fitted records of samples [{start}, {stop}) for "
        f"{n_free} parameters; {fix}, or widen samples"
    )


def split(sc: Scenario, start: int, stop: int) -> int:
    """The first record of the hold-out (``stop`` when there is none)."""
    hf = sc.validation.holdout_fraction
    return stop if hf is None else start + round((1.0 - hf) * (stop - start))


def held(sc: Scenario, model: KinematicModel, log: Log, start: int, stop: int) -> dict[str, str]:
    """Free parameters the records ``start:stop`` cannot determine at all, with the reason: the
    fit holds them at their initial values (with a warning) instead of failing as singular."""
    inputs = model.inputs(log.select(start, stop), sc.objective.residual.steering_sample)
    return {n: why for n, why in model.undetermined(inputs).items() if n not in sc.parameters.fixed}


def prepare(sc: Scenario, log: Log | None = None) -> PreparedLog:
    """Read (unless ``log`` is given), select and check the single-log scenario ``sc``'s log."""
    model, log = read(sc, log)
    start, stop = select(sc, log)
    first_split = split(sc, start, stop)
    undetermined = held(sc, model, log, start, first_split)
    for name, why in undetermined.items():
        warnings.warn(
            f"{name} is held at its initial value: {why} in the fitted records", NlpCalibWarning, stacklevel=2
        )
    return PreparedLog(sc, model, log, start, stop, first_split, undetermined)


def read_checked(sc: Scenario) -> Log:
    """The scenario's log, read and checked against what costs nothing to check."""
    _, log = read(sc)
    select(sc, log)
    return log
