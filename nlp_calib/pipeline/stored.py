"""A ``calibration.yaml`` the tool wrote, read back: the values, the σ to believe and how many
degrees of freedom each σ has, the model, the solver and the scenario it came from."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nlp_calib.analysis.drift import believed_dof, shared_std
from nlp_calib.core.config import fail, key_name, read_yaml
from nlp_calib.core.errors import ConfigError, UsageError
from nlp_calib.core.version import __version__
from nlp_calib.models import MODELS, KinematicModel, get_model
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.models.radians import in_units
from nlp_calib.problem import ProblemSpec
from nlp_calib.problem.functions import problem_layout
from nlp_calib.results import codec
from nlp_calib.results.checks import MIN_FOLDS
from nlp_calib.results.layout import FREE, LAYOUT_VERSION, Layout
from nlp_calib.sensors import SENSORS, sensor_for
from nlp_calib.solvers import SOLVERS


@dataclass(frozen=True)
class StoredSpreads:
    """A stored calibration's σ as a check reads them beside ``std``: ``shared``, each as if errors
    were shared by all of a log's blocks; ``held``, each one's part from the held values' plausible
    errors ('std_held', in ``std`` and ``shared`` in quadrature; empty: none)."""

    shared: Mapping[str, float]
    held: Mapping[str, float]
    #: The values held whose errors ``held`` is ('held_values', by name; empty: none recorded).
    held_values: Mapping[str, float] = field(default_factory=dict)
    #: The parameters the calibration estimated but did not determine ('not_determined'): their σ
    #: vouch for no value, so a check has none of theirs to judge.
    doubted: tuple[str, ...] = ()


@dataclass(frozen=True)
class StoredCalibration:
    """A calibration read from ``path``: ``parameters``, their σ to believe (``std``) and that σ's
    degrees of freedom (``dof``: the jackknife's folds − 1, or infinite for the white-noise σ),
    the ``model`` and ``solver``, the scenario file it was made with (``scenario``, if it still
    exists; ``recorded``: as the file names it), the residual and robust options it fitted
    (``objective``, when recorded) and the log it was fitted to (``dataset``, as recorded)."""

    path: Path
    model: str
    solver: str
    parameters: Mapping[str, float]
    std: Mapping[str, float]
    dof: Mapping[str, float]
    scenario: Path | None
    objective: Mapping[str, Any] | None
    recorded: str | None = None
    dataset: str | None = None
    #: Every stored parameter in its block, with its log (see :mod:`nlp_calib.results.layout`).
    layout: Layout = field(default_factory=lambda: Layout(()))
    #: The σ a check widens or takes apart (see :class:`StoredSpreads`).
    spreads: StoredSpreads = field(default_factory=lambda: StoredSpreads({}, {}))

    @property
    def std_shared(self) -> Mapping[str, float]:
        """Each σ to believe as if errors were shared by all of a log's blocks
        (:func:`~nlp_calib.analysis.drift.between_logs_std`; empty: as ``std``)."""
        return self.spreads.shared

    def start(self) -> dict[str, float]:
        """The stored values a fit of a new log starts from, by the keys a scenario gives: the
        robot's parameters shared by every log (each log's own mount and clock offset belong to the
        logs it was fitted to)."""
        robot = set(self.layout.robot())
        return {
            p.key: self.parameters[p.name]
            for p in self.layout.parameters
            if p.log is None and p.name in robot
        }

    def uncalibrated(self) -> tuple[str, ...]:
        """The parameters this calibration did not estimate (held, or given as known) or estimated
        without determining them (its 'not_determined'): a check has nothing of theirs to judge."""
        held = tuple(p.name for p in self.layout.parameters if p.status != FREE)
        return held + tuple(n for n in self.spreads.doubted if n not in held)

    def stats(self) -> tuple[Mapping[str, float], Mapping[str, float], Mapping[str, float]]:
        """Values, σ to believe and degrees of freedom, as the drift check compares them."""
        return self.parameters, self.std, self.dof


def _numbers(
    doc: Mapping[str, Any], key: str, names: tuple[str, ...], where: str, *, null: bool
) -> dict[str, float]:
    """``doc[key]``: a number (or, with ``null``, nothing) for every one of ``names``."""
    value = doc.get(key)
    if not isinstance(value, Mapping) or set(value) != set(names):
        fail(
            f"{where}: {key}",
            f"expected a mapping of {', '.join(names)} (as nlp_calib writes it), got {value!r:.80}",
        )
    out = {}
    for name in names:
        v = value[name]
        if v is None and null:
            out[name] = math.nan
        elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            fail(f"{where}: {key}.{key_name(name)}", f"expected a finite number, got {v!r:.40}")
        else:
            out[name] = float(v)
    return out


def _scenario_path(doc: Mapping[str, Any]) -> tuple[Path | None, str | None]:
    """The scenario file the calibration was made with, when it still exists, and its path as
    recorded. A relative path is not looked up: it was relative to the folder the run was made
    in, which the file does not say (today's working folder may hold another file of that name)."""
    recorded = doc.get("scenario")
    path = recorded.get("path") if isinstance(recorded, Mapping) else None
    if not isinstance(path, str):
        return None, None
    return (Path(path) if Path(path).is_absolute() and Path(path).is_file() else None), path


def _check_values(
    layout: tuple[str, Layout],
    values: Mapping[str, float],
    spreads: Mapping[str, Mapping[str, float]],
    where: str,
) -> None:
    """Refuse values no robot of the model (``layout[0]``) has and σ that are negative or wider
    than everything the parameter could be (a tampered or foreign file), under the file's own keys."""
    model, laid = layout
    for name, value in values.items():
        lo, hi = laid.param(name).range
        if not lo <= value <= hi:
            fail(
                f"{where}: parameters.{key_name(name)}",
                f"{value:.6g} is outside what a {model} can have ([{lo:.6g}, {hi:.6g}]); give the "
                "calibration.yaml nlp_calib wrote for this robot",
            )
    for key, std in spreads.items():
        for name, sd in std.items():
            lo, hi = laid.param(name).range
            widest = hi - lo
            if sd < 0 or sd > widest:
                what = "negative" if sd < 0 else f"wider than any {name} can be ({widest:.6g})"
                fail(
                    f"{where}: {key}.{key_name(name)}",
                    f"a 1σ of {sd:.6g} is {what}; give the calibration.yaml nlp_calib wrote",
                )


def read_calibration(path: Path) -> StoredCalibration:
    """Read and check a ``calibration.yaml`` that ``nlp-calib run`` (or ``compare``...) wrote."""
    where = str(path)
    try:
        doc = read_yaml(path, "calibration")
    except ConfigError as exc:
        raise UsageError(str(exc)) from None
    if not isinstance(doc, Mapping) or (doc.get("tool") or {}).get("name") != "nlp_calib":
        fail(where, "not a calibration.yaml that nlp_calib wrote (no 'tool: {name: nlp_calib}'); give the "
             "calibration.yaml of an nlp-calib run")  # fmt: skip
    model = doc.get("model")
    if model not in MODELS:
        fail(f"{where}: model", f"{model!r:.40} is not one of {', '.join(MODELS)}")
    kind = _sensor_kind(doc)
    if kind not in SENSORS:
        fail(f"{where}: sensor", f"{kind!r:.40} is not one of {', '.join(SENSORS)}")
    layout = _layout(doc, where, (get_model(model), kind))
    names = layout.names
    solver = doc.get("solver")
    solver = solver if solver in SOLVERS else next(iter(SOLVERS))
    values = _numbers(doc, "parameters", names, where, null=False)
    std = _numbers(doc, "std", names, where, null=True)
    white = _numbers(doc, "std_white_noise", names, where, null=True)
    blocks = _numbers(doc, "std_blocks", names, where, null=True) if doc.get("std_blocks") else {}
    folds = doc.get("std_blocks_folds", MIN_FOLDS)
    if isinstance(folds, bool) or not isinstance(folds, int) or folds < 0:
        fail(f"{where}: std_blocks_folds", f"expected a whole number of folds, got {folds!r:.40}")
    spreads = {"std": std, "std_white_noise": white, **({"std_blocks": blocks} if blocks else {})}
    _check_values((str(model), layout), values, spreads, where)
    dof = {n: believed_dof(white[n], blocks.get(n), folds) for n in names}
    objective = doc.get("objective") if isinstance(doc.get("objective"), Mapping) else None
    scenario, recorded = _scenario_path(doc)
    data = doc.get("dataset")
    dataset = data.get("path") if isinstance(data, Mapping) and isinstance(data.get("path"), str) else None
    return StoredCalibration(
        path,
        model,
        solver,
        values,
        std,
        dof,
        scenario,
        objective,
        recorded,
        dataset,
        layout,
        _spreads(doc, names, where, (std, white, folds)),
    )


def _spreads(
    doc: Mapping[str, Any],
    names: tuple[str, ...],
    where: str,
    believed: tuple[Mapping[str, float], Mapping[str, float], int],
) -> StoredSpreads:
    """The file's σ as a check widens them (``believed``: the σ to believe, the white-noise σ and
    the jackknife's folds) and their held values' parts."""
    std, white, folds = believed
    slip, held = _shifts(doc, names, where)
    own = _numbers(doc, "std_residuals", names, where, null=True) if doc.get("std_residuals") else {}
    scatter = (
        _numbers(doc, "std_block_scatter", names, where, null=True) if doc.get("std_block_scatter") else {}
    )
    # The residuals' own σ and the blocks' scatter both average over a log (see shared_std).
    averaged = {
        n: max(
            (v for v in (own.get(n), scatter.get(n)) if v is not None and math.isfinite(v)), default=math.nan
        )
        for n in names
    }
    shared = {n: shared_std(std[n], (white[n], averaged[n], slip.get(n, math.nan)), folds) for n in names}
    return StoredSpreads(shared, held, _held_values(doc, where), _doubted(doc, names, where))


def _doubted(doc: Mapping[str, Any], names: tuple[str, ...], where: str) -> tuple[str, ...]:
    """'not_determined': the parameters the calibration did not determine, with why (absent:
    none; a file written before it was recorded has none)."""
    value = doc.get("not_determined")
    if value is None:
        return ()
    if not isinstance(value, Mapping) or not all(isinstance(k, str) and k in names for k in value):
        fail(f"{where}: not_determined", f"expected a mapping of its parameters to why, got {value!r:.80}")
    return tuple(value)


def _held_values(doc: Mapping[str, Any], where: str) -> dict[str, float]:
    """'held_values': the values whose errors 'std_held' is, by name (absent: none)."""
    value = doc.get("held_values")
    if value is None:
        return {}
    if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
        fail(f"{where}: held_values", f"expected a mapping of names to numbers, got {value!r:.80}")
    out = {}
    for name, v in value.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            fail(f"{where}: held_values.{key_name(name)}", f"expected a finite number, got {v!r:.40}")
        out[name] = float(v)
    return out


def _shifts(
    doc: Mapping[str, Any], names: tuple[str, ...], where: str
) -> tuple[dict[str, float], dict[str, float]]:
    """Each parameter's σ of the shifts its whole drive shared ('std_slip' and 'std_held', in
    quadrature; absent: none), and its 'std_held' alone."""
    parts = {
        key: _numbers(doc, key, names, where, null=True) for key in ("std_slip", "std_held") if doc.get(key)
    }
    out = {}
    for n in names:
        found = [p[n] for p in parts.values() if math.isfinite(p[n])]
        if found:
            out[n] = math.hypot(*found)
    held = {n: v for n, v in parts.get("std_held", {}).items() if math.isfinite(v)}
    return out, held


def _layout(doc: Mapping[str, Any], where: str, model: tuple[KinematicModel, str]) -> Layout:
    """The file's parameter layout (``layout``), or, in a file written before it had one, the
    layout of one log's fit: the model's parameters in its encoders' units, the sensor's mount and
    the clock offset where the file holds one."""
    stored = doc.get("layout")
    if stored is None:
        kinematic, kind = model
        encoders: list[Any] = doc["encoders"] if isinstance(doc.get("encoders"), list) else []
        radians = any(isinstance(e, Mapping) and e.get("unit") == "rad" for e in encoders)
        params: Mapping[str, Any] = doc["parameters"] if isinstance(doc.get("parameters"), Mapping) else {}
        spec = ProblemSpec(sensor=kind, lags=int(LAG_PARAM in params))
        return problem_layout(in_units(kinematic, "radians" if radians else "counts"), sensor_for(kind), spec)
    version = stored.get("version") if isinstance(stored, Mapping) else None
    if isinstance(version, bool) or not isinstance(version, int) or not 1 <= version <= LAYOUT_VERSION:
        fail(
            f"{where}: layout.version",
            f"expected a layout version nlp_calib {__version__} reads (1 to {LAYOUT_VERSION}), got "
            f"{version!r:.20}; check with the nlp_calib that wrote the file, or recalibrate",
        )
    try:
        layout = codec.load(Layout, {k: v for k, v in stored.items() if k != "version"})
        names = layout.names
        ok = len(set(names)) == len(names) and all(isinstance(n, str) and n for n in names)
    except (TypeError, ValueError, KeyError, AttributeError):
        ok = False
    if not ok:
        fail(f"{where}: layout", "not a parameter layout nlp_calib wrote; give the calibration.yaml it wrote")
    return layout


def _sensor_kind(doc: Mapping[str, Any]) -> str:
    """The sensor a calibration.yaml holds the mount of (its ``sensor.kind``; a file written before
    it said so holds a planar one, unless its parameters are a camera mount's)."""
    sensor = doc.get("sensor")
    if isinstance(sensor, Mapping) and isinstance(sensor.get("kind"), str):
        return str(sensor["kind"])
    params = set(doc["parameters"]) if isinstance(doc.get("parameters"), Mapping) else set()
    kinds = [k for k in SENSORS if set(sensor_for(k).params) <= params]
    return max(kinds, key=lambda k: len(sensor_for(k).params), default=next(iter(SENSORS)))
