"""A robot log in memory: :class:`LogHeader` (what the ``#`` lines say) and :class:`Log` (records)."""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from nlp_calib.core import poses3d
from nlp_calib.core.errors import DatasetError
from nlp_calib.core.numeric import wrap_angle, wrapped_difference
from nlp_calib.core.text import numbered
from nlp_calib.logs.reference import REFERENCES, Poses, ReferenceKind
from nlp_calib.logs.relative import RelativeMotions

#: How an encoder reports: ``absolute`` readings lie in ``[0, max)`` (a steering angle);
#: ``counter`` readings are a uint32 count that wraps at 2³² (a wheel).
EncoderKind = Literal["absolute", "counter"]
ENCODER_KINDS: tuple[EncoderKind, ...] = ("absolute", "counter")
#: What an encoder reading is: a raw ``counts`` reading (the text format's integers) or a joint
#: position in ``radians`` as ROS publishes it (REP 103: a wheel's angle grows without wrapping,
#: a steering joint's is its angle).
EncoderUnits = Literal["counts", "radians"]
ENCODER_UNITS: tuple[EncoderUnits, ...] = ("counts", "radians")


@dataclass(frozen=True)
class DroppedRecord:
    """A record left out by a non-strict read, with the line it came from and why."""

    line: int
    reason: str


@dataclass(frozen=True)
class LogHeader:
    """What the ``#`` lines say: model, initial guess, encoders, nominal ``T_base_sensor``.

    ``parameters`` keeps the header's own names (the model maps them onto its parameter names);
    ``T_base_sensor`` is ordered ``(x, y, theta)``. ``encoder_units`` says what the readings are
    (``encoder_max`` is 0 for joints in radians); ``sensor_z_roll_pitch`` is the nominal mount's
    height, roll and pitch where a source knows them (a bag's ``/tf_static``); ``nominal`` says
    which values are the robot's nominal ones where a source filled in defaults;
    ``counts_per_turn`` each wheel encoder's counts per wheel turn where a source states them
    (``ROBOT.yaml``); ``beside`` the header of a second sensor read beside the reference.
    """

    kinematic_model: str
    parameters: Mapping[str, float]
    encoder_names: tuple[str, ...]
    encoder_max: tuple[int, ...]
    sensor_frame: str
    T_base_sensor: tuple[float, float, float]
    encoder_units: EncoderUnits = "counts"
    sensor_z_roll_pitch: tuple[float, float, float] | None = None
    #: The parameters (the model's names; the mount's ``sensor_x``, ``sensor_y``, ``sensor_theta``)
    #: whose values here are the robot's nominal ones, each with where it comes from; None: all of
    #: them, written by the robot's own logger (a text log's header). The rest are defaults.
    nominal: Mapping[str, str] | None = None
    counts_per_turn: Mapping[str, float] = field(default_factory=dict)
    #: The header of a sensor read beside the reference (a gyro's: its frame, its nominal mount).
    beside: LogHeader | None = None
    #: What reading the log warned of (each warning's text, as shown): its run's result states it.
    said: tuple[str, ...] = ()

    def encoder_index(self, name: str) -> int:
        """Column of the encoder called ``name`` in :attr:`Log.ticks`."""
        if name not in self.encoder_names:
            raise DatasetError(
                "<header>",
                None,
                f"the log has no encoder called {name!r} (it lists {list(self.encoder_names)})",
            )
        return self.encoder_names.index(name)

    def encoder_range(self, name: str) -> int:
        """The ``#joints_max_enc_values`` entry of encoder ``name``."""
        return self.encoder_max[self.encoder_index(name)]


def blended_increment_variance(stamps: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Per interval between the times ``t``, the variance of an increment of readings taken at
    ``stamps`` and interpolated linearly at ``t``, in one reading's (the readings' noises
    independent): 2 where ``t`` are the stamps; less where both ends interpolate one pair of
    readings (their difference's share of it) or the ends share a reading."""
    ts = np.asarray(stamps, dtype=float)
    if ts.size < 2 or np.size(t) < 2:
        return np.full(max(np.size(t) - 1, 0), 2.0)
    k = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, ts.size - 2)
    alpha = np.clip((t - ts[k]) / (ts[k + 1] - ts[k]), 0.0, 1.0)
    # Each end reads (1 − α)·n_k + α·n_{k+1}; the increment weighs the readings k_i, k_i + 1
    # by −(1 − α_i), −α_i and k_{i+1}, k_{i+1} + 1 by 1 − α_{i+1}, α_{i+1}.
    a0, a1, b0, b1 = -(1.0 - alpha[:-1]), -alpha[:-1], 1.0 - alpha[1:], alpha[1:]
    d = k[1:] - k[:-1]
    apart = a0**2 + a1**2 + b0**2 + b1**2
    return np.where(
        d == 0, (a0 + b0) ** 2 + (a1 + b1) ** 2, np.where(d == 1, a0**2 + (a1 + b0) ** 2 + b1**2, apart)
    )


@dataclass(frozen=True)
class JointStream:
    """Joint positions (rad, ``(n, n_joints)`` in the header's encoder order) on the joints' own
    clock: ``time_s`` on the log's time axis. ``resolution`` is each joint's smallest step (rad;
    0 when its positions are not quantised), the floor of its noise; ``integrated`` names the
    encoders whose positions were integrated from velocities (known only up to their start);
    ``breaks`` ``(m, 2)`` the stretches ``(from, to)`` of ``time_s`` over which the joints' motion is
    unknown (a wheel's increments per cycle with rows lost between two stamps)."""

    time_s: np.ndarray
    positions: np.ndarray
    resolution: tuple[float, ...]
    integrated: tuple[str, ...] = ()
    breaks: np.ndarray | None = None
    #: ``(n, n_joints)``: which messages are readings of their own, the others a slow driver's
    #: held reading filled in between its updates (None: every message is one).
    fresh: np.ndarray | None = None
    #: ``(n, n_joints)``: for the joints integrated from speeds (``integrated``), the positions
    #: with each speed held over the interval after its stamp less the trapezoids' (the mean over
    #: the interval before gives the trapezoids' less this): what a speed column leaves open,
    #: half an interval's reading either way (0 for the others; None: none integrated).
    quadrature: np.ndarray | None = None

    def updates_s(self) -> np.ndarray:
        """Each joint's median time between its own readings (s): its driver's update period."""
        ts = np.asarray(self.time_s, dtype=float)
        if self.fresh is None or ts.size < 2:
            return np.full(self.positions.shape[1], float(np.median(np.diff(ts))) if ts.size > 1 else 0.0)
        return np.array([np.median(np.diff(ts[f])) if f.sum() > 1 else 0.0 for f in np.asarray(self.fresh).T])

    def reading_spread(self, t: np.ndarray) -> np.ndarray:
        """Each joint's position read at times ``t`` is known to within this (rad) from its driver's
        updates alone: between two, the stream runs straight, and a rate that changed by ``Δω``
        between them bends the true path off that line by up to ``Δω·P/4`` (``P`` the update
        period: 0.25 s at 4 Hz, where a pivot's start is 0.15 rad of the wheel off)."""
        period = self.updates_s()
        ahead = np.stack([self.slopes(t + p)[:, j] for j, p in enumerate(period)], axis=1)
        behind = np.stack([self.slopes(t - p)[:, j] for j, p in enumerate(period)], axis=1)
        return np.abs(ahead - behind) * period / 4.0

    def broken(self, t: np.ndarray) -> np.ndarray | None:
        """Per interval between the times ``t`` (the joints read there), whether the joints' motion
        over it is unknown: it overlaps a break (None: the stream has none)."""
        if self.breaks is None or not self.breaks.size:
            return None
        t = np.asarray(t, dtype=float)
        # Breaks before an interval's end, minus those that end before its start: any overlap.
        began = np.searchsorted(np.sort(self.breaks[:, 0]), t[1:], side="left")
        ended = np.searchsorted(np.sort(self.breaks[:, 1]), t[:-1], side="right")
        return np.asarray(began > ended)

    def at(self, t: np.ndarray) -> np.ndarray:
        """The positions interpolated at times ``t`` (held at the ends outside the stream)."""
        cols = [np.interp(t, self.time_s, self.positions[:, j]) for j in range(self.positions.shape[1])]
        return frozen(np.stack(cols, axis=1).reshape(np.shape(t)[0], self.positions.shape[1]))

    def slopes(self, t: np.ndarray) -> np.ndarray:
        """Each joint's rate (rad/s) at times ``t``: each sample's rate over the samples either side
        of it (the ends': their one interval's), interpolated between the samples. A reading's own
        noise (a count's quantisation) has no weight in its rate, so a window that ends on a sample
        (a text log's records are the joints' own) does not meet its own noise in the clock's
        derivative: a segment's slope there put the fitted offsets 9-16 ms early."""
        ts, q = self.time_s, self.positions
        if ts.size < 2:
            return np.zeros((np.shape(t)[0], q.shape[1]))
        rate = self._sample_rates
        cols = [np.interp(t, ts, rate[:, j]) for j in range(q.shape[1])]
        return np.stack(cols, axis=1).reshape(np.shape(t)[0], q.shape[1])

    @functools.cached_property
    def _sample_rates(self) -> np.ndarray:
        """Each sample's rate for :meth:`slopes`, once per stream: a lag's re-sampling keeps the
        stream, and a lag search reads the rates at every lag it tries."""
        ts, q = self.time_s, self.positions
        ahead, behind = np.r_[1 : ts.size, ts.size - 1], np.r_[0, 0 : ts.size - 1]
        span = ts[ahead] - ts[behind]
        with np.errstate(divide="ignore", invalid="ignore"):
            return frozen(np.where(span[:, None] > 0, (q[ahead] - q[behind]) / span[:, None], 0.0))

    def travelled_angle(self, t: np.ndarray, angle: int, wheels: Sequence[int]) -> np.ndarray:
        """Per interval between the times ``t``, column ``angle``'s mean over it as the wheels
        (columns ``wheels``) travelled it: the stream's linear interpolation cut at its samples
        inside the interval, each piece's mid-angle weighted by the wheels' travel on it (by its
        duration where they stand). A steered wheel turns the base by its travel times the
        angle's sine, so this is the angle of the interval's turn to the stream's resolution;
        its two ends' mean alone misses the angle's curve between them and its correlation
        with the speed (a gyro's 0.1 s interval over 50 Hz joints: the fitted clock offset
        2-3 ms early)."""
        t = np.asarray(t, dtype=float)
        if t.size < 2:
            return np.zeros(0)
        # The times need not increase (a gyro's records beside a reference's, each read on its own
        # clock): each interval covers the stream between its two ends, whichever comes first.
        cuts = np.union1d(t, self.time_s[(self.time_s > t.min()) & (self.time_s < t.max())])
        at = self.at(cuts)
        k = np.searchsorted(cuts, t)
        a, b = np.minimum(k[:-1], k[1:]), np.maximum(k[:-1], k[1:])
        mid = 0.5 * (at[1:, angle] + at[:-1, angle])
        travel = np.abs(np.diff(at[:, list(wheels)], axis=0)).sum(axis=1)
        span = np.diff(cuts)

        def over(v: np.ndarray) -> np.ndarray:
            total = np.concatenate([[0.0], np.cumsum(v)])
            return np.asarray(total[b] - total[a])

        moved, lasted = over(travel), over(span)
        by_travel = over(travel * mid) / np.where(moved > 0, moved, 1.0)
        by_time = over(span * mid) / np.where(lasted > 0, lasted, 1.0)
        ends = 0.5 * (at[k[1:], angle] + at[k[:-1], angle])
        return np.where(moved > 0, by_travel, np.where(lasted > 0, by_time, ends))

    def increment_variance(self, t: np.ndarray) -> np.ndarray:
        """Per interval between the times ``t``, the variance of the joints' increment read there,
        in one stream reading's (:func:`blended_increment_variance` at the stream's stamps)."""
        return blended_increment_variance(self.time_s, t)

    def covers(self, t: np.ndarray) -> np.ndarray:
        """Which of the times ``t`` lie inside the stream."""
        return (t >= self.time_s[0]) & (t <= self.time_s[-1])


@dataclass(frozen=True)
class LogClock:
    """Where a log's times stand: ``start_ns``, the stamp of its first record on its own clock (ns;
    every time of the log is relative to it), and ``encoder_lag_s``, how much earlier than the
    tracker's stamps its encoders are read (s: 0 as logged, the lag they were re-sampled at);
    ``beside_lag_s``, in a log of two sensors (:attr:`ReferenceData.beside`), how much later still
    they are read at the second sensor's records (its clock's offset over the reference's)."""

    start_ns: int = 0
    encoder_lag_s: float = 0.0
    beside_lag_s: float = 0.0


@dataclass(frozen=True)
class ReferenceData:
    """What the reference measured beyond its planar poses: its 3-D poses ``(n, 7)`` (a tracker's,
    a camera's), or its own motions between records (a scan matcher's)."""

    poses_3d: np.ndarray | None = None
    motions: RelativeMotions | None = None
    #: Its kind's name in :data:`~nlp_calib.logs.reference.REFERENCES`, given by the reader that
    #: filled it (the source knows what its device measures; no stage infers it from a field).
    measures: str = Poses.name
    #: What a record's line number counts: a text file's ``line``, a bag topic's ``/topic message``.
    numbered: str = "line"
    #: A log of two sensors on their own clocks (a gyro beside the reference): per record, whether it
    #: is the second sensor's stamp (the encoders read there on its clock; None: one sensor's log).
    beside: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.measures not in REFERENCES:
            raise ValueError(f"unknown reference kind {self.measures!r} (known: {', '.join(REFERENCES)})")

    @property
    def kind(self) -> ReferenceKind:
        """What the reference measures (:mod:`nlp_calib.logs.reference`), as its reader named it."""
        return REFERENCES[self.measures](self)

    def select(self, start: int, stop: int) -> ReferenceData:
        """Its records ``[start, stop)`` (its own motions within them), of the same kind."""
        motions = None if self.motions is None else self.motions.select(start, stop)
        sl = slice(start, stop)
        return replace(
            self, poses_3d=_rows(self.poses_3d, sl), motions=motions, beside=_rows(self.beside, sl)
        )


@dataclass(frozen=True)
class Log:
    """An immutable robot log: per-record arrays of equal length ``n_records``.

    ``ticks`` holds the raw encoder readings (columns in ``header.encoder_names`` order),
    ``T_world_sensor`` the tracker poses and ``model_pose`` the vendor odometry, both
    ``(x, y, theta)`` per row. ``time_s`` is relative to the first record of the file, whose own
    stamp on the log's clock is ``clock.start_ns`` (ns).

    A log of joints in radians (``header.encoder_units``) has no counts (``ticks`` has no
    columns): ``joint_positions`` holds each joint's position at the records, interpolated from
    ``joint_stream``, the joints as published on their own clock (re-sampled from there when the
    tracker's clock is shifted).

    A reference that measures its own motion between two of its stamps (a scan matcher, visual
    odometry: :class:`~nlp_calib.logs.relative.RelativeMotions`) fills ``motions``: a record is made
    at each stamp, and ``T_world_sensor`` is then only the chain of those motions (held where none
    covers an interval), for figures; the residuals compare each increment itself.

    A tracker that reports 3-D poses (a bag's motion capture, a camera's own trajectory) fills
    ``T_world_sensor_3d`` too, ``(x, y, z, qx, qy, qz, qw)`` per row in its own world frame and
    units; ``T_world_sensor`` is then its planar track (the pose's yaw for a tracker whose world
    is level, the levelled track of :func:`nlp_calib.logs.camera.planar_track` for a camera).
    ``None`` for a planar tracker.
    """

    path: str
    header: LogHeader
    time_s: np.ndarray
    ticks: np.ndarray
    model_pose: np.ndarray
    T_world_sensor: np.ndarray
    line_numbers: np.ndarray
    dropped: tuple[DroppedRecord, ...] = field(default=())
    clock: LogClock = field(default_factory=lambda: LogClock())
    joint_positions: np.ndarray | None = None
    joint_stream: JointStream | None = None
    reference: ReferenceData = field(default_factory=ReferenceData)

    @property
    def T_world_sensor_3d(self) -> np.ndarray | None:
        """The tracker's 3-D poses, where it reports them (None: planar ones)."""
        return self.reference.poses_3d

    @property
    def motions(self) -> RelativeMotions | None:
        """The reference's own motions between records, where it measures them."""
        return self.reference.motions

    def where(self, first: int, last: int | None = None) -> str:
        """``line 5``, ``lines 5-9`` or ``/topic message 5``: where line numbers ``first..last``
        lie in the log's source."""
        return numbered(self.reference.numbered, int(first), None if last is None else int(last))

    @property
    def start_ns(self) -> int:
        """The stamp of the first record on the log's own clock (ns)."""
        return self.clock.start_ns

    @property
    def encoder_lag_s(self) -> float:
        """How much earlier than the tracker's stamps the encoders are read (s)."""
        return self.clock.encoder_lag_s

    @property
    def n_records(self) -> int:
        return int(self.time_s.shape[0])

    def read_times(self, lag_s: float | None = None, beside_lag_s: float | None = None) -> np.ndarray:
        """Where the encoders are read for each record on the log's time axis: its time less the
        encoders' lag (``lag_s``, default the log's own), a second sensor's record less its
        clock's offset over the reference's too (``beside_lag_s``, default the log's own): each
        sensor's records read on its own clock, not the gyro's by the first-order clock correction
        over the two clocks' difference (a turn rate's jump inside it took its offset 6σ off)."""
        lag = self.encoder_lag_s if lag_s is None else lag_s
        read = np.asarray(self.time_s, dtype=float) - lag
        mine = self.reference.beside
        if mine is None:
            return read
        beside = self.clock.beside_lag_s if beside_lag_s is None else beside_lag_s
        return np.asarray(read - beside * mine)

    def at_joint_samples(self) -> tuple[Log, np.ndarray | None]:
        """The log with a record at each of its joints' own samples between its records too (no
        reference there), and where its records fall among those (None: no joint stream finer than
        the records): the wheels integrated over their own samples, as a controller integrates
        them, not by the model's one arc per interval, which a drive that changes inside it (a
        pivot's start inside a scan matcher's 2 s) does not follow."""
        stream = self.joint_stream
        if stream is None or self.reference.beside is not None:
            return self, None
        lag = self.encoder_lag_s
        inner = stream.time_s + lag
        t = np.union1d(self.time_s, inner[(inner > self.time_s[0]) & (inner < self.time_s[-1])])
        if t.size == self.n_records:
            return self, None
        n = t.size
        fine = replace(
            self,
            time_s=frozen(t),
            ticks=frozen(np.zeros((n, 0), dtype=np.int64)),
            model_pose=frozen(np.zeros((n, 3))),
            T_world_sensor=frozen(np.zeros((n, 3))),
            line_numbers=frozen(np.zeros(n, dtype=np.int64)),
            joint_positions=stream.at(t - lag),
            reference=replace(self.reference, motions=None),
        )
        return fine, np.searchsorted(t, self.time_s)

    def joint_breaks(self) -> np.ndarray | None:
        """Per interval, whether the joints' motion over it is unknown where they are read (the
        records' times less the encoders' lag; :meth:`JointStream.broken`); None: nowhere."""
        stream = self.joint_stream
        return None if stream is None else stream.broken(self.read_times())

    def increment_variance(self) -> np.ndarray:
        """Per interval, a counter's increment's variance in one reading's where the encoders are
        read (:meth:`JointStream.increment_variance`): 2 for counts as logged (each record a reading
        of its own); counts re-sampled between the records (fractional, at the log's
        :attr:`encoder_lag_s`) blend two readings' each (:func:`blended_increment_variance`)."""
        stream = self.joint_stream
        if stream is None and np.issubdtype(self.ticks.dtype, np.integer):
            return np.full(max(self.n_records - 1, 0), 2.0)
        if stream is None:
            t = np.asarray(self.time_s, dtype=float)
            return blended_increment_variance(t, t - self.encoder_lag_s)
        return stream.increment_variance(self.read_times())

    def encoder(self, name: str) -> np.ndarray:
        """Readings of one encoder, ``(n_records,)``: int64 as logged, float where re-sampled."""
        return self.ticks[:, self.header.encoder_index(name)]

    def increments(self, name: str) -> np.ndarray:
        """Signed increments of a counter (wrapping uint32), ``(n_records - 1,)``."""
        return wrapped_difference(self.encoder(name))

    def joint_position(self, name: str) -> np.ndarray:
        """The position (rad) of the joint read as encoder ``name`` at each record."""
        if self.joint_positions is None:
            raise DatasetError(self.path, None, "holds raw encoder counts, not joint positions in radians")
        return self.joint_positions[:, self.header.encoder_index(name)]

    def running_position(self, name: str) -> np.ndarray:
        """Encoder ``name``'s running position at each record, as float: the joint's angle (rad),
        or a counter's count unwrapped from the first record's."""
        if self.joint_positions is not None:
            return np.asarray(self.joint_position(name), dtype=float)
        return np.concatenate([[0.0], np.cumsum(self.increments(name))]).astype(float)

    def joint_rates(self) -> np.ndarray | None:
        """Each joint's rate (rad/s) at each record, where the encoders are read (None without a
        joint stream)."""
        if self.joint_stream is None:
            return None
        return self.joint_stream.slopes(self.read_times())

    def poses_3d(self) -> np.ndarray:
        """The tracker's 3-D poses ``(x, y, z, qx, qy, qz, qw)`` (an error when it reports planar ones)."""
        if self.T_world_sensor_3d is None:
            raise DatasetError(
                self.path, None, "a 3-D sensor needs 3-D tracker poses; this log has planar ones"
            )
        return self.T_world_sensor_3d

    def heights(self) -> np.ndarray | None:
        """The tracker's height at each record where it reports 3-D poses (None: planar ones)."""
        return None if self.T_world_sensor_3d is None else np.asarray(self.T_world_sensor_3d[:, 2])

    def with_poses_interpolated(self, bad: np.ndarray) -> Log:
        """This log with the tracker poses of the records ``bad`` (a mask) interpolated in time from
        the nearest good ones around (the nearest at either end): the planar pose along its
        unwrapped heading, a 3-D pose along the shorter arc."""
        if not bad.any() or (~bad).sum() < 2:
            return self
        t = self.time_s
        T = np.array(self.T_world_sensor, dtype=float)
        U = T.copy()
        U[:, 2] = np.unwrap(U[:, 2])
        for j in range(3):
            T[bad, j] = np.interp(t[bad], t[~bad], U[~bad, j])
        T[:, 2] = wrap_angle(T[:, 2])
        out = replace(self, T_world_sensor=frozen(T))
        if self.T_world_sensor_3d is None:
            return out
        good, k = np.flatnonzero(~bad), np.flatnonzero(bad)
        after = np.clip(np.searchsorted(good, k), 1, good.size - 1)
        a, b = good[after - 1], good[after]
        s = np.clip((t[k] - t[a]) / np.maximum(t[b] - t[a], 1e-12), 0.0, 1.0)[:, None]
        P = np.array(self.T_world_sensor_3d, dtype=float)
        P[k] = poses3d.between_at(P[a], P[b], s)
        return replace(out, reference=replace(out.reference, poses_3d=frozen(P)))

    def select(self, start: int, stop: int) -> Log:
        """The records ``start:stop`` (time stays relative to the file's first record)."""
        sl = slice(start, stop)
        return replace(
            self,
            time_s=frozen(self.time_s[sl]),
            ticks=frozen(self.ticks[sl]),
            model_pose=frozen(self.model_pose[sl]),
            T_world_sensor=frozen(self.T_world_sensor[sl]),
            line_numbers=frozen(self.line_numbers[sl]),
            joint_positions=_rows(self.joint_positions, sl),
            reference=self.reference.select(start, stop),
        )


def _rows(a: np.ndarray | None, sl: slice) -> np.ndarray | None:
    return None if a is None else frozen(a[sl])


def frozen(a: np.ndarray) -> np.ndarray:
    """A contiguous, read-only copy (or view) of ``a``."""
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a
