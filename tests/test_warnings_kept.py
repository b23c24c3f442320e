"""A result stands alone: every warning a run prints is in result.json's ``warnings``, and every
warning there reaches the terminal. A real car's run printed its log's gaps in time and how its
joints were read, and wrote ``warnings: []`` (issue #43): the stages warned as they ran, and only
the run's own notes went into the result."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from tests.conftest import cli, write_sim
from tests.test_speeds_quadrature import _write_drive


def _text_log(folder: Path) -> dict[str, object]:
    """A simulated text log with 40 records (1.6 s) cut out of its middle: a gap in time."""
    log = write_sim(folder, "drive.txt", records=600, seed=3)
    lines = log.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("time:"))
    del lines[first + 300 : first + 340]
    log.write_text("\n".join(lines) + "\n")
    return {"dataset": str(log), "model": "tricycle", "initial_guess": "from_file"}


def _tum_joints(folder: Path) -> dict[str, object]:
    """A diff drive's wheel speeds and the tracker's TUM poses with 1.5 s of poses cut out."""
    dataset = _write_drive(folder, 5)
    poses = Path(str(dataset["poses"]))
    lines = poses.read_text().splitlines()
    del lines[400:475]
    poses.write_text("\n".join(lines) + "\n")
    return {"dataset": dataset, "model": "diff_drive", "initial_guess": "auto"}


@pytest.mark.parametrize("make", [_text_log, _tum_joints], ids=["text", "tum_joints"])
def test_every_printed_warning_is_in_the_result(tmp_path: Path, make: object) -> None:
    """A log with a gap in time, run through the command: the gap's warning (the prepare stage's,
    said before the fit) is printed and in result.json, as is every other warning printed; every
    warning result.json holds was printed (before: the gap's was printed, the result held none)."""
    doc = make(tmp_path)  # type: ignore[operator]
    doc |= {"name": "gap", "solvers": ["gauss_newton"]}
    (tmp_path / "gap.yaml").write_text(yaml.safe_dump(doc))
    done = cli("run", str(tmp_path / "gap.yaml"), "--out", str(tmp_path / "out"))
    assert done.returncode in (0, 1), done.stderr
    printed = [
        line.removeprefix("warning: ") for line in done.stderr.splitlines() if line.startswith("warning: ")
    ]
    held = json.loads((tmp_path / "out" / "result.json").read_text())["warnings"]
    assert any("gap(s) in time" in w for w in printed), done.stderr
    assert set(printed) <= set(held), (printed, held)
    terminal = done.stdout + done.stderr
    assert all(w in terminal for w in held), held
