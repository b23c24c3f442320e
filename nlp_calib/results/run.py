"""A calibration's result: one self-contained record of what a run found, for one log or several.

Everything the outputs show is here, computed by the pipeline's analyse stage: the estimates and
their uncertainty, the fair figures, the checks, the verdict and (when asked for) the series
behind the figures. Nothing refers back to the objects that computed it, so a result read back
from its stored form (:meth:`CalibrationRun.to_data`, :meth:`CalibrationRun.from_data`) writes
the same files.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from nlp_calib.core.errors import UsageError
from nlp_calib.results import codec
from nlp_calib.results.check import DriftCheck
from nlp_calib.results.checks import (
    FINE,
    CheckResult,
    ConsistencyCheck,
    CostComparison,
    CrossValidation,
    DirectionCheck,
    LagEffect,
    LagEstimate,
    NominalCheck,
    Observability,
    PivotSpread,
    TruthCheck,
    believed_std,
    truth_view,
)
from nlp_calib.results.faults import Findings
from nlp_calib.results.figures import TrajectoryMetrics
from nlp_calib.results.handoff import ControllerParams
from nlp_calib.results.layout import CLOCK, FREE, HELD, KNOWN, Layout
from nlp_calib.results.mount import LogMount, SensorMount
from nlp_calib.results.preflight import Excitation, Plan
from nlp_calib.results.series import OdometryTrack, RunSeries
from nlp_calib.results.solver import SolverResult
from nlp_calib.results.uncertainty import Uncertainty


@dataclass(frozen=True)
class SensorInfo:
    """The run's sensor as its plug-in describes itself: ``kind`` (its registry name, as the
    scenario's ``sensor`` gives it), the pose ``group`` it measures in, its poses' ``scale``
    (``fixed``, or ``free`` when known up to scale), its mount's parameters and those the drive
    never determines, held, with why."""

    kind: str = "planar"
    group: str = "SE(2)"
    scale: str = "fixed"
    params: tuple[str, ...] = ("sensor_x", "sensor_y", "sensor_theta")
    held: tuple[str, ...] = ()
    held_why: str = ""
    #: What its parameters mean, in words (an angle convention), where the names do not say it.
    convention: str = ""
    #: Why its track has no position, in words (a gyro measures turning, no length): the figures in
    #: metres (ATE, RPE, the distance travelled) are then left out; "": it measures positions.
    no_position: str = ""

    @property
    def positions(self) -> bool:
        """Whether its track has positions the trajectory figures can compare."""
        return not self.no_position


@dataclass(frozen=True)
class ScenarioInfo:
    """What the outputs say about the scenario: its name and file, the model with its units and
    headline parameters, the log(s), the solvers (in order, with display labels) and the residual
    form and kernel as the scenario set them."""

    name: str
    path: str | None
    model: str
    units: Mapping[str, str]
    #: Every parameter in its block, with its log, unit and status (see :mod:`.layout`).
    layout: Layout
    dataset: str
    datasets: tuple[str, ...]
    #: Each solver's display name, in the scenario's order of solvers.
    labels: Mapping[str, str]
    residual: Mapping[str, Any]
    robust: Mapping[str, Any]
    initial_guess: str
    sensor: SensorInfo = field(default_factory=SensorInfo)

    @property
    def headline(self) -> tuple[str, ...]:
        """The kinematic parameters a one-line summary shows."""
        return self.layout.headline

    def label(self, solver: str) -> str:
        """The display name of ``solver``."""
        return self.labels.get(solver, solver)

    @property
    def solvers(self) -> tuple[str, ...]:
        """The scenario's solvers, in its order."""
        return tuple(self.labels)


@dataclass(frozen=True)
class Encoder:
    """An encoder as the log describes it: its name, kind (``absolute`` or ``counter``), unit,
    range (the header's: an absolute encoder's readings per turn, the unit a counter's gain is
    counted in; 0 when the readings are angles) and a wheel's counts per turn where given."""

    name: str
    kind: str
    unit: str
    range: int
    per_turn: float | None = None


@dataclass(frozen=True)
class DroppedLine:
    """A record left out while reading, with its line (or message) and why."""

    line: int
    reason: str


@dataclass(frozen=True)
class LogInfo:
    """The log as read: its source, records, what was dropped while reading, the sensor's frame,
    the encoders, the stamp of its first record on its own clock (ns; every time in the result is
    relative to it), the duration of the records used (s) and the nominal mount's height, roll and
    pitch where the source gives them (a bag's ``/tf_static``; the planar fit cannot see them)."""

    path: str
    records: int
    dropped: tuple[DroppedLine, ...]
    sensor_frame: str
    encoders: tuple[Encoder, ...]
    start_ns: int
    duration_s: float
    sensor_z_roll_pitch: tuple[float, float, float] | None = None
    #: What its line numbers count: a text file's ``line``, a bag topic's ``/topic message``.
    numbered: str = "line"
    #: What reading it and the run's stages warned of as they ran (each warning's text, as shown):
    #: beside the run's notes in :meth:`CalibrationRun.every_warning`.
    said: tuple[str, ...] = ()


@dataclass(frozen=True)
class DataInfo:
    """What of the log the fit used: record ranges ``used`` and ``fit`` (the hold-out follows),
    the residual windows fitted and left out, and the tracker lag applied."""

    used: tuple[int, int]
    fit: tuple[int, int]
    n_residuals: int
    dropped_stationary: int
    dropped_faulty: int
    tracker_lag_s: float
    lag_estimate: LagEstimate | None
    #: A 3-D sensor's closed-form start: the windows it left out, by reason (None: not a camera's).
    start_dropped: Mapping[str, int] | None = None
    #: ... and the fitted windows left out by the reasons that also concern the refinement.
    fit_dropped: Mapping[str, int] | None = None
    #: On a joint fit's per-log view: the joint fit's clock offsets held without a σ (any log's,
    #: :meth:`CalibrationRun.pinned`), which the view's σ, the joint's, leaves out as the joint does.
    pinned: tuple[str, ...] = ()
    #: How the fitted records excite the robot (the pre-flight's reading; several logs' combined),
    #: which the verdict's advice reads (no "turn both ways" to a drive that does).
    excitation: Excitation | None = None
    #: On a joint fit and its per-log views: each log's own time offset by name, with its log's
    #: path and the log's alignment estimate (its return check, whether pinned), which the joint
    #: reads as one log's run reads :attr:`lag_estimate` (empty: one log's run).
    lags: Mapping[str, tuple[str, LagEstimate]] = field(default_factory=dict)


@dataclass(frozen=True)
class Checks:
    """What the run's checks found: observability, blocked cross-validation, the forward/reverse
    comparison, the faults, for several logs fitted together whether each log's own fit agrees
    with theirs, and what each plug-in check found (``more``: the comparison with a stored
    calibration among them, :attr:`drift`); any may be absent when it could not run."""

    observability: Observability | None
    crossval: CrossValidation | None
    direction: DirectionCheck | None
    findings: Findings | None
    consistency: ConsistencyCheck | None = None
    #: What each plug-in check found (its registry name, level, one wording, figures; the
    #: estimate against a simulated log's known truth is one: ``truth``).
    more: tuple[CheckResult, ...] = ()
    #: How each time offset moves the other parameters (see :class:`LagEffect`).
    lag_effects: tuple[LagEffect, ...] = ()
    #: Several logs: the joint fit without each log in turn (its jackknife σ is the logs').
    logs: CrossValidation | None = None
    #: The fit against its starting point, in the objective's own noise.
    start: CostComparison | None = None
    #: The fit against the robot's nominal values (None: no source knows them).
    nominal: NominalCheck | None = None
    #: What to drive next when a parameter is not determined well enough (``plan.md``).
    plan: Plan | None = None
    #: Each pivot of the drive fitted on its own: the σ of a random effect per pivot.
    pivots: PivotSpread | None = None

    def plugin(self, name: str) -> CheckResult | None:
        """The result of the plug-in check ``name``, when it ran and found something to say."""
        return next((r for r in self.more if r.name == name), None)

    @property
    def drift(self) -> DriftCheck | None:
        """A stored calibration against this run's refit (the ``drift`` plug-in; ``nlp-calib check``)."""
        found = self.plugin("drift")
        return None if found is None else codec.load(DriftCheck, found.record)

    @property
    def truth(self) -> TruthCheck | None:
        """The estimate against the known truth of a simulated log (the ``truth`` plug-in)."""
        return truth_view(self.plugin("truth"))

    def spreads(self, white: np.ndarray) -> list[np.ndarray]:
        """Each σ beyond the white-noise one ``white`` that the σ to believe takes in (NaN where one
        has none): the blocks' jackknife where it exceeds ``white`` beyond its own noise
        (:meth:`CrossValidation.beyond`), the pivots' where it does (:meth:`PivotSpread.beyond`),
        then each of :meth:`moving`."""
        n = len(white)
        blocks = self.crossval.beyond(white) if self.crossval is not None else np.full(n, np.nan)
        pivots = self.pivots.beyond(white) if self.pivots is not None else np.full(n, np.nan)
        return [blocks, pivots, *(spread for _, spread in self.moving())]

    def believed(self, u: Uncertainty, slip: bool = True, held: bool = True) -> np.ndarray:
        """The σ to believe of the estimate whose white-noise σ ``u`` gives (see
        :meth:`CalibrationRun.std`; ``slip``: with the shifts the whole drive shares, the slip's
        and, with ``held``, the held values')."""
        base = believed_std(u.std, *u.spreads(), *self.spreads(u.std))
        added = self.shifts(u.names, held) if slip else np.full(len(u.names), np.nan)
        return np.where(np.isfinite(added), np.hypot(base, added), base)

    def slip(self, names: tuple[str, ...]) -> np.ndarray:
        """Each of ``names``' σ of the slip (the ``slip`` plug-in's ``std_slip``: what the drive
        leaves open of a lateral slip the model lacks; NaN where it has none)."""
        return self._record_std("slip", "std_slip", names)

    def held(self, names: tuple[str, ...]) -> np.ndarray:
        """Each of ``names``' σ of the values the fit holds (the ``held`` plug-in's ``std_held``:
        what their plausible errors move it by; NaN where nothing held moves it)."""
        return self._record_std("held", "std_held", names)

    def held_values(self) -> dict[str, float]:
        """The values the fit holds whose plausible errors are in its σ (``std_held``), by name (a
        lag given as a number: ``alignment.tracker_lag``); empty where none is."""
        return {str(n): float(v) for n, v in (self.recorded("held", "held_values") or {}).items()}

    def recorded(self, check: str, key: str) -> Any:
        """What the plug-in check ``check`` recorded under ``key`` (None: nothing)."""
        found = self.plugin(check)
        return (found.record or {}).get(key) if found is not None else None

    def shifts(self, names: tuple[str, ...], held_values: bool = True) -> np.ndarray:
        """The σ of what shifts the whole drive's fit at once, which no spread over the drive
        measures: the slip's and (``held_values``) the held values', in quadrature (NaN where
        neither has one)."""
        slip = self.slip(names)
        held = self.held(names) if held_values else np.full(len(names), np.nan)
        both = np.hypot(np.nan_to_num(slip), np.nan_to_num(held))
        return np.where(np.isfinite(slip) | np.isfinite(held), both, np.nan)

    def _record_std(self, check: str, key: str, names: tuple[str, ...]) -> np.ndarray:
        std = self.recorded(check, key) or {}
        return np.array([np.nan if std.get(n) is None else std[n] for n in names], dtype=float)

    def moving(self) -> list[tuple[str, np.ndarray]]:
        """How much parameters move with the driving, where they do (NaN elsewhere), each with what
        measured it: over several logs, the logs' jackknife for each parameter that moves between
        them beyond their σ; half the forward-reverse difference where it is clear."""
        out = []
        if self.logs is not None and self.consistency is not None:
            label = f"the jackknife over the {len(self.logs.folds)} logs"
            out.append((label, np.where(self.consistency.moved, self.logs.std, np.nan)))
        if self.direction is not None:
            out.append(("half the forward-reverse difference", self.direction.spread()))
        return out


@dataclass(frozen=True)
class SolverReport:
    """One solver's result with its uncertainty and trajectory metrics (full range and hold-out)."""

    result: SolverResult
    uncertainty: Uncertainty
    metrics: TrajectoryMetrics
    holdout: TrajectoryMetrics | None
    #: The estimate in the robot stack's terms (its ros2_control controller's parameters).
    controller: ControllerParams | None = None
    #: The sensor's mount as every hand-off file states it, as the sensor says it (this log's own,
    #: in a fit with a mount per log).
    mount: SensorMount | None = None
    #: A fit with a mount per log: every log's own (one URDF joint each).
    mounts: tuple[LogMount, ...] = ()
    #: The mount of a sensor fitted beside the reference (a gyro's IMU): its own URDF joint.
    beside: SensorMount | None = None
    #: The parameters the fit held rather than estimated, with why (given under ``known:``, held
    #: under ``fixed:``, or held at the guess because the drive cannot determine them).
    held: Mapping[str, str] = field(default_factory=dict)


#: A parameter's standing in the hand-off files (:meth:`CalibrationRun.handoff_status`): live
#: (written as calibrated, with its 1σ), given by the user (written as given, no σ) or not
#: determined well enough to use (never written as calibrated).
LIVE = "live"
GIVEN = "given"
DOUBTFUL = "not determined"

#: The verdict's levels.
GOOD = "good"
CAVEATS = "usable with caveats"
UNDETERMINED = "not determined"
NOT_USABLE = "not usable"


@dataclass(frozen=True)
class Verdict:
    """``level`` (:data:`GOOD`, :data:`CAVEATS`, :data:`NOT_USABLE`, :data:`UNDETERMINED`) and its
    reasons."""

    level: str
    reasons: tuple[str, ...]
    #: False when the estimate must not reach a robot although a solver converged (it cannot be a
    #: real robot of its kind): no hand-off file is written.
    handoff: bool = True
    #: What the calibration gained over the robot's nominal values, or that none are known.
    gain: str = ""
    #: Each parameter a caveat concerns, with that caveat: a hand-off file writes no value resting
    #: on it as if it were calibrated.
    concerns: Mapping[str, str] = field(default_factory=dict)

    def line(self) -> str:
        # A calibration behind the nominal robot has its gain among the reasons already (a caveat).
        gain = (self.gain,) if self.gain and self.gain not in self.reasons else ()
        return f"{self.level.upper()}: " + "; ".join((*self.reasons, *gain))


@dataclass(frozen=True)
class CalibrationRun:
    """Everything a run produced for one log; ``baseline`` scores the initial guess.

    In a calibration from several logs, each log's run carries the joint estimates beside that
    log's own figures.
    """

    scenario: ScenarioInfo
    log: LogInfo
    data: DataInfo
    baseline: TrajectoryMetrics
    baseline_holdout: TrajectoryMetrics | None
    reports: Mapping[str, SolverReport]
    checks: Checks
    warnings: tuple[str, ...]
    verdict: Verdict
    series: RunSeries | None = None
    odometry: OdometryTrack | None = None
    #: A calibration over several logs: each log's run, the joint estimates beside that log's own
    #: figures (this run is the joint fit over every log; empty for one log).
    logs: tuple[CalibrationRun, ...] = ()

    def every_warning(self) -> tuple[str, ...]:
        """Every warning of the run, each once: what its stages said as they ran (reading its log
        first), then its notes (:attr:`warnings`, which the checks and the verdict read)."""
        return tuple(dict.fromkeys((*self.log.said, *self.warnings)))

    def with_said(self, said: Sequence[str]) -> CalibrationRun:
        """This run with ``said`` among what its stages warned of (:attr:`LogInfo.said`)."""
        return replace(self, log=replace(self.log, said=(*self.log.said, *said)))

    @property
    def initial(self) -> dict[str, float]:
        """Where the solvers started, every parameter by name."""
        return self.scenario.layout.starts

    def parts(self) -> list[tuple[CalibrationRun, str]]:
        """Each log's run with the subfolder its files go to (``""``: this run's own folder): for
        one log, this run; for several, each log's under its name, then the joint fit's."""
        if not self.logs:
            return [(self, "")]
        return [*((part, part.scenario.name) for part in self.logs), (self, "")]

    def std(self, solver: str, slip: bool = True, held: bool = True) -> dict[str, float]:
        """The 1σ to believe for ``solver``'s estimate: the largest of the white-noise σ, the block
        cross-validation's jackknife σ and the spreads the checks found (:meth:`Checks.spreads`),
        with the slip's σ and the held values' (:meth:`Checks.shifts`) added in quadrature
        (``slip``: False, without them; ``held``: False, without the held values'). In quadrature:
        each shifts the whole drive's fit at once, an error none of the others measures
        (:meth:`Checks.believed`)."""
        u = self.reports[solver].uncertainty
        std = dict(zip(u.names, map(float, self.checks.believed(u, slip, held))))
        for n, est in self.lag_estimates().items():
            if n in u.names:
                # A lag its fits return to only in part: its white σ over that share, where larger.
                wide = est.returned_std(float(u.std[u.names.index(n)]))
                std[n] = max(std[n], wide) if np.isfinite(wide) else std[n]
        return {n: float("nan") if n in self.pinned() else s for n, s in std.items()}

    def lag_estimates(self) -> dict[str, LagEstimate]:
        """Each time offset's alignment estimate by name: a joint fit's (and its views') each log's
        own (:attr:`DataInfo.lags`), one log's run its one estimate."""
        if self.data.lags:
            return {n: est for n, (_, est) in self.data.lags.items()}
        est = None if self.logs else self.data.lag_estimate
        return {} if est is None else dict.fromkeys(self.scenario.layout.block(CLOCK), est)

    def pinned(self) -> tuple[str, ...]:
        """The time offsets pinned on the edge of their search (the bound's value: the data put
        the lag at or beyond it) or held where no fit at any lag converged: with no σ, the verdict
        naming the log."""
        layout = self.scenario.layout
        if self.data.pinned:
            return self.data.pinned
        if not self.logs:
            est = self.data.lag_estimate
            return layout.block(CLOCK) if est is not None and est.pinned else ()
        return pinned_in(layout, self.logs)

    def std_blocks(self) -> dict[str, float] | None:
        """The jackknife σ of the block cross-validation, when it has enough converged folds."""
        cv = self.checks.crossval
        if cv is None or not cv.available:
            return None
        return cv.std_dict()

    def solver_order(self) -> list[str]:
        """The run's solvers in the scenario's order, then any others in the order they ran."""
        order = [s for s in self.scenario.solvers if s in self.reports]
        return order + [s for s in self.reports if s not in order]

    def chosen_solver(self) -> str | None:
        """ "The" calibration: the first converged solver in :meth:`solver_order`, or None."""
        return next((s for s in self.solver_order() if self.reports[s].result.converged), None)

    def require_series(self) -> RunSeries:
        """The series behind the figures, which a run computes only when asked for them."""
        if self.series is None:
            raise UsageError(f"the result of {self.scenario.name} holds no figure data; run it with --report")
        return self.series

    def relative_difference(self, a: str, b: str) -> float:
        """The largest relative difference between solvers ``a``'s and ``b``'s parameters."""
        pa, pb = self.reports[a].result.params, self.reports[b].result.params
        return float(np.max(np.abs(pa - pb) / np.maximum(np.abs(pa), 1e-12)))

    def handoff_solver(self) -> str | None:
        """The solver whose estimate the hand-off files carry: the chosen one, unless the verdict
        holds the hand-off back or is NOT DETERMINED (no file then carries a value the drive did
        not determine)."""
        if not self.verdict.handoff or self.verdict.level == UNDETERMINED:
            return None
        return self.chosen_solver()

    def held_lags(self) -> dict[str, str]:
        """Each time offset the run holds with no σ (:meth:`pinned`), with why: every file the run
        writes states it held, not free."""
        estimates = self.lag_estimates()
        return {n: estimates[n].held_why if n in estimates else "held with no σ" for n in self.pinned()}

    def held_in(self, solver: str) -> dict[str, str]:
        """What ``solver``'s estimate holds rather than determines, with why: what its fit held
        (:attr:`SolverReport.held`) and the time offsets the run holds (:meth:`held_lags`)."""
        return {**self.held_lags(), **self.reports[solver].held}

    def stated_layout(self) -> Layout:
        """The layout as the run's files state it: each time offset the run holds (:meth:`pinned`)
        held, not free (the fit frees it; the run gives it no σ)."""
        layout = self.scenario.layout
        return layout.with_status({n: HELD for n in self.pinned() if layout.param(n).status == FREE})

    def handoff_status(self, solver: str) -> dict[str, tuple[str, str]]:
        """Each parameter of ``solver``'s estimate with its standing in every hand-off file and
        why: :data:`GIVEN` (``known:``, ``fixed:``), :data:`DOUBTFUL` (held at its guess because
        the drive cannot determine it, a time offset the run holds with no σ, or a caveat of the
        verdict concerns it) or :data:`LIVE`.
        The one decision every hand-off file formats."""
        layout, held = self.scenario.layout, self.held_in(solver)
        given = {p.name for p in layout.parameters if p.status == KNOWN}
        concerns = self.verdict.concerns
        out: dict[str, tuple[str, str]] = {}
        for name in self.reports[solver].result.names:
            if name in given:
                out[name] = (GIVEN, held.get(name, "given"))
            elif name in held:
                out[name] = (DOUBTFUL, held[name])
            elif name in concerns:
                out[name] = (DOUBTFUL, concerns[name])
            else:
                out[name] = (LIVE, "")
        return out

    def waived(self, solver: str) -> dict[str, str]:
        """The controller values whose calibrated parameters are in doubt only as parts of a
        combination loose in the σ to believe (the ``observability`` check's ``only_together``),
        that combination leaving each value known to the precision it needs (its σ within what
        its parameters' needed precisions give it, in quadrature) and every converged solver
        agreeing on it that closely: the doubt is on the combination, not on the value. With why."""
        found = self.checks.plugin("observability")
        alone = set(self.checks.recorded("observability", "only_together") or ())
        report = self.reports[solver]
        params, doubted = report.controller, self.doubts(solver)
        # A caveat on every parameter (a wrong model's) puts every value in doubt.
        every = any(r.level != FINE and r.about.get("concerns") == "all" for r in self.checks.more)
        if not alone or params is None or every:
            return {}
        estimate = report.result.param_dict()
        needed = self.scenario.layout.needed({n: estimate[n] for g in params.gradient.values() for n in g})
        # A parameter another check puts in doubt, or held, is in doubt on its own account.
        others = {n for r in self.checks.more if r is not found and r.level != FINE for n in r.concerns}
        alone -= others | set(report.held)
        theirs = [r.controller for s, r in self.reports.items() if s != solver and r.result.converged]
        out = {}
        for name, deps in params.rests_on.items():
            doubts = [n for n in deps if n in doubted]
            need = _needed_of(params.gradient.get(name, {}), needed)
            sd, value = params.std.get(name, math.inf), params.parameters.get(name, math.nan)
            apart = [abs(c.parameters.get(name, math.inf) - value) if c else math.inf for c in theirs]
            if doubts and set(doubts) <= alone and sd <= need and all(d <= need for d in apart):
                out[name] = (
                    f"{', '.join(doubts)} move together, but this value is known to ±{sd:.2g}, within the "
                    f"{need:.2g} it needs"
                )
        return out

    def doubts(self, solver: str) -> dict[str, str]:
        """The parameters of ``solver``'s estimate not determined well enough to use, with why."""
        return {n: why for n, (status, why) in self.handoff_status(solver).items() if status == DOUBTFUL}

    def to_data(self) -> Any:
        """The run as JSON types (see :mod:`nlp_calib.results.codec`)."""
        return codec.to_data(self)

    @classmethod
    def from_data(cls, data: Any) -> CalibrationRun:
        """The run :meth:`to_data` stored."""
        return codec.load(cls, data)


def _needed_of(gradient: Mapping[str, float], needed: Mapping[str, float]) -> float:
    """The precision a value needs from those its parameters need (``gradient``: its derivative in
    each), in quadrature; 0 where a parameter's need is unknown (nothing is waived then)."""
    if not gradient or any(n not in needed for n in gradient):
        return 0.0
    return math.sqrt(sum((g * needed[n]) ** 2 for n, g in gradient.items()))


def lags_in(layout: Layout, parts: Sequence[CalibrationRun]) -> dict[str, tuple[str, LagEstimate]]:
    """Each log's own time offset in a joint fit's ``layout`` with its log's path and that log's
    alignment estimate, from its logs' runs ``parts`` (:attr:`DataInfo.lags`)."""
    return {
        n: (part.log.path, part.data.lag_estimate)
        for i, part in enumerate(parts)
        if part.data.lag_estimate is not None
        for n in layout.block(CLOCK, log=i)
        if layout.param(n).log == i
    }


def pinned_in(layout: Layout, parts: Sequence[CalibrationRun]) -> tuple[str, ...]:
    """The time offsets of a joint fit's ``layout`` pinned in its logs' runs ``parts`` (each log's
    own lag estimate on the edge of its search, or none converged): the joint's checks hold them
    as the joint run does once its logs are attached (:meth:`CalibrationRun.pinned`)."""
    return tuple(
        n
        for i, part in enumerate(parts)
        if part.data.lag_estimate is not None and part.data.lag_estimate.pinned
        for n in layout.block(CLOCK, log=i)
        if layout.param(n).log in (i, None)
    )
