"""The joints' own white noise, read from their stream, and what it makes of the model's inputs.

A reference whose own noise is far above the wheels' drift (a car's GNSS device: 2 cm against the
wheels' 0.14 mm an interval) cannot show that drift; the readings can. A joint published at a
high rate changes smoothly between messages, so the third differences of its readings are its
noise alone (a smooth motion's third difference is its jerk times the cycle cubed): a position's
third difference has 20 times one reading's variance; a wheel speed integrated by trapezoids
(:func:`~nlp_calib.logs.joint_log.wheel_positions`, a bag's velocities alike) gives the mean of two
neighbouring speeds per message, whose third difference has 2.5 times one speed's. The spread is
read robustly (the median's absolute deviation: a driver's steps do not count), over the readings
that changed (a message repeating a slow encoder's last update is no reading of its own).

That noise adds up along a drive only where a reading's noise enters one interval and not the
next: a speed's (integrated) and a steer angle's (each interval's own angle turns the base
on); a wheel position's noise enters one increment up and the next down and cancels, its
rounding already counted at a drift's ends (:func:`~nlp_calib.analysis.odometry.drift_noise`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nlp_calib.logs import Log
from nlp_calib.logs.log import JointStream, frozen
from nlp_calib.models import KinematicModel

#: The variance of a third difference in one reading's: of a position (``C(6, 3)``) and of the
#: mean of two neighbouring speeds (``(2·C(6, 3) − 2·C(6, 2))/4``).
THIRD_DIFFERENCE = {"position": 20.0, "speed": 2.5}
#: Random draws of the readings' noise that give each input's.
DRAWS = 4


def _robust_std(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if x.size >= 8 else 0.0


def _third_differences(x: np.ndarray, fresh: np.ndarray | None = None) -> np.ndarray:
    """The third differences of the readings ``x`` that changed (a message repeating the last
    update of a slow encoder is no reading of its own; ``fresh``: those that are, where the
    stream filled the held ones in)."""
    if fresh is not None:
        x = x[fresh]
    x = x[np.isfinite(x)]
    return np.diff(x[np.r_[True, np.diff(x) != 0.0]], 3)


def reading_jitter(stream: JointStream, names: tuple[str, ...]) -> np.ndarray:
    """Each joint's white noise of one reading (``names``: the stream's columns' encoders): of its
    speed (rad/s) where it was integrated from speeds, else of its position (rad)."""
    t = np.asarray(stream.time_s, dtype=float)
    out = np.zeros(len(names))
    if t.size < 8:
        return out
    dt = np.diff(t)
    for j, name in enumerate(names):
        if name in stream.integrated:
            step = np.diff(stream.positions[:, j])
            speed = np.divide(step, dt, out=np.full_like(step, np.nan), where=dt > 0)
            out[j] = _robust_std(_third_differences(speed)) / np.sqrt(THIRD_DIFFERENCE["speed"])
        else:
            fresh = None if stream.fresh is None else np.asarray(stream.fresh)[:, j]
            spread = _robust_std(_third_differences(stream.positions[:, j], fresh))
            out[j] = spread / np.sqrt(THIRD_DIFFERENCE["position"])
    return out


def _drawn(stream: JointStream, sigma: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """One draw of the readings' noise: integrated as a speed's readings are, and as drawn."""
    n, m = stream.positions.shape
    noise = rng.normal(size=(n, m)) * sigma
    dt = np.diff(np.asarray(stream.time_s, dtype=float))
    integrated = np.zeros((n, m))
    integrated[1:] = np.cumsum(0.5 * (noise[1:] + noise[:-1]) * dt[:, None], axis=0)
    return integrated, noise


def input_jitter(model: KinematicModel, log: Log, steering_sample: str) -> np.ndarray:
    """Each input's 1σ per interval that the joints' own noise (:func:`reading_jitter`) gives it
    and that adds up along a drive (a speed's, a steer angle's; 0 for a wheel position's, whose
    noise cancels, and without a joint stream): the inputs computed again on the readings with
    :data:`DRAWS` draws of that noise (fixed seed), their mean square difference."""
    n_in = len(model.input_names)
    stream = log.joint_stream
    if stream is None or log.n_records < 2:
        return np.zeros(n_in)
    names = log.header.encoder_names
    sigma = reading_jitter(stream, names)
    adds = np.array([n in stream.integrated or model.encoder_kinds.get(n) != "counter" for n in names])
    sigma = np.where(adds, sigma, 0.0)
    if not np.any(sigma > 0):
        return np.zeros(n_in)
    speeds = np.array([n in stream.integrated for n in names])
    rng = np.random.default_rng(0)
    base = model.inputs(log, steering_sample)
    read = log.read_times()
    total = np.zeros(n_in)
    for _ in range(DRAWS):
        integrated, white = _drawn(stream, sigma, rng)
        moved = replace(stream, positions=frozen(stream.positions + np.where(speeds, integrated, white)))
        noisy = replace(log, joint_stream=moved, joint_positions=moved.at(read))
        total += np.mean((model.inputs(noisy, steering_sample) - base) ** 2, axis=1)
    return np.sqrt(total / DRAWS)
