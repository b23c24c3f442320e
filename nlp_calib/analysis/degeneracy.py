"""Which combinations of parameters a drive cannot determine whatever its noise.

Along a combination the drive leaves (nearly) free, the fit moves by as much as rounding and the
model's discretisation push it, however little the data scatter: such a combination is told by
how little it changes what the model predicts, not by its σ. Each direction of the information
matrix in reference units (one unit: the precision a useful calibration needs of each parameter,
:func:`nlp_calib.models.reference_scales`) changes the predicted motion of the windows by
``√(λ/N)`` in the residual's weights; a direction whose unit step changes it by less than
:data:`FIDELITY` of the motion itself (``√(mean zᵀΩz)``) is not determined by this drive: a
time offset that a drive's sinusoidal wheel speeds turn into a mix of the wheels, a turning gain
and a length on circles of one radius. Well-posed drives sit two orders of magnitude above it.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.models import reference_scales
from nlp_calib.problem import ProblemFunctions

#: A direction whose unit step (in reference units) changes the predicted motion by less than this
#: fraction of the motion is not determined by the drive: what rounding to five significant digits,
#: or the model's own discretisation, already changes.
FIDELITY = 1e-5
#: Windows per block of :func:`motion_terms`.
MOTION_BLOCK = 1 << 14


def motion_scale(fns: ProblemFunctions, z: np.ndarray, omega: np.ndarray) -> float:
    """``mean zᵀΩz`` over the windows' measured motions ``z`` (in the residual's tangent rows)."""
    if z.shape[1] == 0:
        return 0.0
    return float(np.mean(motion_terms(fns, z, omega)))


def motion_terms(fns: ProblemFunctions, z: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Each window's ``zᵀΩz`` (:func:`motion_scale` is their mean; the mean of a subset of them is
    the subset's motion scale to the bit: each window's term is its own arithmetic)."""
    out = np.empty(z.shape[1])
    weight = np.asarray(omega)[:, None]
    # A block of windows at a time: at 10^6 a camera's tangent and its squares were several
    # arrays of every window's rows, allocated (and paged in) at each call.
    for lo in range(0, out.size, MOTION_BLOCK):
        m = fns.sensor.tangent(z[:, lo : lo + MOTION_BLOCK])
        out[lo : lo + MOTION_BLOCK] = np.sum(weight * m**2, axis=0)
    return out


def free_directions(lam: np.ndarray, n_windows: int, motion2: float) -> np.ndarray:
    """Which eigen-directions (eigenvalues ``lam`` of the information matrix ``JᵀΩJ`` in reference
    units, not divided by the noise) the drive leaves free (see the module docstring)."""
    floor = FIDELITY**2 * max(n_windows, 1) * motion2
    numeric = 1e-14 * max(float(np.max(lam)) if lam.size else 0.0, 1e-300)
    return np.asarray(lam < max(floor, numeric))


def scales(fns: ProblemFunctions, values: np.ndarray) -> np.ndarray:
    """Each free parameter's reference precision in its unit at the free parameters' ``values``
    (:func:`nlp_calib.models.reference_scales`, with the sensor's own references: a camera's mount
    is not a planar one's): the one scale the pre-flight and the run read what a drive determines
    in (the pre-flight had read every sensor's mount in a planar one's)."""
    return reference_scales(fns.model, fns.layout.keys(fns.free), values, fns.sensor.reference)
