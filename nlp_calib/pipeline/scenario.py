"""Scenario YAML files: frozen dataclasses, validated on load.

Every section is a frozen dataclass; :func:`load_scenario` checks keys and types against the
dataclass fields, so an unknown key, a wrong type or an inconsistent value is reported with its
place in the file and the valid choices, before any computation starts. Each registered solver
has a top-level block named after it, validated against its own options dataclass.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nlp_calib.core.errors import ConfigError, ScenarioError
from nlp_calib.core.ranges import Range
from nlp_calib.logs.bag_reader import is_bag
from nlp_calib.models import DEFAULT_MODEL, MODELS, encoders, get_model, param_names
from nlp_calib.models.base import INTEGRATIONS, STEERING_SAMPLES
from nlp_calib.pipeline.bags import BagSource, check_joints, dataset_block
from nlp_calib.pipeline.config import coerce, fail, from_mapping, key_name, read_yaml, show
from nlp_calib.problem import ResidualOptions
from nlp_calib.solvers import SOLVERS
from nlp_calib.solvers.backends import BACKENDS
from nlp_calib.symbolic.kernels import KERNELS


@dataclass(frozen=True)
class SampleSelection:
    """Records ``start:stop`` of the log; ``drop_stationary`` drops windows with no motion."""

    start: int = 0
    stop: int | None = None
    drop_stationary: bool = False


@dataclass(frozen=True)
class RobustOptions:
    """Kernel name and its threshold ``delta`` on the Mahalanobis norm ``sqrt(eᵀΩe)``."""

    kernel: str = "huber"
    delta: float = 0.05


@dataclass(frozen=True)
class InformationWeights:
    """Diagonal of Ω: weight of the x/y error (1/m²) and of the angle error (1/rad²)."""

    translation: float = 1.0
    rotation: float = 1.0

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


@dataclass(frozen=True)
class AlignmentOptions:
    """``tracker_lag``: seconds the tracker reports after the encoders, or ``auto`` to estimate
    it by the fit cost over ``search`` at ``step``."""

    tracker_lag: float | str = 0.0
    search: tuple[float, float] = (-0.2, 0.2)
    step: float = 0.01


FAULT_HANDLINGS = ("exclude", "repair", "keep")


@dataclass(frozen=True)
class FaultOptions:
    """What to do with encoder and tracker faults found in the log (every run looks for them).

    ``exclude`` (default): drop every residual window that crosses a fault; ``repair``: correct
    the counts of counter faults (and say what changed), drop windows at tracker jumps; ``keep``:
    report the faults and fit every window.
    """

    handling: str = "exclude"


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on one parameter."""

    mean: float
    std: float


@dataclass(frozen=True)
class LogEntry:
    """One log of a calibration from several (``datasets``): its path, and its own ``samples`` and
    ``alignment`` where they differ from the scenario's."""

    path: Path
    samples: SampleSelection | None = None
    alignment: AlignmentOptions | None = None
    #: How to read ``path`` when the entry is a bag block (docs/bags.md).
    bag: BagSource | None = None


@dataclass(frozen=True)
class Scenario:
    """A calibration run: data, model, residual form, kernel, solvers and their options."""

    name: str
    dataset: Path
    path: Path | None = None
    model: str = DEFAULT_MODEL
    samples: SampleSelection = field(default_factory=SampleSelection)
    initial_guess: str | Mapping[str, float] = "from_file"
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    robust: RobustOptions = field(default_factory=RobustOptions)
    residual: ResidualOptions = field(default_factory=ResidualOptions)
    information: InformationWeights = field(default_factory=InformationWeights)
    solvers: tuple[str, ...] = tuple(SOLVERS)
    #: Each solver's options, by solver name (the YAML block of that name); defaults when absent.
    solver_options: Mapping[str, Any] = field(default_factory=dict)
    validation: ValidationOptions = field(default_factory=ValidationOptions)
    alignment: AlignmentOptions = field(default_factory=AlignmentOptions)
    faults: FaultOptions = field(default_factory=FaultOptions)
    fixed: tuple[str, ...] = ()
    priors: Mapping[str, Prior] = field(default_factory=dict)
    encoder_noise: Mapping[str, float] = field(default_factory=dict)
    strict: bool = True
    backend: str = "compiled"
    threads: int = 1
    #: How to read ``dataset`` when it is a bag (the ``dataset:`` block); None for a text log.
    bag: BagSource | None = None
    #: Several logs calibrated together (``dataset`` is then the first of them).
    datasets: tuple[LogEntry, ...] = ()
    #: Where a single-log part of ``datasets`` comes from in its file (``datasets[1]``).
    origin: str | None = None

    def with_dataset(self, path: str | Path) -> Scenario:
        """The same scenario on another log (``--data``); another bag is read with the same topics."""
        bag = self.bag if is_bag(Path(path)) else None
        return dataclasses.replace(self, dataset=Path(path), bag=bag, datasets=())

    def per_log(self) -> tuple[Scenario, ...]:
        """One single-log scenario per entry of ``datasets`` (named after its log), with that log's
        own samples and alignment."""
        stems = [e.path.stem for e in self.datasets]
        return tuple(
            dataclasses.replace(
                self,
                name=stem if stems.count(stem) == 1 else f"{i + 1}_{stem}",
                dataset=e.path,
                datasets=(),
                origin=f"datasets[{i}]",
                bag=e.bag,
                samples=e.samples or self.samples,
                alignment=e.alignment or self.alignment,
            )
            for i, (stem, e) in enumerate(zip(stems, self.datasets))
        )

    def options_for(self, solver: str) -> Any:
        """The options of ``solver``: the scenario's block, or the solver's defaults."""
        options = self.solver_options.get(solver)
        return options if options is not None else SOLVERS[solver].options_type()

    def with_solver_options(self, solver: str, options: Any) -> Scenario:
        """The same scenario with ``solver``'s options replaced."""
        return dataclasses.replace(self, solver_options={**self.solver_options, solver: options})


#: ``residual.horizon``: each window composes H steps symbolically, so building the problem costs
#: time and memory in proportion to H; the accuracy study's trajectory error flattens by H = 25.
HORIZON = Range(1, 200, integer=True)
STRIDE = Range(1, 1_000_000, integer=True)
#: ``validation.blocks`` (or 0: none): each block costs one more fit.
BLOCKS = Range(2, 100, integer=True)
#: Numbers whose squares still fit a float with room to spare: beyond them a value is a typo, and
#: the cost, its weights or the covariance would overflow (silently, or as a NaN result).
MAGNITUDE = Range(-1e6, 1e6)
DELTA = Range(0.0, 1e6, lo_open=True)
WEIGHT = Range(0.0, 1e12, lo_open=True)
TICKS = Range(0.0, 1e9, lo_open=True)
PRIOR_STD = Range(1e-9, 1e6)
_FINITE = Range(-math.inf, math.inf, lo_open=True, hi_open=True)


# Keys the YAML may hold at top level: the fields (but where the file was, and the solver
# options, which come as one block per registered solver).
_FIELDS = tuple(
    f.name for f in dataclasses.fields(Scenario) if f.name not in ("path", "solver_options", "bag", "origin")
)


def top_level_keys() -> tuple[str, ...]:
    """The keys a scenario file may hold at its top level, one block per registered solver included."""
    return (*_FIELDS, *SOLVERS)


def _check_choice(value: str, choices: typing.Iterable[str], where: str) -> None:
    choices = tuple(choices)
    if value not in choices:
        fail(where, f"{value!r} is not one of {', '.join(choices)}")


def scenario_from_mapping(raw: Any, source: str, base_dir: Path, path: Path | None = None) -> Scenario:
    """Validate a parsed YAML mapping; relative dataset paths resolve against ``base_dir``."""
    try:
        return _scenario_from_mapping(raw, source, base_dir, path)
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None


def _scenario_from_mapping(raw: Any, source: str, base_dir: Path, path: Path | None) -> Scenario:
    if not isinstance(raw, Mapping):
        fail(
            source,
            f"expected a mapping of scenario keys ({', '.join(top_level_keys())}), got {type(raw).__name__}",
        )
    for key in raw:
        if key not in top_level_keys():
            fail(f"{source}: {key_name(key)}", f"unknown key; valid keys are {', '.join(top_level_keys())}")
    if ("dataset" in raw) == ("datasets" in raw):
        fail(
            source,
            "give 'dataset' (path of the log, relative to this file, or a bag block) or 'datasets' (a "
            "list of them), not " + ("both" if "dataset" in raw else "neither"),
        )
    hints = typing.get_type_hints(Scenario)
    values = {
        k: coerce(v, hints[k], f"{source}: {k}")
        for k, v in raw.items()
        if k not in (*SOLVERS, "dataset", "datasets")
    }
    values["solver_options"] = {
        k: from_mapping(SOLVERS[k].options_type, v, f"{source}: {k}") for k, v in raw.items() if k in SOLVERS
    }
    values.setdefault("name", Path(source).stem)
    if "datasets" in raw:
        values["datasets"] = _log_entries(raw["datasets"], f"{source}: datasets", base_dir)
        values["dataset"], values["bag"] = values["datasets"][0].path, values["datasets"][0].bag
    else:
        values["dataset"], values["bag"] = dataset_block(raw["dataset"], f"{source}: dataset", base_dir)
    sc = Scenario(path=path, **values)
    _validate(sc, source)
    return sc


def _log_entries(value: Any, where: str, base_dir: Path) -> tuple[LogEntry, ...]:
    """``datasets``: a plain path stands for ``{path: ...}``; an entry with ``bag`` is a bag block
    (with its own ``samples`` and ``alignment`` if given); paths resolve against ``base_dir``."""
    if not isinstance(value, (list, tuple)) or not value:
        fail(
            where,
            "expected a non-empty list of log paths, {path, samples, alignment} mappings or bag blocks, "
            f"got {show(value)}",
        )
    entries = []
    for i, item in enumerate(value):
        place = f"{where}[{i}]"
        if isinstance(item, Mapping) and "bag" in item:
            own = ("samples", "alignment")
            block = {k: v for k, v in item.items() if k not in own}
            path, bag = dataset_block(block, place, base_dir, also=own)
            fields = {"path": str(path), **{k: v for k, v in item.items() if k in own}}
            entries.append(dataclasses.replace(from_mapping(LogEntry, fields, place), bag=bag))
            continue
        entry = from_mapping(LogEntry, {"path": item} if isinstance(item, str) else item, place)
        path = entry.path if entry.path.is_absolute() else base_dir / entry.path
        entries.append(dataclasses.replace(entry, path=path))
    return tuple(entries)


def _validate(sc: Scenario, source: str) -> None:
    # The name becomes a folder under the output directory: a plain, non-empty file name.
    if sc.name in ("", ".", "..") or any(c in sc.name for c in "/\\\0"):
        fail(f"{source}: name", f"must be a plain folder name (no '/', '\\' or NUL), got {sc.name!r}")
    _check_choice(sc.model, MODELS, f"{source}: model")
    names = param_names(get_model(sc.model))
    bags = [(f"datasets[{i}]", e.bag) for i, e in enumerate(sc.datasets)] or [("dataset", sc.bag)]
    for key, bag in bags:
        if bag is not None:
            check_joints(bag.joints, get_model(sc.model), f"{source}: {key}.joints")
    _check_choice(sc.robust.kernel, KERNELS, f"{source}: robust.kernel")
    _check_range(sc.robust.delta, DELTA, f"{source}: robust.delta")
    r = sc.residual
    for key, limit in (("horizon", HORIZON), ("stride", STRIDE)):
        reason = limit.problem(getattr(r, key))
        if reason is not None:
            fail(f"{source}: residual.{key}", reason)
    _check_choice(r.integration, INTEGRATIONS, f"{source}: residual.integration")
    _check_choice(r.steering_sample, STEERING_SAMPLES, f"{source}: residual.steering_sample")
    _check_range(sc.information.translation, WEIGHT, f"{source}: information.translation")
    _check_range(sc.information.rotation, WEIGHT, f"{source}: information.rotation")
    if not sc.solvers:
        fail(f"{source}: solvers", f"list at least one of {', '.join(SOLVERS)}")
    for s in sc.solvers:
        _check_choice(s, SOLVERS, f"{source}: solvers")
    for s, options in sc.solver_options.items():
        _check_passthrough(options, f"{source}: {s}")
    _check_choice(sc.backend, BACKENDS, f"{source}: backend")
    if not 1 <= sc.threads <= 64:
        fail(f"{source}: threads", f"must lie in [1, 64], got {sc.threads}")
    for where, sel, al in [
        (f"{source}: ", sc.samples, sc.alignment),
        *((f"{source}: datasets[{i}].", e.samples, e.alignment) for i, e in enumerate(sc.datasets)),
    ]:
        if sel is not None and (sel.start < 0 or (sel.stop is not None and sel.stop <= sel.start + 1)):
            fail(f"{where}samples", f"need 0 <= start < stop - 1, got start={sel.start} stop={sel.stop}")
        if al is not None:
            _check_alignment(al, f"{where}alignment")
    ranges = [(e.path.resolve(), e.samples or sc.samples) for e in sc.datasets]
    for i, (path, sel) in enumerate(ranges):
        for j, (other, sel_j) in enumerate(ranges[:i]):
            if (
                path == other
                and sel.start < (sel_j.stop or math.inf)
                and sel_j.start < (sel.stop or math.inf)
            ):
                fail(
                    f"{source}: datasets[{i}]",
                    f"records also in datasets[{j}] ({sc.datasets[i].path}): records fitted twice would "
                    "count as two drives and shrink the σ; give the entries samples that do not overlap",
                )
    hf = sc.validation.holdout_fraction
    if hf is not None and not 0.0 < hf < 1.0:
        fail(f"{source}: validation.holdout_fraction", f"must lie in (0, 1), got {hf}")
    _check_choice(sc.faults.handling, FAULT_HANDLINGS, f"{source}: faults.handling")
    if sc.validation.blocks != 0 and (why := BLOCKS.problem(sc.validation.blocks)):
        fail(f"{source}: validation.blocks", f"0 (none) or {why}")
    if sc.validation.rpe_window < 1:
        fail(f"{source}: validation.rpe_window", "must be >= 1")
    if isinstance(sc.initial_guess, str):
        _check_choice(sc.initial_guess, ("from_file", "auto"), f"{source}: initial_guess")
    else:
        for n, value in sc.initial_guess.items():
            _check_choice(n, names, f"{source}: initial_guess")
            _check_range(value, MAGNITUDE, f"{source}: initial_guess.{n}")
    for n, (lo, hi) in sc.bounds.items():
        _check_choice(n, names, f"{source}: bounds")
        if not lo < hi:
            fail(f"{source}: bounds.{n}", f"needs lo < hi, got [{lo}, {hi}]")
        guess = sc.initial_guess.get(n) if isinstance(sc.initial_guess, Mapping) else None
        if guess is not None and not lo <= guess <= hi:
            fail(f"{source}: bounds.{n}", f"the initial guess {guess:g} lies outside [{lo:g}, {hi:g}]")
    for n in sc.fixed:
        _check_choice(n, names, f"{source}: fixed")
    if len(set(sc.fixed)) == len(names):
        fail(f"{source}: fixed", "every parameter is fixed; nothing is left to estimate")
    for enc, ticks in sc.encoder_noise.items():
        _check_choice(enc, encoders(get_model(sc.model)), f"{source}: encoder_noise")
        _check_range(ticks, TICKS, f"{source}: encoder_noise.{enc}")
    for n, prior in sc.priors.items():
        _check_choice(n, names, f"{source}: priors")
        _check_range(prior.mean, MAGNITUDE, f"{source}: priors.{n}.mean")
        _check_range(prior.std, PRIOR_STD, f"{source}: priors.{n}.std")
        if n in sc.fixed:
            fail(f"{source}: priors.{n}", "a fixed parameter cannot also have a prior; drop one")


def _check_alignment(al: AlignmentOptions, where: str) -> None:
    if isinstance(al.tracker_lag, str):
        _check_choice(al.tracker_lag, ("auto",), f"{where}.tracker_lag")
    lo, hi = al.search
    if not lo < hi:
        fail(f"{where}.search", f"needs [lo, hi] with lo < hi, got [{lo:g}, {hi:g}]")
    if not al.step > 0:
        fail(f"{where}.step", f"must be > 0 s, got {al.step:g}")
    if (hi - lo) / al.step > 1000:
        fail(
            f"{where}.step",
            f"{al.step:g} s over search [{lo:g}, {hi:g}] makes {(hi - lo) / al.step:.0f} lags to fit, more "
            f"than 1000; use a step of at least {(hi - lo) / 1000:.3g} s or a narrower search",
        )


def _check_range(value: float, limit: Range, where: str) -> None:
    reason = limit.problem(value)
    if reason is not None:
        fail(where, reason)


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
                fail(place, f"expected a finite number, a string or true/false, got {show(v)}")


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file."""
    p = Path(path)
    try:
        raw = read_yaml(p, "scenario")
    except ConfigError as exc:
        raise ScenarioError(str(exc)) from None
    return scenario_from_mapping(raw, str(p), p.parent, p)
