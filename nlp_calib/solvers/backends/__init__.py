"""Evaluation backends: how the per-residual Functions are mapped over the data and evaluated."""

from __future__ import annotations

from nlp_calib.solvers.backends.base import (
    BACKENDS,
    INTERPRETED,
    Backend,
    BackendOptions,
    Buffered,
    Request,
    pad_columns,
    pad_in_place,
)
from nlp_calib.solvers.backends.compiled import CompiledBackend, make_compiled_backend


def make_backend(options: BackendOptions) -> Backend:
    """The backend ``options`` asks for (the compiled one falls back when no compiler exists)."""
    if options.kind == "compiled":
        return make_compiled_backend(options)
    return INTERPRETED


__all__ = [
    "BACKENDS",
    "INTERPRETED",
    "Backend",
    "BackendOptions",
    "Buffered",
    "CompiledBackend",
    "Request",
    "make_backend",
    "pad_columns",
    "pad_in_place",
]
