"""What a run says agrees with what it writes: every σ the verdict quotes ("known only to ±σ") is
the one calibration.yaml and result.json state, after every check that widens it (the held check's
re-sampled readings). A real car's verdict said its lag was known to ±6.7 ms while every file
said ±31 ms: the σ was worded before the held check widened it (issue #43)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import yaml

from nlp_calib.simulation import SimulationOptions, simulate_to_file
from nlp_calib.simulation.options import DriveShape, Sampling, TrackerSim
from tests.conftest import cli

#: "NAME is known only to ±SIGMA UNIT": the determinacy check's words on a loose parameter.
LOOSE = re.compile(r"(\w+) is known only to ±(\S+) ")


def test_the_verdict_quotes_the_sigma_every_file_states(tmp_path: Path) -> None:
    """A tricycle driven fast (6 m/s) with its encoders read at 4 Hz, the tracker 29.9 ms late:
    the lag, fitted, re-samples the encoders between records, and the held check widens its σ
    from 0.5 ms to 2.7 ms (over 5× the 0.39 ms it needs). The verdict names it loose and quotes
    the σ result.json and calibration.yaml write (before: its σ read before the widening, within
    5× the needed, no word on it at all)."""
    lag = float(np.random.default_rng(501).uniform(0.0, 0.03))
    opts = SimulationOptions(
        seed=501,
        model="tricycle",
        sampling=Sampling(rate_hz=4.0),
        drive=DriveShape(trajectory="s_curves", max_speed=6.0),
        tracker=TrackerSim(latency_s=lag),
    )
    log, _ = simulate_to_file(opts, tmp_path / "drive.txt")
    doc = {"name": "fast", "dataset": str(log), "model": "tricycle", "initial_guess": "from_file"}
    doc |= {"solvers": ["gauss_newton"], "alignment": {"tracker_lag": "auto"}}
    (tmp_path / "fast.yaml").write_text(yaml.safe_dump(doc))
    done = cli("run", str(tmp_path / "fast.yaml"), "--out", str(tmp_path / "out"))
    assert done.returncode in (0, 2), done.stderr
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    std = result["solvers"]["gauss_newton"]["std"]
    written = yaml.safe_load((tmp_path / "out" / "calibration.yaml").read_text())
    held = result["held"]["std_held"]
    quoted = {m[1]: m[2] for why in result["verdict"]["reasons"] for m in LOOSE.finditer(why)}
    # The case: the held check widens the lag's σ beyond what the data alone give.
    assert held["tracker_lag"] > 0.5 * std["tracker_lag"], (held, std)
    assert "tracker_lag" in quoted, result["verdict"]["reasons"]
    for name, said in quoted.items():
        assert said == f"{std[name]:.2g}" == f"{written['std'][name]:.2g}", (name, said, std[name])
    # What the terminal prints, too.
    assert f"tracker_lag is known only to ±{std['tracker_lag']:.2g} s" in done.stdout
