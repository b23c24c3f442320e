"""Front-tractor tricycle: the front wheel steers and drives; base link at the rear-axle midpoint.

Parameters ``(k_steer, k_traction, axis_length, steer_offset)``; inputs per interval
``(traction_revolutions, steering_angle)``: the unwrapped traction increment divided by
``t_max``, and the steering encoder's angle ``wrap(2π·s/s_max)``. The steering angle is
``φ = k_steer·angle + steer_offset``, the front wheel travels ``d = k_traction·revolutions``, the
base moves ``v = d·cos φ`` and turns ``ω = d·sin φ / axis_length`` (exact arc or Euler).
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
    QUANTISATION,
    QUARTER_TURN,
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
from nlp_calib.models.drives import (
    Pose,
    SimulationSettings,
    arcs,
    counter,
    drive_header,
    first_order,
    integrate_base,
    running,
)
from nlp_calib.models.handeye import hand_eye, robust_lstsq
from nlp_calib.models.radians import WHEEL_RADIUS, InRadians, RadiansForm, Renamed
from nlp_calib.symbolic import se2

STEERING_ENCODER = "steering"
TRACTION_ENCODER = "traction_wheel"


#: The tricycle read from joint positions in radians: the traction wheel's radius (its travel is
#: radius × Δangle) and the wheelbase, as ``tricycle_controller`` names them.
RADIANS = RadiansForm(
    params=MappingProxyType(
        {
            "k_traction": Renamed("wheel_radius", "m", 2.0 * np.pi, plausible=WHEEL_RADIUS),
            "axis_length": Renamed("wheelbase", "m"),
        }
    ),
    inputs=MappingProxyType(
        {
            "traction_revolutions": Renamed("traction_angle", "rad", 1.0 / (2.0 * np.pi), TRACTION_ENCODER),
            "steering_angle": Renamed("steering_angle", "rad", 1.0, STEERING_ENCODER),
        }
    ),
)


class TricycleDrive:
    """Front wheel drives at ``speed`` and steers to ``turn`` (rad); encoders: steering, traction.

    ``steering`` is absolute over ``s_max`` ticks a turn, ``traction_wheel`` counts ``t_max`` ticks
    per ``k_traction`` metres."""

    default_truth: Mapping[str, float] = MappingProxyType(
        {
            "k_steer": 0.55,
            "k_traction": 0.0105,
            "axis_length": 1.5,
            "steer_offset": -0.05,
            "sensor_x": 1.6,
            "sensor_y": 0.1,
            "sensor_theta": 0.05,
        }
    )
    default_guess: Mapping[str, float] = MappingProxyType(
        {
            "k_steer": 0.5,
            "k_traction": 0.01,
            "axis_length": 1.4,
            "steer_offset": 0.0,
            "sensor_x": 1.5,
            "sensor_y": 0.0,
            "sensor_theta": 0.0,
        }
    )
    default_ranges: Mapping[str, int] = MappingProxyType({STEERING_ENCODER: 8192, TRACTION_ENCODER: 5000})
    #: A robot whose controller integrates its odometry with a wrong model (joint units: the
    #: traction wheel's travel in m per revolution), and that model: the vendor odometry
    #: simulator's defaults.
    vendor_truth: Mapping[str, float] = MappingProxyType(
        {"k_steer": 0.55, "k_traction": 0.5, "axis_length": 1.5, "steer_offset": -0.05}
    )
    vendor_model: Mapping[str, float] = MappingProxyType(
        {"k_steer": 0.5, "k_traction": 0.49, "axis_length": 1.45, "steer_offset": 0.0}
    )

    def odometry(self, joints: Mapping[str, np.ndarray], params: Mapping[str, float]) -> np.ndarray:
        """The base poses ``(n, 3)`` a controller integrates (exact arcs) from the traction and
        steering joints' angles with its own model ``params``, each interval steered by the
        angle read at its end (the controller's latest reading)."""
        d = params["k_traction"] * np.diff(joints["traction_wheel_joint"]) / (2.0 * np.pi)
        phi = params["k_steer"] * joints["steering_joint"][1:] + params["steer_offset"]
        return integrate_base(d * np.cos(phi), d * np.sin(phi) / params["axis_length"])

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
        d = speed * dt
        ds, w = d * np.cos(turn), d * np.sin(turn) / opts.truth["axis_length"]
        first: Mapping[str, float | None] = carry or {"front": None, "phi": turn_start, "direction": 0.0}
        channels = {"front": running(d, first["front"]), "phi": np.concatenate([[first["phi"]], turn_end])}
        channels["direction"] = np.concatenate([[first["direction"]], np.sign(d)])
        return ds, w, channels

    def steering_gain(self, truth: Mapping[str, float], direction: np.ndarray) -> np.ndarray:
        """The true steering gain at each sample, given the direction the wheel rolls there."""
        return np.full(direction.shape, truth["k_steer"])

    def ticks(self, opts: SimulationSettings, channels: Mapping[str, np.ndarray]) -> np.ndarray:
        t = opts.truth
        s_max, t_max = opts.encoder_ranges[STEERING_ENCODER], opts.encoder_ranges[TRACTION_ENCODER]
        gain = self.steering_gain(t, np.sign(channels["direction"]))
        steer = np.mod(np.round((channels["phi"] - t["steer_offset"]) / gain * s_max / (2 * np.pi)), s_max)
        traction = counter(channels["front"], t["k_traction"] / t_max, opts.wrap_after_ticks)
        return np.stack([steer.astype(np.int64), traction], axis=1)

    def header(self, opts: SimulationSettings) -> LogHeader:
        return drive_header(opts, "traction_drive_wheel", Tricycle.header_names)

    def vendor_odometry(self, header: LogHeader, ticks: np.ndarray, start: Pose | None = None) -> np.ndarray:
        # The vendor's odometry knows the plain tricycle only.
        p = {
            Tricycle.header_aliases[n.lower()]: v
            for n, v in header.parameters.items()
            if n.lower() in Tricycle.header_aliases
        }
        s_max, t_max = header.encoder_max
        d = p["k_traction"] * wrapped_difference(ticks[:, 1]) / t_max
        phi = p["k_steer"] * wrap_angle(2 * np.pi * ticks[:-1, 0] / s_max) + p["steer_offset"]
        return first_order(d * np.cos(phi), d * np.sin(phi) / p["axis_length"], start)


class Tricycle:
    """Front-wheel-drive bicycle model of a tricycle, parameters ``(k_steer, k_traction,
    axis_length, steer_offset)`` then the sensor pose ``(sensor_x, sensor_y, sensor_theta)``."""

    name: ClassVar[str] = "tricycle"
    log_names: ClassVar[tuple[str, ...]] = ("traction_drive_wheel", "tricycle")
    kinematic_params: ClassVar[tuple[str, ...]] = ("k_steer", "k_traction", "axis_length", "steer_offset")
    units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"k_steer": "1", "k_traction": "m per t_max ticks", "axis_length": "m", "steer_offset": "rad"}
    )
    header_names: ClassVar[Mapping[str, str]] = MappingProxyType(
        {
            "k_steer": "Ksteer",
            "k_traction": "Ktraction",
            "axis_length": "axis_length",
            "steer_offset": "steer_offset",
        }
    )
    header_aliases: ClassVar[Mapping[str, str]] = MappingProxyType(
        {
            "ksteer": "k_steer",
            "k_steer": "k_steer",
            "ktraction": "k_traction",
            "k_traction": "k_traction",
            "axis_length": "axis_length",
            "base_line": "axis_length",
            "steer_offset": "steer_offset",
        }
    )
    encoder_kinds: ClassVar[Mapping[str, EncoderKind]] = MappingProxyType(
        {STEERING_ENCODER: "absolute", TRACTION_ENCODER: "counter"}
    )
    turning_params: ClassVar[tuple[str, ...]] = ("axis_length",)
    turning_note: ClassVar[str] = "the split between steering gain and offset"
    input_names: ClassVar[tuple[str, ...]] = ("traction_revolutions", "steering_angle")
    input_units: ClassVar[Mapping[str, str]] = MappingProxyType(
        {"traction_revolutions": "rev", "steering_angle": "rad"}
    )
    level_inputs: ClassVar[tuple[str, ...]] = ("steering_angle",)
    reference: ClassVar[Mapping[str, Reference]] = MappingProxyType({"steer_offset": ("absolute", 0.005)})
    headline: ClassVar[tuple[str, ...]] = ("k_traction", "axis_length")
    defaults: ClassVar[Mapping[str, float]] = MappingProxyType({})
    symmetries: ClassVar[tuple[Symmetry, ...]] = (
        Symmetry(
            "the base frame turned round",
            "axis_length",
            ("axis_length", *SENSOR_TURNED[0]),
            ("steer_offset", *SENSOR_TURNED[1]),
        ),
        Symmetry(
            "the wheel turned round, counting backwards", "k_traction", ("k_traction",), ("steer_offset",)
        ),
    )
    angle_params: ClassVar[tuple[str, ...]] = ("steer_offset", "sensor_theta")
    #: The steered wheel drives the base: it turns it on the spot at a quarter turn (industrial
    #: tricycles steer ±90° and more).
    steer_max: ClassVar[float | None] = QUARTER_TURN
    drive: ClassVar[TricycleDrive] = TricycleDrive()
    physical_ranges: ClassVar[Mapping[str, tuple[float, float]]] = MappingProxyType(
        {
            "k_steer": (0.01, 3.0),
            "k_traction": (1e-4, 10.0),
            "axis_length": (0.1, 10.0),
            "steer_offset": (-0.5, 0.5),
            "sensor_x": (-5.0, 5.0),
            "sensor_y": (-5.0, 5.0),
            "sensor_theta": (-np.pi, np.pi),
        }
    )

    def reach(self, params: Mapping[str, float], steer_max: float | None = None) -> Reach:
        """The rear-axle midpoint's tightest turn, ``axis_length / tan φ_max`` (0 at a quarter turn)."""
        return steered_reach(params["axis_length"], QUARTER_TURN if steer_max is None else steer_max)

    def steering_angle(self, k: ca.SX, u: ca.SX) -> ca.SX:
        """``φ = k_steer·angle + steer_offset``."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        return p["k_steer"] * inputs["steering_angle"] + p["steer_offset"]

    def increment(self, k: ca.SX, u: ca.SX, integration: str) -> ca.SX:
        """``v = d·cos φ``, ``ω = d·sin φ / L``; exact arc or Euler ``(v, 0, ω)``."""
        p, inputs = named(self.kinematic_params, k), named(self.input_names, u)
        k_traction, axis_length = p["k_traction"], p["axis_length"]
        phi = self.steering_angle(k, u)
        d = k_traction * inputs["traction_revolutions"]
        v = d * ca.cos(phi)
        omega = d * ca.sin(phi) / axis_length
        if integration == "euler":
            return ca.vertcat(v, 0.0, omega)
        return se2.arc(v, omega)

    def inputs(self, log: Log, steering_sample: str) -> np.ndarray:
        """Rows: traction revolutions ``Δt/t_max`` and the steering angle sampled as asked."""
        header = log.header
        if steering_sample not in STEERING_SAMPLES:
            raise ModelError(f"steering_sample must be one of {STEERING_SAMPLES}, got {steering_sample!r}")
        for enc in (STEERING_ENCODER, TRACTION_ENCODER):
            if enc not in header.encoder_names:
                raise ModelError(
                    f"{log.path}: the tricycle model needs encoders {STEERING_ENCODER!r} and "
                    f"{TRACTION_ENCODER!r}; the log has {list(header.encoder_names)}"
                )
        s_max = header.encoder_max[header.encoder_index(STEERING_ENCODER)]
        t_max = header.encoder_max[header.encoder_index(TRACTION_ENCODER)]
        revs = log.increments(TRACTION_ENCODER) / float(t_max)
        angle = wrap_angle(2.0 * np.pi * log.encoder(STEERING_ENCODER) / float(s_max))
        return np.vstack([revs, sampled_angle(angle, steering_sample, revs, np.asarray(log.time_s))])

    def moving(self, inputs: np.ndarray) -> np.ndarray:
        return np.asarray(inputs[0] != 0.0)

    def travel_direction(self, inputs: np.ndarray) -> np.ndarray:
        """The sign of the traction increment (the front wheel never steers past 90°)."""
        return np.sign(inputs[0])

    def undetermined(self, inputs: np.ndarray) -> dict[str, str]:
        """None: every parameter can be determined (the observability analysis judges how well)."""
        return {}

    def controller(self, params: Mapping[str, float], scales: EncoderScales) -> ControllerMap:
        """``tricycle_controller``: the wheelbase is the axis length; the traction wheel's radius is
        its travel per ``t_max`` ticks times the ticks per wheel turn over 2π, written only when
        those are known; the steering gain and offset belong to the steering joint's transmission."""
        t_max = float(scales.ranges.get(TRACTION_ENCODER, 0.0)) or 1.0
        radius, why = wheel_radius(params["k_traction"] / t_max, TRACTION_ENCODER, scales)
        parameters = {"wheelbase": params["axis_length"], **({"wheel_radius": radius} if radius else {})}
        return ControllerMap(
            "tricycle_controller",
            parameters,
            steering_places(params["k_steer"], params["steer_offset"], scales),
            {"wheel_radius": why} if why else {},
        )

    def input_rates(self, log: Log) -> None:
        """None: counts are re-sampled on whole ticks, so the intervals give the rates."""
        return None

    def in_radians(self) -> InRadians:
        """The tricycle read from joint positions in radians (:data:`RADIANS`)."""
        return InRadians(self, RADIANS)

    def implausible(self, params: Mapping[str, float]) -> str:
        """Never: the canonical form turns every mirror image of the tricycle into the robot itself."""
        return ""

    def counter_rows(self, log: Log) -> dict[str, tuple[int, float]]:
        """The traction counter drives row 0, in revolutions of ``t_max`` ticks."""
        return {TRACTION_ENCODER: (0, float(log.header.encoder_range(TRACTION_ENCODER)))}

    def input_noise_std(self, log: Log, encoder_noise: Mapping[str, float] | None = None) -> np.ndarray:
        """1σ of each input from the encoders' noise in ticks (default: quantisation, ``1/√12``)."""
        header = log.header
        s_max = header.encoder_max[header.encoder_index(STEERING_ENCODER)]
        t_max = header.encoder_max[header.encoder_index(TRACTION_ENCODER)]
        ticks = {**dict.fromkeys((TRACTION_ENCODER, STEERING_ENCODER), QUANTISATION), **(encoder_noise or {})}
        return np.array([ticks[TRACTION_ENCODER] / t_max, 2.0 * np.pi * ticks[STEERING_ENCODER] / s_max])

    def steering_gain(self, params: Mapping[str, float], backwards: np.ndarray) -> np.ndarray:
        """The steering joint's gain in each interval, given whether the base drives backwards."""
        return np.full(backwards.shape, params["k_steer"])

    def readings_from_odometry(self, base: np.ndarray, params: Mapping[str, float]) -> dict[str, np.ndarray]:
        """The traction wheel's revolutions (from 0) and the steering angle (rad) a controller of
        model ``params`` read to drive the base poses ``base`` ``(n, 3)`` (each interval steered
        by the angle at its end): each step an arc ``s`` turning ``Δθ``, the front wheel's travel
        ``±√(s² + (axis_length·Δθ)²)`` at ``φ = atan(axis_length·Δθ / s)``; at a stop the
        steering holds its last angle."""
        arc, turn = arcs(base)
        lever = params["axis_length"] * turn
        travel, phi = np.hypot(arc, lever), np.arctan2(lever, arc)
        back = np.abs(phi) > 0.5 * np.pi  # reversing: the wheel rolls backwards, steered ahead
        phi = np.where(back, phi - np.pi * np.sign(phi), phi)
        moving = travel > 1e-9
        last = np.maximum.accumulate(np.where(moving, np.arange(phi.size), 0))
        steer = (phi[last] - params["steer_offset"]) / self.steering_gain(params, back[last])
        return {
            STEERING_ENCODER: np.concatenate([steer[:1], steer]),
            TRACTION_ENCODER: running(np.where(back, -travel, travel) / params["k_traction"]),
        }

    def initial_guess(
        self,
        U: np.ndarray,
        z: np.ndarray,
        base_motion: Callable[[Mapping[str, float]], np.ndarray],
    ) -> dict[str, float]:
        """Closed-form start from windows: inputs ``U (2H, M)``, sensor motions ``z (3, M)``.

        Heading changes give ``k_steer``, ``steer_offset`` and ``c = k_traction/axis_length``
        (``Δθ = c·Σ r·sin(k_steer·a + offset)``: a 1-D search over ``k_steer``, linear in the
        rest); the hand-eye step then gives the sensor pose and ``k_traction``.
        """
        rows = rows_by_name(self.input_names, U)
        revs, angle = rows["traction_revolutions"], rows["steering_angle"]
        dtheta = z[2]

        design = _heading_design(revs, angle)

        def rss(k_steer: float) -> float:
            A = design(k_steer)
            coef, *_ = np.linalg.lstsq(A, dtheta, rcond=None)
            r = dtheta - A @ coef
            return float(np.sum(np.minimum(r * r, 9.0 * np.median(r * r))))  # trimmed: outliers

        lo, hi = self.physical_ranges["k_steer"]
        grid = np.geomspace(lo, hi, 200)
        best = int(np.argmin([rss(float(k)) for k in grid]))
        a, b = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
        for _ in range(40):  # golden-section refinement between the grid neighbours
            m1, m2 = a + 0.382 * (b - a), a + 0.618 * (b - a)
            a, b = (a, m2) if rss(m1) < rss(m2) else (m1, b)
        k_steer = 0.5 * (a + b)
        alpha, beta = robust_lstsq(design(k_steer), dtheta)
        c = float(np.hypot(alpha, beta))
        offset = float(np.arctan2(beta, alpha))
        unit = {
            "k_steer": k_steer,
            "k_traction": 1.0,
            "axis_length": 1.0 / max(c, 1e-9),
            "steer_offset": offset,
        }
        unit.update({"sensor_x": 0.0, "sensor_y": 0.0, "sensor_theta": 0.0})
        base = base_motion(unit)
        he = hand_eye(base[2], base[:2], z)
        x, y, theta = he.T_base_sensor
        return {
            "k_steer": k_steer,
            "k_traction": he.scale,
            "axis_length": he.scale / max(c, 1e-9),
            "steer_offset": offset,
            "sensor_x": x,
            "sensor_y": y,
            "sensor_theta": theta,
        }


def _heading_design(revs: np.ndarray, angle: np.ndarray) -> Callable[[float], np.ndarray]:
    """``k_steer -> [Σ r·sin(k_steer·a), Σ r·cos(k_steer·a)]`` per window (``(M, 2)``). An encoder's
    angles take few values: the sine and cosine of each value once, then gathered (the same
    numbers, a quarter of the search's time)."""
    values, where = np.unique(angle, return_inverse=True)
    few, where = 2 * values.size <= angle.size, where.reshape(angle.shape)

    def design(k_steer: float) -> np.ndarray:
        if few:
            ka = k_steer * values
            sin, cos = np.sin(ka)[where], np.cos(ka)[where]
        else:
            sin, cos = np.sin(k_steer * angle), np.cos(k_steer * angle)
        return np.stack([(revs * sin).sum(0), (revs * cos).sum(0)], 1)

    return design
