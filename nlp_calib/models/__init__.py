"""Kinematic models; :func:`get_model` looks one up by its scenario name."""

from __future__ import annotations

from nlp_calib.errors import ModelError
from nlp_calib.models.base import SENSOR_PARAMS, KinematicModel, param_names
from nlp_calib.models.diff_drive import DiffDrive
from nlp_calib.models.tricycle import Tricycle

MODELS: dict[str, KinematicModel] = {m.name: m for m in (Tricycle(), DiffDrive())}


def get_model(name: str) -> KinematicModel:
    """The model registered under ``name``."""
    try:
        return MODELS[name]
    except KeyError:
        raise ModelError(f"unknown model {name!r}; valid models: {sorted(MODELS)}") from None


def model_for_log(kinematic_model: str) -> KinematicModel:
    """The model that reads logs whose header says ``#kinematic_model: <kinematic_model>``."""
    for m in MODELS.values():
        if kinematic_model in m.log_names:
            return m
    raise ModelError(f"no model reads logs of kind {kinematic_model!r}; known: {sorted(MODELS)}")


__all__ = ["MODELS", "SENSOR_PARAMS", "KinematicModel", "get_model", "model_for_log", "param_names"]
