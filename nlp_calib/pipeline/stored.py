"""A ``calibration.yaml`` the tool wrote, read back: the values, the σ to believe and how many
degrees of freedom each σ has, the model, the solver and the scenario it came from."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from nlp_calib.analysis.drift import believed_dof
from nlp_calib.core.config import fail, key_name, read_yaml
from nlp_calib.core.errors import ConfigError, UsageError
from nlp_calib.models import MODELS, KinematicModel, get_model, param_names
from nlp_calib.results.checks import MIN_FOLDS
from nlp_calib.sensors import SENSORS, sensor_for
from nlp_calib.solvers import SOLVERS


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
    model: KinematicModel, values: Mapping[str, float], spreads: Mapping[str, Mapping[str, float]], where: str
) -> None:
    """Refuse values no robot of ``model`` has and σ that are negative or wider than everything
    the parameter could be (a tampered or foreign file), under the file's own keys."""
    for name, value in values.items():
        lo, hi = model.physical_ranges.get(name, (-math.inf, math.inf))
        if name in model.angle_params:
            lo, hi = -2.0 * math.pi, 2.0 * math.pi
        if not lo <= value <= hi:
            fail(
                f"{where}: parameters.{key_name(name)}",
                f"{value:.6g} is outside what a {model.name} can have ([{lo:.6g}, {hi:.6g}]); give the "
                "calibration.yaml nlp_calib wrote for this robot",
            )
    for key, std in spreads.items():
        for name, sd in std.items():
            lo, hi = model.physical_ranges.get(name, (-math.inf, math.inf))
            widest = 2.0 * math.pi if name in model.angle_params else hi - lo
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
    if kind not in SENSORS or not sensor_for(kind).planar_base:
        fail(
            f"{where}: sensor",
            f"a calibration of a {kind!s:.20} sensor cannot be checked yet: the drift check compares a "
            "planar mount; recalibrate with 'nlp-calib run' on the new log and compare the two",
        )
    kinematic = get_model(model)
    names = param_names(kinematic)
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
    _check_values(kinematic, values, spreads, where)
    dof = {n: believed_dof(white[n], blocks.get(n), folds) for n in names}
    objective = doc.get("objective") if isinstance(doc.get("objective"), Mapping) else None
    scenario, recorded = _scenario_path(doc)
    data = doc.get("dataset")
    dataset = data.get("path") if isinstance(data, Mapping) and isinstance(data.get("path"), str) else None
    return StoredCalibration(path, model, solver, values, std, dof, scenario, objective, recorded, dataset)


def _sensor_kind(doc: Mapping[str, Any]) -> str:
    """The sensor a calibration.yaml holds the mount of (its ``sensor.kind``; a file written before
    it said so holds a planar one, unless its parameters are a camera mount's)."""
    sensor = doc.get("sensor")
    if isinstance(sensor, Mapping) and isinstance(sensor.get("kind"), str):
        return str(sensor["kind"])
    params = set(doc["parameters"]) if isinstance(doc.get("parameters"), Mapping) else set()
    kinds = [k for k in SENSORS if set(sensor_for(k).params) <= params]
    return max(kinds, key=lambda k: len(sensor_for(k).params), default=next(iter(SENSORS)))
