"""Model layer: the kinematic models, each one file carrying its own facts, and their registry.

Adding a model is one file implementing :class:`~nlp_calib.models.base.KinematicModel` and one
entry in :data:`MODELS`.
"""

from __future__ import annotations

from pathlib import Path

from nlp_calib.core.errors import ModelError
from nlp_calib.logs import Log, read_log
from nlp_calib.logs.reader import read_header
from nlp_calib.models.base import (
    SENSOR_PARAMS,
    KinematicModel,
    OdometryInverse,
    Reach,
    canonical,
    counted_inputs,
    encoders,
    header_parameters,
    param_names,
    param_units,
    rate_rows,
    reference_scales,
)
from nlp_calib.models.car_like import CarLike
from nlp_calib.models.car_like_ackermann import CarLikeAckermann
from nlp_calib.models.car_like_bicycle import CarLikeBicycle
from nlp_calib.models.diff_drive import DiffDrive
from nlp_calib.models.skid_steer import SkidSteer
from nlp_calib.models.tricycle import Tricycle
from nlp_calib.models.tricycle_reverse import TricycleReverse

MODELS: dict[str, KinematicModel] = {
    m.name: m
    for m in (
        Tricycle(),
        DiffDrive(),
        TricycleReverse(),
        CarLike(),
        CarLikeAckermann(),
        CarLikeBicycle(),
        SkidSteer(),
    )
}
#: The model a scenario or a simulation uses when it names none.
DEFAULT_MODEL = next(iter(MODELS))


def get_model(name: str) -> KinematicModel:
    """The model registered under ``name``."""
    try:
        return MODELS[name]
    except KeyError:
        raise ModelError(f"unknown model {name!r}; valid models: {', '.join(MODELS)}") from None


def model_for_log(kinematic_model: str) -> KinematicModel:
    """The model that reads logs whose header says ``#kinematic_model: <kinematic_model>``."""
    for m in MODELS.values():
        if kinematic_model in m.log_names:
            return m
    known = sorted(n for m in MODELS.values() for n in m.log_names)
    raise ModelError(f"no model reads logs of kind {kinematic_model!r}; known kinds: {', '.join(known)}")


def load_log(path: str | Path, model: KinematicModel | None = None, *, strict: bool = True) -> Log:
    """Read a log with ``model``'s encoder kinds (default: the model its header names).

    Raises :class:`ModelError` when the header names a kind of robot ``model`` does not read.
    """
    kind = read_header(path).kinematic_model
    if model is None:
        model = model_for_log(kind)
    elif kind not in model.log_names:
        raise ModelError(
            f"{path}: the log is of kind {kind!r}, but the model {model.name!r} reads "
            f"{', '.join(model.log_names)}"
        )
    return read_log(path, model.encoder_kinds, strict=strict)


__all__ = [
    "DEFAULT_MODEL",
    "MODELS",
    "SENSOR_PARAMS",
    "KinematicModel",
    "OdometryInverse",
    "Reach",
    "canonical",
    "counted_inputs",
    "encoders",
    "get_model",
    "header_parameters",
    "load_log",
    "model_for_log",
    "param_names",
    "param_units",
    "rate_rows",
    "reference_scales",
]
