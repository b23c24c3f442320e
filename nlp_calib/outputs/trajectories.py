"""Trajectories as TUM files, so that evo (``evo_ape``, ``evo_rpe``) reproduces the reported figures.

Written into ``trajectories/`` with ``--report``: the tracker's poses and each solver's full-run
dead reckoning over the used records (bad tracker poses left out, as the figures leave them out),
and, per fault-free segment, the tracker's poses (bad
tracker poses left out) and each solver's track restarted from the tracker at the segment's
start. ``README.md`` beside them gives the evo commands and the figures they reproduce. A TUM
line is ``time x y z qx qy qz qw``: the planar pose at the tracker's height (its z where the source
has one, a bag's pose topic; else 0) and the heading as a quaternion about z (a 3-D sensor's poses
as they are, in its own world frame and units); times are stamps on
the log's own clock (the first record's stamp plus the time since it), so ``evo`` compares them with
the recording's own pose topic directly, with no time offset and no projection onto the plane.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlp_calib.core.files import atomic_write_text
from nlp_calib.results import CalibrationRun
from nlp_calib.results.figures import RPE_DISTANCES
from nlp_calib.results.series import SegmentFigures

FOLDER = "trajectories"


def stamps(time_s: np.ndarray, start_ns: int) -> list[str]:
    """Each time (s since the first record) as a stamp on the log's clock, to the nanosecond."""
    ns = start_ns + np.round(np.asarray(time_s) * 1e9).astype(np.int64)
    return [f"{'-' if v < 0 else ''}{abs(v) // 10**9}.{abs(v) % 10**9:09d}" for v in ns.tolist()]


def tum_text(time_s: np.ndarray, T: np.ndarray, start_ns: int = 0, z: np.ndarray | None = None) -> str:
    """TUM lines of poses ``T`` (n, 3) at ``time_s`` after the stamp ``start_ns``, at heights ``z``
    (default 0); 3-D poses ``(n, 7)`` (a 3-D sensor's) as they are."""
    if T.shape[1] == 7:
        cols = np.asarray(T, dtype=float)
    else:
        half = 0.5 * T[:, 2]
        zeros = np.zeros(T.shape[0])
        height = zeros if z is None else np.asarray(z, dtype=float)
        cols = np.column_stack([T[:, 0], T[:, 1], height, zeros, zeros, np.sin(half), np.cos(half)])
    return "".join(
        f"{t} " + " ".join(f"{v:.9f}" for v in row) + "\n" for t, row in zip(stamps(time_s, start_ns), cols)
    )


def write_trajectories(run: CalibrationRun, out_dir: Path, name: str = FOLDER) -> list[Path]:
    """Write the TUM files and their README into ``out_dir/name``; returns their paths."""
    folder = out_dir / name
    tracks = run.require_series().tracks
    t, ref, t0, z = tracks.time_s, tracks.tracker, run.log.start_ns, tracks.tracker_z
    # Bad tracker poses are left out of every file, as they are of every figure.
    good = np.flatnonzero(tracks.good)
    z_good = None if z is None else z[good]
    written: dict[str, str] = {"tracker.tum": tum_text(t[good], ref[good], t0, z_good)}
    for track in tracks.tracks:
        if track.solver is not None:
            written[f"{track.solver}.tum"] = tum_text(t[good], track.T_world_sensor[good], t0, z_good)
    for solver, again in tracks.restarted.items():
        for k, (p, q) in enumerate(tracks.parts, start=1):
            idx = p + np.flatnonzero(tracks.good[p:q])
            z_k = None if z is None else z[idx]
            written[f"segment{k}_{solver}.tum"] = tum_text(t[idx], again[idx], t0, z_k)
            written.setdefault(f"segment{k}_tracker.tum", tum_text(t[idx], ref[idx], t0, z_k))
    written["README.md"] = _readme(run, tracks.segments)
    paths = []
    for file, text in written.items():
        atomic_write_text(folder / file, text)
        paths.append(folder / file)
    return paths


def _readme(run: CalibrationRun, table: tuple[SegmentFigures, ...]) -> str:
    solvers = list(run.reports)
    first = solvers[0]
    rpe_cols = " | ".join(f"RPE {d:g} m mean (pairs)" for d in RPE_DISTANCES)
    lines = [
        f"# Trajectories of {run.scenario.name} (TUM format)",
        "",
        "- `tracker.tum`: the tracker's sensor poses over the used records (bad ones left out); "
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
    for row in table:
        cells = " | ".join(f"{s.mean:.6f} ({s.n})" for s in row.rpe)
        lines.append(
            f"| {row.solver} | {row.segment} | {row.poses} | {row.ate.mean:.6f} | {row.ate.rmse:.6f} "
            f"| {row.aligned.mean:.6f} | {cells} |"
        )
    return "\n".join(lines) + "\n"
