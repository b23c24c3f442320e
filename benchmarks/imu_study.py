"""A gyro as the reference, on simulated bags: every parameter against the truth in its σ.

Each model and seed: ``nlp-calib simulate --imu`` (the gyro stamped ``--latency`` late; ``--roll``
sets the IMU's roll), then ``nlp-calib init`` on the bag (the drafted gyro scenario, its commented
length line given the true length) and ``run``; each fitted parameter's estimate − truth in its σ
as the run's own truth check states it; at the end the share within 1σ, 2σ and 3σ. The drafted
scenario without the length must be refused by the pre-flight as determining only the lengths'
ratios (its words printed once per model)::

    nice -n 10 python3 benchmarks/imu_study.py --models diff_drive tricycle --seeds 301 302 303 304 \
        305 306 307 308 --roll 0.0873 --latency 0.02

With ``--camera DURATION RATE``: a gyro beside a camera's poses instead (docs/imu.md's
``camera_gyro.sim.yaml`` with each seed, the drive ``DURATION`` s of images at ``RATE`` Hz, run with
its ``camera_gyro.yaml``), each parameter's estimate − truth in its σ::

    nice -n 10 python3 benchmarks/imu_study.py --camera 40 30 --seeds 641 642 643

``--noise-seed N`` draws the gyro's noise from a generator of its own (the same drives, other noise).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import yaml

#: This checkout (its code, not an installed one's, is what runs).
REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from nlp_calib.models import MODELS  # noqa: E402
from nlp_calib.models.radians import in_units  # noqa: E402

#: The gyro noise's own seed (``--noise-seed``; None: the drive's generator draws it).
NOISE_SEED: int | None = None
#: The commented line ``init`` drafts for the one measured length a gyro needs.
TODO = re.compile(r"^# known: \{(\w+): <metres>\}.*$", re.MULTILINE)


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "nlp_calib", *args], capture_output=True, text=True, check=False, cwd=REPO
    )


def _simulate(model: str, seed: int, roll: float, latency: float, folder: Path) -> None:
    """The bag at ``folder/gyro`` and its truth beside it (the gyro's noise drawn with
    :data:`NOISE_SEED` where given)."""
    options = {
        "model": model,
        "truth": {"imu_roll": roll},
        **({"noise_seed": NOISE_SEED} if NOISE_SEED is not None else {}),
    }
    (folder / "sim.yaml").write_text(yaml.safe_dump(options))
    sim = _cli(
        "simulate", "--imu", "--out", str(folder / "gyro"), "--seed", str(seed), "--duration", "120",
        "--latency", str(latency), "--config", str(folder / "sim.yaml"),
    )  # fmt: skip
    assert sim.returncode == 0, sim.stderr


def one(model: str, seed: int, roll: float, latency: float, folder: Path) -> tuple[list[float], str]:
    """Each fitted parameter's estimate − truth in σ on one seed's bag, and the pre-flight's words
    for the gyro alone."""
    _simulate(model, seed, roll, latency, folder)
    drafted = folder / "gyro.yaml"
    init = _cli("init", str(folder / "gyro"), "--out", str(drafted), "--model", model)
    assert init.returncode == 0, init.stderr
    alone = _cli("preflight", str(drafted))
    words = next(
        (line.strip() for line in alone.stdout.splitlines() if "measures turning, no length" in line), ""
    )
    text = drafted.read_text()
    todo = TODO.search(text)
    assert todo is not None, text
    # The truth in the fit's names and units (a model in radians), as the run's truth check reads it.
    params = json.loads((folder / "gyro.truth.json").read_text())["params"]
    true = getattr(in_units(MODELS[model], "radians"), "from_counts", dict)(params)
    known = folder / "known.yaml"
    known.write_text(text.replace(todo.group(0), f"known: {{{todo.group(1)}: {true[todo.group(1)]!r}}}"))
    run = _cli("run", str(known), "--out", str(folder / "out"), "--force")
    assert run.returncode == 0, run.stdout + run.stderr
    z = json.loads((folder / "out" / "result.json").read_text())["truth"]["error_in_sigma"]
    fitted = {n: v for n, v in z.items() if v is not None and math.isfinite(v)}
    print(
        f"{model:10s} {seed:5d}  lengths not determined alone: {bool(words)}  "
        + "  ".join(f"{n} {v:+.2f}σ" for n, v in fitted.items()),
        flush=True,
    )
    return [abs(v) for v in fitted.values()], words


#: docs/imu.md's camera_gyro.yaml, its files in the study's folder.
CAMERA_SCENARIO: dict[str, Any] = {
    "name": "camera_gyro",
    "model": "diff_drive",
    "sensor": {"mount": "3d", "beside": "gyro"},
    "dataset": {
        "poses": "camera_gyro.tum",
        "joints": "camera_gyro.joints.csv",
        "gyro": "camera_gyro.gyro.csv",
        "encoders": {"left_wheel": "left_wheel_joint", "right_wheel": "right_wheel_joint"},
    },
    "known": {"sensor_z": 0.30},
    "initial_guess": "auto",
    "alignment": {"tracker_lag": "auto"},
    "information": {"translation": 5.0e5, "rotation": 1.7e5, "gyro": 1.0e8},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}


def camera(seed: int, duration: float, rate: float, folder: Path) -> dict[str, float]:
    """Each fitted parameter's estimate − truth in σ on one seed's camera drive beside a gyro."""
    sim = {
        "model": "diff_drive", "duration_s": duration, "seed": seed, "stamp_offset_s": 0.02,
        "image_rate_hz": rate, "noise": {"position": 0.001, "rotation": 0.0017},
    }  # fmt: skip
    (folder / "camera_gyro.sim.yaml").write_text(yaml.safe_dump(sim))
    made = _cli(
        "simulate", "--imu", "--config", str(folder / "camera_gyro.sim.yaml"),
        "--out", str(folder / "camera_gyro.tum"),
    )  # fmt: skip
    assert made.returncode == 0, made.stderr
    dataset = {k: str(folder / v) if isinstance(v, str) else v for k, v in CAMERA_SCENARIO["dataset"].items()}
    (folder / "camera_gyro.yaml").write_text(yaml.safe_dump({**CAMERA_SCENARIO, "dataset": dataset}))
    run = _cli("run", str(folder / "camera_gyro.yaml"), "--out", str(folder / "out"), "--force")
    assert run.returncode == 0, run.stdout + run.stderr
    z = json.loads((folder / "out" / "result.json").read_text())["truth"]["error_in_sigma"]
    fitted = {n: v for n, v in z.items() if v is not None and math.isfinite(v)}
    print(f"camera+gyro {seed:5d}  " + "  ".join(f"{n} {v:+.2f}σ" for n, v in fitted.items()), flush=True)
    return fitted


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--models", nargs="+", default=["diff_drive"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[201, 202, 203])
    ap.add_argument("--roll", type=float, default=0.02)
    ap.add_argument("--latency", type=float, default=0.02)
    ap.add_argument("--camera", type=float, nargs=2, metavar=("DURATION", "RATE"))
    ap.add_argument("--noise-seed", type=int, help="the gyro noise's own seed: the same drives, other noise")
    args = ap.parse_args()
    global NOISE_SEED
    NOISE_SEED = args.noise_seed
    scores: list[float] = []
    by_name: dict[str, list[float]] = {}
    for seed in args.seeds if args.camera else []:
        with tempfile.TemporaryDirectory() as tmp:
            duration, rate = args.camera
            for name, v in camera(seed, duration, rate, Path(tmp)).items():
                by_name.setdefault(name, []).append(abs(v))
                scores.append(abs(v))
    if by_name:
        shares = (f"{n} {sum(v <= 1 for v in vs)}/{len(vs)}" for n, vs in by_name.items())
        print("within 1σ: " + ", ".join(shares))
    for model in [] if args.camera else args.models:
        said = ""
        for seed in args.seeds:
            with tempfile.TemporaryDirectory() as tmp:
                s, said = one(model, seed, args.roll, args.latency, Path(tmp))
                scores += s
        print(f"{model}, the gyro alone: {said}", flush=True)
    n = len(scores)
    share = [sum(s <= k for s in scores) / n for k in (1, 2, 3)]
    print(
        f"{n} estimates: {share[0]:.0%} within 1σ, {share[1]:.0%} within 2σ, {share[2]:.0%} within 3σ, "
        f"largest {max(scores):.2f}σ"
    )


if __name__ == "__main__":
    main()
