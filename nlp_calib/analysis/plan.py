"""What to drive next: manoeuvres ranked by how much each, appended to the drive, lowers the largest σ.

Each candidate (circles each way at a few radii, figure eights, S-curves, reversals, a straight
run, spot turns, arcs driven backwards) is about :data:`DURATION_S` of driving at the drive's own
speed and sample rate. It is simulated with the model as it stands (the fit's parameters, or the
pre-flight's start): the inputs that drive each of its steady motions are the model's own inverse
(the one-interval residual and its input Jacobian, solved by Gauss-Newton), the tracker's poses
follow from them, and its windows are laid after the drive's last record on the drive's clock
(:func:`nlp_calib.problem.windows.appended`). Its information adds to the drive's, and every
parameter's σ is read as the pre-flight reads it (:mod:`nlp_calib.analysis.determinacy`). The
manoeuvres are ranked by the largest σ over its reference precision once appended, the lag
included; the plan names the parameter that is worst now and what each manoeuvre does to it.
A candidate the model cannot drive is never asked for: the model says what its base can drive
(:meth:`~nlp_calib.models.base.KinematicModel.reach`: its tightest turn at its wheels' largest angle, the
scenario's ``vehicle.max_steering_deg`` or the model's own; a spot turn only where it turns on the
spot), the turns are driven at no more lateral acceleration than :data:`LATERAL_ACCEL`, backwards
no faster than :data:`REVERSE_SPEED` unless the drive itself did, and a candidate no inputs
reproduce is left out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from nlp_calib.analysis.determinacy import Information, information, standing
from nlp_calib.core import poses
from nlp_calib.models import KinematicModel, Reach
from nlp_calib.problem import (
    ProblemFunctions,
    ProblemSpec,
    ResidualData,
    ResidualOptions,
    build,
    over_columns,
)
from nlp_calib.problem.windows import appended
from nlp_calib.results.checks import WEAK
from nlp_calib.results.preflight import Manoeuvre, Plan
from nlp_calib.solvers.backends import Buffered

#: Seconds of driving each candidate takes.
DURATION_S = 30.0
#: The candidates' windows are evaluated up to this work (windows × horizon) each.
WORK = 5_000
#: A steady motion the inverse reproduces to less than this (relative) can be driven.
INVERSE_TOLERANCE = 1e-6
#: The inverse moves an angle by at most this much a step (rad).
MAX_TURN_STEP = 0.2
#: A spot turn's rate (rad/s).
SPOT_RATE = 0.5
#: How much beyond the drive's own largest held angle input a manoeuvre may ask (a share of it).
STEER_MARGIN = 0.05
#: A turn is asked at no more lateral acceleration than this (m/s²): a car on a road's speed is
#: not a circle's.
LATERAL_ACCEL = 2.0
#: A drive that never went backwards is asked to reverse no faster than this (m/s).
REVERSE_SPEED = 1.0
#: The tightest radius asked is this much wider than the model's tightest turn (not at full lock).
LOCK_MARGIN = 1.2


@dataclass(frozen=True)
class Candidate:
    """A manoeuvre as steady segments: each ``(seconds, speed m/s, turn rate rad/s)``; ``speed_mps``
    and ``radius_m`` are those it was made at (:func:`candidates`)."""

    kind: str
    radius_m: float
    speed_mps: float
    words: str
    segments: tuple[tuple[float, float, float], ...]


def candidates(
    speed: float, radii: Sequence[float], reverse_speed: float = math.inf, spot_turns: bool = True
) -> list[Candidate]:
    """The manoeuvres considered, at ``speed`` (backwards at most ``reverse_speed``; a turn at most
    :data:`LATERAL_ACCEL`) and the turn ``radii``; spot turns only with ``spot_turns``."""
    T, v = DURATION_S, speed
    vr = min(v, reverse_speed)
    out = [
        Candidate("straight", 0.0, v, f"straight ahead at {v:.2g} m/s for {T:.0f} s", ((T, v, 0.0),)),
        Candidate(
            "reversals",
            0.0,
            vr,
            f"straight forwards and back, twice, at {vr:.2g} m/s ({T:.0f} s)",
            tuple((T / 4, s * vr, 0.0) for s in (1, -1, 1, -1)),
        ),
    ]
    if spot_turns:
        out.append(
            Candidate(
                "spot_turns",
                0.0,
                v,
                f"turns on the spot, {T / 2:.0f} s each way at {SPOT_RATE:g} rad/s",
                ((T / 2, 0.0, SPOT_RATE), (T / 2, 0.0, -SPOT_RATE)),
            )
        )
    for R in radii:
        out += _turns(R, min(v, math.sqrt(LATERAL_ACCEL * R)), vr)
    return out


def _turns(R: float, v: float, reverse_speed: float) -> list[Candidate]:
    """The turning candidates at radius ``R``, at ``v`` (backwards at most ``reverse_speed``)."""
    T, w = DURATION_S, v / R
    laps = T * v / (2 * np.pi * R)
    at = f"{R:.2g} m radius at {v:.2g} m/s"
    vb = min(v, reverse_speed)
    return [
        Candidate("circle_left", R, v, f"a circle to the left ({at}, {laps:.1f} laps)", ((T, v, w),)),
        Candidate("circle_right", R, v, f"a circle to the right ({at}, {laps:.1f} laps)", ((T, v, -w),)),
        Candidate("figure_eight", R, v, f"a figure eight ({at}, {T:.0f} s)", ((T / 2, v, w), (T / 2, v, -w))),
        Candidate(
            "s_curves",
            R,
            v,
            f"S-curves, quarter turns each way ({at}, {T:.0f} s)",
            tuple((np.pi / 2 / w, v, s * w) for s in (1, -1) * max(1, round(T * w / np.pi))),
        ),
        Candidate(
            "arcs_backwards", R, vb,
            f"backwards round arcs each way ({R:.2g} m radius at {vb:.2g} m/s, {T:.0f} s)",
            ((T / 2, -vb, -vb / R), (T / 2, -vb, vb / R)),
        ),
    ]  # fmt: skip


def _arc(v: float, w: float, dt: float) -> np.ndarray:
    """The exact planar motion ``(x, y, θ)`` of a base moving at ``v`` turning at ``w`` for ``dt``."""
    th = w * dt
    if abs(th) < 1e-9:
        return np.array([v * dt, 0.5 * v * dt * th, th])
    return np.array([v * np.sin(th) / w, v * (1.0 - np.cos(th)) / w, th])


class Inverse:
    """The inputs that drive a steady motion, from the model's one-interval residual."""

    def __init__(
        self,
        model: KinematicModel,
        kinematic: np.ndarray,
        typical: np.ndarray,
        steered: np.ndarray | None = None,
    ) -> None:
        planar = build(model, ProblemSpec(horizon=1))
        self.residual = Buffered(planar.interval_residual)
        self.params = np.concatenate([kinematic, np.zeros(len(planar.names) - kinematic.size)])
        self.levels = levels(model)
        self.typical = typical
        #: The largest held angle input the drive used, each (a plan never asks for more).
        self.limit = np.full(len(self.levels), np.pi) if steered is None or not steered.size else steered

    def __call__(self, v: float, w: float, dt: float) -> np.ndarray | None:
        """One interval's inputs for the motion at ``v``, ``w`` over ``dt`` (None: none reproduce it
        with its angles within ±π). Steps in an angle are kept to :data:`MAX_TURN_STEP`: the model's
        steady motions repeat along an angle, and a full step jumps to a far copy."""
        target = _arc(v, w, dt)
        u = self.typical * (np.sign(v) if v else 0.0)
        u[self.levels] = 0.0
        scale = max(float(np.linalg.norm(target)), 1e-9)
        for _ in range(60):
            e, de_du = self.residual(params=self.params, u=u, z=target)
            e = np.ravel(e)
            if np.linalg.norm(e) < INVERSE_TOLERANCE * scale:
                # An angle the model reads as it is must be one a joint can take, and one the drive
                # steered to (a car's spot turn would need 90°; a tight circle more than it turned).
                reach = np.minimum(self.limit * (1.0 + STEER_MARGIN), np.pi)
                return u if np.all(np.abs(u[self.levels]) <= reach) else None
            step, *_ = np.linalg.lstsq(np.asarray(de_du), -e, rcond=None)
            turn = float(np.max(np.abs(step[self.levels]))) if self.levels else 0.0
            u = u + step * min(1.0, MAX_TURN_STEP / turn if turn > 0 else 1.0)
        return None


def levels(model: KinematicModel) -> list[int]:
    """The rows of the inputs the model reads as angles it holds (not increments)."""
    return [model.input_names.index(n) for n in model.level_inputs]


def synthesised(
    inverse: Inverse, c: Candidate, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The candidate's record times, interval inputs and base path (None: the model cannot drive it)."""
    inputs, steps = [], []
    for seconds, v, w in c.segments:
        u = inverse(v, w, dt)
        if u is None:
            return None
        n = max(1, round(seconds / dt))
        inputs.append(np.repeat(u[:, None], n, axis=1))
        steps.append(np.repeat(_arc(v, w, dt)[None, :], n, axis=0))
    U = np.concatenate(inputs, axis=1)
    path = poses.accumulate(np.zeros(3), np.concatenate(steps))
    return dt * np.arange(U.shape[1] + 1), U, path


def sensor_poses(
    fns: ProblemFunctions, params: np.ndarray, start: np.ndarray, path: np.ndarray
) -> np.ndarray:
    """The tracker's poses from ``start`` as the base follows ``path`` ``(n, 3)`` (from the origin)."""
    (poses_,) = over_columns(fns.carried, start, params, np.ascontiguousarray(path.T))
    return np.ascontiguousarray(poses_.T)


@dataclass(frozen=True)
class Setting:
    """What a plan starts from: the problem, the drive's windows and information, the point the model
    is evaluated at (free ``x``, fixed ``x_fixed``, weights ``omega``), the residuals' variance, the
    free parameters' bounds (1σ) and the residual form; ``model_from`` says where ``x`` comes from."""

    fns: ProblemFunctions
    data: ResidualData
    info: Information
    point: tuple[np.ndarray, np.ndarray, np.ndarray]
    sigma2: float
    bounds_std: np.ndarray | None
    options: ResidualOptions
    delta: float
    units: Mapping[str, str]
    model_from: str
    #: The steered wheel's largest angle the scenario gives (rad; None: the model's own).
    steer_max: float | None = None


@dataclass(frozen=True)
class DriveFacts:
    """What a manoeuvre takes from the drive it is appended to and the base that drives it: its
    speed (m/s), the turn radii to try (m), its record interval (s), its typical inputs per
    interval (where the inverse starts), how far the drive turned each held angle input (its
    largest magnitude, in the input's unit; empty: no bound but the joint's ±π): a plan never asks
    for more; the fastest it may reverse (m/s) and whether the base turns on the spot."""

    speed: float
    radii: tuple[float, ...]
    dt: float
    typical: np.ndarray
    steered: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reverse_speed: float = math.inf
    spot_turns: bool = True


#: The share of the drive's moving records that turn tighter than the tightest radius a plan asks
#: for (the drive's own tightest turns, robust to a few glitches).
TIGHTEST_SHARE = 0.02
#: A drive whose heading spans less than this (rad) did not turn: it says nothing of how far the
#: robot can steer.
TURNED_RAD = 0.5


def tightest_radius(T_world_sensor: np.ndarray, dt: float) -> float:
    """The tightest turn radius the drive took while moving (m; inf: it never turned), from the
    reference's path: its speed over its turn rate, over steps of about a quarter second."""
    step = max(1, round(0.25 / max(dt, 1e-9)))
    P = T_world_sensor[::step]
    if P.shape[0] < 2:
        return float("inf")
    heading = np.unwrap(P[:, 2])
    if np.ptp(heading) < TURNED_RAD:
        return float("inf")  # a straight drive's "turns" are its tracker's noise
    ds = np.hypot(*np.diff(P[:, :2], axis=0).T)
    dth = np.abs(np.diff(heading))
    moving = ds > 0.01 * step * dt
    turning = moving & (dth > 1e-3)
    if not turning.any():
        return float("inf")
    return float(np.quantile(ds[turning] / dth[turning], TIGHTEST_SHARE))


def drive_facts(
    data: ResidualData, model: KinematicModel | None = None, reach: Reach | None = None, asked: bool = False
) -> DriveFacts:
    """The facts of the drive whose windows are ``data`` (its last log's), driven by ``model``
    (None: one with no held angle inputs) that can drive ``reach`` (None: anything); ``asked``:
    the reach's largest wheel angle is the scenario's, and no turn the drive took bounds the plan's."""
    log = data.logs[-1]
    reach = Reach(0.0) if reach is None else reach
    held = levels(model) if model is not None else []
    t = log.time_s
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.04
    xy = log.T_world_sensor[:, :2]
    step = max(1, round(0.25 / max(dt, 1e-9)))
    v = np.hypot(*np.diff(xy[::step], axis=0).T) / (step * dt)
    # The drive's own speed, however fast: a car on a road is driven at its speed, not a robot's.
    speed = float(max(np.median(v[v > 0.01]) if np.any(v > 0.01) else 0.3, 0.05))
    tightest = tightest_radius(log.T_world_sensor, dt) if held and not asked else math.inf
    # The model's tightest turn, off full lock; a steered robot turns no tighter than the drive
    # turned it unless the scenario says how far it steers.
    floor = max(LOCK_MARGIN * reach.min_radius_m, tightest if math.isfinite(tightest) else 0.0)
    R0 = max(speed / 0.5, 0.3, floor)
    moving = np.abs(data.inputs).max(axis=0) > 0
    typical = (
        np.median(np.abs(data.inputs[:, moving]), axis=1) if moving.any() else np.ones(data.inputs.shape[0])
    )
    # A drive that never turned says nothing of how far the robot can steer: then only the joint's
    # own ±π bounds a manoeuvre (and the reach the radii).
    turned = held and data.inputs.size and math.isfinite(tightest)
    steered = np.abs(data.inputs[held]).max(axis=1) if turned else np.zeros(0)
    backwards = model is None or bool(np.any(model.travel_direction(data.inputs) < 0))
    return DriveFacts(
        speed, (R0, 2 * R0, 4 * R0), dt, np.where(np.isfinite(typical), typical, 1.0), steered,
        math.inf if backwards else REVERSE_SPEED, reach.spot_turns,
    )  # fmt: skip


def candidate_of(m: Manoeuvre) -> Candidate:
    """The candidate a ranked manoeuvre was made from."""
    return next(c for c in candidates(m.speed_mps, [m.radius_m or 1.0]) if c.kind == m.kind)


def simulated(
    fns: ProblemFunctions,
    data: ResidualData,
    params: np.ndarray,
    c: Candidate,
    facts: DriveFacts,
    options: ResidualOptions,
) -> tuple[ResidualData, np.ndarray] | None:
    """``data`` with the candidate appended as the model with the full parameters ``params`` drives
    it (see :func:`~nlp_calib.problem.windows.appended`), and the base's path; None when no inputs
    of the model drive it."""
    inverse = Inverse(fns.model, params[: len(fns.model.kinematic_params)], facts.typical, facts.steered)
    made = synthesised(inverse, c, facts.dt)
    if made is None:
        return None
    time_s, U, path = made
    # The manoeuvre continues the last log: its own mount (with a mount per log) carries the sensor.
    last = int(data.log_of(np.array([data.n_records - 1]))[0])
    track = sensor_poses(fns, fns.view(params, last), data.T_world_sensor[-1], path)
    return appended(fns, data, (time_s, U, track), options), path


def plan(s: Setting, free_only: bool = False) -> Plan | None:
    """The manoeuvres ranked (see the module docstring); None when every parameter is already
    determined to :data:`~nlp_calib.results.checks.WEAK` times its reference precision (with
    ``free_only``, for a model not fitted to the data, whose residuals say nothing of the noise:
    when the drive leaves no direction free)."""
    fns, (x, x_fixed, omega) = s.fns, s.point
    values = np.asarray(x, dtype=float)
    before = standing(fns, s.info, s.sigma2, values, s.bounds_std)
    ratio = np.where(np.isfinite(before.std_reference), before.std_reference, np.inf)
    if not np.any(ratio > WEAK) or (free_only and not before.undetermined.any()):
        return None
    params = np.asarray(fns.assemble(x, x_fixed)).ravel()
    # What the robot can drive, from a robot the model can be (a fit that wandered along a free
    # direction to a wheelbase of kilometres would ask for circles of hundreds).
    ranges = fns.model.physical_ranges
    plausible = {n: float(np.clip(v, *ranges.get(n, (-np.inf, np.inf)))) for n, v in zip(fns.names, params)}
    reach = fns.model.reach(plausible, s.steer_max)
    facts = drive_facts(s.data, fns.model, reach, asked=s.steer_max is not None)
    tried = []
    for c in candidates(facts.speed, facts.radii, facts.reverse_speed, facts.spot_turns):
        made = simulated(fns, s.data, params, c, facts, s.options)
        if made is None:
            continue
        extra, path = made
        new = extra.select(np.arange(s.data.n_residuals, extra.n_residuals))
        if new.n_residuals == 0:
            continue
        info = s.info.plus(information(fns, new, x, x_fixed, omega, s.delta, WORK))
        duration = float(extra.n_records - s.data.n_records - 1) * facts.dt
        tried.append((c, path, duration, standing(fns, info, s.sigma2, values, s.bounds_std)))
    # The worst parameter now; of several equally bad (unbounded), the one a manoeuvre helps most.
    worst = np.flatnonzero(ratio == np.max(ratio))
    helped = [min((float(t[3].std_reference[j]) for t in tried), default=math.inf) for j in worst]
    target = int(worst[int(np.argmin(helped))])
    ranked = [
        Manoeuvre(
            c.kind, c.radius_m, c.speed_mps, duration, c.words, _thinned(path),
            float(np.max(after.std_reference)), float(after.std[target]),
        )
        for c, path, duration, after in tried
    ]  # fmt: skip
    ranked.sort(key=lambda m: (m.worst_after, m.target_std_after))
    name = fns.free[target]
    unit = s.units.get(name, "")
    kinematic = fns.model.kinematic_params
    size = {n: abs(float(v)) for n, v in zip(kinematic, params) if s.units.get(n) == "m" and v != 0}
    beyond = tuple(
        fns.free[j]
        for j in np.flatnonzero(before.undetermined)
        if all(after.undetermined[j] for *_, after in tried)
    )
    return Plan(
        name, unit, float(ratio[target]), float(before.std[target]), s.model_from, tuple(ranked), size, beyond
    )


def _thinned(path: np.ndarray, most: int = 400) -> np.ndarray:
    """At most ``most`` poses of a path, its ends kept."""
    if path.shape[0] <= most:
        return path
    return path[np.unique(np.linspace(0, path.shape[0] - 1, most).round().astype(int))]


def believed(plan: Plan | None, std: Mapping[str, float]) -> Plan | None:
    """``plan`` with its target's σ the run's σ to believe ``std`` (what the summary and the
    observability say of it: the plan's own is the white-noise σ, which the jackknife's can exceed
    several times), each manoeuvre's σ after scaled by the same factor (the plan's information
    says by how much each lowers it, and the largest σ over its needed precision by the same
    factor, so the table's columns and its header speak of one σ)."""
    if plan is None:
        return None
    s, before = std.get(plan.target, math.nan), plan.target_std_before
    if not (math.isfinite(s) and math.isfinite(before) and before > 0):
        return plan
    k = s / before
    ranked = tuple(
        replace(m, target_std_after=m.target_std_after * k, worst_after=m.worst_after * k)
        for m in plan.ranked
    )
    return replace(plan, target_std_before=s, worst_before=plan.worst_before * k, ranked=ranked)
