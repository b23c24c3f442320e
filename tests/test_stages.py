"""A calibration as named stages: a result that stands alone, and seams for new sources and outputs."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Hashable
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
from conftest import SCENARIOS

from nlp_calib.cli import main
from nlp_calib.core.errors import NlpCalibWarning, ScenarioError
from nlp_calib.logs import Log
from nlp_calib.models import KinematicModel
from nlp_calib.outputs import registry
from nlp_calib.pipeline import Calibration, Scenario, Wanted, load_scenario, scenario_from_mapping
from nlp_calib.results import CalibrationRun
from nlp_calib.sources import SOURCES, load_log


@pytest.fixture(scope="module")
def demo_run(small_demo_module: Scenario) -> CalibrationRun:
    return Calibration(small_demo_module).run(wanted=Wanted(series=True))


@pytest.fixture(scope="module")
def small_demo_module() -> Scenario:
    demo = load_scenario(SCENARIOS / "demo.yaml")
    return demo.with_options(samples=dataclasses.replace(demo.log.samples, stop=500))


def _files(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def _write_all(run: CalibrationRun, folder: Path) -> None:
    folder.mkdir()
    outputs = registry.selected(("result", "handoff", "figures"), report=True)
    registry.write(outputs, [(run, folder)], (run, folder), registry.OutputOptions())


def test_a_result_read_back_from_its_stored_form_writes_the_same_files(
    demo_run: CalibrationRun, tmp_path: Path
) -> None:
    stored = json.dumps(demo_run.to_data(), allow_nan=False)  # strict JSON: NaN stored as text
    again = CalibrationRun.from_data(json.loads(stored))
    assert again.to_data() == demo_run.to_data()
    _write_all(demo_run, tmp_path / "live")
    _write_all(again, tmp_path / "stored")
    live, stored_files = _files(tmp_path / "live"), _files(tmp_path / "stored")
    assert {
        "report.md",
        "result.json",
        "calibration.yaml",
        "trajectory.png",
        "trajectories/README.md",
    } <= set(live)
    assert stored_files == live


def test_the_residual_histogram_before_is_the_initial_guess(demo_run: CalibrationRun) -> None:
    residuals = demo_run.require_series().residuals
    after = residuals.after["gauss_newton"]
    assert residuals.before.shape == after.shape
    # The initial guess's residuals are the wider ones; the calibrated ones are not read twice.
    assert np.std(residuals.before) > 2 * np.std(after)
    assert residuals.inliers_after["gauss_newton"] >= residuals.inliers_before


def test_a_report_needs_the_series_and_says_how_to_get_them(
    small_demo_module: Scenario, tmp_path: Path
) -> None:
    run = Calibration(small_demo_module).run(("gauss_newton",))
    with pytest.raises(Exception, match="run it with --report"):
        _write_all(run, tmp_path / "x")


# --- the source seam: one class and one registry entry ----------------------------------------


@dataclasses.dataclass(frozen=True)
class MemorySource:
    """A toy source: a log already in memory, named in a scenario as ``{memory: NAME}``."""

    kind: ClassVar[str] = "memory"
    record_word: ClassVar[str] = "record"
    joint_units: ClassVar[str] = "counts"
    LOGS: ClassVar[dict[str, Log]] = {}
    name: str

    @property
    def path(self) -> Path:
        return Path(self.name)

    @property
    def numbered(self) -> Path:
        return Path(self.name)

    def files(self) -> tuple[Path, ...]:
        return ()

    def clock(self) -> str:
        return "the stored log's times"

    def identity(self) -> Hashable:
        return ("memory", self.name)

    def read(self, model: KinematicModel, *, strict: bool) -> Log:
        return self.LOGS[self.name]

    def moved(self, path: Path) -> MemorySource:
        return MemorySource(str(path))

    @classmethod
    def claims(cls, raw: Any) -> bool:
        return isinstance(raw, dict) and set(raw) == {"memory"}

    @classmethod
    def accepts(cls, path: Path) -> bool:
        return False

    @classmethod
    def parse(cls, raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> MemorySource:
        if raw["memory"] not in cls.LOGS:
            raise ScenarioError(f"{where}.memory: no log called {raw['memory']!r} in memory")
        return MemorySource(raw["memory"])


def _params_txt(run: CalibrationRun, folder: Path, name: str, options: registry.OutputOptions) -> list[Path]:
    solver = run.chosen_solver()
    if solver is None:
        return []
    text = "".join(f"{n} = {v!r}\n" for n, v in run.reports[solver].result.param_dict().items())
    (folder / name).write_text(text)
    return [folder / name]


def test_a_new_source_and_a_new_output_are_one_class_and_one_registry_line_each(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = load_log(SCENARIOS / "data" / "demo_tricycle.txt")
    monkeypatch.setitem(MemorySource.LOGS, "drive", log)
    monkeypatch.setitem(SOURCES, MemorySource.kind, MemorySource)
    toy = registry.Output(
        "params.txt", "handoff", _params_txt, per_log=False, next_step="every parameter, one per line"
    )
    monkeypatch.setattr(registry, "OUTPUTS", (*registry.OUTPUTS, toy))

    raw = {
        "name": "toy",
        "dataset": {"memory": "drive"},
        "samples": {"stop": 500},
        "validation": {"blocks": 0},
    }
    sc = scenario_from_mapping(raw, "toy.yaml", tmp_path)
    assert isinstance(sc.log.source, MemorySource)
    with pytest.raises(ScenarioError, match=r"toy\.yaml: dataset\.memory: no log called 'nope'"):
        scenario_from_mapping({**raw, "dataset": {"memory": "nope"}}, "toy.yaml", tmp_path)

    path = tmp_path / "toy.yaml"
    path.write_text(json.dumps(raw))  # JSON is YAML
    out = tmp_path / "out"
    assert main(["run", str(path), "--out", str(out), "--solver", "gauss_newton"]) == 0
    printed = capsys.readouterr().out
    written = (out / "params.txt").read_text()
    result = json.loads((out / "result.json").read_text())
    assert written == "".join(
        f"{n} = {v!r}\n" for n, v in result["solvers"]["gauss_newton"]["params"].items()
    )
    assert "params.txt: every parameter, one per line" in printed
    # The new name is checked for collisions like every other output.
    (tmp_path / "out2").mkdir()
    (tmp_path / "out2" / "params.txt").write_text("mine")
    assert main(["run", str(path), "--out", str(tmp_path / "out2"), "--solver", "gauss_newton"]) == 2
    assert "params.txt" in capsys.readouterr().err
    assert (tmp_path / "out2" / "params.txt").read_text() == "mine"


def test_a_lag_no_fit_converges_at_says_so_naming_its_key(tmp_path: Path) -> None:
    """A search where no fit converges is not an error of the initial guess: the run goes on,
    warns naming the key and says in its verdict that the lag could not be fitted."""
    sc = load_scenario(SCENARIOS / "demo.yaml")
    far = dataclasses.replace(sc.log.alignment, tracker_lag="auto", search=(5.0, 5.5), step=0.05)
    with pytest.warns(
        NlpCalibWarning, match=r"alignment\.search: no fit converged from any lag in \[5, 5\.5\] s"
    ):
        calib = Calibration(
            sc.with_options(alignment=far, samples=dataclasses.replace(sc.log.samples, stop=300))
        )
    run = calib.run(["gauss_newton"])
    assert (
        run.verdict.level == "not determined" and "the tracker lag could not be fitted" in run.verdict.line()
    )
