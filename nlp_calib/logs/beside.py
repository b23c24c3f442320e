"""One log of a reference's own motions and a gyro's increments, read from the same joints.

A reference that gives poses (a tracker's) gives its motions as each interval's between two
consecutive poses, the windows its own fit would make by default (``residual: {horizon: 1}``):
planar ``(x, y, θ)``, or with ``in_3d`` a camera's 3-D motions ``(x, y, z, qx, qy, qz, qw)``.
Each source reads its own log (records at its own stamps); the two are laid on one time axis: a
record at every stamp of either, the joints read there from the reference's joint stream, and
each increment in the layout of :mod:`nlp_calib.sensors.beside` (the reference's motion, the
gyro's integrated rates and duration, and a last row: 1 for the gyro's). Each record is one
sensor's (a gyro stamp that is the reference's too moved 1 ns), so each is read on its own
sensor's clock (:meth:`~nlp_calib.logs.log.Log.read_times`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nlp_calib.core import poses, poses3d
from nlp_calib.core.errors import DatasetError
from nlp_calib.logs.log import Log, LogClock, LogHeader, ReferenceData
from nlp_calib.logs.reference import Motions, PoseMotions
from nlp_calib.logs.relative import RelativeMotions, _frozen

#: Rows of a planar reference's increment (a 3-D one's: 7) and of a gyro's.
REFERENCE_ROWS, GYRO_ROWS = 3, 4


def _stamps_ns(log: Log) -> np.ndarray:
    return log.clock.start_ns + np.round(np.asarray(log.time_s) * 1e9).astype(np.int64)


def _poses_at(log: Log, stamps_ns: np.ndarray) -> np.ndarray:
    """The reference's poses at ``stamps_ns``, interpolated between its own (for figures only)."""
    t = _stamps_ns(log).astype(float)
    T = np.array(log.T_world_sensor, dtype=float)
    heading = np.unwrap(T[:, 2])
    at = stamps_ns.astype(float)
    return np.column_stack([np.interp(at, t, T[:, 0]), np.interp(at, t, T[:, 1]), np.interp(at, t, heading)])


def _poses_3d_at(log: Log, stamps_ns: np.ndarray) -> np.ndarray:
    """The reference's 3-D poses at ``stamps_ns`` (the rotation along the shorter arc)."""
    P = log.poses_3d()
    t = _stamps_ns(log)
    after = np.clip(np.searchsorted(t, stamps_ns), 1, t.size - 1)
    a, b = after - 1, after
    s = np.clip((stamps_ns - t[a]) / np.maximum(t[b] - t[a], 1), 0.0, 1.0).astype(float)[:, None]
    return _frozen(np.asarray(poses3d.between_at(np.asarray(P)[a], np.asarray(P)[b], s)))


def _placed(
    inc: RelativeMotions, own_ns: np.ndarray, stamps_ns: np.ndarray, z: np.ndarray
) -> RelativeMotions:
    return RelativeMotions(
        np.searchsorted(stamps_ns, own_ns[inc.first]).astype(np.int64),
        np.searchsorted(stamps_ns, own_ns[inc.last]).astype(np.int64),
        z,
        inc.line_numbers,
        {},
    )


def _joined(a: RelativeMotions, b: RelativeMotions, quality: dict[str, np.ndarray]) -> RelativeMotions:
    order = np.lexsort((np.arange(a.n + b.n), np.concatenate([a.first, b.first])))
    return RelativeMotions(
        _frozen(np.concatenate([a.first, b.first])[order]),
        _frozen(np.concatenate([a.last, b.last])[order]),
        _frozen(np.vstack([a.z, b.z])[order]),
        _frozen(np.concatenate([a.line_numbers, b.line_numbers])[order]),
        {k: _frozen(v[order]) for k, v in quality.items()},
    )


def own_motions(log: Log, in_3d: bool = False) -> RelativeMotions | None:
    """The reference's motions: its own increments, or a tracker's each interval's motion between
    its two poses (in the sensor's frame at the first; with ``in_3d`` its 3-D poses'), each
    numbered by the line of its last pose."""
    if log.reference.motions is not None:
        return None if in_3d else log.reference.motions
    T = np.asarray(log.T_world_sensor_3d if in_3d else log.T_world_sensor, dtype=float)
    if T.ndim != 2 or T.shape[0] < 2 or T.shape[1] != (7 if in_3d else REFERENCE_ROWS):
        return None
    first = np.arange(T.shape[0] - 1, dtype=np.int64)
    z = poses3d.between(T[:-1], T[1:]) if in_3d else poses.between(T[:-1], T[1:])
    return RelativeMotions(_frozen(first), _frozen(first + 1), _frozen(z), _frozen(log.line_numbers[1:]))


def _apart(own_ns: np.ndarray, other_ns: np.ndarray) -> np.ndarray:
    """``own_ns`` with each stamp another sensor's too moved 1 ns later: each record is one
    sensor's, read on its own clock."""
    own = np.array(own_ns, dtype=np.int64)
    while (same := np.isin(own, other_ns)).any():
        own[same] += 1
    return own


def _both(reference: Log, gyro: Log) -> LogHeader:
    """The reference's header with the gyro's beside it; one frame cannot be both sensors' (each is
    a joint of its own from the base)."""
    frame = gyro.header.sensor_frame
    if frame == reference.header.sensor_frame:
        raise DatasetError(
            str(gyro.path),
            None,
            f"the gyro's frame {frame!r} is also the reference's: each sensor's mount is a joint from the "
            "base to a frame of its own; leave sensor_frame out of ROBOT.yaml (each sensor's frame is then "
            "its messages' frame_id) or give the dataset's sensor_frame",
        )
    return replace(reference.header, beside=gyro.header)


def beside_gyro(reference: Log, gyro: Log, in_3d: bool = False) -> Log:
    """The log of ``reference``'s motions (with ``in_3d``: its 3-D poses') and ``gyro``'s
    increments on one time axis (each increment's ``z``: reference rows, gyro rows, the gyro flag)."""
    ref_inc, gyro_inc = own_motions(reference, in_3d), gyro.reference.motions
    if ref_inc is None or gyro_inc is None:
        which = "3-D poses" if in_3d else "planar poses or motions"
        raise DatasetError(
            str(reference.path), None, f"a gyro beside this reference needs its {which} and the gyro's rates"
        )
    stream = reference.joint_stream
    if stream is None:
        raise ValueError(f"{reference.path}: a gyro beside it needs the joints' own stream")
    header = _both(reference, gyro)
    measures = Motions.name if reference.reference.motions is not None else PoseMotions.name
    ref_ns = _stamps_ns(reference)
    gyro_ns = _apart(_stamps_ns(gyro), ref_ns)
    first_ns, last_ns = ref_ns[0], ref_ns[-1]
    # Only the gyro's increments within the reference's span: the wheels are read on its stream.
    inside = (gyro_ns[gyro_inc.first] >= first_ns) & (gyro_ns[gyro_inc.last] <= last_ns)
    gyro_inc = gyro_inc.take(inside)
    used = np.unique(np.concatenate([gyro_inc.first, gyro_inc.last]))
    stamps = np.unique(np.concatenate([ref_ns, gyro_ns[used]]))
    n_ref, n_gyro = ref_inc.n, gyro_inc.n
    z_ref = np.hstack([ref_inc.z, np.zeros((n_ref, GYRO_ROWS + 1))])
    # A gyro's window holds the reference's motion as none at all (a 3-D one's unit quaternion: its
    # residual, weighed by 0 there, stays finite).
    still = np.zeros(ref_inc.z.shape[1])
    still[-1] = 1.0 if in_3d else 0.0
    z_gyro = np.hstack([np.tile(still, (n_gyro, 1)), gyro_inc.z, np.ones((n_gyro, 1))])
    quality = {k: np.concatenate([v, np.full(n_gyro, np.nan)]) for k, v in ref_inc.quality.items()}
    motions = _joined(
        _placed(ref_inc, ref_ns, stamps, z_ref), _placed(gyro_inc, gyro_ns, stamps, z_gyro), quality
    )
    poses_3d = _poses_3d_at(reference, stamps) if in_3d else None
    start_ns = int(stamps[0])
    time_s = _frozen((stamps - start_ns).astype(float) * 1e-9)
    shift = (reference.clock.start_ns - start_ns) * 1e-9
    breaks = None if stream.breaks is None else _frozen(np.asarray(stream.breaks) + shift)
    stream = replace(stream, time_s=_frozen(np.asarray(stream.time_s) + shift), breaks=breaks)
    n = int(stamps.size)
    line = np.zeros(n, dtype=np.int64)
    for idx in (motions.last, motions.first):
        line[idx[::-1]] = motions.line_numbers[::-1]
    return replace(
        reference,
        header=header,
        time_s=time_s,
        ticks=_frozen(np.zeros((n, 0), dtype=np.int64)),
        model_pose=_frozen(np.zeros((n, 3))),
        T_world_sensor=_frozen(_poses_at(reference, stamps)),
        line_numbers=_frozen(line),
        clock=LogClock(start_ns=start_ns),
        joint_positions=stream.at(time_s),
        joint_stream=stream,
        # A tracker's increments are differences of its poses: their noise is the poses'.
        reference=ReferenceData(poses_3d, motions, measures, beside=_frozen(np.isin(stamps, gyro_ns[used]))),
    )
