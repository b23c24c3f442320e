"""A gyro's closed-form start: its tilt and biases, then the wheels' turning, from the data alone.

Over each increment the gyro integrates ``z_ω ≈ v·Δθ + b·Δt`` (``v = s·Rᵀ·e_z``: the base's
vertical in the IMU's frame): with the heading changes ``Δθ`` the wheels predict at some
kinematic parameters, ``v`` and ``b`` are a linear least-squares fit, and ``v``'s direction is
the tilt whatever the wheels' error (it only scales ``Δθ``). The gyro's heading change,
``v̂ᵀ(z_ω − b·Δt)``, then fits the model's turning by Levenberg-Marquardt steps (numeric
Jacobians of the model's own motion). A gyro leaves the lengths' common scale free: a known
length sets it, else it is put where the longest length of the simulator's guess of the model is
that guess (the fit's observability then says the lengths are not determined). Two rounds, so the
biases are fitted against the fitted turning.

The same fit against the turning of typical wheels (each radius a quarter of the base's longest
length; beside a reference, the reference's wheels) is the gyro's turning over the wheels'
(``|v|``): near 180/π it is a gyro publishing degrees per second, which a slow robot's rates
(below 0.21 rad/s of turning) keep under the reader's 12 rad/s refusal; it is refused here with
the fix.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.models.base import KinematicModel
from nlp_calib.models.radians import default_guess
from nlp_calib.sensors.base import BaseMotion
from nlp_calib.sensors.mount import length_params

#: Rounds of (tilt and biases, then turning), and damped Gauss-Newton steps per round.
ROUNDS = 2
STEPS = 30
#: The weak pull towards the defaults (of the data's own curvature), which holds the free scale.
PULL = 1e-6
#: A typical wheel's radius over the base's longest length (its track, its wheelbase).
TYPICAL_SHARE = 0.25
#: The gyro's turning over typical wheels' within this factor of 180/π: degrees per second (wheels
#: 3 times smaller or larger than typical still land in it; a gyro in rad/s, at ~1, is 19 times below).
DEGREES_FACTOR = 3.0
#: The ratio is judged only where it is this many of its standard errors from 0 (a drive that
#: barely turns says nothing of it).
MIN_SIGNIFICANCE = 10.0


def _typical(
    model: KinematicModel, k: dict[str, float], known: Mapping[str, float]
) -> tuple[dict[str, float], str]:
    """``k`` with its lengths those of typical wheels (:data:`TYPICAL_SHARE`; a gyro sees only their
    ratios), unless every length is known; and what they are, in words."""
    lengths = [n for n in length_params(model) if n in k]
    if not lengths or all(n in known for n in lengths):
        return k, "the wheels did"
    longest = max(lengths, key=lambda n: abs(k[n]))
    typical = {n: (1.0 if n == longest else TYPICAL_SHARE) if n in lengths else v for n, v in k.items()}
    return typical, f"typical wheels (a radius {TYPICAL_SHARE:g} of {longest}) would have"


def _ratio(z: np.ndarray, turn: np.ndarray) -> tuple[float, float]:
    """``|v|`` of :func:`axis_and_bias` and its standard error."""
    v, b = axis_and_bias(z, turn)
    A = np.column_stack([turn, z[3]])
    r = z[:3].T - A @ np.vstack([v, b])
    s2 = float(np.sum(r**2)) / max(3 * (turn.size - 2), 1)
    try:
        var = s2 * float(np.linalg.inv(A.T @ A)[0, 0])
    except np.linalg.LinAlgError:
        return float(np.linalg.norm(v)), np.inf
    return float(np.linalg.norm(v)), float(np.sqrt(max(var, 0.0)))


def check_rad_s(z: np.ndarray, base_motion: BaseMotion, wheels: tuple[dict[str, float], str]) -> None:
    """Refuse a gyro whose turning is about 180/π times that of the ``wheels`` (their parameters,
    and what they are in words) over the increments ``z``."""
    k, what = wheels
    turn = np.asarray(base_motion(k))[2]
    (ratio, se), degree = _ratio(z, turn), 180.0 / np.pi
    if ratio < MIN_SIGNIFICANCE * se or not degree / DEGREES_FACTOR < ratio < degree * DEGREES_FACTOR:
        return
    raise DatasetError(
        "the gyro's rates",
        None,
        f"they turned {ratio:.3g} times as far as {what} ({float(np.sum(np.abs(turn))):.3g} rad "
        f"over {turn.size} increments): degrees per second (180/π = {degree:.1f}); sensor_msgs/Imu holds "
        "rad/s (REP 103): give the angular velocity in rad/s (× π/180)",
    )


def tilt_of(v: np.ndarray) -> tuple[float, float]:
    """Roll and pitch (rad) whose ``Rᵀ·e_z`` is the direction of ``v``."""
    u = v / max(float(np.linalg.norm(v)), 1e-300)
    return float(np.arctan2(u[1], u[2])), float(np.arcsin(np.clip(-u[0], -1.0, 1.0)))


def axis_and_bias(z: np.ndarray, turn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``v`` and ``b`` of ``z_ω ≈ v·Δθ + b·Δt`` by least squares (``z`` ``(4, n)``)."""
    A = np.column_stack([turn, z[3]])
    coef, *_ = np.linalg.lstsq(A, z[:3].T, rcond=None)
    return coef[0], coef[1]


def _turning(
    names: list[str], k: dict[str, float], heading: np.ndarray, base_motion: BaseMotion
) -> dict[str, float]:
    """The parameters ``names`` fitting the model's heading changes to ``heading`` (Levenberg-
    Marquardt in units of each parameter's size, weakly pulled to its start)."""
    k0 = dict(k)
    scale = np.array([max(abs(k0[n]), 1e-3) for n in names])
    y0 = np.array([k0[n] for n in names]) / scale

    def turns(y: np.ndarray) -> np.ndarray:
        return np.asarray(base_motion({**k0, **dict(zip(names, y * scale))}))[2]

    def cost(y: np.ndarray, pull: float) -> float:
        return float(np.sum((turns(y) - heading) ** 2) + pull * np.sum((y - y0) ** 2))

    y, damping, pull = y0.copy(), 1e-3, 0.0
    for _ in range(STEPS):
        r = turns(y) - heading
        J = np.column_stack([(turns(y + 1e-6 * e) - turns(y - 1e-6 * e)) / 2e-6 for e in np.eye(y.size)])
        H = J.T @ J
        pull = pull or PULL * max(float(np.trace(H)), 1e-300)
        g = J.T @ r + pull * (y - y0)
        before = cost(y, pull)
        while damping < 1e12:
            step = -np.linalg.solve(H + (pull + damping * np.trace(H) / y.size) * np.eye(y.size), g)
            if cost(y + step, pull) < before:
                y, damping = y + step, damping / 3.0
                break
            damping *= 4.0
        else:
            break
    return {**k0, **dict(zip(names, map(float, y * scale)))}


def _scale_anchor(model: KinematicModel, known: Mapping[str, float]) -> str | None:
    """The one known length, which sets the lengths' common scale (None: none is known, or several,
    whose ratio the user gave)."""
    given = [n for n in length_params(model) if n in known]
    return given[0] if len(given) == 1 else None


def _anchored(
    model: KinematicModel, k: dict[str, float], guess: Mapping[str, float], known: Mapping[str, float]
) -> dict[str, float]:
    """``k`` with its lengths' common scale, which a gyro cannot see, put where the one known length
    is its value, else where the longest of the guess's lengths is its guessed value (several
    known lengths: already set)."""
    lengths = [n for n in length_params(model) if n in k]
    if not lengths or (any(n in known for n in lengths) and _scale_anchor(model, known) is None):
        return k
    anchor = _scale_anchor(model, known) or max(lengths, key=lambda n: abs(guess[n]))
    if k[anchor] == 0.0:
        return k
    target = float(known.get(anchor, guess[anchor]))
    c = target / k[anchor]
    return {n: target if n == anchor else v * c if n in lengths else v for n, v in k.items()}


def gyro_start(
    model: KinematicModel, z: np.ndarray, base_motion: BaseMotion, known: Mapping[str, float]
) -> dict[str, float]:
    """Every kinematic parameter, the biases and the tilt from the increments ``z`` ``(4, n)``."""
    guess = {**default_guess(model), **model.defaults}
    # The turning sees the lengths' ratios alone: the one known length is fitted with the others
    # from the guess, as when none is known, and the scale set by it after (held at its value, the
    # others' steps from the guess stalled far from their ratios on some drives: a known left radius,
    # wheel_separation 177 m).
    held = {n: v for n, v in known.items() if n != _scale_anchor(model, known)}
    k = {n: float(held.get(n, guess[n])) for n in model.kinematic_params}
    free = [n for n in model.kinematic_params if n not in held]
    v, b = np.zeros(3), np.zeros(3)
    check_rad_s(z, base_motion, _typical(model, k, known))
    for _ in range(ROUNDS):
        v, b = axis_and_bias(z, np.asarray(base_motion(k))[2])
        u = v / max(float(np.linalg.norm(v)), 1e-300)
        heading = u @ (z[:3] - b[:, None] * z[3])
        if free:
            k = _turning(free, k, heading, base_motion)
    k = _anchored(model, k, guess, known)
    roll, pitch = tilt_of(v)
    bias = dict(zip(("gyro_bias_x", "gyro_bias_y", "gyro_bias_z"), map(float, b)))
    return {**k, **bias, "imu_roll": roll, "imu_pitch": pitch}
