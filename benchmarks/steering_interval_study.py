"""Which part of the tricycle's interval model biases the steering gain?

    python benchmarks/steering_interval_study.py                  # seed 4243, 20000 records
    python benchmarks/steering_interval_study.py --seed 4244 --stops 0

On a noise-free simulated drive, each parameter's Gauss-Newton step from the truth (lag 0) is the
bias the model's error gives it (the demo's residual options: horizon 10, exact arcs). Printed for
k_steer and the tracker lag:

- the simulator's track, fitted with the readings' mean as it was read before (no curvature
  correction), with ``mean`` and with ``travel`` as they are read now;
- tracks integrated from the log's own readings instead of the simulator's, each removing one
  effect the model leaves out: (b) the sine and cosine of a changing angle (the mean of ``sin``
  over a linear change is ``sin(φ̄)·sinc(Δφ/2)``), (c) the chord of a curvature linear over the
  interval (turned by ``−d·Δφ/(12·L·cos φ̄)``), and a fine integration of the angle linear in
  travel (both, exactly);
- the simulator itself: 200 sub-steps instead of 20, and a steering encoder of 2²⁰ ticks.

``--model car_like`` (or ``car_like_ackermann``, ``car_like_bicycle``) decomposes a car's, whose
curvature is ``tan φ / wheelbase``: each steering row replaced by the angle that makes the model's
bicycle angle (the Ackermann pair's mean) a reference, in turn the mean angle and the mean tangent
the travel saw, from a quadratic through the readings (the curvature correction's own reading) and
from the simulator's sub-steps; then the sub-steps' exact curvature with the counters' travel
unrounded. ``--ticks 20`` reads the steering on 2²⁰ ticks, ``--substeps 200`` refines the simulator,
``--horizon 1`` fits one-interval windows (a scenario's default).
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import Log
from nlp_calib.models import get_model, load_log
from nlp_calib.models.base import curvature_correction, record_rates
from nlp_calib.models.drives import integrate_base
from nlp_calib.problem import ProblemSpec, build, build_residual_data
from nlp_calib.problem.windows import ResidualOptions
from nlp_calib.simulation.blocks import _plan
from nlp_calib.simulation.options import profiles_on
from nlp_calib.simulation.simulate import SimulatedLog, SimulationOptions, simulate, write_simulation
from nlp_calib.solvers import ProblemEvaluator

MODEL = get_model("tricycle")
FNS = build(MODEL, ProblemSpec(horizon=10, lags=1))
FINE = 64


def _step(
    log: Log, truth: dict[str, float], sample: str, inputs: np.ndarray | None = None
) -> dict[str, float]:
    data = build_residual_data(FNS, log, ResidualOptions(horizon=10, steering_sample=sample), inputs=inputs)
    ev = ProblemEvaluator(FNS, data, x_fixed=np.zeros(0), omega=np.ones(3), delta=1e9)
    ne = ev.normal_equations(np.array([*(truth[n] for n in FNS.names[:-1]), 0.0]))
    return dict(zip(FNS.names, -np.linalg.solve(ne.H, ne.g)))


def _arcs(d: np.ndarray, phi: np.ndarray, length: float, scale: np.ndarray, chord: np.ndarray) -> np.ndarray:
    """Base poses from exact arcs ``(d·cos φ, d·sin φ / L)·scale``, each chord turned by ``chord``."""
    v, w = d * np.cos(phi) * scale, d * np.sin(phi) * scale / length
    small = np.abs(w) < 1e-12
    ws = np.where(small, 1.0, w)
    a = np.where(small, v, v * np.sin(ws) / ws)
    b = np.where(small, 0.5 * v * w, v * (1.0 - np.cos(ws)) / ws)
    a, b = np.cos(chord) * a - np.sin(chord) * b, np.sin(chord) * a + np.cos(chord) * b
    theta = np.concatenate([[0.0], np.cumsum(w)])
    c, s = np.cos(theta[:-1]), np.sin(theta[:-1])
    return np.stack([np.concatenate([[0.0], np.cumsum(c * a - s * b)]),
                     np.concatenate([[0.0], np.cumsum(s * a + c * b)]), theta], 1)  # fmt: skip


def _fine(d: np.ndarray, phi0: np.ndarray, phi1: np.ndarray, length: float) -> np.ndarray:
    """Base poses integrated on :data:`FINE` sub-arcs per interval, the angle linear in travel."""
    u = (np.arange(FINE) + 0.5) / FINE
    phi = phi0[:, None] + (phi1 - phi0)[:, None] * u[None]
    ds = d[:, None] / FINE
    return integrate_base((ds * np.cos(phi)).ravel(), (ds * np.sin(phi) / length).ravel())[::FINE]


def _tracked(log: Log, base: np.ndarray, start: np.ndarray, truth: dict[str, float]) -> Log:
    """``log`` whose tracker saw the sensor on ``base`` (from the origin) placed at ``start``."""
    c0, s0 = np.cos(start[2]), np.sin(start[2])
    x, y = start[0] + c0 * base[:, 0] - s0 * base[:, 1], start[1] + s0 * base[:, 0] + c0 * base[:, 1]
    th = base[:, 2] + start[2]
    mx, my = truth["sensor_x"], truth["sensor_y"]
    sensor = np.stack(
        [x + np.cos(th) * mx - np.sin(th) * my, y + np.sin(th) * mx + np.cos(th) * my,
         wrap_angle(th + truth["sensor_theta"])], 1)  # fmt: skip
    return replace(log, T_world_sensor=sensor)


def _references(sim: SimulatedLog, log: Log, truth: dict[str, float], s_max: int) -> dict[str, Log]:
    a = wrap_angle(2.0 * np.pi * log.encoder("steering") / float(s_max))
    phi0 = truth["k_steer"] * a[:-1] + truth["steer_offset"]
    dphi = truth["k_steer"] * wrap_angle(np.diff(a))
    phi = phi0 + 0.5 * dphi
    d, length = truth["k_traction"] * MODEL.inputs(log, "start")[0], truth["axis_length"]
    sinc = np.sinc(dphi / (2.0 * np.pi))
    chord = -d * dphi / (12.0 * length * np.cos(phi))
    tracks = {
        "(b) sin/cos of a changing angle": _arcs(d, phi, length, sinc, np.zeros_like(d)),
        "(b)+(c) and the chord": _arcs(d, phi, length, sinc, chord),
        "fine, angle linear in travel": _fine(d, phi0, phi0 + dphi, length),
    }
    start = sim.T_world_base_true[0]
    return {name: _tracked(log, base, start, truth) for name, base in tracks.items()}


def _drive(args: argparse.Namespace, substeps: int, s_max: int) -> tuple[SimulatedLog, Log]:
    opts = SimulationOptions.of(
        records=args.records, seed=args.seed, tracker_noise_xy=0.0, tracker_noise_theta=0.0,
        stop_fraction=args.stops, substeps=substeps, rate_hz=args.rate,
        encoder_ranges={"steering": s_max},
    )  # fmt: skip
    sim = simulate(opts)
    path, _ = write_simulation(sim, Path(tempfile.mkdtemp()) / "drive.txt")
    return sim, load_log(path, MODEL)


def _show(what: str, step: dict[str, float]) -> None:
    print(f"{what:70s} k_steer {step['k_steer']:+.2e}  tracker_lag {step['tracker_lag'] * 1e3:+.4f} ms")


def _tricycle(args: argparse.Namespace) -> None:
    sim, log = _drive(args, 20, 8192)
    truth = dict(sim.options.truth)
    a = wrap_angle(2.0 * np.pi * log.encoder("steering") / 8192.0)
    plain = np.vstack([MODEL.inputs(log, "start")[0], wrap_angle(a[:-1] + 0.5 * wrap_angle(np.diff(a)))])
    _show("simulator, readings' mean (uncorrected)", _step(log, truth, "mean", plain))
    for sample in ("mean", "travel"):
        _show(f"simulator, {sample} (curvature-corrected)", _step(log, truth, sample))
    for name, ref in _references(sim, log, truth, 8192).items():
        _show(f"track from the readings: {name}, readings' mean", _step(ref, truth, "mean", plain))
    for substeps, s_max in ((200, 8192), (20, 2**20)):
        _, log2 = _drive(args, substeps, s_max)
        a2 = wrap_angle(2.0 * np.pi * log2.encoder("steering") / float(s_max))
        plain2 = np.vstack(
            [MODEL.inputs(log2, "start")[0], wrap_angle(a2[:-1] + 0.5 * wrap_angle(np.diff(a2)))]
        )
        _show(
            f"simulator, {substeps} sub-steps, 2^{int(np.log2(s_max))} ticks, readings' mean",
            _step(log2, truth, "mean", plain2),
        )


class _Car:
    """A car's noise-free drive, its log and the Gauss-Newton step of any of its inputs."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.model = get_model(args.model)
        self.horizon = args.horizon
        self.fns = build(self.model, ProblemSpec(horizon=args.horizon, lags=1))
        ranges = {e: 2**args.ticks for e, kind in self.model.encoder_kinds.items() if kind == "absolute"}
        self.opts = SimulationOptions.of(
            model=args.model, records=args.records, seed=args.seed, tracker_noise_xy=0.0,
            tracker_noise_theta=0.0, stop_fraction=args.stops, substeps=args.substeps, rate_hz=args.rate,
            encoder_ranges=ranges,
        )  # fmt: skip
        path, _ = write_simulation(simulate(self.opts), Path(tempfile.mkdtemp()) / "drive.txt")
        self.log, self.truth = load_log(path, self.model), dict(self.opts.truth)
        self.mean = self.model.inputs(self.log, "mean")
        names = self.model.input_names
        self.steer = [i for i, n in enumerate(names) if self.model.input_units[n] == "rad"]
        self.wheels = [i for i, n in enumerate(names) if self.model.input_units[n] == "ticks"]
        self.angles = [
            wrap_angle(2.0 * np.pi * self.log.encoder(e) / float(self.log.header.encoder_range(e)))
            for e, kind in self.model.encoder_kinds.items()
            if kind == "absolute"
        ]

    def step(self, inputs: np.ndarray) -> dict[str, float]:
        options = ResidualOptions(horizon=self.horizon, steering_sample="mean")
        data = build_residual_data(self.fns, self.log, options, inputs=inputs)
        ev = ProblemEvaluator(self.fns, data, x_fixed=np.zeros(0), omega=np.ones(3), delta=1e9)
        ne = ev.normal_equations(np.array([*(self.truth[n] for n in self.fns.names[:-1]), 0.0]))
        return dict(zip(self.fns.names, -np.linalg.solve(ne.H, ne.g)))

    def phi(self, wheel: np.ndarray | list[np.ndarray]) -> np.ndarray:
        """The bicycle angle of the steering joints' wheel angles (one joint: itself)."""
        if len(self.steer) == 1:
            return wheel[0]
        length, half = self.truth["wheelbase"], 0.5 * self.truth["steering_track"]
        tl, tr = np.tan(wheel[0]), np.tan(wheel[1])
        return 0.5 * (
            np.arctan(length * tl / (length + half * tl)) + np.arctan(length * tr / (length - half * tr))
        )

    def reading(self, phi: np.ndarray) -> np.ndarray:
        """The ``mean`` inputs with the steering rows moved so the model's bicycle angle is ``phi``:
        an Ackermann pair's both joints by one shift (Newton on it), their split as read, since the
        Gauss-Newton step's Jacobian follows each joint's reading, not only the angle they give."""
        u = self.mean.copy()
        k, off = self.truth["k_steer"], self.truth["steer_offset"]
        for _ in range(1 if len(self.steer) == 1 else 4):
            shift = (phi - self.phi([k * u[row] + off for row in self.steer])) / k
            for row in self.steer:
                u[row] = u[row] + shift
        return u


def _car_quadratic(car: _Car) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per interval, the bicycle angle of each joint's mean angle the travel saw (the model's
    reading of the Ackermann pair), the mean bicycle angle and the mean tangent the travel saw, each
    joint's angle the quadratic through its readings whose mean the curvature correction gives,
    the speed linear."""
    t = np.asarray(car.log.time_s, dtype=float)
    u = (np.arange(FINE) + 0.5) / FINE
    v = np.abs(record_rates(car.mean[car.wheels].sum(0)[None], t)[0])
    w = v[:-1, None] + (v[1:] - v[:-1])[:, None] * u[None]
    w[w.sum(1) == 0.0] = 1.0
    wheel = []
    for a in car.angles:
        bend = -6.0 * curvature_correction(a, t)[:, None] * u[None] * (u[None] - 1.0)
        wheel.append(car.truth["k_steer"] * (a[:-1, None] + wrap_angle(np.diff(a))[:, None] * u[None] + bend))
    wheel = [x + car.truth["steer_offset"] for x in wheel]
    pair = car.phi([(w * x).sum(1) / w.sum(1) for x in wheel])
    phi = car.phi(wheel)
    return pair, (w * phi).sum(1) / w.sum(1), np.arctan((w * np.tan(phi)).sum(1) / w.sum(1))


def _car_simulator(car: _Car, substeps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per interval, from the simulator's sub-steps: the mean angle and the mean tangent the travel
    saw, and the inputs of both, the counters' travel unrounded."""
    t = np.asarray(car.log.time_s, dtype=float)
    frac = np.arange(substeps) / substeps
    fine = np.concatenate([(t[:-1, None] + np.diff(t)[:, None] * frac).ravel(), t[-1:]])
    speed, turn, _ = profiles_on(_plan(car.opts, car.opts.records).knots, fine, 0.0)
    ds, phi = (speed * np.diff(fine)).reshape(-1, substeps), turn.reshape(-1, substeps)
    travel = ds.sum(1)
    per = np.where(travel != 0.0, travel, 1.0)
    mean, tan = (ds * phi).sum(1) / per, np.arctan((ds * np.tan(phi)).sum(1) / per)
    exact = car.reading(tan)
    k = car.truth["k_traction"]
    if len(car.wheels) == 1:
        exact[car.wheels[0]] = travel / k
    else:
        half = 0.5 * np.tan(phi) / car.truth["wheelbase"] * car.truth["rear_track"]
        exact[car.wheels[0]], exact[car.wheels[1]] = (
            (ds * (1 - half)).sum(1) / k,
            (ds * (1 + half)).sum(1) / k,
        )
    return mean, tan, exact


def _show_car(what: str, step: dict[str, float]) -> None:
    rear = f"  rear_track {step['rear_track']:+.2e} m" if "rear_track" in step else ""
    print(
        f"{what:62s} k_steer {step['k_steer']:+.2e}  wheelbase {step['wheelbase']:+.2e} m  "
        f"tracker_lag {step['tracker_lag'] * 1e6:+.2f} us{rear}"
    )


def _car(args: argparse.Namespace) -> None:
    car = _Car(args)
    plain = car.mean.copy()
    for row, a in zip(car.steer, car.angles):
        plain[row] = wrap_angle(a[:-1] + 0.5 * wrap_angle(np.diff(a)))
    _show_car("readings' mean (uncorrected)", car.step(plain))
    _show_car("mean (curvature-corrected)", car.step(car.mean))
    _show_car("travel (curvature-corrected)", car.step(car.model.inputs(car.log, "travel")))
    pair, mean, tan = _car_quadratic(car)
    if len(car.steer) > 1:
        _show_car(
            "readings' quadratic: the pair of each joint's mean the travel saw", car.step(car.reading(pair))
        )
    _show_car("readings' quadratic: tan of the mean angle the travel saw", car.step(car.reading(mean)))
    _show_car("readings' quadratic: mean tan the travel saw", car.step(car.reading(tan)))
    mean, tan, exact = _car_simulator(car, args.substeps)
    _show_car("simulator: tan of the mean angle the travel saw", car.step(car.reading(mean)))
    _show_car("simulator: mean tan the travel saw (its curvature)", car.step(car.reading(tan)))
    _show_car("simulator: its curvature, the counters' travel unrounded", car.step(exact))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--model",
        default="tricycle",
        choices=("tricycle", "car_like", "car_like_ackermann", "car_like_bicycle"),
    )
    parser.add_argument("--seed", type=int, default=4243)
    parser.add_argument("--records", type=int, default=20000)
    parser.add_argument("--rate", type=float, default=25.0)
    parser.add_argument("--stops", type=float, default=0.15)
    parser.add_argument("--ticks", type=int, default=13, help="a car's steering encoder: 2^ticks a turn")
    parser.add_argument("--substeps", type=int, default=20, help="a car's simulator sub-steps")
    parser.add_argument("--horizon", type=int, default=10, help="a car's windows, in intervals")
    args = parser.parse_args()
    if args.model == "tricycle":
        _tricycle(args)
    else:
        _car(args)


if __name__ == "__main__":
    main()
