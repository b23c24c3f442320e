"""Problem layer: the calibration problem's named CasADi Functions and the data they are mapped over."""

from nlp_calib.problem.functions import PER_RESIDUAL, ProblemFunctions, ProblemSpec, build, unpack_upper
from nlp_calib.problem.windows import ResidualData, ResidualOptions, build_residual_data, window_starts

__all__ = [
    "PER_RESIDUAL",
    "ProblemFunctions",
    "ProblemSpec",
    "ResidualData",
    "ResidualOptions",
    "build",
    "build_residual_data",
    "unpack_upper",
    "window_starts",
]
