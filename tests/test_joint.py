"""Several logs in one calibration (``datasets``): windows stay inside their log, each log keeps its
own samples, lag and faults, and two drives together beat either alone."""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import cli

from nlp_calib.core.errors import DatasetError, ScenarioError
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.calibration import CalibrationRun
from nlp_calib.problem import build_residual_data
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation

BASE: dict[str, Any] = {
    "model": "tricycle",
    "initial_guess": "auto",
    "residual": {"horizon": 10},
    "solvers": ["gauss_newton"],
}


def drives(folder: Path, seed: int, records: int = 800) -> tuple[list[Path], dict[str, float]]:
    """Two simulated drives of one robot: S-curves with reversing, and forward-only driving."""
    paths = []
    truth: dict[str, float] = {}
    for i, trajectory in enumerate(("s_curves", "no_reversals")):
        path = folder / f"drive{i}_{seed}.txt"
        opts = SimulationOptions.of(records=records, seed=10 * seed + i, trajectory=trajectory)
        _, truth_file = write_simulation(simulate(opts), path)
        truth = json.loads(Path(truth_file).read_text())["params"]
        paths.append(path)
    return paths, truth


def single(path: Path) -> CalibrationRun:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(scenario_from_mapping({**BASE, "dataset": str(path)}, "s", path.parent)).run()


def joint(paths: list[Any], folder: Path, **extra: Any) -> CalibrationRun:
    sc = scenario_from_mapping({**BASE, "datasets": paths, **extra}, "j", folder)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Calibration(sc).run().logs[0]


def test_windows_never_cross_from_one_log_into_the_next(tmp_path: Path) -> None:
    (a, b), _ = drives(tmp_path, 0, records=120)
    sc = scenario_from_mapping({**BASE, "datasets": [str(a), str(b)]}, "j", tmp_path)
    calib = Calibration(sc)
    data = calib.data
    assert len(data.logs) == 2
    boundary = data.offsets[1]
    assert np.all((data.stops < boundary) | (data.starts >= boundary))
    # Every window of the joint fit is one of a log's own windows, with the same tracker motion.
    for part, offset in zip(calib.parts, data.offsets):
        own = build_residual_data(calib.fns, part.aligned.select(*part.fit), sc.objective.residual)
        mine = (data.starts >= offset) & (data.starts < offset + own.n_records)
        np.testing.assert_array_equal(data.starts[mine] - offset, own.starts)
        np.testing.assert_allclose(data.z[:, mine], own.z, rtol=0, atol=1e-15)


def test_each_log_keeps_its_own_samples_and_lag(tmp_path: Path) -> None:
    (a, b), _ = drives(tmp_path, 1, records=300)
    entries = [str(a), {"path": str(b), "samples": {"start": 100}, "alignment": {"tracker_lag": 0.04}}]
    sc = scenario_from_mapping({**BASE, "datasets": entries}, "j", tmp_path)
    calib = Calibration(sc)
    fitted, held = calib.parts
    # The first log's lag fitted (the default), its records from the first the lag leaves inside
    # the log; the second's held where its entry says, its samples its own.
    assert fitted.alignment.estimate is not None and held.alignment.estimate is None
    assert fitted.used[0] == fitted.alignment.valid[0] and held.used[0] == 100
    assert held.alignment.lag_s == 0.04
    assert calib.data.n_records == sum(p.fit[1] - p.fit[0] for p in calib.parts)


def test_two_drives_together_recover_truth_better_with_a_smaller_honest_sigma(tmp_path: Path) -> None:
    """Over three seeds: the joint fit's error (in units of its own honest σ) is below either
    single-log fit's, and its honest σ is smaller than either single fit's for every parameter."""
    errors: list[list[float]] = []
    sigma: dict[str, list[np.ndarray]] = {"a": [], "b": [], "joint": []}
    for seed in range(3):
        paths, truth = drives(tmp_path, seed)
        runs = {
            "a": single(paths[0]),
            "b": single(paths[1]),
            "joint": joint([str(p) for p in paths], tmp_path),
        }
        for run in runs.values():
            assert run.reports["gauss_newton"].result.converged
        # The robot's and the mount's parameters, which the logs share (each log's clock offset
        # is its own).
        names = [n for n in runs["joint"].std("gauss_newton") if n in truth]
        scale = np.array([runs["joint"].std("gauss_newton")[n] for n in names])
        row = []
        for key, run in runs.items():
            p = run.reports["gauss_newton"].result.param_dict()
            row.append(float(np.sum(((np.array([p[n] - truth[n] for n in names])) / scale) ** 2)))
            sigma[key].append(np.array([run.std("gauss_newton")[n] for n in names]))
        errors.append(row)
    total = np.sum(errors, axis=0)  # a χ²-like sum over seeds and parameters: a, b, joint
    assert total[2] <= min(total[0], total[1]), total
    mean = {k: np.mean(v, axis=0) for k, v in sigma.items()}
    assert np.all(mean["joint"] < np.minimum(mean["a"], mean["b"])), mean


def test_datasets_and_dataset_together_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=r"'dataset' .* or 'datasets'.* not both"):
        scenario_from_mapping({**BASE, "dataset": "a.txt", "datasets": ["b.txt"]}, "j", tmp_path)
    with pytest.raises(ScenarioError, match="not neither"):
        scenario_from_mapping(dict(BASE), "j", tmp_path)
    with pytest.raises(ScenarioError, match=r"datasets\[1\]\.samples"):
        scenario_from_mapping(
            {**BASE, "datasets": ["a.txt", {"path": "b.txt", "samples": {"start": -1}}]}, "j", tmp_path
        )
    with pytest.raises(ScenarioError, match="non-empty list"):
        scenario_from_mapping({**BASE, "datasets": []}, "j", tmp_path)


def test_run_writes_the_joint_hand_off_and_each_logs_result(tmp_path: Path) -> None:
    drives(tmp_path, 2, records=300)
    sc = tmp_path / "joint.yaml"
    sc.write_text(
        "name: joint\ndatasets: [drive0_2.txt, drive1_2.txt]\nmodel: tricycle\ninitial_guess: auto\n"
        "residual: {horizon: 10}\nsolvers: [gauss_newton]\n"
    )
    out = tmp_path / "out"
    proc = cli("run", str(sc), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "joint fit of 2 logs" in proc.stdout
    assert "summary of the joint fit of 2 logs (joint):" in proc.stdout
    whole = json.loads((out / "result.json").read_text())
    assert whole["dataset"]["path"].startswith("2 logs: ") and whole["logs"]["consistency"]["logs"]
    assert whole["verdict"]["level"] in proc.stdout.split("summary of the joint fit")[1].lower()
    results = [json.loads((out / name / "result.json").read_text()) for name in ("drive0_2", "drive1_2")]
    calibration = (out / "calibration.yaml").read_text()
    params = [r["solvers"]["gauss_newton"]["params"] for r in results]
    assert params[0] == params[1]  # one set of parameters for both logs
    for name, value in params[0].items():
        assert f"{value!r}"[:8] in calibration or name not in calibration


def test_records_fitted_twice_are_refused_and_errors_name_the_entry(tmp_path: Path) -> None:
    (a, b), _ = drives(tmp_path, 3, records=120)
    with pytest.raises(ScenarioError, match=r"datasets\[1\]: records also in datasets\[0\]"):
        scenario_from_mapping(
            {**BASE, "datasets": [str(a), {"path": str(a), "samples": {"start": 60}}]}, "j", tmp_path
        )
    halves = [{"path": str(a), "samples": {"stop": 60}}, {"path": str(a), "samples": {"start": 60}}]
    assert len(scenario_from_mapping({**BASE, "datasets": halves}, "j", tmp_path).per_log()) == 2
    short = scenario_from_mapping(
        {**BASE, "datasets": [str(a), {"path": str(b), "samples": {"start": 118}}]}, "j", tmp_path
    )
    with pytest.raises(ScenarioError, match=r"datasets\[1\] \(drive1_3\.txt\): residual\.horizon"):
        Calibration(short)
    missing = scenario_from_mapping({**BASE, "datasets": [str(a), "nope.txt"]}, "j", tmp_path)
    with pytest.raises(DatasetError, match=r"fix 'datasets\[1\]'"):
        Calibration(missing)


def test_each_log_view_needs_of_every_lag_what_its_own_log_drives(tmp_path: Path) -> None:
    """A joint fit's view of one log reads every log's clock offset by the precision that log's
    drive needs (the joint run's, from the drive's speed and turn rate), never by the reference
    robot's constant 2 ms: a view had said "tracker_lag_2 is known only to ±0.026 s (over 5× the
    0.002 needed)" where the joint fit needs 0.01 s of it (Censi's Khepera). Two slow drives
    (0.2 m/s at most) need more than 2 ms of each lag."""
    paths = []
    for i, trajectory in enumerate(("s_curves", "no_reversals")):
        opts = SimulationOptions.of(records=300, seed=40 + i, trajectory=trajectory, max_speed=0.2)
        paths.append(str(write_simulation(simulate(opts), tmp_path / f"slow{i}.txt")[0]))
    sc = scenario_from_mapping(
        {**BASE, "datasets": paths, "alignment": {"tracker_lag": "auto"}}, "j", tmp_path
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    lags = [p for p in run.scenario.layout.parameters if p.name.startswith("tracker_lag")]
    assert len(lags) == 2 and all(p.needed(0.0) > 0.002 for p in lags), lags
    for view in run.logs:
        for p in lags:
            assert view.scenario.layout.param(p.name).needed(0.0) == pytest.approx(p.needed(0.0)), p
