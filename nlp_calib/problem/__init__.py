"""Problem layer: the calibration problem's named CasADi Functions and the windows they are mapped over."""

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
