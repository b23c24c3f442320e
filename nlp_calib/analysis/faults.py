"""Encoder and tracker faults: data no calibration can explain, found by its own inconsistency.

The records are screened as logged, before anything is re-sampled, and each mismatch is put down
to the stream that explains it:

- a **tracker** pose off the path its neighbours agree on is the tracker's own glitch
  (``tracker_jump``; :mod:`nlp_calib.analysis.streams`): a stop, a reversal or a start is a kink
  the neighbours on one side continue into, and is never one;
- a **tracker** that repeats its last pose exactly over records while the wheels turn lost its
  target and republished the pose (``tracker_stuck``; a motion-capture dropout): the repeated poses
  are wrong, and no window starts or ends at them. A tracker that moves by steps (over a quarter of
  its travel right after a repeat: poses held between slower updates) repeats by its nature, and
  is not judged so. A reference of its own increments froze the same way when increments that
  follow on read no motion at all (``sensor.motion_of``) over as many stamps (:data:`FROZEN`: one
  rule per reference kind; a gyro's rates cannot show it);
- an **absolute encoder** (e.g. a wheel's angle) that leaves the span of its neighbours for one record
  and returns (``steering_spike``), or holds its reading while the robot moves and then catches
  up in one jump (``steering_stuck``), is that encoder's own glitch;
- a **counter** whose count over a stretch of records is wrong in total, as its own history shows
  and the tracker's motion over several intervals confirms through the calibrated model
  (:mod:`nlp_calib.analysis.counters`): ``stall_then_jump`` (the counter reads stale, then its
  catch-up is off; on the real robot by 2¹⁶ ticks, a 16-bit counter wrapped in the logger),
  ``reversal`` (one increment against the motion, not made up afterwards) and ``counter_jump``
  (counts gained or lost in the direction of motion, not made up afterwards).

A reference that measures its own motions (``Log.motions``: a scan matcher's) has no poses to
be off a path; each increment is judged on its own (``bad_match``): first by what its matcher said
of it (not converged, few points matched, a large fit error against the log's own), then by its
disagreement with the wheels at the fit that judges the encoders, far beyond the increments'
robust scatter; the counters are then judged without them (a counter's fault shows over several
increments; over one it is not told from a bad match). A bad increment spoils its own window only.

The counters are judged with a fit that leaves out the tracker's and the absolute encoders'
glitches, against readings with those glitches interpolated over, so that one stream's glitch is
never blamed on another. Stale readings that catch up are counted (``stale``) but harmless to
horizon windows.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from nlp_calib.analysis.counters import screen_counters
from nlp_calib.analysis.joint_repair import repair_joints
from nlp_calib.analysis.readings import Readings, interpolated_over, readings, turning
from nlp_calib.analysis.readings import unit as unit_of
from nlp_calib.analysis.streams import (
    MIN_STUCK,
    moves_by_steps,
    off_neighbours,
    printed_step,
    scatter,
    stuck_runs,
)
from nlp_calib.core import poses, poses3d
from nlp_calib.core.numeric import COUNTER_MODULUS, robust_spread, wrapped_difference
from nlp_calib.logs import EncoderKind, Log
from nlp_calib.logs.log import JointStream, frozen
from nlp_calib.logs.reference import Motions, PoseMotions, Poses
from nlp_calib.logs.relative import RelativeMotions
from nlp_calib.logs.resample import Resampler
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.problem.windows import tracker_poses
from nlp_calib.results.faults import (
    ABSOLUTE_KINDS,
    COARSE_ARC,
    MATCH_KINDS,
    PIVOT_RADIUS_M,
    PIVOT_SLIP,
    TRACKER_KINDS,
    TRACKER_STUCK,
    Fault,
    FaultReport,
)
from nlp_calib.sensors import Sensor

#: A 16-bit counter wraps after this many ticks (named in the evidence when the deficit matches).
WRAP_16 = 2**16
#: An absolute encoder's glitch must leave the span of its neighbours by this angle (rad): less
#: is not told from a sharp turn of the thing it measures. A stuck reading must catch up by more
#: than this many of its smallest steps (ticks; a joint's resolution).
SPIKE_MIN_ANGLE = 0.03
STUCK_FLOOR_STEPS = 3.0
#: The longest group of tracker records judged as one glitch; an absolute encoder's is one record.
#: A glitch of the tracker leaves the span of its near neighbours by this many times its scatter
#: at rest (a corner cut by a slow tracker interpolated onto faster records stays inside it).
TRACKER_GROUP = 4
TRACKER_EXCURSION = 3.0
#: A match whose share of points matched is below this fraction of the log's median share, or
#: whose fit error exceeds this many times the log's median, is poor by its matcher's own word.
MATCH_INLIERS = 0.5
MATCH_ERROR = 3.0
#: An increment that disagrees with the wheels at the fit by more than this many robust σ of the
#: increments' scatter (in any of x, y, θ) is a bad match (5σ: a false alarm in 10⁶ Gaussian ones).
MATCH_SCATTER = 5.0


def _norm(x: np.ndarray) -> float:
    return float(np.hypot.reduce(np.abs(x)))


def _fault(
    log: Log,
    kind: str,
    encoder: str | None,
    intervals: tuple[int, int],
    record: int,
    size: tuple[float, float, float],
    evidence: str,
) -> Fault:
    """A fault at ``record`` of ``log`` over ``intervals``; ``size`` is (logged, implied, noise)."""
    t, line = float(log.time_s[record]), int(log.line_numbers[record])
    return Fault(kind, encoder, intervals[0], intervals[1], record, t, line, *size, evidence)


#: A sensor's jump signal of a log and how many of its leading columns are positions
#: (``Sensor.jump_signal``).
Signal = tuple[np.ndarray, int]


def tracker_faults(log: Log, sensor: Sensor, signal: Signal | None = None) -> list[Fault]:
    """Tracker poses off the path their neighbours agree on (see :mod:`nlp_calib.analysis.streams`),
    on the signal the ``sensor`` judges them by (its jump signal; ``signal``: computed already), its
    positions in its length unit."""
    T, position = sensor.jump_signal(log) if signal is None else signal
    length = sensor.length_unit
    t, lines = log.time_s, log.line_numbers
    # The printed precision of the poses (and their discretisation, the path's own bend: see
    # streams.path_bend) is the least scatter a miss is judged by, however clean the data.
    sc = replace(scatter(t, T, printed_step(T)), vector=position)
    if not np.any(sc.floor > 0):
        # Poses without scatter at rest (a noise-free simulation) give no scale to judge a miss by:
        # a smooth path's own curvature would be taken for glitches.
        return []
    noise = _norm(sc.floor[:position])
    found = []
    for g in off_neighbours(t, T, sc, excursion=TRACKER_EXCURSION * sc.floor, max_group=TRACKER_GROUP):
        off, turn = _norm(g.offset[:position]), _norm(g.offset[position:])
        for q in range(g.first, g.last + 1):
            group = f"records {g.first}-{g.last} " if g.last > g.first else ""
            evidence = (
                f"the tracker pose at record {q} ({log.where(lines[q])}) is off the path its neighbours "
                f"agree on ({group}by up to {off:.3f} {length} and {turn:.3f} rad, "
                f"{g.score:.0f}× the tracker's scatter)"
            )
            found.append(
                _fault(log, "tracker_jump", None, (g.first - 1, g.last), q, (0.0, off, noise), evidence)
            )
    return found


def _counters_turning(log: Log, kinds: Mapping[str, EncoderKind]) -> np.ndarray | None:
    """Per interval between records, whether a counter of the wheels changed (None: no counter)."""
    return turning(log, [n for n in log.header.encoder_names if kinds.get(n) == "counter"], records=True)


def _stuck_fault(log: Log, first: int, last: int, what: str, why: str) -> Fault:
    """A frozen reference from record ``first`` (the last reading it made) to ``last``."""
    t, lines = log.time_s, log.line_numbers
    evidence = (
        f"the {what} of record {first} ({log.where(lines[first])}) over records {first + 1}-{last} "
        f"({t[last] - t[first]:.2f} s) while the wheels turn: {why}"
    )
    return _fault(log, TRACKER_STUCK, None, (first, last - 1), first + 1, (0.0, 0.0, 0.0), evidence)


def stuck_tracker(
    log: Log, sensor: Sensor, kinds: Mapping[str, EncoderKind], signal: Signal | None = None
) -> list[Fault]:
    """Runs of records whose tracker pose repeats the one before exactly, over
    :data:`~nlp_calib.analysis.streams.MIN_STUCK` records or more, while the wheels turn over most
    of them: the tracker lost its target and republished its last pose (judged on the sensor's jump
    signal; ``signal``: computed already). One fault per run."""
    moving = _counters_turning(log, kinds)
    T, position = sensor.jump_signal(log) if signal is None else signal
    if moving is None or T.shape[0] < MIN_STUCK + 1:
        return []
    step = np.linalg.norm(np.diff(T[:, :position], axis=0), axis=1)
    if moves_by_steps(np.concatenate([[0.0], np.cumsum(step)])):
        return []  # poses held between slower updates: a repeat is how this tracker moves
    # Runs of repeats: record ``first`` is the last pose read, ``first + 1 … last`` repeat it.
    same = np.all(np.diff(T, axis=0) == 0, axis=1)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], same.astype(np.int8), [0]])))
    return [
        _stuck_fault(
            log, first, last, "tracker repeats its pose", "it lost its target and republished the last pose"
        )
        for first, last in zip(edges[::2], edges[1::2])
        if last - first + 1 >= MIN_STUCK and np.mean(moving[first:last]) >= 0.5
    ]


def frozen_increments(
    log: Log, sensor: Sensor, kinds: Mapping[str, EncoderKind], signal: Signal | None = None
) -> list[Fault]:
    """A reference of its own increments that froze: :func:`stuck_tracker`'s rule on its increments.
    A run of increments that follow on (each from the stamp the one before ended at) and read no
    motion at all (``sensor.motion_of``: exactly zero), over :data:`~nlp_calib.analysis.streams.MIN_STUCK`
    of its stamps or more, while the wheels turn over most of the records they span: its poses
    repeat the run's first. A robot standing still reads zero too, and its wheels say so; a
    reference that moves by steps (zero increments between slower updates) is not judged; one
    whose increments cannot show it (``motion_of`` None: a gyro's) neither. One fault per run
    (``signal``: the poses' jump signal, which increments do not judge by)."""
    inc, moving = log.motions, _counters_turning(log, kinds)
    motion = None if inc is None or moving is None else sensor.motion_of(inc.z)
    if inc is None or moving is None or motion is None:
        return []
    own = np.flatnonzero(~np.isnan(motion[:, 0]))
    own = own[np.argsort(inc.first[own], kind="stable")]
    travel = np.concatenate([[0.0], np.cumsum(motion[own, 0])])
    if own.size < MIN_STUCK or moves_by_steps(travel):
        return []
    a, b = inc.first[own], inc.last[own]
    # A run goes on while the next increment is still and starts where this one ended.
    still = np.all(motion[own] == 0, axis=1)
    joined = np.concatenate([[False], still[1:] & still[:-1] & (a[1:] == b[:-1])])
    # Each run from its first still increment (none joined before it) to its last (none after).
    starts = np.flatnonzero(still & ~joined)
    ends = np.flatnonzero(still & ~np.concatenate([joined[1:], [False]]))
    found = []
    for k, j in zip(starts, ends):
        first, last = int(a[k]), int(b[j])
        if j - k + 2 >= MIN_STUCK and np.mean(moving[first:last]) >= 0.5:
            why = f"its {j - k + 1} increments read no motion at all, as a frozen reference republishes"
            found.append(_stuck_fault(log, first, last, "reference holds its pose", why))
    return found


def _match_fault(
    log: Log, k: int, size: tuple[float, float, float], why: str, kind: str = "bad_match"
) -> Fault:
    """Increment ``k`` of ``log`` as a bad match (or ``kind``)."""
    inc = log.motions
    assert inc is not None
    a, b, line = int(inc.first[k]), int(inc.last[k]), int(inc.line_numbers[k])
    evidence = f"the increment of {log.where(line)} (records {a}-{b}) {why}"
    return Fault(kind, None, a, b - 1, a, float(log.time_s[a]), line, *size, evidence)


def match_faults(log: Log) -> list[Fault]:
    """RelativeMotions whose matcher said they are poor (see the module docstring), from the quality
    the log keeps of each: ``converged`` (0 or 1), ``inliers`` (the share of points matched) and
    ``fit_error`` (the match's cost per matched point, in the matcher's own units), as far as the log
    has them."""
    inc = log.motions
    if inc is None:
        return []
    q, why = inc.quality, [""] * inc.n
    checks = []
    if "converged" in q:
        checks.append((q["converged"] < 0.5, lambda k: "did not converge in its matcher"))
    if "inliers" in q and np.median(q["inliers"]) > 0:
        floor = MATCH_INLIERS * float(np.median(q["inliers"]))
        checks.append(
            (
                q["inliers"] < floor,
                lambda k: (
                    f"matched {q['inliers'][k]:.2f} of its points (the log's median "
                    f"{floor / MATCH_INLIERS:.2f})"
                ),
            )
        )
    if "fit_error" in q and np.median(q["fit_error"]) > 0:
        ceiling = MATCH_ERROR * float(np.median(q["fit_error"]))
        checks.append(
            (
                q["fit_error"] > ceiling,
                lambda k: (
                    f"fits its points at a cost of {q['fit_error'][k]:.3g} a point (the log's median "
                    f"{ceiling / MATCH_ERROR:.3g})"
                ),
            )
        )
    for bad, words in checks:
        for k in np.flatnonzero(bad):
            why[k] = f"{why[k]}; " if why[k] else ""
            why[k] += words(int(k))
    nan = float("nan")
    return [
        _match_fault(log, k, (nan, nan, nan), f"is poor by its matcher's word: {w}")
        for k, w in enumerate(why)
        if w
    ]


def increment_faults(
    fns: ProblemFunctions,
    params: np.ndarray,
    log: Log,
    steering_sample: str,
    known: Sequence[Fault],
    lag: float | tuple[float, float] = 0.0,
) -> list[Fault]:
    """Increments that disagree with the wheels at ``params`` by more than :data:`MATCH_SCATTER`
    robust σ of the others' scatter (``known``: faults already found, whose increments are
    neither judged nor counted in the scatter), the wheels read at the reference's ``lag`` (s, or a
    range to fit it in: :func:`_screen_lag`). A wheel's wrong reading over one increment looks the
    same (its rotation can always be taken up by one wheel): such an increment is named a bad
    match too, and left out all the same."""
    inc = log.motions
    if inc is None or inc.n == 0:
        return []
    p = np.ravel(np.asarray(params, dtype=float))
    screened, _ = fns.sensor.screened(inc.z)
    judged = np.array(screened, dtype=bool)
    for f in known:
        judged &= (inc.last - 1 < f.first) | (inc.first > f.last)
    if judged.sum() < 10:
        return []
    at = _IncrementsAt(fns, p, log, steering_sample, Resampler(log, fns.model.encoder_kinds))
    lag_s = _screen_lag(at, judged, lag)
    error, unit, travel, turned, arc, valid = at(lag_s)
    judged &= (inc.first >= valid[0]) & (inc.last < valid[1])
    centre, spread = robust_spread(error[judged])
    if judged.sum() < 10 or not np.all(spread > 0):
        return []  # no scatter to judge by (a noise-free simulation)
    # A pivot: the base turns more than it travels (a gyro's steps hold no travel: never one).
    pivot = (travel[inc.last] - travel[inc.first] < PIVOT_RADIUS_M * turned) & (unit[0] == "m")
    # Beyond the scatter by more than the wheels' own readings can move it (a slow driver's).
    reach = at.reach(lag_s, error)
    beyond = np.maximum(np.abs(error - centre) - reach, 0.0)
    score = np.max(beyond / spread, axis=1)
    missed = np.max(np.abs(arc) / spread, axis=1)
    found = []
    for k in np.flatnonzero(judged & ((score > MATCH_SCATTER) | (missed > MATCH_SCATTER))):
        if score[k] > MATCH_SCATTER:
            kind, e, by = PIVOT_SLIP if pivot[k] else "bad_match", error[k], score[k]
        else:
            kind, e, by = COARSE_ARC, arc[k], missed[k]
        size = (
            float(np.hypot(e[0], e[1])),
            float(e[-1] if len(e) == 3 else np.linalg.norm(e[3:])),
            float(by),
        )
        found.append(_match_fault(log, int(k), size, _words(kind, e, unit, by, turned[k]), kind))
    return found


def _words(kind: str, e: np.ndarray, unit: tuple[str, ...], by: float, turned: float) -> str:
    """Why increment faults of ``kind`` are one: its disagreement ``e`` (``by`` robust σ)."""
    amounts = ", ".join(f"{v:+.4f} {u}" for v, u in zip(e, unit))
    if kind == COARSE_ARC:
        return (
            f"agrees with the wheels over their own samples, but the model's one arc per interval misses "
            f"their motion by ({amounts}), {by:.0f}× the increments' robust scatter: the drive changed "
            "inside it (a pivot's start or stop), which the fit cannot follow at the records' spacing; "
            "left out of the fit and of the noise model (odometry integrated at the joints' rate has no "
            "such error)"
        )
    why = f"disagrees with the wheels by ({amounts}), {by:.0f}× the increments' robust scatter"
    if kind == PIVOT_SLIP:
        why += (
            f", over a pivot turn ({turned:.2f} rad on the spot): slip on the ground the calibration "
            "leaves out, as it does every pivot the wheels disagree with (the noise model keeps it: "
            "the robot's odometry meets it)"
        )
    return why


#: The screen's lag is fitted by this many Gauss-Newton steps on the increments' disagreement,
#: its change with the lag from the encoders read this much (s) either side.
SCREEN_LAG_STEPS = 3
SCREEN_LAG_STEP_S = 0.01


@dataclass(frozen=True)
class _IncrementsAt:
    """The reference's increments against the wheels at ``params``, the encoders re-sampled at a
    lag: the disagreement, its units, the base's travel and turn (:func:`_disagreement`), the
    model's own miss over each increment (its one arc per interval against the wheels composed
    over their own samples, :meth:`~nlp_calib.logs.log.Log.at_joint_samples`; zero where the joints
    stream no finer than the records) and the records whose re-sampled readings lie inside the log.
    One ``resampler`` of the log serves every lag the screen's search tries (what does not depend
    on the lag computed once)."""

    fns: ProblemFunctions
    params: np.ndarray
    log: Log
    steering_sample: str
    resampler: Resampler

    def __call__(
        self, lag_s: float
    ) -> tuple[np.ndarray, tuple[str, ...], np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]:
        inc = self.log.motions
        assert inc is not None
        shifted, valid = self.resampler.at(lag_s)
        _, z = self.fns.sensor.screened(inc.z)
        coarse = self._steps(shifted)
        fine, at = shifted.at_joint_samples()
        if at is None or z.shape[1] != 3:
            error, unit, travel, turned = _disagreement(inc, z, coarse[:, : z.shape[1]])
            return error, unit, travel, turned, np.zeros_like(error), valid
        steps = self._steps(fine)
        prefix = poses.accumulate(np.zeros(3), steps[:, :3])
        travel = np.concatenate([[0.0], np.cumsum(np.abs(steps[:, 0]))])[at]
        error, unit, _, turned = _disagreement(inc, z, poses.between(prefix[at[:-1]], prefix[at[1:]]))
        # The fine motion over each increment against the model's one arc per interval.
        own = poses.between(prefix[at[inc.first]], prefix[at[inc.last]])
        arc = _disagreement(inc, own, coarse[:, :3])[0]
        return error, unit, travel, turned, arc, valid

    def reach(self, lag_s: float, error: np.ndarray) -> np.ndarray:
        """How far each increment's disagreement ``error`` (at ``lag_s``) moves with the wheels read
        anywhere within their readings' spread at the records (:meth:`JointStream.reading_spread`:
        a slow driver's updates leave a pivot's start between two of them), each joint either way,
        the records of even and of odd index apart (one end of a chained increment at a time), the
        path bent as a straight run between two updates misses it (a tent one update period wide);
        zero without a joint stream finer than the records."""
        inc = self.log.motions
        assert inc is not None
        fine, at = self.resampler.at(lag_s)[0].at_joint_samples()
        stream, q = fine.joint_stream, fine.joint_positions
        _, z = self.fns.sensor.screened(inc.z)
        reach = np.zeros_like(error)
        if at is None or stream is None or q is None or z.shape[1] != 3:
            return reach
        read = fine.read_times()
        # The records and the joints' own readings between them: where a straight run between two
        # updates starts or ends.
        own = np.flatnonzero(np.isin(read, np.asarray(stream.time_s)[_fresh_any(stream)]))
        centres = np.union1d(at, own)
        spread, period = stream.reading_spread(read[centres]), stream.updates_s()
        for parity, signs in itertools.product((0, 1), itertools.product((-1.0, 1.0), repeat=q.shape[1])):
            bent = _tents(read, read[centres[parity::2]], spread[parity::2], period)
            steps = self._steps(replace(fine, joint_positions=frozen(q + bent * np.array(signs))))
            prefix = poses.accumulate(np.zeros(3), steps[:, :3])
            other = _disagreement(inc, z, poses.between(prefix[at[:-1]], prefix[at[1:]]))[0]
            reach = np.maximum(reach, np.abs(other - error))
        return reach

    def _steps(self, log: Log) -> np.ndarray:
        """The model's motion over each interval of ``log`` at the params, one row each."""
        inputs = self.fns.model.inputs(log, self.steering_sample)
        return np.asarray(over_columns(self.fns.predict, self.params, inputs)[0].T)


def _fresh_any(stream: JointStream) -> np.ndarray:
    """Which of the stream's messages hold a reading of their own for some joint."""
    return np.ones(stream.time_s.size, dtype=bool) if stream.fresh is None else np.any(stream.fresh, axis=1)


def _tents(t: np.ndarray, centres: np.ndarray, height: np.ndarray, width: np.ndarray) -> np.ndarray:
    """At times ``t``, per joint, tents of ``height`` ``(c, joints)`` at ``centres`` (increasing,
    at least two ``width`` apart, so none overlap), each ``width`` (per joint) either side."""
    out = np.zeros((t.size, height.shape[1]))
    if centres.size == 0:
        return out
    k = np.clip(np.searchsorted(centres, t), 1, max(centres.size - 1, 1))
    for side in (k - 1, np.minimum(k, centres.size - 1)):
        near = np.abs(t - centres[side])[:, None]
        out = np.maximum(out, np.clip(1.0 - near / np.maximum(width, 1e-9), 0.0, None) * height[side])
    return out


def _screen_lag(at: _IncrementsAt, judged: np.ndarray, lag: float | tuple[float, float]) -> float:
    """``lag`` when given, else the lag in its range that best explains the ``judged`` increments'
    disagreement with the wheels: Gauss-Newton steps on its change with the lag (a central
    difference, :data:`SCREEN_LAG_STEPS` of them), each column in units of its robust scatter,
    the increments beyond :data:`MATCH_SCATTER` left out. Judged at the stamps as logged, a sound
    scan match where the turn rate changes fast disagrees by the lag's share (12 ms late over a
    jump of 0.15 rad/s: 1.8 mrad, 6× a matcher's scatter)."""
    if not isinstance(lag, tuple):
        return float(lag)
    lo, hi = lag
    h = min(SCREEN_LAG_STEP_S, 0.5 * (hi - lo))
    inc = at.log.motions
    assert inc is not None
    tau = float(np.clip(0.0, lo, hi))
    keep = judged.copy()
    for _ in range(SCREEN_LAG_STEPS):
        (error, *_, v0), (ahead, *_, v1), (behind, *_, v2) = at(tau), at(tau + h), at(tau - h)
        keep &= (inc.first >= max(v0[0], v1[0], v2[0])) & (inc.last < min(v0[1], v1[1], v2[1]))
        centre, spread = robust_spread(error[keep]) if keep.sum() >= 10 else (0.0, np.zeros(1))
        if not np.all(spread > 0):
            return tau
        a, b = (ahead - behind) / (2 * h) / spread, (error - centre) / spread
        step = 0.0
        for _ in range(2):  # the step on every increment, then without those beyond it
            denominator = float(np.sum(a[keep] ** 2))
            if denominator <= 0:
                return tau
            step = -float(np.sum(a[keep] * b[keep])) / denominator
            keep &= np.all(np.abs(b + step * a) <= MATCH_SCATTER, axis=1)
        tau = float(np.clip(tau + step, lo, hi))
        keep = judged.copy()
    return tau


def _disagreement(
    inc: RelativeMotions, z: np.ndarray, steps: np.ndarray
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray, np.ndarray]:
    """Each increment ``z`` against the wheels' predicted ``steps`` over it: the disagreement (its
    rows and their units), and the base's travel to each record and its turn over each increment."""
    if z.shape[1] == 3:
        prefix = poses.accumulate(np.zeros(3), steps)
        error = poses.between(z, poses.between(prefix[inc.first], prefix[inc.last]))
        travel = np.concatenate([[0.0], np.cumsum(np.abs(steps[:, 0]))])
        return error, ("m", "m", "rad"), travel, np.abs(prefix[inc.last, 2] - prefix[inc.first, 2])
    if z.shape[1] == 7:  # a camera's 3-D motions: translation, then the rotation vector
        prefix = poses3d.accumulate(np.array([0.0, 0, 0, 0, 0, 0, 1]), steps)
        d = poses3d.between(z, poses3d.between(prefix[inc.first], prefix[inc.last]))
        error = np.hstack([d[:, :3], poses3d.quat_to_rotvec(d[:, 3:])])
        moved = poses3d.between(prefix[inc.first], prefix[inc.last])
        travel = np.concatenate([[0.0], np.cumsum(np.linalg.norm(steps[:, :3], axis=1))])
        turned = np.linalg.norm(poses3d.quat_to_rotvec(moved[:, 3:]), axis=1)
        return error, ("m", "m", "m", "rad", "rad", "rad"), travel, turned
    # A gyro's integrated rates add up (its bias, the same over each interval, is the centre's).
    prefix = np.vstack([np.zeros((1, steps.shape[1])), np.cumsum(steps, axis=0)])
    error = (z - (prefix[inc.last] - prefix[inc.first]))[:, :3]
    travel = np.zeros(steps.shape[0] + 1)
    return error, ("rad", "rad", "rad"), travel, np.abs(prefix[inc.last, 2] - prefix[inc.first, 2])


def _messages(log: Log, r: Readings, lo: int, hi: int) -> str:
    """Where a joint stream's glitch lands: the records (and lines) its messages reach."""
    lines = log.line_numbers
    span = f"record {lo}" if hi - lo == 1 else f"records {lo}-{hi - 1}"
    return f"{span} ({log.where(lines[lo], lines[hi - 1])})"


def _stuck(log: Log, r: Readings, moving: np.ndarray | None) -> tuple[list[Fault], np.ndarray]:
    """An absolute encoder's readings that held while the robot moved, then caught up at once;
    and which readings are left to judge for spikes."""
    name, lines, t, y = r.name, log.line_numbers, r.t, r.values
    usable = np.ones(y.size, dtype=bool)
    found = []
    for first, last, jump in stuck_runs(t, y, STUCK_FLOOR_STEPS * r.step, moving):
        usable[first + 1 : last + 1] = False
        lo, hi = r.records_of(first + 1, last)
        if hi <= lo:
            continue  # between two records: no record read it
        if r.records is None:
            evidence = (
                f"{name!r} holds {r.shown(y[first])} over records {first}-{last} "
                f"({log.where(lines[first], lines[last])}) while the robot moves, then jumps by "
                f"{r.shown(jump, True)} at record {last + 1}: the reading was stuck"
            )
        else:
            evidence = (
                f"{name!r} holds {r.shown(y[first])} over {last - first + 1} messages from {t[first]:.3f} s "
                f"while the robot moves, then jumps by {r.shown(jump, True)}: the reading was stuck "
                f"({_messages(log, r, lo, hi)})"
            )
        k = first + 1
        implied = y[first] + jump * (t[k] - t[first]) / max(t[last + 1] - t[first], 1e-9)
        size = (float(y[k]), float(implied), r.step)
        found.append(_fault(log, "steering_stuck", name, (lo - 1, hi - 1), lo, size, evidence))
    return found, usable


def _spikes(log: Log, r: Readings, usable: np.ndarray) -> list[Fault]:
    """An absolute encoder's readings that leave the span of their neighbours for one reading."""
    lines, t, y = log.line_numbers, r.t, r.values
    sc = scatter(t, y, r.step)
    found = []
    for g in off_neighbours(t, y, sc, usable, excursion=SPIKE_MIN_ANGLE * r.per_radian, max_group=1):
        k, off = g.first, float(g.offset[0])
        lo, hi = r.records_of(k, k)
        if hi <= lo:
            continue
        if r.records is None:
            evidence = (
                f"{r.name!r} reads {r.shown(y[k])} at record {k} ({log.where(lines[k])}), "
                f"{r.shown(off, True)} off the line between its neighbours, which agree with each other: "
                "a one-record spike"
            )
        else:
            evidence = (
                f"{r.name!r} reads {r.shown(y[k])} in its message at {t[k]:.3f} s, {r.shown(off, True)} "
                "off the line between its neighbours, which agree with each other: a one-message spike "
                f"({_messages(log, r, lo, hi)})"
            )
        size = (float(y[k]), float(y[k] - off), float(sc.floor[0]))
        found.append(_fault(log, "steering_spike", r.name, (lo - 1, hi - 1), lo, size, evidence))
    return found


def absolute_faults(log: Log, kinds: Mapping[str, EncoderKind]) -> list[Fault]:
    """Stuck readings (judged while the robot moves: a counter's increment) and one-reading spikes
    of the log's absolute encoders (a joint in radians: on its own stream)."""
    names = log.header.encoder_names
    moving = turning(log, [n for n in names if kinds.get(n) == "counter"])
    found = []
    for name in (n for n in names if kinds.get(n) == "absolute"):
        r = readings(log, name)
        stuck, usable = _stuck(log, r, moving)
        found += stuck + _spikes(log, r, usable)
    return found


def cleaned(log: Log, faults: Sequence[Fault]) -> Log:
    """``log`` with the tracker's and the absolute encoders' glitches interpolated over (in time,
    from the readings around them), and its bad matches dropped, so that they mislead no
    judgement of another stream."""
    out = log
    inc = log.motions
    matches = [f for f in faults if f.kind in MATCH_KINDS]
    if inc is not None and matches:
        keep = np.ones(inc.n, dtype=bool)
        for f in matches:
            keep &= ~((inc.first == f.first) & (inc.last == f.last + 1))
        kept = inc.take(keep)
        out = replace(
            out,
            reference=replace(out.reference, motions=kept),
            T_world_sensor=frozen(kept.chain(log.n_records)),
        )
    bad_pose = np.zeros(log.n_records, dtype=bool)
    for f in faults:
        if f.kind == TRACKER_STUCK:
            bad_pose[f.first + 1 : f.last + 2] = True
        elif f.kind in TRACKER_KINDS:
            bad_pose[f.record] = True
        elif f.kind in ABSOLUTE_KINDS and f.encoder is not None:
            bad = np.zeros(log.n_records, dtype=bool)
            bad[f.first + 1 : f.last + 1] = True
            out = interpolated_over(out, f.encoder, bad)
    return out.with_poses_interpolated(bad_pose)


def _evidence(
    kind: str, name: str, logged: float, implied: float, noise: float, records: str, unit: str
) -> str:
    deficit = implied - logged
    if unit != "ticks":  # joint angles: no counter width to name
        text = (
            f"{name} reads {logged:+.4g} {unit} over {records}; the tracker's motion implies "
            f"{implied:+.4g} ± {noise:.2g}: {deficit:+.4g} {unit} unexplained"
        )
        return text + ("; the joint stood still before the jump" if kind == "stall_then_jump" else "")
    text = (
        f"{name} reads {logged:+.0f} ticks over {records}; the tracker's motion implies "
        f"{implied:+.0f} ± {noise:.0f}: {deficit:+.0f} ticks unexplained"
    )
    wraps = round(deficit / WRAP_16)
    if wraps and abs(deficit - wraps * WRAP_16) < 3.0 * max(noise, 1.0):
        text += f" (= {wraps:+d} × 2^16: a 16-bit counter wrapped)"
    return text + ("; the counter was stale before the jump" if kind == "stall_then_jump" else "")


def counter_faults(
    fns: ProblemFunctions,
    params: np.ndarray,
    log: Log,
    inputs: np.ndarray,
    lag: float | tuple[float, float],
    unjudged: np.ndarray | None = None,
) -> FaultReport:
    """The counter faults of ``log`` (every interval) given calibrated ``params``, the model
    ``inputs`` and the tracker ``lag`` (s, or a range to estimate it in); the intervals
    ``unjudged`` (a mask) are taken as no measurement covers them (a frozen reference's)."""
    N = inputs.shape[1]
    counters = fns.model.counter_rows(log)
    if N == 0:
        return FaultReport(faults=(), stale={}, noise={}, unit=unit_of(log))
    T = tracker_poses(fns, log)
    z = over_columns(fns.between, T[:-1].T, T[1:].T)[0]
    # Intervals no measurement covers: the wheels' own motion, which accuses no counter.
    gap = log.reference.kind.uncovered(log.n_records)
    if unjudged is not None:
        gap = gap | unjudged
    if gap.any():
        z[:, gap] = over_columns(fns.predict, np.ravel(np.asarray(params, dtype=float)), inputs[:, gap])[0]
    e, de_du = over_columns(fns.interval_residual, np.ravel(np.asarray(params, dtype=float)), inputs, z)
    de_du = de_du.reshape(fns.error_rows, N, inputs.shape[0])
    screens, lag_s = screen_counters(e, de_du, inputs, counters, log.time_s, lag)
    lines, unit = log.line_numbers, unit_of(log)
    faults = []
    for name, sc in screens.items():
        for f in sc.findings:
            k = f.last
            records = f"records {f.first}-{k + 1} ({log.where(lines[f.first], lines[k + 1])})"
            why = _evidence(f.kind, f"counter {name!r}", f.logged, f.implied, f.noise, records, unit)
            faults.append(_fault(log, f.kind, name, (f.first, k), k + 1, (f.logged, f.implied, f.noise), why))
    stale = {n: sc.stale for n, sc in screens.items()}
    noise = {n: sc.noise for n, sc in screens.items()}
    return FaultReport(tuple(faults), stale, noise, lag_s=lag_s, unit=unit)


#: Each reference kind's own glitches (:mod:`nlp_calib.logs.reference`): poses off their
#: neighbours, or motions its matcher said are poor (the jump signal given where it is computed
#: already: ``FROZEN`` judges the same one).
JUMPS: dict[str, Callable[[Log, Sensor, Signal | None], list[Fault]]] = {
    Poses.name: tracker_faults,
    Motions.name: lambda log, sensor, signal: match_faults(log),
    # A tracker's increments beside a gyro's: judged as increments (increment_faults), as a
    # scan matcher's are.
    PoseMotions.name: lambda log, sensor, signal: match_faults(log),
}


#: Each reference kind's frozen stretches (``tracker_stuck``): poses repeated exactly, or
#: increments that follow on reading no motion at all, while the wheels turn.
FROZEN: dict[str, Callable[[Log, Sensor, Mapping[str, EncoderKind], Signal | None], list[Fault]]] = {
    Poses.name: stuck_tracker,
    Motions.name: frozen_increments,
    PoseMotions.name: frozen_increments,
}


#: Fits the model leaving out the windows the masks (per interval, per record) spoil; its
#: parameters, or None when the fit does not converge.
Judge = Callable[[np.ndarray, np.ndarray], np.ndarray | None]


def screen(
    fns: ProblemFunctions, log: Log, steering_sample: str, lag: float | tuple[float, float], judge: Judge
) -> FaultReport:
    """Every fault of ``log``: the tracker's and the absolute encoders' glitches from each stream
    alone, then the counters' against a fit (``judge``) that leaves those glitches out, on readings
    with them interpolated over, at the tracker ``lag`` (s, or a range to estimate it in)."""
    model, n = fns.model, log.n_records
    kind = log.reference.kind.name
    # A tracker's poses are judged on one jump signal for its glitches and its frozen stretches.
    signal = fns.sensor.jump_signal(log) if kind == Poses.name else None
    jumps = JUMPS[kind](log, fns.sensor, signal) + FROZEN[kind](log, fns.sensor, model.encoder_kinds, signal)
    glitches = tuple(jumps + absolute_faults(log, model.encoder_kinds))
    report = FaultReport(glitches, {}, {}, unit=unit_of(log))
    params = judge(report.bad_intervals(n - 1), report.bad_records(n))
    if params is None:
        # Judged by a wrong model every interval looks faulty; the solvers will say why.
        why = "the fit that judges the encoders did not converge from the initial guess"
        return replace(report, unchecked=why)
    if log.reference.kind.own_increments:
        # An increment's disagreement is its own unless one wheel's reading explains it. Judged
        # again by a fit without the increments found (slipped pivots, coarse arcs, bad matches
        # pull the first fit's turn law off, by as much as a sound pivot's scatter).
        found = increment_faults(fns, params, log, steering_sample, glitches, lag)
        if found:
            n_int = max(n - 1, 0)
            more = replace(report, faults=glitches + tuple(found))
            again = judge(more.bad_intervals(n_int), more.bad_records(n))
            if again is not None:
                params = again
                found = increment_faults(fns, params, log, steering_sample, glitches, lag)
        glitches += tuple(found)
    clean = cleaned(log, glitches)
    # Over a frozen reference the path is unknown (poses interpolated over a second miss a
    # reversal inside it): the counters are not judged there.
    frozen_at = FaultReport(glitches, {}, {}).frozen_intervals(max(n - 1, 0))
    counters = counter_faults(fns, params, clean, model.inputs(clean, steering_sample), lag, frozen_at)
    faults = tuple(sorted(glitches + counters.faults, key=lambda f: (f.first, f.kind)))
    return replace(counters, faults=faults)


def repair(log: Log, report: FaultReport) -> tuple[Log, tuple[str, ...]]:
    """``log`` with its encoder faults corrected, and one line per change.

    A counter's deficit within 3σ of a multiple of 2¹⁶ ticks is corrected by exactly that multiple
    (a wrapped 16-bit counter); any other by the tracker-implied amount, rounded. The correction is
    added to the reading that shows the fault and to every later one, so the total over the
    fault's stretch becomes right; the stalled readings before it are left as they are. An absolute
    encoder's spike or stuck readings are interpolated from the readings around them. Joints in
    radians have no counter width: their counters take the tracker-implied amount
    (:mod:`nlp_calib.analysis.joint_repair`).
    """
    fixed, changes = repair_joints(log, report) if unit_of(log) == "rad" else _repair_counts(log, report)
    absolute = [f for f in report.faults if f.kind in ABSOLUTE_KINDS]
    for f in absolute:
        what = "spike" if f.kind == "steering_spike" else "stuck readings"
        changes += (
            f"{f.encoder!r} at record {f.record} ({log.where(f.line)}): {what} interpolated from its "
            "neighbours",
        )
    return cleaned(fixed, absolute), changes


def _repair_counts(log: Log, report: FaultReport) -> tuple[Log, tuple[str, ...]]:
    """``log`` with its counters' faults corrected (see :func:`repair`), one line per change."""
    ticks = np.array(log.ticks)  # its own dtype: whole ticks as logged, fractional re-sampled
    changes = []
    for f in report.counter_faults:
        assert f.encoder is not None
        col = log.header.encoder_index(f.encoder)
        deficit = f.implied - f.logged
        wraps = round(deficit / WRAP_16)
        exact = wraps != 0 and abs(deficit - wraps * WRAP_16) < 3.0 * max(f.noise, 1.0)
        correction = wraps * WRAP_16 if exact else round(deficit)
        before = int(wrapped_difference(ticks[f.record - 1 : f.record + 1, col])[0])
        ticks[f.record :, col] = np.mod(ticks[f.record :, col] + correction, COUNTER_MODULUS)
        how = f"{wraps:+d} × 2^16" if exact else "the tracker-implied amount"
        changes.append(
            f"counter {f.encoder!r} at record {f.record} ({log.where(f.line)}): increment {before:+d} → "
            f"{before + correction:+d} ticks ({how}; the tracker's motion implied "
            f"{f.implied - f.logged:+.0f} ± {f.noise:.0f} more over records {f.first}-{f.record})"
        )
    return replace(log, ticks=frozen(ticks)), tuple(changes)
