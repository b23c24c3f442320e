"""Figures as PNG bytes. The only package of nlp_calib that imports matplotlib.

Figures are drawn on an explicit Agg canvas, so an interactive matplotlib session that imports
this package keeps its own backend.
"""

from nlp_calib.outputs.plots.benchmark import scaling_png
from nlp_calib.outputs.plots.odometry import odometry_png
from nlp_calib.outputs.plots.plan import plan_png
from nlp_calib.outputs.plots.residuals import residuals_png, residuals_time_png
from nlp_calib.outputs.plots.run import convergence_png, model_check_png, trajectory_png
from nlp_calib.outputs.plots.trust import lag_png, trust_png

__all__ = [
    "convergence_png",
    "lag_png",
    "model_check_png",
    "odometry_png",
    "plan_png",
    "residuals_png",
    "residuals_time_png",
    "scaling_png",
    "trajectory_png",
    "trust_png",
]
