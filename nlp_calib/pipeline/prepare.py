"""The prepare stage: a log read from its source, its records selected and checked, once.

What costs nothing to check (the record range, windows enough for the parameters, parameters the
drive cannot determine at all) is checked here, before anything is built, so several scenarios
are all checked before the first is solved.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis.streams import GAP_FACTOR, MIN_GAP_S, gap_threshold, time_gaps
from nlp_calib.core.errors import DatasetError, ModelError, NlpCalibWarning, ScenarioError
from nlp_calib.core.said import each_once, kept
from nlp_calib.logs import Log
from nlp_calib.logs.reference import Poses
from nlp_calib.models import KinematicModel, get_model
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline.keys import scenario_key
from nlp_calib.pipeline.scenario import Scenario, scenario_params
from nlp_calib.problem import ResidualOptions
from nlp_calib.results.mount import BASE_LINK

#: At this rate or above (Hz), a record horizon shorter than :data:`SHORT_WINDOW_S` is warned about:
#: each window's motion is then little more than the tracker's noise.
HIGH_RATE_HZ = 50.0
SHORT_WINDOW_S = 0.05
#: A tracker that travels this far (m) or turns this much (rad) has moved: the wheels must have.
MOVING_M = 0.5
MOVING_RAD = 1.0
#: Logs fitted together whose record horizon spans durations further apart than this factor are
#: warned about.
DURATION_RATIO = 2.0


@dataclass(frozen=True)
class PreparedLog:
    """One log ready for the later stages: its single-log ``scenario``, the model, the records as
    read, the selected range ``[start, stop)``, the first hold-out record ``split`` and the free
    parameters the selection cannot determine at all (``held``, with the reason), and the intervals
    of the log that are gaps in time (``gaps``: no window crosses them)."""

    scenario: Scenario
    model: KinematicModel
    log: Log
    start: int
    stop: int
    split: int
    held: Mapping[str, str]
    gaps: np.ndarray | None = None


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
        with kept() as said:
            log = _own_frame(sc.log.source.read(model, strict=sc.data.strict))
        return model, replace(log, header=replace(log.header, said=each_once(log.header.said, said)))
    except DatasetError as exc:
        if exc.droppable:
            raise exc.with_hint("set 'strict: false' in the scenario to drop such records") from None
        if exc.line is None and exc.problem == "no such file":
            key = sc.origin or "dataset"
            raise exc.with_hint(f"pass the log with --data or fix '{key}' in the scenario") from None
        raise


def _own_frame(log: Log) -> Log:
    """``log``, whose sensor has a frame of its own: every hand-off file mounts it on
    ``base_link``, and a joint from a link to itself breaks the robot's description."""
    if log.header.sensor_frame.strip("/") == BASE_LINK:
        raise DatasetError(
            log.path,
            None,
            f"the sensor's frame is {BASE_LINK!r}, the frame its mount is calibrated in: a sensor's mount "
            "is a joint from the base to a frame of its own; name the sensor's frame (the dataset's "
            "sensor_frame, sensor_frame in ROBOT.yaml, the driver's frame_id)",
        )
    return log


def select(sc: Scenario, log: Log, model: KinematicModel | None = None) -> tuple[int, int]:
    """The record range ``[start, stop)`` the scenario's ``samples`` ask for (with ``model``:
    checked for counters that never move; joints in degrees are the pre-flight's to find)."""
    n = log.n_records
    samples = sc.log.samples
    start = samples.start
    stop = n if samples.stop is None else samples.stop
    if stop > n or start >= stop - 1:
        raise ScenarioError(f"{sc.path or sc.name}: samples: [{start}, {stop}) exceeds the log's {n} records")
    check_windows(sc, start, stop, log)
    if model is not None:
        check_moving(model, log.select(start, stop), str(sc.log.source.path))
    return start, stop


def check_moving(model: KinematicModel, log: Log, path: str) -> None:
    """Refuse a wheel's counter (or joint) that never changes while the tracker travels."""
    track = np.asarray(log.T_world_sensor, dtype=float)
    travel = float(np.sum(np.linalg.norm(np.diff(track[:, :2], axis=0), axis=1)))
    turn = float(np.sum(np.abs(np.diff(np.unwrap(track[:, 2])))))
    if travel < MOVING_M and turn < MOVING_RAD:
        return
    radians = log.joint_positions is not None
    for name, kind in model.encoder_kinds.items():
        if kind != "counter" or name not in log.header.encoder_names:
            continue
        values = log.joint_position(name) if radians else log.encoder(name)
        if np.all(values == values[0]):
            what = f"the joint read as {name}" if radians else f"encoder {name}"
            key = "dataset.encoders" if radians else "the log's header and columns"
            raise DatasetError(
                path,
                None,
                f"{what} reads {float(values[0]):g} in all {log.n_records} records while the tracker travels "
                f"{travel:.2f} m and turns {turn:.2f} rad: a wheel that never turns; is it the right one "
                f"({key}), and did its driver publish it?",
            )


def check_windows(sc: Scenario, start: int, stop: int, log: Log | None = None) -> None:
    """Refuse, before anything is built, a horizon that leaves fewer windows than parameters (a
    log of measured increments: fewer increments)."""
    H, stride = sc.objective.residual.horizon, sc.objective.residual.stride
    first, fit_stop = start, split(sc, start, stop)
    ends = ""
    if sc.log.alignment.tracker_lag == "auto" and log is not None:
        first, fit_stop = fit_records(sc, log, start, stop)
        lo, hi = sc.log.alignment.search
        ends = f" (the fitted lag's search [{lo:g}, {hi:g}] s leaves out the records its reach covers)"
    intervals = fit_stop - first - 1
    kind = Poses() if log is None else log.reference.kind
    windows = kind.window_count((first, fit_stop), H, stride)
    always = sc.objective.sensor.held()
    n_free = len(set(scenario_params(sc)) - set(sc.parameters.fixed) - set(always))
    if windows >= n_free:
        return
    if kind.horizon(H) is not None:  # windows of its own: no horizon to shorten
        part = f"{sc.origin} ({sc.dataset.name}): " if sc.origin else ""
        raise ScenarioError(
            f"{sc.path or sc.name}: {part}{windows} {kind.window_words} in the {fit_stop - first} fitted "
            f"records of samples [{start}, {stop}){ends} for {n_free} parameters; widen samples"
        )
    longest = intervals - (n_free - 1) * stride
    fix = f"shorten residual.horizon to at most {longest}" if longest >= 1 else "select more samples"
    part = f"{sc.origin} ({sc.dataset.name}): " if sc.origin else ""
    raise ScenarioError(
        f"{sc.path or sc.name}: {part}residual.horizon {H} (stride {stride}) leaves {windows} residual "
        f"window(s) in the {fit_stop - first} fitted records of samples [{start}, {stop}){ends} for "
        f"{n_free} parameters; {fix}, or widen samples"
    )


def fit_records(sc: Scenario, log: Log, start: int, stop: int) -> tuple[int, int]:
    """The records a fitted lag is found on: those whose shifted times stay inside the log for
    every lag of the search (up to the hold-out)."""
    reach = max(abs(v) for v in sc.log.alignment.search)
    t = log.time_s
    first = max(start, int(np.searchsorted(t, t[0] + reach, side="left")))
    last = min(stop, int(np.searchsorted(t, t[-1] - reach, side="right")))
    return first, split(sc, first, last)


def split(sc: Scenario, start: int, stop: int) -> int:
    """The first record of the hold-out (``stop`` when there is none)."""
    hf = sc.validation.holdout_fraction
    return stop if hf is None else start + round((1.0 - hf) * (stop - start))


def held(sc: Scenario, model: KinematicModel, log: Log, start: int, stop: int) -> dict[str, str]:
    """Free parameters the records ``start:stop`` cannot determine at all, with the reason: the
    fit holds them at their initial values (with a warning) instead of failing as singular."""
    inputs = model.inputs(log.select(start, stop), sc.objective.residual.steering_sample)
    return {n: why for n, why in model.undetermined(inputs).items() if n not in sc.parameters.fixed}


def median_dt(sc: Scenario, log: Log) -> float:
    """The median time between the selected records (s)."""
    t = log.time_s[sc.log.samples.start : sc.log.samples.stop]
    return float(np.median(np.diff(t))) if t.size > 1 else 1.0


def resolved(sc: Scenario, log: Log) -> Scenario:
    """``sc`` with its horizon in records for ``log``: ``residual.horizon_s`` over the log's median
    interval when given; a record horizon that spans a very short time at a high rate is warned
    about. A log of measured increments has them as its windows: the horizon only says whether an
    increment may span several records (2 or more) or not (1, the fastest form)."""
    residual, dt = sc.objective.residual, median_dt(sc, log)
    own = log.reference.kind.horizon(residual.horizon)
    if own is not None:
        return sc.with_options(residual=replace(residual, horizon=own, horizon_s=None))
    if residual.horizon_s is not None:
        H = max(1, round(residual.horizon_s / dt)) if dt > 0 else 1
        return sc.with_options(residual=replace(residual, horizon=int(H)))
    span = residual.horizon * dt
    if 0 < dt <= 1.0 / HIGH_RATE_HZ and span < SHORT_WINDOW_S:
        part = f"{sc.origin} ({sc.dataset.name}): " if sc.origin else ""
        warnings.warn(
            f"{part}residual.horizon {residual.horizon} record(s) spans {1e3 * span:.0f} ms at "
            f"{1.0 / dt:.0f} Hz: each window's motion is little more than the tracker's noise; give the "
            "windows' duration as residual.horizon_s (e.g. 0.5)",
            NlpCalibWarning,
            stacklevel=3,
        )
    return sc


def joint_residual(sc: Scenario, parts: Sequence[PreparedLog]) -> ResidualOptions:
    """The residual form of logs fitted together: one record horizon. ``horizon_s`` that means
    different record horizons on the logs is refused; a record horizon that spans very different
    durations is warned about."""
    horizons = [p.scenario.objective.residual.horizon for p in parts]
    spans = [H * median_dt(p.scenario, p.log) for H, p in zip(horizons, parts)]
    each = ", ".join(
        f"{h} records, {s:.3g} s on datasets[{i}]" for i, (h, s) in enumerate(zip(horizons, spans))
    )
    given = sc.objective.residual
    if given.horizon_s is not None and len(set(horizons)) > 1:
        raise ScenarioError(
            f"{sc.path or sc.name}: residual.horizon_s {given.horizon_s:g} s is {each}: logs fitted together "
            "need one record horizon; give residual.horizon (records) instead"
        )
    if min(spans) > 0 and max(spans) > DURATION_RATIO * min(spans):
        warnings.warn(
            f"residual.horizon {horizons[0]} records spans very different durations ({each}): the logs' "
            "windows weigh very different stretches of driving",
            NlpCalibWarning,
            stacklevel=3,
        )
    return replace(given, horizon=horizons[0])


def prepare(sc: Scenario, log: Log | None = None) -> PreparedLog:
    """Read (unless ``log`` is given), select and check the single-log scenario ``sc``'s log (its
    horizon in records resolved for the log)."""
    model, log = read(sc, log)
    sc = resolved(sc, log)
    start, stop = select(sc, log, model)
    first_split = split(sc, start, stop)
    undetermined = held(sc, model, log, start, first_split)
    for name, why in undetermined.items():
        warnings.warn(
            f"{name} is held at its initial value: {why} in the fitted records", NlpCalibWarning, stacklevel=2
        )
    gaps = gaps_said(sc, log, start, stop)
    windows_between(sc, log, gaps, start, stop)
    return PreparedLog(sc, model, log, start, stop, first_split, undetermined, gaps)


def windows_between(sc: Scenario, log: Log, gaps: np.ndarray, start: int, stop: int) -> None:
    """Refuse a horizon that fits between none of the selected records' gaps: no window would be
    left to fit, and the closed form and the pre-flight would say the drive shows nothing. A
    tracker that delivers its poses in bursts (stamped on arrival) does this: its median interval
    is milliseconds, so ``horizon_s`` asks for hundreds of records, and its pauses are gaps."""
    H = sc.objective.residual.horizon
    if log.reference.kind.horizon(H) is not None or stop - start < 2:
        return  # measured increments are their own windows
    cut = np.asarray(gaps[start : stop - 1], dtype=bool)
    if not cut.any():
        return
    # The longest run of intervals between two gaps: a window needs H of them.
    edges = np.flatnonzero(np.diff(np.concatenate([[1], cut.astype(int), [1]])))
    longest = int(np.max(edges[1::2] - edges[::2])) if edges.size > 1 else 0
    if longest >= H:
        return
    dt = np.diff(log.time_s[start:stop])
    part = f"{sc.origin} ({sc.dataset.name})" if sc.origin else str(sc.path or sc.name)
    raise ScenarioError(
        f"{part}: residual.horizon: a window of {H} records fits between none of the {int(cut.sum())} gaps "
        f"in time over {gap_threshold(log.time_s):.3g} s in the selected records (at most {longest} "
        f"intervals run between two): no window is left to fit. The records are {1e3 * np.median(dt):.3g} ms "
        f"apart at the median but {1e3 * np.mean(dt):.3g} ms on average: poses that arrive in bursts, "
        "stamped on arrival, look like this; check the reference's stamps (re-time it, or keep one pose "
        "per burst), or give residual.horizon in records short enough to fit between the gaps"
    )


def gaps_said(sc: Scenario, log: Log, start: int, stop: int) -> np.ndarray:
    """The log's gaps in time (per interval), with a warning naming those in the selected records;
    with the intervals over which the joints' motion is unknown (said where they were read:
    :meth:`~nlp_calib.logs.log.Log.joint_breaks`)."""
    gaps = time_gaps(log.time_s)
    broken = log.joint_breaks()
    inside = np.flatnonzero(gaps[start : stop - 1]) + start
    if inside.size:
        dt = np.diff(log.time_s)
        k = int(inside[np.argmax(dt[inside])])
        part = f"{sc.origin} ({sc.dataset.name}): " if sc.origin else ""
        warnings.warn(
            f"{part}{sc.log.source.numbered}: {inside.size} gap(s) in time over "
            f"{gap_threshold(log.time_s):.3g} s ({GAP_FACTOR:g}× the median interval, at least "
            f"{MIN_GAP_S:g} s) between records (the longest {dt[k]:.3g} s, after "
            f"{log.where(log.line_numbers[k])}, t = {log.time_s[k]:.3f} s: the tracker or the joints "
            "missing); no residual window crosses them",
            NlpCalibWarning,
            stacklevel=3,
        )
    return gaps if broken is None else gaps | broken


def read_checked(sc: Scenario) -> Log:
    """The scenario's log, read and checked against what costs nothing to check."""
    _, log = read(sc)
    select(sc, log)
    return log


def read_all(sc: Scenario) -> list[Log]:
    """Every log of the scenario (its ``datasets``, or its one log), each read and checked."""
    return [read_checked(s) for s in (sc.per_log() if sc.data.joint else (sc,))]
