"""Independent checks of a real car's calibration from its data alone, and its odometry's σ against
the drift the reference shows.

    python benchmarks/real_car_checks.py OUT                    # the converter's car.csv, car.tum
    python benchmarks/real_car_checks.py OUT --noise SCENARIO   # and the odometry's σ

``OUT``: a folder ``benchmarks/polimi_car_convert.py`` wrote (a steering wheel's angle and a speed
per row of ``car.csv``, the front antenna's pose headed from the rear one in ``car.tum``). Without
any model fit, from the reference and the joints:

- the speed's scale: each stretch's path length (the antenna's, between gaps) over the speed's
  integral at the same times (zero readings amid motion, a speedometer's dropouts, left out);
- the antennas' line against the travel direction: ``travel - line = atan(x·κ) - θ`` for the
  front antenna ``x`` ahead of the rear axle, its yaw ``θ`` off the car's axis, κ the path's
  curvature (the heading's rate over the speed), fitted by least squares (with a term in the lateral
  acceleration beside, a rear axle that slides);
- the steering: ``atan(L·κ) = k·wheel + offset + u·a_lat`` (``L`` the wheelbase given, ``u`` an
  understeer gradient), the steering ratio ``1/k``;
- the lag: the reference's speed against the wheel's, and its turn rate against the bicycle's
  from the steering wheel, each over lags on a 5 ms grid (the least squares' vertex).

``--noise SCENARIO``: the scenario calibrated, then its odometry's σ over the σ whose 2σ holds 95 %
of the errors against the reference's base poses (the sensor's poses moved through the calibrated
mount), per component, as ``benchmarks/vehicle_noise.py`` scores a simulated car against its
truth; spans across a gap in the reference's time are left out. The σ are white (least squares);
the scatter over the stretches or blocks is printed beside where it says more.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

#: This checkout (its code, not an installed one's, is what runs), and the tests' truth helper.
REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

#: The course's wheelbase (m); a stretch ends at a gap in the reference longer than this (s).
WHEELBASE_M, GAP_S = 1.765, 0.15


def _fit(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least squares' coefficients and their white σ."""
    c, *_ = np.linalg.lstsq(A, y, rcond=None)
    r = y - A @ c
    cov = np.linalg.inv(A.T @ A) * float(r @ r) / max(len(r) - A.shape[1], 1)
    return c, np.sqrt(np.diag(cov))


def _load(out: Path) -> tuple[np.ndarray, ...]:
    j = np.loadtxt(out / "car.csv", delimiter=",", skiprows=1)
    v = j[:, 2]
    drop = np.zeros(v.size, dtype=bool)
    drop[1:-1] = (v[1:-1] == 0) & (v[:-2] > 1) & (v[2:] > 1)
    print(f"speed dropouts (a zero amid motion): {drop.sum()} of {v.size} readings")
    p = np.loadtxt(out / "car.tum")
    return j[~drop, 0], j[~drop, 1], v[~drop], p[:, 0], p[:, 1:3], 2 * np.arctan2(p[:, 6], p[:, 7])


def speed_scale(tj: np.ndarray, v: np.ndarray, t: np.ndarray, xy: np.ndarray, lag: float) -> None:
    breaks = np.flatnonzero(np.diff(t) > GAP_S)
    ratios, paths, integrals = [], [], []
    for a, b in zip(np.r_[0, breaks + 1], np.r_[breaks, t.size - 1]):
        if b - a < 50:
            continue
        fine = np.linspace(t[a], t[b], 20_000)
        paths.append(float(np.sum(np.hypot(*np.diff(xy[a : b + 1], axis=0).T))))
        integrals.append(float(np.trapezoid(np.interp(fine - lag, tj, v), fine)))
        ratios.append(paths[-1] / integrals[-1])
    r = np.array(ratios)
    print(
        f"speed scale (path / ∫v): {sum(paths) / sum(integrals):.5f} over {sum(paths):.0f} m; "
        f"{r.size} stretches {r.min():.5f}-{r.max():.5f}, sd {r.std(ddof=1):.5f}, "
        f"sem {r.std(ddof=1) / np.sqrt(r.size):.5f}"
    )


def mount_and_steering(
    tj: np.ndarray, sw: np.ndarray, t: np.ndarray, xy: np.ndarray, yaw: np.ndarray
) -> tuple[float, float]:
    """The mount's checks and the steering's (``t``: the reference's times less the lag), and the
    steering's gain and offset."""
    ok = np.r_[np.diff(t) <= GAP_S, False] & np.r_[False, np.diff(t) <= GAP_S]
    i = np.flatnonzero(ok)
    dt = t[i + 1] - t[i - 1]
    vel = (xy[i + 1] - xy[i - 1]) / dt[:, None]
    speed = np.hypot(vel[:, 0], vel[:, 1])
    rate = np.angle(np.exp(1j * (yaw[i + 1] - yaw[i - 1]))) / dt
    m = speed > 5.0
    i, vel, speed, rate = i[m], vel[m], speed[m], rate[m]
    kappa, alat = rate / speed, rate * speed
    beta = np.angle(np.exp(1j * (np.arctan2(vel[:, 1], vel[:, 0]) - yaw[i])))
    one = np.ones_like(kappa)
    c, s = _fit(np.column_stack([one, kappa]), beta)
    print(f"antennas' line vs travel: sensor_theta {-c[0]:.5f} ± {s[0]:.5f} rad, x {c[1]:.3f} ± {s[1]:.3f} m")
    c, s = _fit(np.column_stack([one, kappa, alat]), beta)
    print(
        f"  with a lateral-acceleration term: sensor_theta {-c[0]:.5f} ± {s[0]:.5f} rad, x {c[1]:.3f} ± "
        f"{s[1]:.3f} m, slide {c[2]:.5f} ± {s[2]:.5f} rad/(m/s²)"
    )
    straight = np.flatnonzero(np.abs(kappa) < 0.002)
    blocks = np.array([-beta[b].mean() for b in np.array_split(straight, 10)])
    print(
        f"  on straights (|κ| < 0.002/m, {straight.size}): sensor_theta {blocks.mean():.5f} ± "
        f"{blocks.std(ddof=1) / np.sqrt(blocks.size):.5f} rad (10 blocks' scatter)"
    )
    return steering(tj, sw, t[i], kappa, alat)


def steering(
    tj: np.ndarray, sw: np.ndarray, t: np.ndarray, kappa: np.ndarray, alat: np.ndarray
) -> tuple[float, float]:
    wheel = np.interp(t, tj, sw)
    c, s = _fit(np.column_stack([wheel, np.ones_like(wheel), alat]), np.arctan(WHEELBASE_M * kappa))
    print(
        f"steering (wheelbase {WHEELBASE_M} m): k_steer {c[0]:.5f} ± {s[0]:.5f} (ratio {1 / c[0]:.2f}), "
        f"steer_offset {c[1]:.5f} ± {s[1]:.5f} rad, understeer {c[2]:.5f} ± {s[2]:.5f} rad/(m/s²)"
    )
    return float(c[0]), float(c[1])


def lags(
    joints: tuple[np.ndarray, ...], t: np.ndarray, xy: np.ndarray, yaw: np.ndarray, k: float, off: float
) -> None:
    """The lag from the speeds and from the turn rates (``joints``: times, steering wheel, speed;
    ``k``, ``off``: the steering's gain and offset)."""
    tj, sw, v = joints
    i = np.flatnonzero((np.diff(t[:-1]) <= GAP_S) & (np.diff(t[1:]) <= GAP_S)) + 1
    dt = t[i + 1] - t[i - 1]
    speed = np.hypot(*((xy[i + 1] - xy[i - 1]) / dt[:, None]).T)
    rate = np.angle(np.exp(1j * (yaw[i + 1] - yaw[i - 1]))) / dt
    m = speed > 5.0
    i, speed, rate = i[m], speed[m], rate[m]
    grid = np.arange(-0.2, 0.3001, 0.005)
    cost = np.array(
        [
            [
                np.mean((speed - np.interp(t[i] - g, tj, v)) ** 2),
                np.mean(
                    (
                        rate
                        - np.interp(t[i] - g, tj, v)
                        * np.tan(k * np.interp(t[i] - g, tj, sw) + off)
                        / WHEELBASE_M
                    )
                    ** 2
                ),
            ]
            for g in grid
        ]
    )
    for name, c in zip(("speed", "turn rate"), cost.T):
        k = int(np.clip(np.argmin(c), 1, c.size - 2))
        a, b, d = c[k - 1 : k + 2]
        print(f"lag from the {name}: {1e3 * (grid[k] + 0.0025 * (a - d) / (a - 2 * b + d)):.1f} ms")


def noise(scenario: Path) -> None:
    from odometry_truth import sigma_over_truth

    from nlp_calib import load_scenario
    from nlp_calib.core import poses
    from nlp_calib.pipeline import Calibration

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calib = Calibration(load_scenario(scenario))
        run = calib.run()
    p = run.reports[run.handoff_solver() or next(iter(run.reports))].result.param_dict()
    windows = calib.parts[0].windows
    masks = windows.masks
    gap = np.diff(np.asarray(windows.selected.time_s)) > 0.5  # a span across the GNSS's gaps is no drift
    object.__setattr__(windows, "masks", lambda: (masks()[0] | gap[: masks()[0].size], masks()[1]))
    sensor = np.asarray(windows.selected.T_world_sensor)
    mount = poses.between(np.array([[p["sensor_x"], p["sensor_y"], p["sensor_theta"]]]), np.zeros((1, 3)))
    base = poses.compose(sensor, np.broadcast_to(mount, sensor.shape))
    truth = (np.asarray(windows.selected.time_s), base, run.log.start_ns)
    found = sigma_over_truth(calib, run, truth, (1, 5, 25, 100), every_metre=True)
    print("way      span    x      y      θ   together  (σ over the σ whose 2σ holds 95 % of the errors)")
    for (way, length), r in found.items():
        print(f"{way:10s} {length:4d} " + " ".join(f"{v:6.2f}" for v in r[:3]) + f"   {r[3]:6.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--lag", type=float, default=0.045, help="the reference's lag behind the joints (s)")
    ap.add_argument("--noise", type=Path, help="a scenario to calibrate and score the odometry's σ of")
    args = ap.parse_args()
    tj, sw, v, t, xy, yaw = _load(args.out)
    speed_scale(tj, v, t, xy, args.lag)
    k, off = mount_and_steering(tj, sw, t - args.lag, xy, yaw)
    lags((tj, sw, v), t, xy, yaw, k, off)
    if args.noise is not None:
        noise(args.noise)


if __name__ == "__main__":
    main()
