"""What the data imply of units and signs: joints in degrees, wheel angles that wrap, a wheel whose
joint turns backwards as the robot drives forwards.

Each is told from the data alone, against the tracker where it takes a scale or a direction:

- **a wheel's angle that wraps** (joints in radians): its position jumps by about 2π between two
  samples whose neighbours move little (no gap in time between them), where REP 103 has a wheel's
  angle grow without end;
- **degrees**: an angle joint (an absolute encoder's) that reads beyond 2π; wheels whose joints
  turn so far for the tracker's travel that a radian of them would move the robot less than
  :data:`MIN_RADIUS` (the smallest wheels a robot carrying a tracker rolls on are several times
  larger; read in degrees, a wheel of up to 35 cm radius falls below it);
- **a mirrored wheel axis**: two wheels whose joints turn opposite ways where the base drives a
  gentle curve and the same way where it turns on the spot, where both wheels of any robot do the
  reverse (:data:`OPPOSITE_SHARE` of those steps); the base's track is the reference's moved by the
  nominal mount (a sensor turned 90° or off the axle is no mirror), and both kinds of step are
  judged (a reference's slips, gentle curves where the wheels turn on the spot, are outweighed
  where it turns with them). The one that turns against the base's forward travel is named.

Every finding says what was measured and how to fix it; the run cannot succeed on such data as
they are (a degree taken for a radian makes a wheel radius 57 times too small, a mirrored wheel a
negative one).
"""

from __future__ import annotations

import numpy as np

from nlp_calib.analysis.excitation import STEP_S, taken
from nlp_calib.analysis.streams import time_gaps
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel
from nlp_calib.results.preflight import UnitFinding

DEGREE = np.pi / 180.0
#: A wheel whose joint, read in radians, moves the robot less than this per radian (m) is not
#: turning in radians.
MIN_RADIUS = 0.006
#: A wheel whose radius is less than this share of the distance between two wheels is no robot's
#: (wheels in rpm read as rad/s make it 9.5 times smaller: 2 % of the track for most robots).
MIN_RADIUS_SHARE = 0.06
#: A radian of the wheel joints moving the robot farther than this (m) is a wheel larger than any
#: robot's: columns of wheel speeds read as positions (they barely change as the robot drives).
MAX_RADIUS = 5.0
#: A robot's wheel radius: a typical share of its track, and a typical size (m).
TYPICAL_RADIUS_SHARE = 0.25
TYPICAL_RADIUS = 0.1
#: Units wheel speeds are given in by mistake, and how many of them make a radian per second.
SPEED_UNITS = {"rpm": 60.0 / (2.0 * np.pi), "deg/s": 180.0 / np.pi, "rev/s": 1.0 / (2.0 * np.pi)}
#: A wheel whose radius is more than this share of the distance between two wheels is no robot's
#: (a wheelchair's drive wheels are about half of it; wheels in revolutions make it 6.3 times larger).
MAX_RADIUS_SHARE = 0.8
#: The track is measured well enough to judge a wheel too large for it, or the reference's units,
#: where the wheels' difference follows the reference's turning this closely (correlation): slips
#: and a lagging tracker make the track come out half of it, a wheel twice its share.
TURNING_AGREES = 0.95
#: The distance between two wheels of a robot (m): the models' plausible wheel separation.
TRACK_RANGE = (0.05, 5.0)
#: Length units a reference's positions are given in by mistake, in metres.
LENGTH_UNITS = {"millimetres": 1e-3, "centimetres": 1e-2}
#: Wheel columns whose values follow the reference's speed this closely (their correlation), and
#: closer by :data:`SPEED_MARGIN` than their changes do: speeds, not positions (a position's change
#: follows the speed; a speed's own value does, whatever its noise: a noisy speed column read as
#: positions looked like a wheel that wraps, or like nothing).
SPEED_CORRELATION = 0.8
SPEED_MARGIN = 0.3
#: The speed detector's steps span at least this many record intervals (a bursty tracker's stamps
#: are off by up to one: its speed over six is within about a sixth), and no more than this (s: a
#: log's dropout is no interval of its records).
SPEED_STEP_RECORDS = 6
SPEED_STEP_MAX_S = 2.0
#: Two wheels turning against a robot's on this share of the steps judged: one axis is mirrored.
OPPOSITE_SHARE = 0.8
#: A curve is gentle where the heading turns less than this per metre (rad/m): both wheels of a
#: base narrower than 2 m turn the same way there.
GENTLE_CURVATURE = 1.0
#: The base turns on the spot where it travels less than this per radian turned (m/rad): under
#: half the narrowest track (:data:`TRACK_RANGE`), so its two wheels turn opposite ways there ...
PIVOT_RADIUS = 0.025
#: ... and turns at least this much per step (rad), beyond a tracker's noise.
PIVOT_TURN = 0.05
#: The wheels' signs are judged on steps this long (s): a turn on the spot of a few centimetres of
#: the wheels then moves a tracker by more than its noise.
SIGN_STEP_S = 1.0


def wrapped(log: Log, model: KinematicModel) -> list[UnitFinding]:
    """Wheels in radians whose angle wraps (see the module docstring)."""
    if log.joint_positions is None:
        return []
    out = []
    names = log.header.encoder_names
    stream = log.joint_stream
    for j, name in enumerate(names):
        # A position the reader integrated from speeds grows as they do: it cannot have wrapped.
        if model.encoder_kinds.get(name) != "counter" or (stream is not None and name in stream.integrated):
            continue
        pos = stream.positions[:, j] if stream is not None else log.joint_positions[:, j]
        time_s = stream.time_s if stream is not None else log.time_s
        finite = np.isfinite(pos)
        # A wheel turns any angle across a gap in the stream: only steps between neighbours count.
        d = np.diff(pos[finite])[~time_gaps(time_s[finite])]
        if d.size < 3:
            continue
        typical = float(np.median(np.abs(d)))
        jumps = (np.abs(d) > np.pi) & (
            np.abs(d - 2 * np.pi * np.round(d / (2 * np.pi))) < max(0.5, 4 * typical)
        )
        if jumps.any() and typical < 1.0:
            lo, hi = float(np.min(pos)), float(np.max(pos))
            out.append(
                UnitFinding(
                    "wrapped",
                    name,
                    f"the joint read as {name} wraps its angle ({int(jumps.sum())} jumps of 2π, its "
                    f"positions stay within [{lo:.2f}, {hi:.2f}] rad): a wheel's position must grow without "
                    "wrapping (REP 103): publish it unwrapped, or numpy.unwrap it before calibrating",
                )
            )
    return out


def _steering_degrees(log: Log, model: KinematicModel) -> list[UnitFinding]:
    if log.joint_positions is None:
        return []
    out = []
    for j, name in enumerate(log.header.encoder_names):
        if model.encoder_kinds.get(name) != "absolute":
            continue
        top = float(np.nanmax(np.abs(log.joint_positions[:, j])))
        if top > 2 * np.pi + 0.01:
            out.append(
                UnitFinding(
                    "degrees",
                    name,
                    f"the joint read as {name} reads up to {top:.4g}, beyond 2π: its angle is not in radians "
                    f"(degrees? {top:.4g}° is {top * DEGREE:.3g} rad); publish it in radians (REP 103)",
                )
            )
    return out


def _gentle(time_s: np.ndarray, xy: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices of records about :data:`STEP_S` apart and, per step between them, whether the robot
    moves on a gentle curve (its heading turns less than :data:`GENTLE_CURVATURE` per metre)."""
    k = taken(time_s, STEP_S)
    ds = np.hypot(*np.diff(xy[k], axis=0).T)
    dth = np.abs(np.diff(heading[k]))
    return k, (ds > 1e-3) & (dth < GENTLE_CURVATURE * np.maximum(ds, 1e-9))


def _counters(log: Log, model: KinematicModel) -> list[str]:
    return [n for n in log.header.encoder_names if model.encoder_kinds.get(n) == "counter"]


def _wheel_degrees(log: Log, model: KinematicModel, xy: np.ndarray, heading: np.ndarray) -> list[UnitFinding]:
    counters = _counters(log, model)
    if log.joint_positions is None or not counters:
        return []
    scales = _scales(log, counters, xy, heading)
    if scales is None:
        # No gentle curve: a heading in degrees turns 57 times too fast for any (their finding),
        # unless the wheels turn opposite ways there: a pivot on the spot, in any unit.
        degrees = _scales(log, counters, xy, heading * DEGREE)
        if degrees is None or not degrees[2] or _pivoting(log, counters, xy, heading * DEGREE):
            return []
        return _reference_units(degrees[0], degrees[1] * DEGREE)
    radius, track, agrees = scales
    if agrees and (reference := _reference_units(radius, track)):
        return reference
    stream = log.joint_stream
    if stream is not None and set(counters) <= set(stream.integrated):
        return _speed_units(counters, radius, track, agrees)
    if radius > MAX_RADIUS:
        return [
            UnitFinding(
                "speeds",
                ", ".join(counters),
                f"the wheel joints ({', '.join(counters)}) barely turn for the robot's travel: a radian of "
                f"them moves it {radius:.3g} m, a wheel larger than any robot's: their columns look like "
                "speeds (rad/s) read as positions; say so (form: speeds)",
            )
        ]
    if radius < MIN_RADIUS:
        return [
            UnitFinding(
                "degrees",
                ", ".join(counters),
                f"the wheel joints ({', '.join(counters)}) turn too far for the robot's travel: a radian of "
                f"them moves it {1e3 * radius:.2g} mm, a wheel smaller than any robot's (read as degrees, "
                f"one of {1e3 * radius / DEGREE:.3g} mm radius): their angles look like degrees; publish "
                "them in radians (REP 103)",
            )
        ]
    if agrees and np.isfinite(track) and track > 0 and radius / track > MAX_RADIUS_SHARE:
        return _wrong_unit("angles", "revolutions", counters, radius, track, 1.0 / (2.0 * np.pi))
    return []


def _scales(
    log: Log, counters: list[str], xy: np.ndarray, heading: np.ndarray
) -> tuple[float, float, bool] | None:
    """The robot's travel per radian of its wheels on gentle curves (m: the wheel's radius as read),
    the track their turning implies against ``heading``, and whether their difference follows the
    heading's turning closely enough to judge by it (None without three gentle steps)."""
    k, gentle = _gentle(log.time_s, xy, heading)
    if gentle.sum() < 3:
        return None
    travel = float(np.sum(np.hypot(*np.diff(xy[k], axis=0).T)[gentle]))
    turned = float(np.mean([np.sum(np.abs(np.diff(log.running_position(n)[k]))[gentle]) for n in counters]))
    radius = travel / turned if turned > 0 else np.inf
    agrees = False
    if len(counters) >= 2:
        apart = np.diff(log.running_position(counters[1])[k] - log.running_position(counters[0])[k])
        dth = np.diff(heading[k])
        with np.errstate(invalid="ignore", divide="ignore"):
            agrees = bool(abs(np.corrcoef(apart, dth)[0, 1]) >= TURNING_AGREES)
    return radius, _track_width(log, counters, radius, k, heading), agrees


def _pivoting(log: Log, counters: list[str], xy: np.ndarray, heading: np.ndarray) -> bool:
    """Whether the first two wheels turn opposite ways more than together on the steps gentle at
    ``heading``: the robot pivots there (a tracker off the axle's middle draws a small circle),
    where on a gentle curve both wheels of a base narrower than 2 m turn the same way."""
    if len(counters) < 2:
        return False
    k, gentle = _gentle(log.time_s, xy, heading)
    a, b = (np.diff(log.running_position(n)[k])[gentle] for n in counters[:2])
    return float(np.sum(np.abs(a + b))) < float(np.sum(np.abs(a - b)))


def _reference_units(radius: float, track: float) -> list[UnitFinding]:
    """The reference's own units wrong, told by the wheels' two scales: its positions in mm or cm
    make the wheel and the track both a robot's times a thousand or a hundred (their ratio, which no
    unit changes, a robot's); its heading in degrees makes the track 57 times too small while the
    wheel (from the travel alone) is a robot's."""
    if not np.isfinite(track) or track <= 0:
        return []
    share = radius / track
    plausible_share = MIN_RADIUS_SHARE <= share <= MAX_RADIUS_SHARE
    if plausible_share and radius > MAX_RADIUS:
        unit, factor = min(LENGTH_UNITS.items(), key=lambda u: abs(np.log(radius * u[1] / TYPICAL_RADIUS)))
        return [
            UnitFinding(
                "reference units",
                "reference",
                f"a radian of the wheels moves the reference {radius:.3g} m and their turning implies "
                f"{track:.3g} m between them, both {1 / factor:.0f} times a robot's (in {unit}: a wheel "
                f"of {1e3 * radius * factor:.3g} mm, {track * factor:.3g} m between the wheels): the "
                f"reference's positions look like {unit}; give them in metres (REP 103)",
            )
        ]
    low, high = TRACK_RANGE
    if MIN_RADIUS <= radius <= MAX_RADIUS and track < low and low <= track / DEGREE <= high:
        return [
            UnitFinding(
                "reference units",
                "reference",
                f"the reference turns {1 / DEGREE:.0f} times more than the wheels: their turning implies "
                f"{1e3 * track:.3g} mm between them (a wheel of {1e3 * radius:.3g} mm from the travel; "
                f"read as degrees, {track / DEGREE:.3g} m between them): the reference's heading looks like "
                "degrees; give it in radians (REP 103)",
            )
        ]
    return []


def _track_width(log: Log, counters: list[str], radius: float, k: np.ndarray, heading: np.ndarray) -> float:
    """The distance between the first two wheels that the wheels' own turning implies at ``radius``
    (m per radian of them): the robot's heading change against their difference, by least squares
    (NaN with fewer than two wheels or no turning)."""
    if len(counters) < 2:
        return float("nan")
    dth = np.diff(heading[k])
    apart = np.diff(log.running_position(counters[1])[k] - log.running_position(counters[0])[k])
    scale = float(np.sum(dth * dth))
    return abs(radius * float(np.sum(apart * dth)) / scale) if scale > 0 else float("nan")


def _speed_units(counters: list[str], radius: float, track: float, agrees: bool) -> list[UnitFinding]:
    """Wheels given as speeds in rpm, deg/s or rev/s, not rad/s: a radian of them moves the robot
    less than :data:`MIN_RADIUS`, or (two wheels) less than :data:`MIN_RADIUS_SHARE` or more than
    :data:`MAX_RADIUS_SHARE` of the distance between them their turning implies (the track: a scale
    no unit of the wheels changes; ``agrees``: measured well enough to judge a wheel too large).
    The unit named is the one that brings the wheel to :data:`TYPICAL_RADIUS_SHARE` of the track
    (to :data:`TYPICAL_RADIUS` without one)."""
    share = radius / track if np.isfinite(track) and track > 0 else float("nan")
    if radius >= MIN_RADIUS and not share < MIN_RADIUS_SHARE and not (agrees and share > MAX_RADIUS_SHARE):
        return []
    size, typical = (share, TYPICAL_RADIUS_SHARE) if np.isfinite(share) else (radius, TYPICAL_RADIUS)
    unit, factor = min(SPEED_UNITS.items(), key=lambda u: abs(np.log(size * u[1] / typical)))
    return _wrong_unit("speeds", unit, counters, radius, track, factor)


def _wrong_unit(
    what: str, unit: str, counters: list[str], radius: float, track: float, factor: float
) -> list[UnitFinding]:
    """The finding that the wheels' ``what`` (speeds, angles) are in ``unit`` (``factor`` of them a
    radian, or a radian per second), with the wheel they make at the track ``track``."""
    share = radius / track if np.isfinite(track) and track > 0 else float("nan")
    beside = f", {100 * share:.2g} % of the {track:.3g} m between the wheels" if np.isfinite(share) else ""
    size = "smaller" if radius * factor > radius else "larger"
    names = ", ".join(counters)
    fix = "rad/s" if what == "speeds" else "radians"
    return [
        UnitFinding(
            "speed units" if what == "speeds" else "angle units",
            names,
            f"the wheel {what} ({names}) turn too {'far' if size == 'smaller' else 'little'} for the "
            f"robot's travel: a radian of them moves it {1e3 * radius:.2g} mm{beside}, a wheel {size} than "
            f"any robot's; read as {unit}, one of {1e3 * radius * factor:.3g} mm radius: their {what} look "
            f"like {unit}; give them in {fix} ({unit} × {1 / factor:.4g}; REP 103)",
        )
    ]


def base_track(
    xy: np.ndarray, heading: np.ndarray, mount: tuple[float, float, float] | None
) -> tuple[np.ndarray, np.ndarray]:
    """The base's positions and heading from a planar sensor's (``xy``, ``heading``) and its
    nominal mount ``(x, y, yaw)`` in the base (the sensor's own where None): a sensor turned 90°
    travels sideways and one off the axle swings about it on the spot; the base does neither."""
    if mount is None:
        return xy, heading
    x, y, yaw = mount
    th = heading - yaw
    lever = np.column_stack([np.cos(th) * x - np.sin(th) * y, np.sin(th) * x + np.cos(th) * y])
    return xy - lever, th


def _mirrored(
    log: Log,
    model: KinematicModel,
    track: tuple[np.ndarray, np.ndarray],
    mount: tuple[float, float, float] | None,
) -> list[UnitFinding]:
    """Two wheels whose joints turn opposite ways where the base (by the reference and the nominal
    ``mount``) drives a gentle curve, or the same way where it turns on the spot, on
    :data:`OPPOSITE_SHARE` of those steps: both say one axis is mirrored, and a reference's fault
    (a scan matcher's slip, a swing of the sensor about the axle) says only one of them."""
    counters = _counters(log, model)
    if len(counters) < 2:
        return []
    xy, heading = base_track(*track, mount)
    k = taken(log.time_s, SIGN_STEP_S)
    ds = np.hypot(*np.diff(xy[k], axis=0).T)
    dth = np.abs(np.diff(heading[k]))
    gentle = (ds > 1e-3) & (dth < GENTLE_CURVATURE * ds)
    pivot = (dth > PIVOT_TURN) & (ds < PIVOT_RADIUS * dth)
    steps = {n: np.diff(log.running_position(n)[k]) for n in counters[:2]}
    a, b = steps.values()
    judged = (a != 0) & (b != 0) & np.isfinite(a) & np.isfinite(b) & (gentle | pivot)
    against = judged & ((np.sign(a) != np.sign(b)) == gentle)
    share = float(against.sum() / judged.sum()) if judged.any() else 0.0
    if against.sum() < 5 or share < OPPOSITE_SHARE:
        return []
    backwards, which = _backwards(steps, against & gentle, _forward(xy, heading, k) if mount else None)
    return [
        UnitFinding(
            "mirrored",
            backwards,
            f"the joints read as {counters[0]} and {counters[1]} turn opposite ways where the base drives "
            "a gentle curve, or the same way where it turns on the spot (by the reference and the nominal "
            f"mount), on {100 * share:.0f} % of {int(judged.sum())} such steps, where a robot's two wheels "
            f"do the reverse: one wheel's axis is mirrored, and {which}; negate that joint (its URDF axis, "
            "or its sign in the driver) or its wheel radius comes out negative",
        )
    ]


def _backwards(
    steps: dict[str, np.ndarray], gentle: np.ndarray, forward: np.ndarray | None
) -> tuple[str, str]:
    """Which of two mirrored wheels turns backwards, and how it is told, from the ``gentle`` steps
    that show the mirror: against the base's travel along its own x axis (``forward``, per step;
    None without a planar mount), else against most of the driving."""
    names = list(steps)
    if not gentle.any():
        return names[0], (
            "the steps turning on the spot do not tell which one turns backwards: drive a straight line "
            f"forwards, and negate the one of {names[0]} and {names[1]} that counts down"
        )
    if forward is not None:
        agree = {n: float(np.sum(np.sign(v[gentle]) == forward[gentle])) for n, v in steps.items()}
        name = min(agree, key=lambda n: agree[n])
        return name, f"{name} turns backwards as the robot drives forwards (by the reference and its mount)"
    totals = {n: float(np.sum(v[gentle])) for n, v in steps.items()}
    name = min(totals, key=lambda n: totals[n])
    return name, f"{name} turns backwards on most of the driving"


def _forward(xy: np.ndarray, heading: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Per step, the sign of the base's travel along its own x axis (``xy``, ``heading``: the
    base's track)."""
    d = np.diff(xy[k], axis=0)
    th = heading[k][:-1]
    return np.sign(np.cos(th) * d[:, 0] + np.sin(th) * d[:, 1])


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    with np.errstate(invalid="ignore", divide="ignore"):
        c = float(np.corrcoef(a, b)[0, 1])
    return c if np.isfinite(c) else 0.0


def covering_interval(time_s: np.ndarray) -> float:
    """The interval between records that half the log's time passes in (s): the records' interval
    where they come evenly; where a tracker delivers its poses in bursts stamped on arrival (16
    poses 2.5 ms apart every 0.3 s), the time between its bursts, not the 2.5 ms of their median."""
    dt = np.sort(np.diff(np.asarray(time_s, dtype=float)))
    if dt.size == 0:
        return 0.0
    passed = np.cumsum(dt)
    return float(dt[min(int(np.searchsorted(passed, 0.5 * passed[-1])), dt.size - 1)])


def _speed_columns(log: Log, model: KinematicModel, xy: np.ndarray) -> list[UnitFinding]:
    """Wheel columns read as positions whose values, not their changes, follow the reference's
    speed (:data:`SPEED_CORRELATION`): speeds."""
    counters = _counters(log, model)
    stream = log.joint_stream
    if (
        log.joint_positions is None
        or not counters
        or (stream is not None and set(counters) & set(stream.integrated))
    ):
        return []
    # Steps of several records: a tracker that delivers its poses in bursts stamps them up to one
    # interval off, and a speed over one interval is then mostly that error.
    interval = min(SPEED_STEP_RECORDS * covering_interval(log.time_s), SPEED_STEP_MAX_S)
    k = taken(log.time_s, max(STEP_S, interval))
    if k.size < 8:
        return []
    moved = np.diff(xy[k], axis=0)
    # A step over which the tracker repeats its pose exactly (it lost its target and republished
    # the last one) says nothing of the speed.
    seen = np.any(moved != 0.0, axis=1)
    speed = np.hypot(*moved.T)[seen] / np.diff(log.time_s[k])[seen]
    columns = np.stack([log.running_position(n) for n in counters])
    wheels = columns[:, k]
    # A column's mean over each step (by the trapezoid over its records), the speed a speed column
    # says the robot kept there: its two ends' mean is that only where the speed changes slowly.
    area = np.cumsum(0.5 * (columns[:, 1:] + columns[:, :-1]) * np.diff(log.time_s), axis=1)
    area = np.concatenate([np.zeros((len(counters), 1)), area], axis=1)[:, k]
    level = np.mean(np.abs(np.diff(area, axis=1) / np.diff(log.time_s[k])), axis=0)[seen]
    change = np.mean(np.abs(np.diff(wheels, axis=1)), axis=0)[seen]
    as_speed, as_position = _correlation(level, speed), _correlation(change, speed)
    if as_speed < SPEED_CORRELATION or as_speed < as_position + SPEED_MARGIN:
        return []
    names = ", ".join(counters)
    return [
        UnitFinding(
            "speeds",
            names,
            f"the wheel joints' values ({names}) follow the robot's speed (correlation {as_speed:.2f}), "
            f"their changes do not ({as_position:.2f}): their columns look like speeds (rad/s) read as "
            "positions; say so (form: speeds)",
        )
    ]


def findings(
    log: Log,
    model: KinematicModel,
    track: tuple[np.ndarray, np.ndarray],
    mount: tuple[float, float, float] | None,
    positions: bool = True,
) -> tuple[UnitFinding, ...]:
    """Every unit and sign finding on ``log`` read for ``model``: ``track`` the tracker's positions
    ``(n, 2)`` and unwrapped heading at the records; ``mount`` the nominal planar mount ``(x, y,
    yaw)`` (None for a 3-D sensor); ``positions``: whether the reference measures any (a gyro's
    heading alone does not: every turn of it would look like one on the spot). Wheel columns that
    look like speeds are said as such alone (their swings looked like wraps, their scale like a
    wheel of metres); a reference in the wrong units is no measure of the wheels' signs (its curves
    and turns on the spot are not what they seem), so no sign is judged against it, nor against one
    without positions."""
    xy, heading = track
    speeds = _speed_columns(log, model, xy)
    out = speeds or wrapped(log, model)
    out += _steering_degrees(log, model)
    out += [] if speeds else _wheel_degrees(log, model, xy, heading)
    if positions and not any(f.kind == "reference units" for f in out):
        out += _mirrored(log, model, track, mount)
    return tuple(out)
