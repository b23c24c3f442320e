"""``nlp-calib simulate``: a synthetic drive log (or a camera's trajectory and joints) with its truth."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from nlp_calib.core import interrupts
from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.pipeline.simconfig import camera_options, simulation_options
from nlp_calib.simulation import simulate_to_file, truth_path
from nlp_calib.simulation.camera import camera_paths, simulate_camera, write_camera_simulation


def cmd_simulate(args: argparse.Namespace) -> int:
    overrides = {
        k: getattr(args, k)
        for k in (
            "records",
            "seed",
            "model",
            "trajectory",
            "tracker_noise_xy",
            "tracker_noise_theta",
            "outlier_fraction",
            "latency_s",
            "duration_s",
        )
        if getattr(args, k) is not None
    }
    out: Path = args.out
    if out.is_dir() or out.name in ("", ".", ".."):
        raise UsageError(f"--out {out} is a folder; give the path of the log file to write")
    if out.suffix.lower() == ".tum":
        return _simulate_camera(args, overrides)
    opts = simulation_options(args.config, overrides)
    folder = check_output_dir(out.parent)
    # The target may be the user's own log: never replaced without --force.
    refuse_collisions(folder, [out.name, truth_path(out).name], tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        log_path, truth = simulate_to_file(opts, stage.path / out.name)
        interrupts.hold()
        stage.commit()
    print(f"wrote {stage.final(log_path)} ({opts.records} records) and {stage.final(truth)}")
    return 0


def _simulate_camera(args: argparse.Namespace, overrides: dict[str, Any]) -> int:
    """A tilted camera's TUM trajectory, its joint CSV and the truth, beside each other."""
    opts = camera_options(args.config, overrides)
    out: Path = args.out
    folder = check_output_dir(out.parent)
    names = [p.name for p in camera_paths(out)]
    refuse_collisions(folder, names, tracked=False, force=args.force)
    with StagedOutput(folder, None, force=args.force) as stage:
        written = write_camera_simulation(simulate_camera(opts), stage.path / out.name)
        interrupts.hold()
        stage.commit()
    tum, joints, truth = (stage.final(p) for p in written)
    print(f"wrote {tum} ({opts.duration_s:g} s at {opts.image_rate_hz:g} Hz), {joints} and {truth}")
    return 0
