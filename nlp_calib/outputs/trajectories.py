"""Trajectories as TUM files, so that evo (``evo_ape``, ``evo_rpe``) reproduces the reported figures.

Written into ``trajectories/`` with ``--report``: the tracker's poses and each solver's full-run
dead reckoning over the used records, and, per fault-free segment, the tracker's poses (bad
tracker poses left out) and each solver's track restarted from the tracker at the segment's
start. ``README.md`` beside them gives the evo commands and the figures they reproduce. A TUM
line is ``time x y z qx qy qz qw``: the planar pose with z = 0 and the heading as a quaternion
about z; times are seconds since the log's first record.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlp_calib.analysis.metrics import (
    RPE_DISTANCES,
    ErrorStats,
    aligned_errors,
    restarted,
    rpe_by_distance,
    segments,
    steps,
)
from nlp_calib.core.files import atomic_write_text
from nlp_calib.pipeline import Calibration, CalibrationRun

FOLDER = "trajectories"


def tum_text(time_s: np.ndarray, T: np.ndarray) -> str:
    """TUM lines of poses ``T`` (n, 3) at ``time_s``."""
    half = 0.5 * T[:, 2]
    zeros = np.zeros(T.shape[0])
    cols = np.column_stack([time_s, T[:, 0], T[:, 1], zeros, zeros, zeros, np.sin(half), np.cos(half)])
    return "".join(" ".join(f"{v:.9f}" for v in row) + "\n" for row in cols)


def write_trajectories(calib: Calibration, run: CalibrationRun, out_dir: Path) -> list[Path]:
    """Write the TUM files and their README into ``out_dir/trajectories``; returns their paths."""
    folder = out_dir / FOLDER
    a, b = run.used
    sel = calib.selected
    t, ref = sel.time_s, np.asarray(sel.T_world_sensor)
    inputs = calib.model.inputs(sel, run.scenario.residual.steering_sample)
    good = ~calib.fault_masks[1][a:b]
    parts = [(p, q) for p, q in segments(b - a, calib.fault_masks[0][a : b - 1])]
    written: dict[str, str] = {"tracker.tum": tum_text(t, ref)}
    table = []
    for name, rep in run.reports.items():
        step = steps(calib.fns, rep.result.params, inputs)
        full = restarted(step, ref, [(0, b - a)])
        written[f"{name}.tum"] = tum_text(t, full)
        track = restarted(step, ref, parts)
        for k, (p, q) in enumerate(parts, start=1):
            idx = p + np.flatnonzero(good[p:q])
            written[f"segment{k}_{name}.tum"] = tum_text(t[idx], track[idx])
            written.setdefault(f"segment{k}_tracker.tum", tum_text(t[idx], ref[idx]))
            ate = ErrorStats.of(np.linalg.norm(track[idx, :2] - ref[idx, :2], axis=1))
            aligned = ErrorStats.of(aligned_errors(track[idx], ref[idx]))
            rpe = [rpe_by_distance(track, ref, [idx], d) for d in RPE_DISTANCES]
            table.append((name, k, len(idx), ate, aligned, rpe))
    written["README.md"] = _readme(run, table)
    paths = []
    for file, text in written.items():
        atomic_write_text(folder / file, text)
        paths.append(folder / file)
    return paths


def _readme(
    run: CalibrationRun, table: list[tuple[str, int, int, ErrorStats, ErrorStats, list[ErrorStats]]]
) -> str:
    solvers = list(run.reports)
    first = solvers[0]
    rpe_cols = " | ".join(f"RPE {d:g} m mean (pairs)" for d in RPE_DISTANCES)
    lines = [
        f"# Trajectories of {run.scenario.name} (TUM format)",
        "",
        "- `tracker.tum`: the tracker's sensor poses over the used records; "
        + ", ".join(f"`{s}.tum`" for s in solvers)
        + ": each solver's sensor track dead-reckoned from the tracker's first pose (full run).",
        "- `segment<k>_tracker.tum`, `segment<k>_<solver>.tum`: each fault-free segment, the track "
        "restarted from the tracker at its start; bad tracker poses left out.",
        "",
        "Reproduce the report's figures with [evo](https://github.com/MichaelGrupp/evo):",
        "",
        "```",
        f"evo_ape tum tracker.tum {first}.tum                    # full-run ATE",
        f"evo_ape tum segment1_tracker.tum segment1_{first}.tum  # segment 1's ATE; --align: aligned",
        *(
            f"evo_rpe tum segment1_tracker.tum segment1_{first}.tum --delta {d:g} --delta_unit m "
            "--all_pairs --pairs_from_reference"
            for d in RPE_DISTANCES
        ),
        "```",
        "",
        "The report pools the segments: its mean is the mean over every pose (ATE) or pair (RPE) of",
        "all segments. Per segment:",
        "",
        f"| solver | segment | poses | ATE mean | ATE rmse | aligned ATE mean | {rpe_cols} |",
        "|---|---|---|---|---|---|" + "---|" * len(RPE_DISTANCES),
    ]
    for name, k, n, ate, aligned, rpe in table:
        cells = " | ".join(f"{s.mean:.6f} ({s.n})" for s in rpe)
        lines.append(
            f"| {name} | {k} | {n} | {ate.mean:.6f} | {ate.rmse:.6f} | {aligned.mean:.6f} | {cells} |"
        )
    return "\n".join(lines) + "\n"
