"""False-alarm survey of the forward/reverse check on clean simulated camera logs.

Usage: nice -n 10 python3 benchmarks/direction_false_alarms.py SEED... (prints each seed's largest
|z|, the parameter and whether the check flags a disagreement, then how many logs exceed 3σ and how
many the check flags: a finding needs 3σ and a difference beyond the precision needed)."""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path


def largest_z(seed: int, folder: Path) -> tuple[str, float, bool]:
    """The parameter with the largest forward/reverse |z| on a noise-free 60 s camera log, and
    whether the check flags a disagreement."""
    data = folder / f"cam{seed}.tum"
    run = [sys.executable, "-m", "nlp_calib"]
    subprocess.run(
        [
            *run,
            "simulate",
            "--out",
            str(data),
            "--duration",
            "60",
            "--seed",
            str(seed),
            "--noise-xy",
            "0",
            "--noise-theta",
            "0",
        ],
        check=True,
        capture_output=True,
    )
    out = folder / f"out{seed}"
    subprocess.run(
        [*run, "run", "scenarios/camera_demo.yaml", "--data", str(data), "--out", str(out)],
        check=True,
        capture_output=True,
    )
    direction = json.loads((out / "result.json").read_text())["direction"]
    z = direction["difference_in_sigma"]
    finite = {k: abs(v) for k, v in z.items() if isinstance(v, (int, float))}
    name = max(finite, key=finite.__getitem__)
    return name, finite[name], bool(direction["significant"])


def main() -> None:
    seeds = [int(s) for s in sys.argv[1:]]
    beyond = flagged = 0
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            name, z, significant = largest_z(seed, Path(tmp))
            beyond += z > 3
            flagged += significant
            said = "flagged" if significant else "not flagged"
            print(f"seed {seed}: largest |z| {z:.2f} ({name}), {said}", flush=True)
    print(f"{beyond} of {len(seeds)} clean logs beyond 3σ; {flagged} of {len(seeds)} flagged")


if __name__ == "__main__":
    main()
