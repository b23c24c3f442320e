"""What a pre-flight check found before any fit, and the plan of what to drive next.

The pre-flight (``nlp-calib preflight``, and the start of every calibrating command) reads a
recording and says what it holds, how the drive excites the robot, what the data imply of units
and signs, and for each parameter whether the drive determines it, from the problem's Jacobian at
a start (no fit). The plan ranks manoeuvres by how much each, appended to the drive, would lower
the largest σ relative to the precision a useful calibration needs. These records hold the
findings in numbers and words; :mod:`nlp_calib.analysis` computes them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from nlp_calib.results import codec
from nlp_calib.results.checks import UNUSABLE, CheckResult

#: A parameter's standing on a drive.
DETERMINED = "determined"
WEAKLY = "weakly"
NOT_DETERMINED = "not"

#: Why a parameter the run holds at its start is held (a pinned time offset is held where the run's
#: fit settled: its own words).
HELD_AT_START = "it is held at its initial value"

#: The pre-flight's verdicts, from best to worst, and the exit code each gives.
ENOUGH = "enough"
WEAK_DRIVE = "weak"
NOT_ENOUGH = "not enough"
CHECK_DATA = "check the data"
EXIT_CODES = {ENOUGH: 0, WEAK_DRIVE: 3, NOT_ENOUGH: 4, CHECK_DATA: 5}


@dataclass(frozen=True)
class Stream:
    """One stream of a recording (a bag's topic, a file, a text log's records): its messages,
    their median rate, the span of their times (s, on the stream's own clock), the gaps longer
    than a few median intervals and the longest, and what else it says (joints, frames)."""

    name: str
    kind: str
    count: int
    rate_hz: float
    span_s: tuple[float, float]
    gaps: int
    longest_gap_s: float
    note: str = ""


@dataclass(frozen=True)
class Recording:
    """One log as the pre-flight read it: where it comes from, its streams, the records it is
    read as, their duration, the overlap of the joints' and the tracker's clocks (s; None when
    they share one) and notes on its stamps and what was left out."""

    path: str
    source: str
    streams: tuple[Stream, ...]
    records: int
    duration_s: float
    overlap_s: float | None
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Excitation:
    """How a drive excites the robot: distance (the tracker's path), time moving, how far the
    heading ranges and turns each way (rad), the typical turn radii each way (m: the 10th, 50th
    and 90th percentiles of the turning stretches; empty: no turn that way), direction changes of
    travel and the share of driving backwards, and the speeds (m/s)."""

    distance_m: float
    duration_s: float
    moving_fraction: float
    heading_span_rad: float
    turned_left_rad: float
    turned_right_rad: float
    radii_left_m: tuple[float, ...]
    radii_right_m: tuple[float, ...]
    reversals: int
    reverse_fraction: float
    speed_median_mps: float
    speed_max_mps: float


@dataclass(frozen=True)
class UnitFinding:
    """Something the data imply of units or signs (an angle in degrees, a wheel's angle that
    wraps, a wheel that turns backwards as the robot drives forwards), for which encoder, in
    words with the fix; ``blocking``: a calibration from these data cannot succeed as they are."""

    kind: str
    subject: str
    words: str
    blocking: bool = True


@dataclass(frozen=True)
class ParameterStatus:
    """One parameter on this drive: ``status`` (:data:`DETERMINED`, :data:`WEAKLY`,
    :data:`NOT_DETERMINED`), its 1σ (in its unit; inf when nothing holds it), that σ over the
    precision a useful calibration needs (``reference``), the parameters it trades off with and
    why, in words."""

    name: str
    status: str
    std: float
    std_reference: float
    reference: float
    unit: str
    trades_with: tuple[str, ...]
    because: str
    #: Held by the run with no σ: at its initial value (the model says the drive cannot determine it
    #: at all), or a time offset where the run's fit settled (its alignment's estimate pinned).
    held: bool = False

    def words(self) -> str:
        """``wheelbase: not determined, because …``"""
        head = {DETERMINED: "determined", WEAKLY: "weakly determined", NOT_DETERMINED: "not determined"}
        size = ""
        if np.isfinite(self.std) and self.status != DETERMINED:
            size = (
                f" (±{self.std:.2g} {self.unit}, {self.std_reference:.3g}× the {self.reference:.2g} needed)"
            )
        elif self.status == DETERMINED and np.isfinite(self.std):
            size = f" (±{self.std:.2g} {self.unit})"
        why = f", because {self.because}" if self.because else ""
        if self.status == DETERMINED and self.because:  # a caveat, not a cause
            why = f"; {self.because}"
        return f"{self.name}: {head[self.status]}{size}{why}"


@dataclass(frozen=True)
class Manoeuvre:
    """A manoeuvre to drive: its kind, radius (m; 0 for none), speed (m/s) and duration (s), in
    words, the base's path for a sketch (``(n, 3)``, starting at the origin heading along x), and
    what appending it to the drive gives: the largest σ over its reference precision and the plan's
    target parameter's σ (its unit)."""

    kind: str
    radius_m: float
    speed_mps: float
    duration_s: float
    words: str
    path: np.ndarray
    worst_after: float
    target_std_after: float


@dataclass(frozen=True)
class Plan:
    """What to drive next: the parameter whose σ is largest relative to its reference precision
    (``target``) and that ratio and σ on the drive as it is, where the model was evaluated
    (``model_from``: the fit, or the pre-flight's start), and the manoeuvres ranked by the largest
    such ratio once each is appended (best first)."""

    target: str
    target_unit: str
    worst_before: float
    target_std_before: float
    model_from: str
    ranked: tuple[Manoeuvre, ...]
    #: The robot's lengths (m) by name (its wheelbase, its track), for a sketch's scale.
    size_m: Mapping[str, float] = field(default_factory=dict)
    #: The parameters the drive does not determine that no manoeuvre considered determines either
    #: (a car's steering gain against its wheelbase at radii it can drive): only ``known:`` does.
    beyond: tuple[str, ...] = ()

    @property
    def best(self) -> Manoeuvre | None:
        """The first manoeuvre that lowers the target's σ (None: none does)."""
        before = self.target_std_before
        return next((m for m in self.ranked if m.target_std_after < before), None)

    def line(self) -> str:
        """The "next" line: the first manoeuvre and what it would do to the target's σ."""
        best = self.best
        if best is None:
            # model_from is a phrase of its own (the fit, or a start with how it was reached):
            # in parentheses, a sentence around it stays one.
            where = f"the model evaluated at {self.model_from}"
            beyond = f"; {self.beyond_words()}" if self.beyond else ""
            return f"no manoeuvre considered lowers the σ of {self.target} ({where}){beyond}"
        unit = f" {self.target_unit}" if self.target_unit not in ("", "1") else ""
        before, after = self.target_std_before, best.target_std_after
        return (
            f"drive {best.words}: the σ of {self.target} would fall from {_sigma(before)}"
            f"{unit if np.isfinite(before) else ''} to {_sigma(after)}{unit if np.isfinite(after) else ''}"
            + (f"; {self.beyond_words()}" if self.beyond else "")
        )

    def beyond_words(self) -> str:
        """What no manoeuvre of the plan determines (:attr:`beyond`), and what does, in words."""
        names = ", ".join(self.beyond)
        what = "what you know of them" if len(self.beyond) > 1 else "its measured value"
        return f"no manoeuvre considered determines {names}: give {what} under known:"


def _sigma(value: float) -> str:
    return f"{value:.2g}" if np.isfinite(value) else "unbounded"


@dataclass(frozen=True)
class Preflight:
    """A pre-flight check of one scenario's logs: each log as read, the drive's excitation (each
    log's, in order), the unit and sign findings, each free parameter's standing, where the
    Jacobian was taken (``start``) and the tracker noise it assumed (its words), the plan (when a
    parameter is not determined well enough), the way out in words and the time it took (s)."""

    scenario: str
    model: str
    recordings: tuple[Recording, ...]
    excitation: tuple[Excitation, ...]
    #: What each of the pre-flight's plug-in checks found (``units``: the units and signs).
    checks: tuple[CheckResult, ...]
    parameters: tuple[ParameterStatus, ...]
    start: str
    noise: str
    plan: Plan | None
    way_out: str
    time_s: float

    @property
    def verdict(self) -> str:
        """:data:`CHECK_DATA` (a blocking unit or sign finding), :data:`NOT_ENOUGH` (a parameter
        not determined that the run would fit: its verdict would be NOT DETERMINED),
        :data:`WEAK_DRIVE` (one weakly, or one the run holds at its start: a caveat of its verdict)
        or :data:`ENOUGH`."""
        if self.blocking():
            return CHECK_DATA
        if self.missing():
            return NOT_ENOUGH
        return WEAK_DRIVE if self.named(WEAKLY) or self.named(NOT_DETERMINED) else ENOUGH

    def check(self, name: str) -> CheckResult | None:
        """The result of the pre-flight's plug-in check ``name``, when it ran."""
        return next((r for r in self.checks if r.name == name), None)

    @property
    def units(self) -> tuple[UnitFinding, ...]:
        """The unit and sign findings (the ``units`` check's record)."""
        found = self.check("units")
        return () if found is None else tuple(codec.load(UnitFinding, f) for f in found.record)

    def blocking(self) -> list[str]:
        """Why the data stop a calibration before any fit: each unusable check's reasons."""
        return [reason for r in self.checks if r.level == UNUSABLE for reason in r.reasons]

    def missing(self) -> list[ParameterStatus]:
        """The parameters not determined that the run would fit (not those it holds)."""
        return [p for p in self.parameters if p.status == NOT_DETERMINED and not p.held]

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]

    def named(self, status: str) -> tuple[str, ...]:
        """The parameters of ``status``."""
        return tuple(p.name for p in self.parameters if p.status == status)

    def stop_words(self) -> str:
        """Why a calibration from these data cannot succeed, in one line ("" when it can)."""
        blocking = self.blocking()
        if blocking:
            return "; ".join(blocking)
        missing = self.missing()
        if not missing:
            return ""
        plan = f"; plan: {self.plan.line()}" if self.plan is not None and self.plan.best is not None else ""
        why = "; ".join(c for c in _causes(missing) if c)
        because = f" ({why})" if why else ""  # never an empty "()"
        return (
            f"this drive cannot determine {', '.join(p.name for p in missing)}{because}; {self.way_out}{plan}"
        )


def _causes(loose: list[ParameterStatus]) -> list[str]:
    """Why the parameters ``loose`` are not determined, each reason once."""
    out: dict[str, None] = {}
    pairs: set[frozenset[str]] = set()
    for p in loose:
        cause = p.because.split("; ")[0]
        if cause.startswith("it trades off"):
            group = frozenset((p.name, *p.trades_with))
            if group in pairs:
                continue
            pairs.add(group)
            cause = f"{', '.join(sorted(group))} trade off"
        elif cause.startswith("the drive carries no information"):
            cause = f"nothing in the drive shows {p.name}"
        out[cause] = None
    return list(out)
