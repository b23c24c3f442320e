"""Wheel speeds (``form: speeds``) whose rates are held over each cycle and jump between cycles:
a speed column does not say whether its value is a sample at its stamp, the mean over the cycle
before or the rate held over the cycle after. Each reads the motion half a cycle apart, and the
trapezoids' positions err by |Δω|·dt/2 where the rate jumps: the run's σ carries that (or it says
what rests on it), never a lag wrong by many of its σ under GOOD."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nlp_calib import Calibration, scenario_from_mapping
from nlp_calib.results.run import GOOD

#: The drive's truth: a diff drive's wheels and a planar sensor's mount, the tracker stamped late.
TRUTH = {
    "left_wheel_radius": 0.1,
    "right_wheel_radius": 0.1,
    "wheel_separation": 0.5,
    "sensor_x": 0.3,
    "sensor_y": 0.05,
    "sensor_theta": 0.1,
    "tracker_lag": 0.004,
}
CYCLE = 0.01
SUBSTEPS = 20


def _held_rates(rng: np.random.Generator, n: int) -> np.ndarray:
    """Two wheels' rates (rad/s) per cycle: a slow swing, each cycle's rate jumping from the last."""
    t = np.arange(n) * CYCLE
    base = np.column_stack([5.0 + 3.0 * np.sin(0.7 * t), 5.0 + 3.0 * np.sin(0.45 * t + 1.0)])
    return base + rng.normal(0.0, 1.5, (n, 2))


def _write_drive(folder: Path, seed: int, n: int = 2000) -> dict[str, object]:
    """The joints (the rates held over the cycle after each stamp, as a speed column) and the
    sensor's poses every second cycle, integrated exactly (:data:`SUBSTEPS` per cycle), stamped
    ``tracker_lag`` late with 0.1 mm / 0.1 mrad of noise; the dataset entry."""
    rng = np.random.default_rng(seed)
    rates = _held_rates(rng, n)
    r, b = TRUTH["left_wheel_radius"], TRUTH["wheel_separation"]
    h = CYCLE / SUBSTEPS
    fine = np.repeat(rates, SUBSTEPS, axis=0)
    v, w = 0.5 * r * (fine[:, 0] + fine[:, 1]), r * (fine[:, 1] - fine[:, 0]) / b
    yaw = np.concatenate([[0.0], np.cumsum(w * h)])
    mid = yaw[:-1] + 0.5 * w * h
    x = np.concatenate([[0.0], np.cumsum(v * np.cos(mid) * h)])
    y = np.concatenate([[0.0], np.cumsum(v * np.sin(mid) * h)])
    k = np.arange(0, n, 2) * SUBSTEPS
    sx, sy, st = TRUTH["sensor_x"], TRUTH["sensor_y"], TRUTH["sensor_theta"]
    px = x[k] + np.cos(yaw[k]) * sx - np.sin(yaw[k]) * sy + rng.normal(0, 1e-4, k.size)
    py = y[k] + np.sin(yaw[k]) * sx + np.cos(yaw[k]) * sy + rng.normal(0, 1e-4, k.size)
    pt = yaw[k] + st + rng.normal(0, 1e-4, k.size)
    stamps = k * h + TRUTH["tracker_lag"]
    joints, poses = folder / f"drive{seed}.csv", folder / f"drive{seed}.tum"
    rows = [f"{i * CYCLE:.6f},{a:.17g},{c:.17g}" for i, (a, c) in enumerate(rates)]
    joints.write_text("time,left,right\n" + "\n".join(rows) + "\n")
    tum = [
        f"{t:.6f} {a:.17g} {c:.17g} 0 0 0 {np.sin(q / 2):.17g} {np.cos(q / 2):.17g}"
        for t, a, c, q in zip(stamps, px, py, pt)
    ]
    poses.write_text("\n".join(tum) + "\n")
    return {
        "joints": str(joints),
        "poses": str(poses),
        "form": "speeds",
        "encoders": {"left_wheel": "left", "right_wheel": "right"},
    }


@pytest.mark.parametrize("seed", [5, 6])
def test_speeds_held_over_their_cycle_give_each_parameter_within_its_sigma(tmp_path: Path, seed: int) -> None:
    """Rates held over each 10 ms cycle and jumping between cycles, read as speeds (trapezoids):
    every parameter the run gives a σ lies within 3σ of the truth, and a run that calls itself GOOD
    has them within 3σ too (not only what it hands off)."""
    doc = {"dataset": _write_drive(tmp_path, seed), "model": "diff_drive", "initial_guess": "auto"}
    sc = scenario_from_mapping({**doc, "solvers": ["gauss_newton"]}, f"speeds{seed}", tmp_path)
    run = Calibration(sc).run(["gauss_newton"])
    params, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    z = {n: (params[n] - TRUTH[n]) / std[n] for n in TRUTH if np.isfinite(std.get(n, np.nan))}
    assert "tracker_lag" in z, (run.verdict.line(), std)
    assert max(abs(v) for v in z.values()) < 3.0, (z, run.verdict.line())
    if run.verdict.level != GOOD:
        assert "tracker_lag" in run.verdict.line() or "form" in run.verdict.line(), run.verdict.line()
