"""Car-like base: a steered front axle, a driven rear axle; base link at the rear-axle midpoint.

Parameters ``(k_steer, steer_offset, k_traction, wheelbase, rear_track)``; inputs per interval
``(rear_left_ticks, rear_right_ticks, steering_angle)``: the rear wheels' unwrapped increments and
the steering encoder's angle ``wrap(2π·s/s_max)``. The bicycle-equivalent steering angle
``φ = k_steer·angle + steer_offset`` turns the base at curvature ``κ = tan φ / wheelbase``; each
rear wheel travels ``k_traction·Δticks`` and the rear-axle midpoint the mean of both, each taken
back to the midline by its distance from the turn's centre,
``d = ½·(d_r / (1 + κ·T/2) + d_l / (1 − κ·T/2))`` (``T`` the rear track); the base turns by
``κ·d`` (exact arc or Euler). This is the odometry of ros2_control's steering controllers, so the
calibrated values are the ones that controller's odometry is best with. The rear track enters
only through that correction: a drive determines it from its tight turns, weakly.

Subclasses read the steering from both front wheels' joints (:mod:`.car_like_ackermann`) or the
traction from one joint (:mod:`.car_like_bicycle`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import ClassVar

import casadi as ca
import numpy as np

from nlp_calib.core.errors import ModelError
from nlp_calib.core.numeric import wrap_angle, wrapped_difference
from nlp_calib.logs import EncoderKind, Log, LogHeader
from nlp_calib.models.base import (
    CAR_STEER_MAX,
    QUANTISATION,
    SENSOR_TURNED,
    STEERING_SAMPLES,
    Reach,
    Reference,
    Symmetry,
    named,
    rows_by_name,
    sampled_angle,
    steered_reach,
)
from nlp_calib.models.controllers import ControllerMap, EncoderScales, steering_places, wheel_radius
from nlp_calib.models.drives import Pose, SimulationSettings, counter, drive_header, first_order, running
from nlp_calib.models.handeye import hand_eye, robust_lstsq
from nlp_calib.models.radians import WHEEL_RADIUS, InRadians, RadiansForm, Renamed
from nlp_calib.symbolic import se2

STEERING_ENCODER = "steering"
LEFT_ENCODER = "rear_left_wheel"
RIGHT_ENCODER = "rear_right_wheel"

#: The rear wheels' split ``(d_r − d_l)/(d_r + d_l)`` of a tight turn (radius five rear tracks),
#: and how many intervals of such turns a drive needs to determine the rear track.
TIGHT_SPLIT = 0.1
MIN_TIGHT = 200

#: The car read from joint positions in radians, its parameters as ros2_control's steering
#: controllers name them: the traction wheels' radius and track width.
RADIANS = RadiansForm(
    params=MappingProxyType(
        {
            "k_traction": Renamed("traction_wheels_radius", "m", plausible=WHEEL_RADIUS),
            "rear_track": Renamed("traction_track_width", "m"),
        }
    ),
    inputs=MappingProxyType(
        {
            "rear_left_ticks": Renamed("rear_left_angle", "rad", 1.0, LEFT_ENCODER),
            "rear_right_ticks": Renamed("rear_right_angle", "rad", 1.0, RIGHT_ENCODER),
            "steering_angle": Renamed("steering_angle", "rad", 1.0, STEERING_ENCODER),
        }
    ),
)


def rear_travel(left: ca.SX, right: ca.SX, curvature: ca.SX, track: ca.SX) -> ca.SX:
    """The rear-axle midpoint's travel from each rear wheel's, each taken back to the midline by
    its distance from the turn's centre."""
    half = 0.5 * curvature * track
    return 0.5 * (right / (1.0 + half) + left / (1.0 - half))


#: The highway simulator's car (:mod:`nlp_calib.simulation.vehicles`, in joint units: the wheels'
#: rolling radius in m per rad): a 2.8 m wheelbase and 1.6 m track, its steering joint reading the
#: road wheels' angle, a windshield device 1.9 m ahead of the rear axle turned 0.92°.
HIGHWAY_TRUTH: Mapping[str, float] = MappingProxyType(
    {
        "k_steer": 1.0,
        "steer_offset": 0.0004,
        "k_traction": 0.3185,
        "wheelbase": 2.8,
        "rear_track": 1.6,
        "sensor_x": 1.9,
        "sensor_y": -0.25,
        "sensor_theta": 0.016,
    }
)

#: How a scenario reads the highway simulator's files, after its ``joints`` and ``poses`` paths.
HIGHWAY_SCENARIO = (
    "form: speeds, encoders: {steering: steering, rear_left_wheel: rear_left_wheel, rear_right_wheel: "
    "rear_right_wheel}}, with model: car_like (the axle distance, steer gain, track and the device's "
    "position given under known:, as a straight kilometre cannot determine them)"
)


#: The highway car's joints as its log names them: the four wheels' speeds, then the steering.
HIGHWAY_JOINTS = ("rear_left_wheel", "rear_right_wheel", "front_left_wheel", "front_right_wheel", "steering")


def highway_steer(
    truth: Mapping[str, float], ds: np.ndarray, wobble: np.ndarray, heading_change: float
) -> np.ndarray:
    """The road wheels' angle: a driver's ``wobble`` plus the steady angle that turns the heading
    by ``heading_change`` over the steps ``ds`` (m) on ``truth``'s wheelbase."""
    steady = (heading_change * truth["wheelbase"] - np.sum(ds * np.tan(wobble))) / np.sum(ds)
    return wobble + steady


def highway_curvature(truth: Mapping[str, float], phi: np.ndarray) -> np.ndarray:
    """The rear axle's curvature (1/m) at road-wheel angle ``phi``."""
    return np.tan(phi) / truth["wheelbase"]


def highway_wheels(truth: Mapping[str, float], speed: np.ndarray, curvature: np.ndarray) -> np.ndarray:
    """Each wheel's speed ``(n, 4)`` (rad/s: rear left, rear right, front left, front right) and the
    steering joint's angle ``(n,)`` as the last column, of the rear-axle midpoint driving at
    ``speed`` (m/s) on ``curvature`` (1/m): the rear wheels at their distance from the turn's centre,
    the front ones (the rear's track apart) at theirs, the steering joint at ``(φ − offset)/k_steer``."""
    half = 0.5 * curvature * truth["rear_track"]
    ahead = curvature * truth["wheelbase"]
    wheels = [1.0 - half, 1.0 + half, np.hypot(1.0 - half, ahead), np.hypot(1.0 + half, ahead)]
    steering = (np.arctan(ahead) - truth["steer_offset"]) / truth["k_steer"]
    return np.stack([*(speed * w / truth["k_traction"] for w in wheels), steering], axis=1)


class CarLikeDrive:
    """The car drives its rear-axle midpoint at ``speed`` and steers to the bicycle angle ``turn``
    (rad); encoders: the steering (absolute over ``s_max`` ticks a turn) and each rear wheel's
    counter (``k_traction`` metres a tick)."""

    default_truth: Mapping[str, float] = MappingProxyType(
        {
            "k_steer": 0.95,
            "steer_offset": 0.03,
            "k_traction": 5.2e-4,
            "wheelbase": 1.0,
            "rear_track": 0.6,
            "sensor_x": 0.5,
            "sensor_y": 0.05,
            "sensor_theta": 0.04,
        }
    )
    default_guess: Mapping[str, float] = MappingProxyType(
        {
            "k_steer": 1.0,
            "steer_offset": 0.0,
            "k_traction": 5e-4,
            "wheelbase": 0.9,
            "rear_track": 0.5,
            "sensor_x": 0.4,
            "sensor_y": 0.0,
            "sensor_theta": 0.0,
        }
    )
    default_ranges: Mapping[str, int] = MappingProxyType(
        {STEERING_ENCODER: 8192, LEFT_ENCODER: 4096, RIGHT_ENCODER: 4096}
    )
    log_kind: ClassVar[str] = "car_like"
    steering_encoders: ClassVar[tuple[str, ...]] = (STEERING_ENCODER,)

    def steps(
        self,
        opts: SimulationSettings,
        speed: np.ndarray,
        turn: np.ndarray,
        turn_end: np.ndarray,
        dt: np.ndarray,
        turn_start: float,
        carry: Mapping[str, float] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
        t = opts.truth
        ds = speed * dt
        curvature = np.tan(turn) / t["wheelbase"]
        half = 0.5 * curvature * t.get("rear_track", 0.0)
        first: Mapping[str, float | None] = carry or {"left": None, "right": None, "phi": turn_start}
        channels = {
            "left": running(ds * (1.0 - half), first["left"]),
            "right": running(ds * (1.0 + half), first["right"]),
            "phi": np.concatenate([[first["phi"]], turn_end]),
        }
        return ds, ds * curvature, channels

    def steering_ticks(self, opts: SimulationSettings, phi: np.ndarray, encoder: str) -> np.ndarray:
        """The absolute steering encoder ``encoder`` reading the wheel angle ``phi``."""
        t, s_max = opts.truth, opts.encoder_ranges[encoder]
        return np.mod(np.round((phi - t["steer_offset"]) / t["k_steer"] * s_max / (2 * np.pi)), s_max)

    def ticks(self, opts: SimulationSettings, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        k, wrap = opts.truth["k_traction"], opts.wrap_after_ticks
        steer = self.steering_ticks(opts, channels["phi"], STEERING_ENCODER).astype(np.int64)
        return np.stack([steer, counter(channels["left"], k, wrap), counter(channels["right"], k, wrap)], 1)

    def header(self, opts: SimulationSettings) -> LogHeader:
        names = {n: n for n in self.default_guess if not n.startswith("sensor_")}
        return drive_header(opts, self.log_kind, names)

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray, start: Pose | None = None) -> np.ndarray:
        # The vendor's odometry: the wheels' mean travel, steered by the steering joints' mean angle.
        p, names = header.parameters, header.encoder_names
        steering = [names.index(e) for e in self.steering_encoders]
        wheels = [i for i in range(len(names)) if i not in steering]
        d = p["k_traction"] * np.mean([wrapped_difference(ticks[:, i]) for i in wheels], axis=0)
        angles = [wrap_angle(2 * np.pi * ticks[:-1, i] / header.encoder_max[i]) for i in steering]
        phi = p["k_steer"] * np.mean(angles, axis=0) + p["steer_offset"]
        return first_order(d, d * np.tan(phi) / p["wheelbase"], start)


class CarLike:
    """Car-like base, parameters ``(k_steer, steer_offset, k_traction, wheelbase, rear_track)``
    then the sensor pose ``(sensor_x, sensor_y, sensor_theta)``."""

    name: ClassVar[str] = "car_like"
    log_names: ClassVar[tuple[str, ...]] = ("car_like",)
    kinematic_params: ClassVar[tuple[str, ...]] = (
        "k_steer",
        "steer_offset",
        "k_traction",
        "wheelbase",
        "rear_track",
    )
    units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {
            "k_steer": "1",
            "steer_offset": "rad",
            "k_traction": "m per tick",
            "wheelbase": "m",
            "rear_track": "m",
        }
    )
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType(
        {n: n for n in ("k_steer", "steer_offset", "k_traction", "wheelbase", "rear_track")}
    )
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType(
        {n: n for n in ("k_steer", "steer_offset", "k_traction", "wheelbase", "rear_track")}
    )
    encoder_kinds: ClassVar[Mapping[str, EncoderKind]] = MappingProxyType(
        {STEERING_ENCODER: "absolute", LEFT_ENCODER: "counter", RIGHT_ENCODER: "counter"}
    )
    input_names: ClassVar[tuple[str, ...]] = ("rear_left_ticks", "rear_right_ticks", "steering_angle")
    input_units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"rear_left_ticks": "ticks", "rear_right_ticks": "ticks", "steering_angle": "rad"}
    )
    level_inputs: ClassVar[tuple[str, ...]] = ("steering_angle",)
    turning_params: ClassVar[tuple[str, ...]] = ("wheelbase", "rear_track")
    turning_note: ClassVar[str] = "the split between steering gain and offset"
    reference: ClassVar[Mapping[str, Reference]] = MappingProxyType({"steer_offset": ("absolute", 0.005)})
    headline: ClassVar[tuple[str, ...]] = ("k_traction", "wheelbase", "rear_track")
    defaults: ClassVar[Mapping[str, float]] = MappingProxyType({})
    symmetries: ClassVar[tuple[Symmetry, ...]] = (
        Symmetry(
            "the base frame turned round",
            "wheelbase",
            ("k_traction", "wheelbase", "rear_track", *SENSOR_TURNED[0]),
            SENSOR_TURNED[1],
        ),
    )
    angle_params: ClassVar[tuple[str, ...]] = ("steer_offset", "sensor_theta")
    steer_max: ClassVar[float | None] = CAR_STEER_MAX
    drive: ClassVar[CarLikeDrive] = CarLikeDrive()
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {
            "k_steer": (0.01, 3.0),
            "steer_offset": (-0.5, 0.5),
            "k_traction": (1e-7, 1.0),
            "wheelbase": (0.05, 10.0),
            "rear_track": (0.05, 5.0),
            "sensor_x": (-5.0, 5.0),
            "sensor_y": (-5.0, 5.0),
            "sensor_theta": (-np.pi, np.pi),
        }
    )
    #: The controller this base's joints go to, and the name the newest release gives its radius.
    controller_name: ClassVar[str] = "tricycle_steering_controller"
    radius_name: ClassVar[str] = "traction_wheels_radius"

    def reach(self, params: Mapping[str, float], steer_max: float | None = None) -> Reach:
        """The rear-axle midpoint's tightest turn, ``wheelbase / tan φ_max``: a car never turns on
        the spot."""
        return steered_reach(params["wheelbase"], CAR_STEER_MAX if steer_max is None else steer_max)

    # --- the symbolic increment ----------------------------------------------------------------

    def steering_angle(self, k: ca.SX, u: ca.SX) -> ca.SX:
        """The bicycle-equivalent steering angle ``φ = k_steer·angle + steer_offset``."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        return p["k_steer"] * inputs["steering_angle"] + p["steer_offset"]

    def travel(self, k: ca.SX, u: ca.SX, curvature: ca.SX) -> ca.SX:
        """The rear-axle midpoint's travel: both rear wheels', taken back to the midline."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        left, right = (
            p["k_traction"] * inputs["rear_left_ticks"],
            p["k_traction"] * inputs["rear_right_ticks"],
        )
        return rear_travel(left, right, curvature, p["rear_track"])

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """Travel ``d`` at curvature ``κ = tan φ / wheelbase``; exact arc or Euler ``(d, 0, κ·d)``."""
        curvature = ca.tan(self.steering_angle(k, u)) / named(self.kinematic_params, k)["wheelbase"]
        d = self.travel(k, u, curvature)
        if integration == "euler":
            return ca.vertcat(d, 0.0, curvature * d)
        return se2.arc(d, curvature * d)

    # --- the inputs --------------------------------------------------------------------------

    def _check_encoders(self, log: Log, steering_sample: str) -> None:
        if steering_sample not in STEERING_SAMPLES:
            raise ModelError(f"steering_sample must be one of {STEERING_SAMPLES}, got {steering_sample!r}")
        missing = [e for e in self.encoder_kinds if e not in log.header.encoder_names]
        if missing:
            raise ModelError(
                f"{log.path}: the {self.name} model needs encoders {list(self.encoder_kinds)}; the log has "
                f"{list(log.header.encoder_names)}"
            )

    def steering_rows(
        self, log: Log, steering_sample: str, travel: np.ndarray | None = None
    ) -> list[np.ndarray]:
        """Each steering encoder's angle ``wrap(2π·s/s_max)``, sampled as asked (``travel``: each
        interval's travel in any unit, for ``steering_sample: travel``)."""
        rows = []
        time_s = np.asarray(log.time_s, dtype=float)
        for enc, kind in self.encoder_kinds.items():
            if kind == "absolute":
                s_max = float(log.header.encoder_range(enc))
                angle = wrap_angle(2.0 * np.pi * log.encoder(enc) / s_max)
                rows.append(sampled_angle(angle, steering_sample, travel, time_s))
        return rows

    def inputs(self, log: Log, steering_sample: str) -> np.ndarray:
        """Rows: each wheel counter's increments, then each steering angle sampled as asked (the
        travel that weighs it, the counters' summed increments: only their speeds' ratio counts)."""
        self._check_encoders(log, steering_sample)
        wheels = [
            log.increments(e).astype(float) for e, kind in self.encoder_kinds.items() if kind == "counter"
        ]
        return np.vstack([*wheels, *self.steering_rows(log, steering_sample, np.sum(wheels, axis=0))])

    def input_rates(self, log: Log) -> None:
        """None: counts are re-sampled on whole ticks, so the intervals give the rates."""
        return None

    def wheel_rows(self) -> int:
        """How many input rows are wheel counters (they come first)."""
        return sum(kind == "counter" for kind in self.encoder_kinds.values())

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        return np.asarray(np.any(inputs[: self.wheel_rows()] != 0.0, axis=0))

    def travel_direction(self, inputs: np.ndarray) -> np.ndarray:
        """The sign of the wheels' summed increments (a car never turns on the spot)."""
        return np.sign(inputs[: self.wheel_rows()].sum(axis=0))

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """The rear track without enough tight turns: it moves the travel only through the rear
        wheels' split ``x = (d_r − d_l)/(d_r + d_l) = κ·T/2``, by ``x²`` of its relative error."""
        left, right = inputs[0], inputs[1]
        total = left + right
        split = np.abs(right - left) / np.where(total != 0.0, np.abs(total), np.inf)
        tight = int(np.sum(split >= TIGHT_SPLIT))
        if tight >= MIN_TIGHT:
            return {}
        return {
            "rear_track": (
                f"only {tight} intervals turn tighter than {0.5 / TIGHT_SPLIT:g} rear tracks' radius "
                f"(give the measured track; {MIN_TIGHT} are needed)"
            )
        }

    def counter_rows(self, log: Log) -> dict[str, tuple[int, float]]:
        """Each wheel counter drives its own row, in ticks."""
        counters = [e for e, kind in self.encoder_kinds.items() if kind == "counter"]
        return {e: (row, 1.0) for row, e in enumerate(counters)}

    def input_noise_std(self, log: Log, encoder_noise: Mapping[str, float] | None = None) -> np.ndarray:
        """1σ of each input: a counter's in ticks, a steering angle's in rad (default: quantisation)."""
        ticks = {**dict.fromkeys(self.encoder_kinds, QUANTISATION), **(encoder_noise or {})}
        wheels = [ticks[e] for e, kind in self.encoder_kinds.items() if kind == "counter"]
        angles = [
            2.0 * np.pi * ticks[e] / log.header.encoder_range(e)
            for e, kind in self.encoder_kinds.items()
            if kind == "absolute"
        ]
        return np.array([*wheels, *angles])

    # --- the hand-off ------------------------------------------------------------------------

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """ros2_control's steering controller for these joints: the wheelbase, the rear (traction)
        track and, where the counts per wheel turn are known, the traction wheels' radius; the
        steering gain and offset belong to the steering joints' transmission."""
        counters = [e for e, kind in self.encoder_kinds.items() if kind == "counter"]
        radii = [wheel_radius(params["k_traction"], e, scales) for e in counters]
        parameters = {"wheelbase": params["wheelbase"], **self.tracks(params)}
        unknown = [why for r, why in radii if r is None]
        omitted = {self.radius_name: unknown[0]} if unknown else {}
        if not unknown:
            parameters[self.radius_name] = float(np.mean([r for r, _ in radii]))
        return ControllerMap(
            self.controller_name,
            parameters,
            {
                **steering_places(params["k_steer"], params["steer_offset"], scales),
                **self.track_places(params),
            },
            omitted,
        )

    def tracks(self, params: Mapping[str, float]) -> dict[str, float]:
        """The controller's track widths."""
        return {"traction_track_width": params["rear_track"]}

    def track_places(self, params: Mapping[str, float]) -> dict[str, str]:
        """Where a track the controller does not take belongs (none here)."""
        return {}

    def in_radians(self) -> InRadians:
        """The car read from joint positions in radians (:data:`RADIANS`)."""
        return InRadians(self, RADIANS)

    def implausible(self, params: Mapping[str, float]) -> str:
        """Never: the canonical form turns the mirror image of the car into the car itself."""
        return ""

    # --- the closed-form start ---------------------------------------------------------------

    def mean_travel(self, rows: Mapping[str, np.ndarray]) -> np.ndarray:
        """Per interval of the windows, the rear wheels' mean increment (ticks)."""
        return 0.5 * (rows["rear_left_ticks"] + rows["rear_right_ticks"])

    def bicycle_angle(self, rows: Mapping[str, np.ndarray], k_steer: float, offset: float) -> np.ndarray:
        """Per interval of the windows, the bicycle-equivalent steering angle."""
        return k_steer * rows["steering_angle"] + offset

    def start_lengths(
        self, rows: Mapping[str, np.ndarray], steering: tuple[float, float], wheelbase: float
    ) -> dict[str, float]:
        """The lengths besides the wheelbase the closed form starts from (unit scale): a rear track
        of half the wheelbase, which the correction it enters makes all but neutral."""
        return {"rear_track": 0.5 * wheelbase}

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """Closed-form start from windows: inputs ``U``, sensor motions ``z (3, M)``.

        Heading changes ``Δθ = c·Σ m·tan φ`` (``m`` the rear wheels' mean ticks, ``c =
        k_traction/wheelbase``) give ``k_steer`` by a 1-D search and ``c`` and the offset by
        least squares, linearised about the offset; the hand-eye step then gives the sensor pose
        and ``k_traction``."""
        rows = rows_by_name(self.input_names, U)
        k_steer, offset, c = steering_start(self, rows, z[2])
        unit_wheelbase = 1.0 / max(abs(c), 1e-12)
        lengths = self.start_lengths(rows, (k_steer, offset), unit_wheelbase)
        unit = {"k_steer": k_steer, "steer_offset": offset, "k_traction": 1.0, "wheelbase": unit_wheelbase}
        unit.update({**lengths, "sensor_x": 0.0, "sensor_y": 0.0, "sensor_theta": 0.0})
        base = base_motion(unit)
        he = hand_eye(base[2], base[:2], z)
        x, y, theta = he.T_base_sensor
        out = {n: unit[n] for n in self.kinematic_params}
        out.update({n: he.scale * unit[n] for n in ("k_traction", "wheelbase", *lengths)})
        return {**out, "sensor_x": x, "sensor_y": y, "sensor_theta": theta}


def steering_start(
    model: CarLike, rows: Mapping[str, np.ndarray], dtheta: np.ndarray
) -> tuple[float, float, float]:
    """``k_steer``, ``steer_offset`` and ``c = k_traction/wheelbase`` from heading changes
    ``Δθ = c·Σ m·tan(φ)``: a search over ``k_steer``, each a least-squares fit of ``c`` and ``c``
    times the offset, linearised about the offset and refitted about the last."""
    m = model.mean_travel(rows)

    def fit(k_steer: float, offset: float = 0.0) -> tuple[float, float, float]:
        phi = model.bicycle_angle(rows, k_steer, offset)
        tan, sec2 = np.tan(phi), 1.0 + np.tan(phi) ** 2
        A = np.stack([(m * tan).sum(0), (m * sec2).sum(0)], 1)
        coef, *_ = np.linalg.lstsq(A, dtheta, rcond=None)
        r = dtheta - A @ coef
        c = float(coef[0])
        return (
            float(np.sum(np.minimum(r * r, 9.0 * np.median(r * r)))),
            c,
            offset + float(coef[1]) / (c or 1.0),
        )

    lo, hi = model.physical_ranges["k_steer"]
    grid = np.geomspace(lo, hi, 120)
    best = float(grid[int(np.argmin([fit(float(k))[0] for k in grid]))])
    a, b = best / 1.06, best * 1.06
    for _ in range(40):  # golden-section refinement between the grid neighbours
        m1, m2 = a + 0.382 * (b - a), a + 0.618 * (b - a)
        a, b = (a, m2) if fit(m1)[0] < fit(m2)[0] else (m1, b)
    k_steer, offset = 0.5 * (a + b), 0.0
    for _ in range(4):
        _, c, offset = fit(k_steer, offset)
    phi = model.bicycle_angle(rows, k_steer, offset)
    c = float(robust_lstsq((m * np.tan(phi)).sum(0)[:, None], dtheta)[0])
    return k_steer, float(wrap_angle(offset)), c
