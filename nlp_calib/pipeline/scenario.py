"""Scenario YAML files: frozen dataclasses, validated once, on load.

A scenario file is flat (``residual:``, ``samples:``, ``gauss_newton:`` ... at its top level); in
memory its keys are grouped by what they decide (:class:`Scenario`). Every option dataclass checks
its own values when it is made, in neutral words naming the field; :func:`load_scenario` adds the
file and the place, so an unknown key, a wrong type or a value out of range is one line saying
where to fix it, before any computation starts. What can only be checked against the model (a
parameter name, an encoder name, bounds around the initial guess) is checked once the whole
scenario is read (:func:`check_against_model`). Each registered solver has a top-level block
named after it, validated against its own options dataclass.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nlp_calib.core.config import coerce, fail, from_mapping, key_name, read_yaml
from nlp_calib.core.errors import ConfigError, FieldError, ScenarioError
from nlp_calib.core.ranges import Range, check_choice, shown
from nlp_calib.models import DEFAULT_MODEL, MODELS, KinematicModel, encoders, get_model
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline.options import (
    STEERING_DEG,
    AlignmentOptions,
    ComputeOptions,
    DataOptions,
    FaultOptions,
    HandoffOptions,
    InformationWeights,
    LogEntry,
    ObjectiveOptions,
    ParameterOptions,
    Prior,
    RobustOptions,
    SampleSelection,
    SensorOptions,
    ValidationOptions,
)
from nlp_calib.sensors import BESIDE
from nlp_calib.solvers import SOLVERS
from nlp_calib.sources import (
    BagSource,
    BesideSource,
    DatasetSource,
    JointLogSource,
    LidarSource,
    MotionsSource,
    TextSource,
    moved,
    parse_source,
)
from nlp_calib.sources.bag import check_joints
from nlp_calib.sources.base import encoder_joints
from nlp_calib.sources.beside import PAIRS as BESIDE_PAIRS
from nlp_calib.sources.joints import check_encoders

#: Numbers a library may be handed as they are (``ipopt.options``).
_FINITE = Range(-math.inf, math.inf, lo_open=True, hi_open=True)

__all__ = [
    "AlignmentOptions",
    "ComputeOptions",
    "DataOptions",
    "FaultOptions",
    "HandoffOptions",
    "InformationWeights",
    "LogEntry",
    "ObjectiveOptions",
    "ParameterOptions",
    "Prior",
    "RobustOptions",
    "SampleSelection",
    "Scenario",
    "SensorOptions",
    "ValidationOptions",
    "load_scenario",
    "scenario_from_mapping",
]


@dataclass(frozen=True)
class Scenario:
    """A calibration run: its data, model, objective, parameters, solvers and checks.

    ``path`` is the file it was read from; ``origin`` names, for a single-log part of a
    calibration from several logs, where that log comes from in the file (``datasets[1]``).
    """

    name: str
    data: DataOptions
    path: Path | None = None
    origin: str | None = None
    model: str = DEFAULT_MODEL
    objective: ObjectiveOptions = field(default_factory=ObjectiveOptions)
    parameters: ParameterOptions = field(default_factory=ParameterOptions)
    solvers: tuple[str, ...] = tuple(SOLVERS)
    #: Each solver's options, by solver name (the YAML block of that name); defaults when absent.
    solver_options: Mapping[str, Any] = field(default_factory=dict)
    validation: ValidationOptions = field(default_factory=ValidationOptions)
    compute: ComputeOptions = field(default_factory=ComputeOptions)
    #: What the hand-off files name (the ros2_control controller).
    handoff: HandoffOptions = field(default_factory=HandoffOptions)

    @classmethod
    def of(cls, name: str, dataset: str | Path, **flat: Any) -> Scenario:
        """A scenario made in code: a text log at ``dataset`` and the top-level keys of a scenario
        file as values of their types (``residual=ResidualOptions(horizon=5)``)."""
        data = DataOptions(logs=(LogEntry(TextSource(Path(dataset))),))
        return cls(name=name, data=data).with_options(**flat)

    @property
    def log(self) -> LogEntry:
        """The log of a single-log scenario (the first of several)."""
        return self.data.logs[0]

    @property
    def dataset(self) -> Path:
        """The path of the (first) log."""
        return self.log.path

    def with_dataset(self, path: str | Path) -> Scenario:
        """The same scenario on another log (``--data``); another bag is read with the same topics."""
        entry = dataclasses.replace(self.log, source=moved(self.log.source, Path(path)))
        return dataclasses.replace(self, data=dataclasses.replace(self.data, logs=(entry,), joint=False))

    def with_datasets(self, paths: Sequence[str | Path]) -> Scenario:
        """The same scenario on several logs fitted together (``datasets:``), each read as this
        scenario's log is and with its ``samples`` and ``alignment``."""
        entries = tuple(dataclasses.replace(self.log, source=moved(self.log.source, Path(p))) for p in paths)
        return dataclasses.replace(self, data=dataclasses.replace(self.data, logs=entries, joint=True))

    def with_options(self, **flat: Any) -> Scenario:
        """The same scenario with top-level keys of its file replaced by values of their types
        (``samples=SampleSelection(...)``): ``samples`` and ``alignment`` apply to every log."""
        sc = self
        for key, value in flat.items():
            if key == "dataset":
                sc = sc.with_dataset(value)
                continue
            if key == "datasets":
                sc = sc.with_datasets(value)
                continue
            if key in ("samples", "alignment"):
                logs = tuple(dataclasses.replace(e, **{key: value}) for e in sc.data.logs)
                sc = dataclasses.replace(sc, data=dataclasses.replace(sc.data, logs=logs))
                continue
            group = _GROUP_OF.get(key)
            if group is None:
                sc = dataclasses.replace(sc, **{key: value})
                continue
            inner = dataclasses.replace(getattr(sc, group), **{key: value})
            sc = dataclasses.replace(sc, **{group: inner})
        return sc

    def per_log(self) -> tuple[Scenario, ...]:
        """One single-log scenario per log, named after its log (numbered when names repeat)."""
        if not self.data.joint:
            return (self,)
        names = log_names([e.path for e in self.data.logs])
        return tuple(
            dataclasses.replace(
                self,
                name=name,
                data=dataclasses.replace(self.data, logs=(e,), joint=False),
                origin=f"datasets[{i}]",
            )
            for i, (name, e) in enumerate(zip(names, self.data.logs))
        )

    def options_for(self, solver: str) -> Any:
        """The options of ``solver``: the scenario's block, or the solver's defaults."""
        options = self.solver_options.get(solver)
        return options if options is not None else SOLVERS[solver].options_type()

    def with_solver_options(self, solver: str, options: Any) -> Scenario:
        """The same scenario with ``solver``'s options replaced."""
        return dataclasses.replace(self, solver_options={**self.solver_options, solver: options})

    def model_form(self) -> KinematicModel:
        """The scenario's model in the form its logs' encoder units call for (joints in radians:
        parameters in robot units, ``nlp_calib.models.radians``)."""
        return in_units(get_model(self.model), self.log.source.joint_units)

    def where(self) -> str:
        """How messages name this scenario (its file, or its name), with the log of a part."""
        part = f": {self.origin} ({self.dataset.name})" if self.origin else ""
        return f"{self.path or self.name}{part}"


def log_names(paths: list[Path]) -> list[str]:
    """A folder name for each log, unique and recognisable: the file's stem; where stems repeat,
    its folder's name first (``a-drive``); where that repeats too (one file twice), its place in
    the list (``1_drive``); never hidden (a leading dot would hide it, or take the staging prefix)."""
    stems = [p.stem.lstrip(".") or "log" for p in paths]
    names = [s if stems.count(s) == 1 else f"{p.parent.name.lstrip('.')}-{s}" for p, s in zip(paths, stems)]
    names = [n if names.count(n) == 1 else f"{i + 1}_{stems[i]}" for i, n in enumerate(names)]
    unique: list[str] = []
    for n in names:
        name, k = n, 2
        while name in unique:
            name, k = f"{n}_{k}", k + 1
        unique.append(name)
    return unique


#: The group of each top-level key of a scenario file that is not a field of :class:`Scenario`
#: itself (``dataset``, ``datasets``, ``samples`` and ``alignment`` make the logs).
_GROUP_OF: Mapping[str, str] = {
    **{f.name: "data" for f in dataclasses.fields(DataOptions) if f.name not in ("logs", "joint")},
    **{f.name: "objective" for f in dataclasses.fields(ObjectiveOptions)},
    **{f.name: "parameters" for f in dataclasses.fields(ParameterOptions)},
    **{f.name: "compute" for f in dataclasses.fields(ComputeOptions)},
}
_LOG_KEYS = ("dataset", "datasets", "samples", "alignment")
_OWN_KEYS = ("name", "model", "solvers", "validation", "handoff")


def top_level_keys() -> tuple[str, ...]:
    """The keys a scenario file may hold at its top level, one block per registered solver included."""
    return (*_OWN_KEYS, *_LOG_KEYS, *_GROUP_OF, *SOLVERS)


def scenario_from_mapping(raw: Any, source: str, base_dir: Path, path: Path | None = None) -> Scenario:
    """Validate a parsed YAML mapping; relative dataset paths resolve against ``base_dir``."""
    try:
        sc = _scenario(raw, source, base_dir, path)
        check_against_model(sc, source)
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None
    return sc


def _check_keys(raw: Any, source: str) -> None:
    if not isinstance(raw, Mapping):
        keys = ", ".join(top_level_keys())
        fail(source, f"expected a mapping of scenario keys ({keys}), got {type(raw).__name__}")
    for key in raw:
        if key not in top_level_keys():
            fail(f"{source}: {key_name(key)}", f"unknown key; valid keys are {', '.join(top_level_keys())}")
    if ("dataset" in raw) == ("datasets" in raw):
        fail(
            source,
            "give 'dataset' (path of the log, relative to this file, or a bag block) or 'datasets' (a "
            "list of them), not " + ("both" if "dataset" in raw else "neither"),
        )


def _group(cls: type, raw: Mapping[str, Any], source: str, **given: Any) -> Any:
    """The group dataclass ``cls`` made of the top-level keys of ``raw`` that belong to it (and of
    the ``given`` values, already of their types)."""
    hints = typing.get_type_hints(cls)
    values = {k: coerce(raw[k], hints[k], f"{source}: {k}") for k in hints if k in raw and k not in given}
    try:
        return cls(**values, **given)
    except FieldError as exc:
        fail(f"{source}: {exc.field}", exc.reason)


def _scenario(raw: Any, source: str, base_dir: Path, path: Path | None) -> Scenario:
    _check_keys(raw, source)
    if isinstance(raw.get("sensor"), str):
        # ``sensor: 3d`` is short for ``sensor: {mount: 3d}``.
        raw = {**raw, "sensor": {"mount": raw["sensor"]}}
    hints = typing.get_type_hints(Scenario)
    own = {k: coerce(raw[k], hints[k], f"{source}: {k}") for k in _OWN_KEYS if k in raw}
    own.setdefault("name", Path(source).stem)
    options = {
        k: from_mapping(SOLVERS[k].options_type, v, f"{source}: {k}") for k, v in raw.items() if k in SOLVERS
    }
    objective = _group(ObjectiveOptions, raw, source)
    logs = _in_3d(_log_entries(raw, source, base_dir), objective.sensor.sensor.group == "SE(3)")
    return Scenario(
        path=path,
        data=_group(DataOptions, raw, source, logs=logs, joint="datasets" in raw),
        objective=objective,
        parameters=_group(ParameterOptions, raw, source),
        compute=_group(ComputeOptions, raw, source),
        solver_options=options,
        **own,
    )


def _in_3d(logs: tuple[LogEntry, ...], in_3d: bool) -> tuple[LogEntry, ...]:
    """A gyro's dataset beside a 3-D sensor's (``{mount: 3d, beside: gyro}``): the reference's
    motions between its 3-D poses."""
    if not in_3d:
        return logs
    return tuple(
        dataclasses.replace(e, source=dataclasses.replace(e.source, in_3d=True))
        if isinstance(e.source, BesideSource)
        else e
        for e in logs
    )


def _log_entries(raw: Mapping[str, Any], source: str, base_dir: Path) -> tuple[LogEntry, ...]:
    """The logs: ``dataset`` (one source) or ``datasets`` (a list of sources, each a path, a
    ``{path, samples, alignment}`` mapping or a source block with its own samples and alignment)."""
    samples = coerce(raw.get("samples"), SampleSelection, f"{source}: samples")
    alignment = coerce(raw.get("alignment"), AlignmentOptions, f"{source}: alignment")
    if "dataset" in raw:
        return (LogEntry(parse_source(raw["dataset"], f"{source}: dataset", base_dir), samples, alignment),)
    where = f"{source}: datasets"
    value = raw["datasets"]
    if not isinstance(value, (list, tuple)) or not value:
        fail(
            where,
            "expected a non-empty list of log paths, {path, samples, alignment} mappings or bag blocks, "
            f"got {type(value).__name__}",
        )
    return tuple(
        _log_entry(item, f"{where}[{i}]", base_dir, samples, alignment) for i, item in enumerate(value)
    )


def _log_entry(
    item: Any, place: str, base_dir: Path, samples: SampleSelection, alignment: AlignmentOptions
) -> LogEntry:
    own = ("samples", "alignment")
    block: Any = item
    if isinstance(item, Mapping):
        block = {k: v for k, v in item.items() if k not in own}
        if set(block) == {"path"}:
            block = block["path"]
    return LogEntry(
        source=parse_source(block, place, base_dir, own),
        samples=coerce(item["samples"], SampleSelection, f"{place}.samples")
        if _has(item, "samples")
        else samples,
        alignment=coerce(item["alignment"], AlignmentOptions, f"{place}.alignment")
        if _has(item, "alignment")
        else alignment,
    )


def _has(item: Any, key: str) -> bool:
    return isinstance(item, Mapping) and key in item


def check_against_model(sc: Scenario, source: str) -> None:
    """What only the model can tell: names of parameters and encoders, bag joints, the solvers'
    capabilities, and logs fitted twice."""
    _check_name(sc, source)
    try:
        check_choice("model", sc.model, MODELS)
    except FieldError as exc:
        fail(f"{source}: {exc.field}", exc.reason)
    model = sc.model_form()
    _check_parameter_names(sc.parameters, scenario_params(sc), sc.objective.sensor.sensor.clocks, source)
    for enc in sc.data.encoder_noise:
        _choice(enc, encoders(model), f"{source}: encoder_noise")
    for enc in sc.data.counts_per_turn:
        _choice(enc, encoders(model), f"{source}: counts_per_turn")
    for i, entry in enumerate(sc.data.logs):
        key = f"datasets[{i}]" if sc.data.joint else "dataset"
        _check_beside(sc, entry.source, f"{source}: {key}")
        # A gyro beside a reference: each of its two sources reads the joints.
        both = (entry.source.reference, entry.source.gyro) if isinstance(entry.source, BesideSource) else ()
        for one in both or (entry.source,):
            if isinstance(one, (BagSource, LidarSource)):
                check_joints(one.joints, model, f"{source}: {key}.joints")
            if isinstance(one, (JointLogSource, MotionsSource)):
                check_encoders(one.encoders, model, f"{source}: {key}.encoders")
    _check_units(sc, source)
    _check_solvers(sc, source)
    _check_overlaps(sc, source)


def _check_beside(sc: Scenario, source: DatasetSource, where: str) -> None:
    """A sensor beside the reference (``sensor: {…, beside: gyro}``) reads a dataset naming both
    sensors' streams, and such a dataset is read by no other sensor."""
    sensor = sc.objective.sensor
    pairs = " or ".join(f"{{{ref}: …, {gyro}: …}}" for _, _, ref, gyro in BESIDE_PAIRS)
    if sensor.beside and not isinstance(source, BesideSource):
        fail(
            where,
            f"sensor: {{mount: {sensor.mount}, beside: {sensor.beside}}} reads the reference's poses or "
            f"motions and a gyro's rates from one dataset naming both ({pairs}, beside the joints; "
            "docs/imu.md)",
        )
    if (
        isinstance(source, BesideSource)
        and source.in_3d
        and isinstance(source.reference, (LidarSource, MotionsSource))
    ):
        fail(
            where,
            f"sensor: {{mount: {sensor.mount}, beside: {sensor.beside}}} reads a camera's 3-D poses "
            "(poses: a TUM file, or tracker: a bag's pose topic) beside the gyro's rates; a lidar's scans "
            "and a motions file are planar motions: fit them with sensor: {mount: planar, beside: gyro}",
        )
    if isinstance(source, BesideSource) and not sensor.beside:
        fail(
            where,
            f"it names a reference's poses or motions and a gyro's rates ({pairs}): fit both with sensor: "
            f"{_besides()}, or leave one of the two keys out (sensor: {sensor.mount})",
        )


def _besides() -> str:
    return " or ".join(f"{{mount: {m}, beside: {b}}}" for m, b in BESIDE)


def refuse_off_the_base(sc: Scenario, what: str, why: str) -> None:
    """A one-line error when ``what`` needs the base's planar pose and ``sc``'s sensor does not
    give it (``why``)."""
    sensor = sc.objective.sensor.sensor
    if not sensor.planar_base:
        raise ScenarioError(
            f"{sc.where()}: sensor: {sensor.kind}: {what} is not available for a {sensor.label}: {why}"
        )


def scenario_params(sc: Scenario) -> tuple[str, ...]:
    """Every parameter of the scenario's problem: the model's, then its sensor's mount, then the
    tracker lag when it is estimated (``tracker_lag``: each log's, in a joint fit)."""
    lag = sc.objective.sensor.sensor.clocks if sc.log.alignment.tracker_lag == "auto" else ()
    return (*sc.model_form().kinematic_params, *sc.objective.sensor.params(), *lag)


def _check_units(sc: Scenario, source: str) -> None:
    """Logs fitted together read their encoders in one unit: the parameters' names follow it."""
    units = [e.source.joint_units for e in sc.data.logs]
    if len(set(units)) > 1:
        listed = ", ".join(f"datasets[{i}] {u}" for i, u in enumerate(units))
        fail(
            f"{source}: datasets",
            f"logs fitted together need their joints in one unit ({listed}): the parameters differ "
            "(wheel radius or gain per tick); set joint_units alike",
        )


def _choice(value: str, choices: typing.Iterable[str], where: str) -> None:
    choices = tuple(choices)
    if value not in choices:
        fail(where, f"{value!r} is not one of {', '.join(choices)}")


def _check_name(sc: Scenario, source: str) -> None:
    # The name becomes a folder under the output directory: a plain, non-empty file name.
    if sc.name in ("", ".", "..") or any(c in sc.name for c in "/\\\0"):
        fail(f"{source}: name", f"must be a plain folder name (no '/', '\\' or NUL), got {sc.name!r}")


def _check_parameter_names(
    p: ParameterOptions, names: tuple[str, ...], clocks: tuple[str, ...], source: str
) -> None:
    if isinstance(p.initial_guess, Mapping):
        for n in p.initial_guess:
            _choice(n, names, f"{source}: initial_guess")
    for key, given in (("bounds", p.bounds), ("fixed", p.fixed), ("priors", p.priors), ("known", p.known)):
        for n in given:
            _choice(n, names, f"{source}: {key}")
    # The time offset is the recording's, not the robot's: fitted by default alongside the
    # robot's and the mount's parameters, it is no calibration alone.
    if set(names) - set(clocks) <= set(p.fixed):
        fail(
            f"{source}: fixed",
            "every parameter of the robot and its sensor's mount is fixed; nothing is left to estimate "
            "(the time offset is fitted only with them)",
        )


def _check_solvers(sc: Scenario, source: str) -> None:
    if not sc.solvers:
        fail(f"{source}: solvers", f"list at least one of {', '.join(SOLVERS)}")
    bounded = ", ".join(n for n, c in SOLVERS.items() if c.supports_bounds)
    for s in sc.solvers:
        _choice(s, SOLVERS, f"{source}: solvers")
        if sc.parameters.bounds and not SOLVERS[s].supports_bounds:
            fail(
                f"{source}: bounds",
                f"{s} cannot honour bounds; remove {s} from 'solvers' or the bounds "
                f"(solvers that honour bounds: {bounded})",
            )
    for s, options in sc.solver_options.items():
        _check_passthrough(options, f"{source}: {s}")


def _check_overlaps(sc: Scenario, source: str) -> None:
    """One log is one log, whatever it is called: entries of one file may not share records."""
    logs = sc.data.logs
    ranges = [(e.source.identity(), e.samples) for e in logs]
    for i, (log, sel) in enumerate(ranges):
        for j, (other, sel_j) in enumerate(ranges[:i]):
            if log == other and sel.start < (sel_j.stop or math.inf) and sel_j.start < (sel.stop or math.inf):
                fail(
                    f"{source}: datasets[{i}]",
                    f"records also in datasets[{j}] ({logs[i].path} is the same log as datasets[{j}], "
                    f"{logs[j].path}): records fitted twice would count as two drives and shrink the σ; "
                    "give the entries samples that do not overlap",
                )


def _check_passthrough(options: Any, where: str) -> None:
    """Options a solver hands on to a library as they are (``ipopt.options``) must be plain
    scalars: the library, not this package, would otherwise meet a list or a mapping."""
    for f in dataclasses.fields(options):
        value = getattr(options, f.name)
        if not isinstance(value, Mapping):
            continue
        for k, v in value.items():
            place = f"{where}.{f.name}.{key_name(k)}"
            if not (isinstance(k, str) and k.isidentifier()):
                fail(place, "option names are plain words (letters, digits, '_')")
            if isinstance(v, (bool, str)) and len(str(v)) <= 1000:
                continue
            finite = Range(-(2**63), 2**63 - 1, integer=True) if isinstance(v, int) else _FINITE
            if finite.problem(v) is not None:
                fail(place, f"expected a finite number, a string or true/false, got {shown(v)}")


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file."""
    p = Path(path)
    try:
        raw = read_yaml(p, "scenario")
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None
    return scenario_from_mapping(raw, str(p), p.parent, p)


def with_joint_limits(sc: Scenario, limits: Mapping[str, float]) -> tuple[Scenario, str | None]:
    """``sc`` with its steered wheels' largest angle (``vehicle.max_steering_deg``) from the joint
    ``limits`` (rad, by joint name: a URDF's ``<limit>``) of the joints its angle encoders read,
    the tightest of them, and a line saying so; unchanged where the scenario gives the angle itself
    or names no such joint. A limit beyond a quarter turn is taken as a quarter turn."""
    if sc.parameters.vehicle.max_steering_deg is not None:
        return sc, None
    model = get_model(sc.model)
    steering = [e for e, kind in model.encoder_kinds.items() if kind == "absolute"]
    found = {
        joint: limits[joint]
        for entry in sc.data.logs
        for encoder, joint in encoder_joints(entry.source, model).items()
        if encoder in steering and joint in limits
    }
    if not found:
        return sc, None
    joint = min(found, key=found.__getitem__)
    degrees = min(math.degrees(found[joint]), STEERING_DEG.hi)
    if not degrees > 0:
        raise ScenarioError(
            f"{sc.name}: the steered wheel's joint {joint!r}'s <limit> in the URDF is 0: the wheel cannot "
            "steer; give its real limits, or vehicle: {max_steering_deg: <degrees>}"
        )
    vehicle = dataclasses.replace(sc.parameters.vehicle, max_steering_deg=degrees)
    said = f"{sc.name}: the plan steers within ±{degrees:.3g}°, the URDF's <limit> of joint {joint!r}"
    return sc.with_options(vehicle=vehicle), said
