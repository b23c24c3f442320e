"""A result's records as plain JSON data and back, driven by their type annotations.

Every record of :mod:`nlp_calib.results` is a frozen dataclass of numbers, strings, tuples,
mappings, numpy arrays and other such records, so one walk over the annotations turns any of them
into JSON types (:func:`to_data`) and back (:func:`from_data`) without a hand-written schema.
Strict JSON has no NaN or infinity: such floats become the strings ``"NaN"``, ``"Infinity"`` and
``"-Infinity"``; an array is ``{"dtype", "shape", "data"}`` with its values flattened.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar, Union

import numpy as np

T = TypeVar("T")
_NON_FINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def _float(value: float) -> float | str:
    if math.isfinite(value):
        return value
    return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")


def _array(a: np.ndarray) -> dict[str, Any]:
    flat = a.ravel().tolist()
    if a.dtype.kind == "f":
        flat = [_float(v) for v in flat]
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": flat}


def to_data(obj: Any) -> Any:
    """``obj`` as JSON types: dataclasses as mappings of their fields, arrays as
    ``{dtype, shape, data}``, non-finite floats as strings, mapping keys as strings."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_data(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, np.ndarray):
        return _array(obj)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return _float(float(obj))
    if isinstance(obj, Mapping):
        return {(k if isinstance(k, str) else repr(k)): to_data(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_data(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if obj is None or isinstance(obj, str):
        return obj
    raise TypeError(f"cannot store a {type(obj).__name__} in a result")  # programming error


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


def _from_array(data: Mapping[str, Any]) -> np.ndarray:
    dtype = np.dtype(data["dtype"])
    values = data["data"]
    if dtype.kind == "f":
        values = [_NON_FINITE[v] if isinstance(v, str) else v for v in values]
    out = np.array(values, dtype=dtype).reshape(data["shape"])
    return out


def _scalar(tp: Any, data: Any) -> Any:
    if tp is float:
        return _NON_FINITE[data] if isinstance(data, str) and data in _NON_FINITE else float(data)
    if tp is int:
        return int(data)
    if tp is Path:
        return Path(data)
    return data


def from_data(tp: Any, data: Any) -> Any:
    """The value of type ``tp`` that :func:`to_data` turned into ``data``."""
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if data is None:
            return None
        if len(args) == 1:
            return from_data(args[0], data)
        if float in args and (isinstance(data, (int, float)) or data in _NON_FINITE):
            return _scalar(float, data)
        return data  # a union of plain JSON types (str | float ...) keeps its value
    if tp is np.ndarray:
        return _from_array(data)
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        hints = _hints(tp)
        return tp(**{k: from_data(hints[k], v) for k, v in data.items()})
    if origin is tuple:
        items = typing.get_args(tp)
        if len(items) == 2 and items[1] is Ellipsis:
            return tuple(from_data(items[0], v) for v in data)
        return tuple(from_data(a, v) for a, v in zip(items, data))
    if origin in (Mapping, dict) or tp in (Mapping, dict):
        k_tp, v_tp = typing.get_args(tp) or (Any, Any)
        return {_scalar(k_tp, k): from_data(v_tp, v) for k, v in data.items()}
    return _scalar(tp, data)


def load(cls: type[T], data: Any) -> T:
    """A record of type ``cls`` from its :func:`to_data` form."""
    out: T = from_data(cls, data)
    return out


def finite_or_null(obj: Any) -> Any:
    """The same structure with NaN and infinities as ``None`` (JSON has no such numbers)."""
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_or_null(v) for v in obj]
    return obj
