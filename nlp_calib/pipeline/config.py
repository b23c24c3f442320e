"""Validation of YAML mappings against frozen dataclasses (scenarios, simulation options).

A dataclass's fields and type annotations are the schema: unknown keys, wrong types and the
dataclass's own ``__post_init__`` checks (in neutral words) become :class:`ConfigError` naming
the key's place, so each message says where in the file to fix it.
"""

from __future__ import annotations

import dataclasses
import math
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Union

import yaml

from nlp_calib.core.errors import ConfigError, NlpCalibError


def fail(where: str, msg: str) -> typing.NoReturn:
    raise ConfigError(f"{where}: {msg}")


def coerce(value: Any, tp: Any, where: str) -> Any:
    """Check ``value`` against the annotation ``tp`` and convert it (YAML ints to floats...)."""
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return coerce(value, arg, where)
            except ConfigError as exc:
                errors.append(str(exc).split(": ", 1)[-1])
        fail(where, " or ".join(errors))
    if tp is Any:
        return value
    if tp is bool:
        if not isinstance(value, bool):
            fail(where, f"expected true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            fail(where, f"expected an integer, got {value!r}")
        return value
    if tp is float:
        # A YAML integer beyond float range would overflow float(): no usable number either.
        if (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or (isinstance(value, int) and abs(value) > 1e308)
            or not math.isfinite(value)
        ):
            fail(where, f"expected a finite number, got {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            fail(where, f"expected a string, got {value!r}")
        return value
    if tp is Path:
        if not isinstance(value, str) or not value:
            fail(where, f"expected a file path, got {value!r}")
        return Path(value)
    if origin is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            fail(where, f"expected a list, got {value!r}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            fail(where, f"expected a list of {len(args)} values, got {value!r}")
        return tuple(coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args)))
    if origin in (Mapping, dict) or tp is Mapping:
        k_tp, v_tp = typing.get_args(tp)
        if not isinstance(value, Mapping):
            fail(where, f"expected a mapping, got {value!r}")
        return {coerce(k, k_tp, where): coerce(v, v_tp, f"{where}.{k}") for k, v in value.items()}
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return from_mapping(tp, value, where)
    raise TypeError(f"unsupported annotation {tp!r} at {where}")  # programming error


def from_mapping(cls: type, value: Any, where: str) -> Any:
    if value is None:
        value = {}
    if not isinstance(value, Mapping):
        fail(where, f"expected a mapping of {keys_of(cls)}, got {value!r}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    for key in value:
        if key not in names:
            fail(f"{where}.{key}", f"unknown key; valid keys are {', '.join(names)}")
    kwargs = {k: coerce(v, hints[k], f"{where}.{k}") for k, v in value.items()}
    try:
        return cls(**kwargs)
    except (ValueError, TypeError, NlpCalibError) as exc:
        fail(where, str(exc))


def keys_of(cls: type) -> str:
    return ", ".join(f.name for f in dataclasses.fields(cls))


def read_yaml(path: Path, what: str) -> Any:
    """Parse a YAML file; unreadable files and syntax errors become one-line errors."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such {what} file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the {what} file ({exc})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"{path}:{mark.line + 1}" if mark is not None else str(path)
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise ConfigError(f"{where}: not valid YAML ({problem})") from None
