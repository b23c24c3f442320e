"""Faults found in a log: stretches of data no calibration can explain, and what was done with them.

:mod:`nlp_calib.analysis.faults` finds them; these records say where they are, how large, the
evidence in words, and how the fit handled them.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

COUNTER_KINDS = ("stall_then_jump", "reversal", "counter_jump")
ABSOLUTE_KINDS = ("steering_spike", "steering_stuck")
#: ``tracker_stuck``: the tracker repeats its last pose over records while the wheels turn (it lost
#: its target and republished the pose): the poses after the first are wrong, no window may start or
#: end at them.
TRACKER_STUCK = "tracker_stuck"
TRACKER_KINDS = ("tracker_jump", TRACKER_STUCK)
#: A measured increment (a scan match) that is wrong: its matcher said so, or the wheels disagree
#: with it far beyond the increments' scatter; ``pivot_slip``: such an increment over which the
#: base pivoted (turned more than it travelled, see ``PIVOT_RADIUS_M``), where the ground lets a
#: skid-steer slip as no calibration holds. Its own window is left out, no other.
#: An increment over a pivot the wheels disagree with (the ground slipped).
PIVOT_SLIP = "pivot_slip"
#: An increment the wheels agree with over their own samples, but whose model motion, one arc per
#: interval between the records, misses theirs: the drive changed inside it (a pivot's start or
#: stop inside a scan matcher's 2 s), which the fit's model cannot follow at the records' spacing.
COARSE_ARC = "coarse_arc"
MATCH_KINDS = ("bad_match", PIVOT_SLIP, COARSE_ARC)
#: The faults of the ground, not of any stream: the robot's own odometry meets them, so the drift
#: the noise model states holds them (the fit leaves their windows out all the same).
GROUND_KINDS = (PIVOT_SLIP,)
#: The faults of the reference itself: its poses or increments are wrong (a chain breaks there).
REFERENCE_KINDS = (*TRACKER_KINDS, "bad_match")
#: An increment whose turn radius (its travel over its turn, as the wheels give them at the fit)
#: is under this (m) is a pivot turn.
PIVOT_RADIUS_M = 0.5


@dataclass(frozen=True)
class Fault:
    """A stretch of intervals ``first..last`` (interval k joins records k and k+1) whose data are wrong.

    ``record`` is the record whose reading shows the fault (for a tracker jump: the bad pose; for
    a stuck reading: its first repeat); ``logged`` and ``implied`` are the encoder's total
    increment over the stretch as logged and as the tracker's motion implies (for an absolute
    encoder: its reading and the one its neighbours imply), ``noise`` the 1σ of ``implied``
    (ticks; for a tracker jump: 0, the pose's position error and the tracker's noise, in m; for
    a bad match: its disagreement with the wheels in m and rad, and in the increments' robust
    scatter, or NaN where its matcher's own word condemned it).
    """

    kind: str
    encoder: str | None
    first: int
    last: int
    record: int
    time_s: float
    line: int
    logged: float
    implied: float
    noise: float
    evidence: str

    def as_dict(self, unit: str = "ticks") -> dict[str, object]:
        """The fault as JSON types; an encoder's sizes in ``unit`` (``ticks``; ``rad`` for joints)."""
        where = {
            "kind": self.kind,
            "encoder": self.encoder,
            "record": self.record,
            "line": self.line,
            "time_s": self.time_s,
            "intervals": [self.first, self.last],
        }
        if self.kind in TRACKER_KINDS:
            size = {"offset_m": self.implied, "noise_m": self.noise}
        elif self.kind in MATCH_KINDS:
            size = {"error_m": self.logged, "error_rad": self.implied, "in_scatter": self.noise}
        else:
            size = {
                f"logged_{unit}": self.logged,
                f"implied_{unit}": self.implied,
                f"noise_{unit}": self.noise,
            }
        return {**where, **size, "evidence": self.evidence}


def count_kinds(faults: Sequence[Fault]) -> str:
    """``"4 stall_then_jump, 11 tracker_jump"``: how many faults of each kind, in order of appearance."""
    return ", ".join(f"{n} {k}" for k, n in Counter(f.kind for f in faults).items())


@dataclass(frozen=True)
class FaultReport:
    """The faults found in a log, and the harmless stale readings counted per encoder.

    ``lag_s`` is the tracker lag the counters were judged at (the scenario's, or the screen's own
    estimate when the lag is to be estimated; None when they were not judged).
    """

    faults: tuple[Fault, ...]
    stale: Mapping[str, int]
    noise: Mapping[str, float]
    #: Why the log's counters could not be checked ("" when they were).
    unchecked: str = ""
    lag_s: float | None = None
    #: What the encoders' sizes and ``noise`` (each counter's 1σ per interval) are in: ``ticks``,
    #: or ``rad`` for joints in radians.
    unit: str = "ticks"

    def shifted(self, offset: int, line_numbers: np.ndarray) -> FaultReport:
        """The same findings with record and interval indices moved by ``offset``; ``line_numbers``
        are the log lines of the records the indices then refer to."""
        moved = tuple(
            replace(
                f,
                first=f.first + offset,
                last=f.last + offset,
                record=f.record + offset,
                line=int(line_numbers[f.record + offset]),
            )
            for f in self.faults
        )
        return replace(self, faults=moved)

    @property
    def counter_faults(self) -> tuple[Fault, ...]:
        return tuple(f for f in self.faults if f.kind in COUNTER_KINDS)

    @property
    def encoder_faults(self) -> tuple[Fault, ...]:
        """The counters' and the absolute encoders' faults (all but the reference's)."""
        return tuple(f for f in self.faults if f.kind not in (*TRACKER_KINDS, *MATCH_KINDS))

    @property
    def reference_faults(self) -> tuple[Fault, ...]:
        """The reference's own faults: tracker jumps and bad matches (a slipped pivot's or a coarse
        arc's increment is sound: the wheels or the model miss it)."""
        return tuple(f for f in self.faults if f.kind in REFERENCE_KINDS)

    @property
    def unrepaired(self) -> tuple[Fault, ...]:
        """The faults a repair leaves: all but the encoders' (whose readings it corrects)."""
        return tuple(f for f in self.faults if f.kind in (*TRACKER_KINDS, *MATCH_KINDS))

    def apart(self, kinds: Sequence[str]) -> FaultReport:
        """The report without the faults of ``kinds``."""
        return replace(self, faults=tuple(f for f in self.faults if f.kind not in kinds))

    def bad_intervals(self, n_intervals: int) -> np.ndarray:
        """Mask of intervals a residual window must not cross (encoder faults, bad matches)."""
        mask = np.zeros(n_intervals, dtype=bool)
        for f in self.faults:
            if f.kind in TRACKER_KINDS:
                continue
            mask[max(f.first, 0) : min(f.last + 1, n_intervals)] = True
        return mask

    def frozen_intervals(self, n_intervals: int) -> np.ndarray:
        """Mask of the intervals a frozen reference's repeated poses bound (``tracker_stuck``: its
        run, and the interval after, from its last repeat): a chain of increments breaks there."""
        mask = np.zeros(n_intervals, dtype=bool)
        for f in self.faults:
            if f.kind == TRACKER_STUCK:
                mask[max(f.first, 0) : min(f.last + 2, n_intervals)] = True
        return mask

    def bad_records(self, n_records: int) -> np.ndarray:
        """Mask of records a residual window must not start or end at (tracker jumps, and every pose
        a stuck tracker repeated)."""
        mask = np.zeros(n_records, dtype=bool)
        for f in self.faults:
            if f.kind == TRACKER_STUCK:
                mask[max(f.first + 1, 0) : min(f.last + 2, n_records)] = True
            elif f.kind in TRACKER_KINDS and 0 <= f.record < n_records:
                mask[f.record] = True
        return mask


@dataclass(frozen=True)
class Findings:
    """The faults found in the used records, how they were handled and what a repair changed."""

    report: FaultReport
    handling: str
    repairs: tuple[str, ...] = ()
