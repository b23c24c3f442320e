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
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nlp_calib.core.config import coerce, fail, from_mapping, key_name, read_yaml
from nlp_calib.core.errors import ConfigError, FieldError, ScenarioError
from nlp_calib.core.ranges import Range, check_choice, check_range, shown
from nlp_calib.models import DEFAULT_MODEL, MODELS, encoders, get_model, param_names
from nlp_calib.problem import ResidualOptions
from nlp_calib.solvers import SOLVERS
from nlp_calib.solvers.backends import BACKENDS
from nlp_calib.sources import BagSource, DatasetSource, TextSource, moved, parse_source
from nlp_calib.sources.bag import check_joints
from nlp_calib.symbolic.kernels import KERNELS

#: ``validation.blocks`` (or 0: none): each block costs one more fit.
BLOCKS = Range(2, 100, integer=True)
#: Numbers whose squares still fit a float with room to spare: beyond them a value is a typo, and
#: the cost, its weights or the covariance would overflow (silently, or as a NaN result).
MAGNITUDE = Range(-1e6, 1e6)
DELTA = Range(0.0, 1e6, lo_open=True)
WEIGHT = Range(0.0, 1e12, lo_open=True)
TICKS = Range(0.0, 1e9, lo_open=True)
PRIOR_STD = Range(1e-9, 1e6)
THREADS = Range(1, 64, integer=True)
RPE_WINDOW = Range(1, 1_000_000, integer=True)
_FINITE = Range(-math.inf, math.inf, lo_open=True, hi_open=True)
FAULT_HANDLINGS = ("exclude", "repair", "keep")
INITIAL_GUESSES = ("from_file", "auto")


@dataclass(frozen=True)
class SampleSelection:
    """Records ``start:stop`` of the log; ``drop_stationary`` drops windows with no motion."""

    start: int = 0
    stop: int | None = None
    drop_stationary: bool = False

    def __post_init__(self) -> None:
        if self.start < 0 or (self.stop is not None and self.stop <= self.start + 1):
            raise FieldError("start", f"need 0 <= start < stop - 1, got start={self.start} stop={self.stop}")


@dataclass(frozen=True)
class RobustOptions:
    """Kernel name and its threshold ``delta`` on the Mahalanobis norm ``sqrt(eᵀΩe)``."""

    kernel: str = "huber"
    delta: float = 0.05

    def __post_init__(self) -> None:
        check_choice("kernel", self.kernel, KERNELS)
        check_range("delta", self.delta, DELTA)


@dataclass(frozen=True)
class InformationWeights:
    """Diagonal of Ω: weight of the x/y error (1/m²) and of the angle error (1/rad²)."""

    translation: float = 1.0
    rotation: float = 1.0

    def __post_init__(self) -> None:
        check_range("translation", self.translation, WEIGHT)
        check_range("rotation", self.rotation, WEIGHT)

    def omega(self) -> tuple[float, float, float]:
        return (self.translation, self.translation, self.rotation)


@dataclass(frozen=True)
class ValidationOptions:
    """``holdout_fraction``: trailing fraction of the records kept out of the fit and scored;
    ``blocks``: contiguous blocks of the blocked cross-validation that gives the data-driven σ
    (0: none); ``rpe_window``: records of the fixed-window RPE."""

    holdout_fraction: float | None = None
    rpe_window: int = 25
    blocks: int = 10

    def __post_init__(self) -> None:
        hf = self.holdout_fraction
        if hf is not None and not 0.0 < hf < 1.0:
            raise FieldError("holdout_fraction", f"must lie in (0, 1), got {hf}")
        if self.blocks != 0 and (why := BLOCKS.problem(self.blocks)):
            raise FieldError("blocks", f"0 (none) or {why}")
        check_range("rpe_window", self.rpe_window, RPE_WINDOW)


@dataclass(frozen=True)
class AlignmentOptions:
    """``tracker_lag``: seconds the tracker reports after the encoders, or ``auto`` to estimate
    it by the fit cost over ``search`` at ``step``."""

    tracker_lag: float | str = 0.0
    search: tuple[float, float] = (-0.2, 0.2)
    step: float = 0.01

    def __post_init__(self) -> None:
        if isinstance(self.tracker_lag, str):
            check_choice("tracker_lag", self.tracker_lag, ("auto",))
        lo, hi = self.search
        if not (lo < hi and self.step > 0 and (hi - lo) / self.step <= 1000):
            raise FieldError("search", "needs search [lo, hi] with lo < hi and 0 < step, at most 1000 steps")


@dataclass(frozen=True)
class FaultOptions:
    """What to do with encoder and tracker faults found in the log (every run looks for them).

    ``exclude`` (default): drop every residual window that crosses a fault; ``repair``: correct
    the counts of counter faults (and say what changed), drop windows at tracker jumps; ``keep``:
    report the faults and fit every window.
    """

    handling: str = "exclude"

    def __post_init__(self) -> None:
        check_choice("handling", self.handling, FAULT_HANDLINGS)


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on one parameter."""

    mean: float
    std: float

    def __post_init__(self) -> None:
        check_range("mean", self.mean, MAGNITUDE)
        check_range("std", self.std, PRIOR_STD)


@dataclass(frozen=True)
class LogEntry:
    """One log of a calibration: where its records come from, and its ``samples`` and
    ``alignment`` (its own, or the scenario's)."""

    source: DatasetSource
    samples: SampleSelection = field(default_factory=SampleSelection)
    alignment: AlignmentOptions = field(default_factory=AlignmentOptions)

    @property
    def path(self) -> Path:
        return self.source.path


@dataclass(frozen=True)
class DataOptions:
    """The logs (one, or several fitted together: ``datasets``), how strictly they are read, the
    encoders' noise (ticks) and what to do with faults."""

    logs: tuple[LogEntry, ...]
    joint: bool = False
    strict: bool = True
    encoder_noise: Mapping[str, float] = field(default_factory=dict)
    faults: FaultOptions = field(default_factory=FaultOptions)

    def __post_init__(self) -> None:
        for enc, ticks in self.encoder_noise.items():
            check_range(f"encoder_noise.{enc}", ticks, TICKS)


@dataclass(frozen=True)
class ObjectiveOptions:
    """What the fit minimises: the residual form, the robust kernel and the information weights."""

    residual: ResidualOptions = field(default_factory=ResidualOptions)
    robust: RobustOptions = field(default_factory=RobustOptions)
    information: InformationWeights = field(default_factory=InformationWeights)


@dataclass(frozen=True)
class ParameterOptions:
    """Where the parameters start (``from_file``, ``auto`` or values), bounds, fixed ones, priors."""

    initial_guess: str | Mapping[str, float] = "from_file"
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    fixed: tuple[str, ...] = ()
    priors: Mapping[str, Prior] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if isinstance(self.initial_guess, str):
            check_choice("initial_guess", self.initial_guess, INITIAL_GUESSES)
        else:
            for n, value in self.initial_guess.items():
                check_range(f"initial_guess.{n}", value, MAGNITUDE)
        for n, (lo, hi) in self.bounds.items():
            if not lo < hi:
                raise FieldError(f"bounds.{n}", f"needs lo < hi, got [{lo}, {hi}]")
            guess = self.guess(n)
            if guess is not None and not lo <= guess <= hi:
                raise FieldError(f"bounds.{n}", f"the initial guess {guess:g} lies outside [{lo:g}, {hi:g}]")
        for n in self.priors:
            if n in self.fixed:
                raise FieldError(f"priors.{n}", "a fixed parameter cannot also have a prior; drop one")

    def guess(self, name: str) -> float | None:
        """The scenario's own initial value of ``name``, if it gives one."""
        return self.initial_guess.get(name) if isinstance(self.initial_guess, Mapping) else None


@dataclass(frozen=True)
class ComputeOptions:
    """How the problem's Functions are evaluated: ``backend`` and ``threads``."""

    backend: str = "compiled"
    threads: int = 1

    def __post_init__(self) -> None:
        check_choice("backend", self.backend, BACKENDS)
        check_range("threads", self.threads, THREADS)


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

    def with_options(self, **flat: Any) -> Scenario:
        """The same scenario with top-level keys of its file replaced by values of their types
        (``samples=SampleSelection(...)``): ``samples`` and ``alignment`` apply to every log."""
        sc = self
        for key, value in flat.items():
            if key == "dataset":
                sc = sc.with_dataset(value)
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
        stems = [e.path.stem for e in self.data.logs]
        return tuple(
            dataclasses.replace(
                self,
                name=stem if stems.count(stem) == 1 else f"{i + 1}_{stem}",
                data=dataclasses.replace(self.data, logs=(e,), joint=False),
                origin=f"datasets[{i}]",
            )
            for i, (stem, e) in enumerate(zip(stems, self.data.logs))
        )

    def options_for(self, solver: str) -> Any:
        """The options of ``solver``: the scenario's block, or the solver's defaults."""
        options = self.solver_options.get(solver)
        return options if options is not None else SOLVERS[solver].options_type()

    def with_solver_options(self, solver: str, options: Any) -> Scenario:
        """The same scenario with ``solver``'s options replaced."""
        return dataclasses.replace(self, solver_options={**self.solver_options, solver: options})

    def where(self) -> str:
        """How messages name this scenario (its file, or its name), with the log of a part."""
        part = f": {self.origin} ({self.dataset.name})" if self.origin else ""
        return f"{self.path or self.name}{part}"


#: The group of each top-level key of a scenario file that is not a field of :class:`Scenario`
#: itself (``dataset``, ``datasets``, ``samples`` and ``alignment`` make the logs).
_GROUP_OF: Mapping[str, str] = {
    **{f.name: "data" for f in dataclasses.fields(DataOptions) if f.name not in ("logs", "joint")},
    **{f.name: "objective" for f in dataclasses.fields(ObjectiveOptions)},
    **{f.name: "parameters" for f in dataclasses.fields(ParameterOptions)},
    **{f.name: "compute" for f in dataclasses.fields(ComputeOptions)},
}
_LOG_KEYS = ("dataset", "datasets", "samples", "alignment")
_OWN_KEYS = ("name", "model", "solvers", "validation")


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
    hints = typing.get_type_hints(Scenario)
    own = {k: coerce(raw[k], hints[k], f"{source}: {k}") for k in _OWN_KEYS if k in raw}
    own.setdefault("name", Path(source).stem)
    options = {
        k: from_mapping(SOLVERS[k].options_type, v, f"{source}: {k}") for k, v in raw.items() if k in SOLVERS
    }
    logs = _log_entries(raw, source, base_dir)
    return Scenario(
        path=path,
        data=_group(DataOptions, raw, source, logs=logs, joint="datasets" in raw),
        objective=_group(ObjectiveOptions, raw, source),
        parameters=_group(ParameterOptions, raw, source),
        compute=_group(ComputeOptions, raw, source),
        solver_options=options,
        **own,
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
    model = get_model(sc.model)
    _check_parameter_names(sc.parameters, param_names(model), source)
    for enc in sc.data.encoder_noise:
        _choice(enc, encoders(model), f"{source}: encoder_noise")
    for i, entry in enumerate(sc.data.logs):
        if isinstance(entry.source, BagSource):
            key = f"datasets[{i}]" if sc.data.joint else "dataset"
            check_joints(entry.source.joints, model, f"{source}: {key}.joints")
    _check_solvers(sc, source)
    _check_overlaps(sc, source)


def _choice(value: str, choices: typing.Iterable[str], where: str) -> None:
    choices = tuple(choices)
    if value not in choices:
        fail(where, f"{value!r} is not one of {', '.join(choices)}")


def _check_name(sc: Scenario, source: str) -> None:
    # The name becomes a folder under the output directory: a plain, non-empty file name.
    if sc.name in ("", ".", "..") or any(c in sc.name for c in "/\\\0"):
        fail(f"{source}: name", f"must be a plain folder name (no '/', '\\' or NUL), got {sc.name!r}")


def _check_parameter_names(p: ParameterOptions, names: tuple[str, ...], source: str) -> None:
    if isinstance(p.initial_guess, Mapping):
        for n in p.initial_guess:
            _choice(n, names, f"{source}: initial_guess")
    for key, given in (("bounds", p.bounds), ("fixed", p.fixed), ("priors", p.priors)):
        for n in given:
            _choice(n, names, f"{source}: {key}")
    if len(set(p.fixed)) == len(names):
        fail(f"{source}: fixed", "every parameter is fixed; nothing is left to estimate")


def _check_solvers(sc: Scenario, source: str) -> None:
    if not sc.solvers:
        fail(f"{source}: solvers", f"list at least one of {', '.join(SOLVERS)}")
    for s in sc.solvers:
        _choice(s, SOLVERS, f"{source}: solvers")
        if sc.parameters.bounds and not SOLVERS[s].supports_bounds:
            fail(
                f"{source}: bounds",
                f"{s} cannot honour bounds; remove {s} from 'solvers' or the bounds "
                f"(solvers that honour bounds: {', '.join(n for n, c in SOLVERS.items() if c.supports_bounds)})",
            )
    for s, options in sc.solver_options.items():
        _check_passthrough(options, f"{source}: {s}")


def _check_overlaps(sc: Scenario, source: str) -> None:
    ranges = [(e.path.resolve(), e.samples) for e in sc.data.logs]
    for i, (path, sel) in enumerate(ranges):
        for j, (other, sel_j) in enumerate(ranges[:i]):
            if (
                path == other
                and sel.start < (sel_j.stop or math.inf)
                and sel_j.start < (sel.stop or math.inf)
            ):
                fail(
                    f"{source}: datasets[{i}]",
                    f"records also in datasets[{j}] ({sc.data.logs[i].path}): records fitted twice would "
                    "count as two drives and shrink the σ; give the entries samples that do not overlap",
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
