"""Problem layer: the calibration problem's named CasADi Functions and the windows they are mapped over."""

from __future__ import annotations

from typing import TYPE_CHECKING

from nlp_calib.core import lazy

if TYPE_CHECKING:
    from nlp_calib.problem.functions import (
        DATA_ROWS,
        ORDER,
        PER_RESIDUAL,
        STEPS,
        SUMMED,
        WINDOW_INPUTS,
        ProblemFunctions,
        ProblemSpec,
        build,
        unpack_upper,
        upper_indices,
    )
    from nlp_calib.problem.windows import (
        ResidualData,
        ResidualOptions,
        build_residual_data,
        interval_inputs,
        joined,
        over_columns,
        window_starts,
    )

# Each name's module is imported at the name's first use (core/lazy.py).
_EXPORTS: dict[str, str] = {
    "DATA_ROWS": "nlp_calib.problem.functions",
    "ORDER": "nlp_calib.problem.functions",
    "PER_RESIDUAL": "nlp_calib.problem.functions",
    "STEPS": "nlp_calib.problem.functions",
    "SUMMED": "nlp_calib.problem.functions",
    "WINDOW_INPUTS": "nlp_calib.problem.functions",
    "ProblemFunctions": "nlp_calib.problem.functions",
    "ProblemSpec": "nlp_calib.problem.functions",
    "build": "nlp_calib.problem.functions",
    "unpack_upper": "nlp_calib.problem.functions",
    "upper_indices": "nlp_calib.problem.functions",
    "ResidualData": "nlp_calib.problem.windows",
    "ResidualOptions": "nlp_calib.problem.windows",
    "build_residual_data": "nlp_calib.problem.windows",
    "interval_inputs": "nlp_calib.problem.windows",
    "joined": "nlp_calib.problem.windows",
    "over_columns": "nlp_calib.problem.windows",
    "window_starts": "nlp_calib.problem.windows",
}

__getattr__, __dir__ = lazy.exports(__name__, _EXPORTS)

__all__ = [
    "DATA_ROWS",
    "ORDER",
    "PER_RESIDUAL",
    "STEPS",
    "SUMMED",
    "WINDOW_INPUTS",
    "ProblemFunctions",
    "ProblemSpec",
    "ResidualData",
    "ResidualOptions",
    "build",
    "build_residual_data",
    "interval_inputs",
    "joined",
    "over_columns",
    "unpack_upper",
    "upper_indices",
    "window_starts",
]
