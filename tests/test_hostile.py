"""Hostile input, round two: nothing hangs, nothing is lost, nothing passes silently.

Interrupts and kills are real signals sent to a child process (or, where the point is which
solver is running, to this process from inside the solver). Costs are bounded before they are
paid: inputs that would take minutes are refused by a check that does not depend on them (the
tests assert the error, never a time). The tool never overwrites or deletes a file it did not
write. Duplicate YAML keys, option values out of range and rejected solver options are one-line
errors with exit 2 naming the key or option.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import REPO, SCENARIOS, write_sim
from conftest import cli as run_cli
from test_faults import assert_nothing_written, assert_one_line_error

from nlp_calib import cli
from nlp_calib.core import interrupts
from nlp_calib.core.config import MAX_YAML_DEPTH, parse_yaml
from nlp_calib.core.errors import ConfigError, NlpCalibError, NlpCalibWarning, ScenarioError
from nlp_calib.outputs import outdir
from nlp_calib.outputs.outdir import MANIFEST_FILE, StagedOutput
from nlp_calib.pipeline import Calibration, load_scenario, scenario_from_mapping
from nlp_calib.solvers.evaluation import ProblemEvaluator

DEMO_LOG = SCENARIOS / "data" / "demo_tricycle.txt"


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_sim(tmp_path_factory.mktemp("hostile"), records=300, seed=5)


def scenario(tmp_path: Path, text: str, name: str = "case.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def quick(log: Path) -> str:
    return f"dataset: {log}\nresidual: {{horizon: 10}}\nsolvers: [gauss_newton]\n"


def contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def staging_folders(folder: Path) -> list[str]:
    return [p.name for p in folder.iterdir() if p.name.startswith(".nlp_calib_staging.")]


# ------------------------------------------------------------------------ 1. interrupts and kills

#: IPOPT that runs for minutes on the demo log and prints its iterations (the signal is sent once
#: the child is inside the solve).
SLOW_IPOPT = (
    f"dataset: {DEMO_LOG}\nresidual: {{horizon: 10}}\nsolvers: [ipopt]\n"
    "ipopt: {hessian: limited_memory, max_iter: 1000000, print_level: 5, tol: 1.0e-30, "
    "options: {acceptable_iter: 0}}\n"
)


def start_cli(*args: str, stdout: Path) -> subprocess.Popen[bytes]:
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    with stdout.open("wb") as fh:
        return subprocess.Popen(
            [sys.executable, "-m", "nlp_calib", *args], cwd=REPO, env=env, stdout=fh, stderr=subprocess.PIPE
        )


def wait_for(proc: subprocess.Popen[bytes], ready: object, limit_s: float = 120.0) -> None:
    """Poll until ``ready()`` holds (the child reached the point to interrupt)."""
    deadline = time.monotonic() + limit_s
    while not ready():  # type: ignore[operator]
        assert proc.poll() is None, "the child ended before it was interrupted"
        assert time.monotonic() < deadline, "the child never reached the point to interrupt"
        time.sleep(0.02)


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_ipopt_ends_the_run_and_keeps_the_previous_result(
    signum: int, code: int, sim_log: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    assert run_cli("run", str(scenario(tmp_path, quick(sim_log))), "--out", str(out)).returncode == 0
    before = contents(out)
    log = tmp_path / "stdout.txt"
    proc = start_cli("run", str(scenario(tmp_path, SLOW_IPOPT, "slow.yaml")), "--out", str(out), stdout=log)
    wait_for(proc, lambda: "iter" in log.read_text(errors="replace"))
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert f"error: interrupted ({signal.Signals(signum).name})" in err.decode()
    assert "Traceback" not in err.decode()
    assert contents(out) == before
    assert staging_folders(out) == []


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_during_gauss_newton_ends_the_run_and_keeps_the_previous_result(
    signum: int,
    code: int,
    sim_log: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    sc = scenario(tmp_path, quick(sim_log))
    out = tmp_path / "out"
    assert cli.main(["run", str(sc), "--out", str(out)]) == 0
    before = contents(out)
    original = ProblemEvaluator.normal_equations
    calls = []

    def signalled(self: ProblemEvaluator, x: object) -> object:
        calls.append(1)
        if len(calls) == 3:  # inside the solve, between two iterations
            os.kill(os.getpid(), signum)
        return original(self, x)  # type: ignore[arg-type]

    monkeypatch.setattr(ProblemEvaluator, "normal_equations", signalled)
    assert cli.main(["run", str(sc), "--out", str(out)]) == code
    assert len(calls) >= 3
    assert contents(out) == before and staging_folders(out) == []
    assert f"interrupted ({signal.Signals(signum).name})" in capsys.readouterr().err


def test_a_signal_that_native_code_swallowed_still_ends_the_run() -> None:
    with interrupts.handled(), pytest.raises(interrupts.Interrupted):
        # What CasADi's IPOPT interface does: catch what the handler raises, carry on.
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(1)
        except interrupts.Interrupted:
            pass
        interrupts.check()
    assert interrupts.pending() is None


def test_a_signal_once_the_last_files_are_being_moved_no_longer_stops_the_run(
    sim_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    original = StagedOutput._write_manifest

    def signalled(self: StagedOutput, groups: object) -> None:
        os.kill(os.getpid(), signal.SIGTERM)  # in the middle of the commit
        original(self, groups)  # type: ignore[arg-type]

    monkeypatch.setattr(StagedOutput, "_write_manifest", signalled)
    assert cli.main(["run", str(scenario(tmp_path, quick(sim_log))), "--out", str(out)]) == 0
    assert {"result.json", "calibration.yaml", MANIFEST_FILE} <= set(contents(out))
    assert "interrupted" not in capsys.readouterr().err


def test_a_signal_that_lands_in_a_finalizer_is_raised_where_the_program_can_unwind(
    capsys: pytest.CaptureFixture[str],
) -> None:
    class Dying:
        def __del__(self) -> None:
            os.kill(os.getpid(), signal.SIGINT)  # the handler runs inside the finalizer

    deadline = time.monotonic() + 30
    with interrupts.handled(), pytest.raises(interrupts.Interrupted):
        Dying()
        while time.monotonic() < deadline:
            pass
    assert time.monotonic() < deadline
    assert "Exception ignored" not in capsys.readouterr().err


def test_signals_inside_a_commit_wait_until_every_file_is_in_place(tmp_path: Path) -> None:
    with interrupts.handled(), pytest.raises(interrupts.Interrupted):
        with interrupts.deferred():
            os.kill(os.getpid(), signal.SIGINT)
            (tmp_path / "a").write_text("moved\n")  # still runs: the signal waits
        pytest.fail("the deferred signal was not raised at the end of the block")
    assert (tmp_path / "a").read_text() == "moved\n"


_HOLD_STAGING = """
import sys, time
from pathlib import Path
from nlp_calib.core import interrupts
from nlp_calib.outputs.outdir import StagedOutput
with interrupts.handled(), StagedOutput(Path(sys.argv[1])) as stage:
    (stage.path / "result.json").write_text("half")
    print(stage.path, flush=True)
    time.sleep(600)
"""


def hold_staging(out: Path) -> tuple[subprocess.Popen[str], Path]:
    """A child that holds a staging folder in ``out`` (a run killed while writing)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", _HOLD_STAGING, str(out)], cwd=REPO, stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None
    return proc, Path(proc.stdout.readline().strip())


def test_staging_folders_of_killed_runs_are_removed_by_the_next_run(sim_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    proc, staged = hold_staging(out)
    assert staged.is_dir()
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert staged.is_dir()  # nothing can clean up after SIGKILL...
    assert run_cli("run", str(scenario(tmp_path, quick(sim_log))), "--out", str(out)).returncode == 0
    assert staging_folders(out) == []  # ...but the next run does


def test_a_live_runs_staging_folder_is_never_removed(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = tmp_path / "out"
    out.mkdir()
    proc, staged = hold_staging(out)
    try:
        monkeypatch.setattr(outdir, "LOCK_WAIT_S", 0.3)
        busy = pytest.raises(NlpCalibError, match="another nlp-calib run has been writing into")
        with busy, pytest.warns(NlpCalibWarning, match="waiting for another"), StagedOutput(out):
            pass
        assert (staged / "result.json").read_text() == "half"
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
    assert staging_folders(out) == []  # SIGTERM: the holder removed its own folder


# ------------------------------------------------------------------------ 2. costs bounded first


@pytest.mark.parametrize(
    ("residual", "samples", "needles"),
    [
        ("{horizon: 5000}", "", ("residual.horizon: must be a whole number in [1, 200], got 5000",)),
        ("{horizon: 150}", "{stop: 150}", ("residual.horizon 150", "leaves 0 residual window(s)", "samples")),
        # 8 parameters: the robot's and the mount's 7 and the time offset, fitted by default,
        # whose search of ±0.5 s leaves the first 13 records (25 Hz) out of the fit.
        (
            "{horizon: 135}",
            "{stop: 150}",
            ("leaves 2 residual window(s)", "at most 129", "search", "samples"),
        ),
        ("{horizon: 10, stride: 1000}", "", ("residual.horizon 10 (stride 1000)", "leaves 1 residual")),
        # The lag fitted: 8 parameters, and its search of ±0.5 s leaves the first 13 records
        # (25 Hz) out of its fit, which the check counts (it was refused later, in the lag's fit).
        (
            "{horizon: 135}\nalignment: {tracker_lag: auto, search: [-0.5, 0.5]}",
            "{stop: 150}",
            ("leaves 2 residual window(s)", "at most 129", "search", "samples"),
        ),
    ],
)
def test_a_horizon_the_samples_cannot_hold_is_refused_before_the_build(
    residual: str, samples: str, needles: tuple[str, ...], sim_log: Path, tmp_path: Path
) -> None:
    text = f"dataset: {sim_log}\nresidual: {residual}\n" + (f"samples: {samples}\n" if samples else "")
    out = tmp_path / "out"
    assert_one_line_error(run_cli("run", str(scenario(tmp_path, text)), "--out", str(out)), 2, *needles)
    assert_nothing_written(out)


def test_the_horizon_check_counts_windows_as_the_residual_data_does(sim_log: Path, tmp_path: Path) -> None:
    # The longest horizon the check allows builds exactly as many windows as there are parameters
    # (the lag held); with the lag fitted, the longest builds (the lag's search on the records its
    # reach leaves, the final fit on more), one more is refused.
    def setup(horizon: int, alignment: str) -> Calibration:
        text = f"dataset: {sim_log}\nresidual: {{horizon: {horizon}}}\nsamples: {{stop: 150}}\n{alignment}"
        return Calibration.setup(load_scenario(scenario(tmp_path, text + "solvers: [gauss_newton]\n")))

    calib = setup(143, "alignment: {tracker_lag: 0.0}\n")
    assert calib.data.n_residuals == calib.fns.n_free == 7
    assert setup(129, "").fns.n_free == 8
    with pytest.raises(ScenarioError, match="at most 129"):
        setup(130, "")


def test_the_horizon_check_counts_the_records_a_fitted_lag_leaves(sim_log: Path, tmp_path: Path) -> None:
    # With the lag fitted the longest horizon the check allows builds (the lag's search on the
    # records its reach leaves, the final fit on more); one more is refused before any fit.
    def setup(horizon: int) -> Calibration:
        text = (
            f"dataset: {sim_log}\nresidual: {{horizon: {horizon}}}\nsamples: {{stop: 150}}\n"
            "alignment: {tracker_lag: auto, search: [-0.5, 0.5]}\nsolvers: [gauss_newton]\n"
        )
        return Calibration.setup(load_scenario(scenario(tmp_path, text)))

    assert setup(129).fns.n_free == 8
    with pytest.raises(ScenarioError, match="at most 129"):
        setup(130)


def laughs(indent: str, levels: int = 9) -> str:
    lines = [f'{indent}a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    lines += [f"{indent}a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def test_yaml_nesting_is_bounded_at_its_limit_not_before() -> None:
    # The mapping is a level too: 1 + 63 lists is the limit.
    deepest = "x: " + "[" * (MAX_YAML_DEPTH - 1) + "]" * (MAX_YAML_DEPTH - 1) + "\n"
    nested: list[object] = []
    for _ in range(MAX_YAML_DEPTH - 2):
        nested = [nested]
    assert parse_yaml(deepest, "deep.yaml") == {"x": nested}
    with pytest.raises(ConfigError, match="nested too deeply"):
        parse_yaml("x: " + "[" * MAX_YAML_DEPTH + "]" * MAX_YAML_DEPTH + "\n", "deeper.yaml")


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("dataset: x.txt\n" + laughs(""), "more than 20,000 values"),
        (
            "dataset: x.txt\nsolvers: [ipopt]\nipopt:\n  options:\n" + laughs("    "),
            "more than 20,000 values",
        ),
        ("dataset: x.txt\ninitial_guess:\n" + laughs("  "), "more than 20,000 values"),
        ("dataset: x.txt\nipopt:\n  options: &a {x: *a}\n", "an alias refers to a block that contains it"),
        ("dataset: x.txt\nipopt: {options: {x: " + "[" * 3000 + "]" * 3000 + "}}\n", "nested too deeply"),
        # Within the size bound: as deep as 64 KiB allows (libyaml's recursion ends the process).
        ("x: " + "[" * 32_000 + "]" * 32_000 + "\n", "nested too deeply"),
        ("x:\n" + "".join(" " * i + "a:\n" for i in range(65)), "nested too deeply"),
        ("dataset: x.txt\nfixed: [" + ",".join(["1"] * 25000) + "]\n", "more than 20,000 values"),
        ("dataset: x.txt\n#" + "x" * 70_000 + "\n", "larger than 64 KiB"),
        ("dataset: x.txt\nrobust: {delta: " + "9" * 5000 + "}\n", "a number with thousands of digits"),
    ],
)
def test_yaml_bombs_are_refused_before_their_values_are_used(text: str, needle: str, tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=re.escape(needle)):
        load_scenario(scenario(tmp_path, text))


def test_a_fifo_or_device_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "scenario.yaml"
    os.mkfifo(fifo)  # opening it for reading would block until a writer appears
    with pytest.raises(ScenarioError, match="not a regular file"):
        load_scenario(fifo)
    with pytest.raises(ScenarioError, match="not a regular file"):
        load_scenario("/dev/zero")


# ------------------------------------------------------------------------ 3. files we did not write


def test_a_users_file_named_like_a_report_file_is_never_overwritten_or_deleted(
    sim_log: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "trajectory.png").write_text("my own figure\n")
    sc = str(scenario(tmp_path, quick(sim_log)))
    assert run_cli("run", sc, "--out", str(out)).returncode == 0  # no report: no clash
    before = contents(out)
    proc = run_cli("run", sc, "--out", str(out), "--report")
    assert_one_line_error(proc, 2, str(out / "trajectory.png"), "not written by nlp_calib", "--force")
    assert contents(out) == before
    assert run_cli("run", sc, "--out", str(out)).returncode == 0
    assert (out / "trajectory.png").read_text() == "my own figure\n"
    # --force: the user says the file may go; it is ours from then on.
    assert run_cli("run", sc, "--out", str(out), "--report", "--force").returncode == 0
    assert (out / "trajectory.png").read_bytes().startswith(b"\x89PNG")
    assert "trajectory.png" in json.loads((out / MANIFEST_FILE).read_text())["files"]


@pytest.mark.parametrize("name", ["result.json", "calibration.yaml", "sensor_mount.urdf.xml"])
def test_a_users_file_named_like_a_result_file_stops_the_run(
    name: str, sim_log: Path, tmp_path: Path
) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("mine\n")
    proc = run_cli("run", str(scenario(tmp_path, quick(sim_log))), "--out", str(out))
    assert_one_line_error(proc, 2, str(out / name))
    assert contents(out) == {name: b"mine\n"}


def test_files_of_other_commands_are_not_removed_by_a_run(sim_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    sc = str(scenario(tmp_path, quick(sim_log)))
    assert run_cli("odometry", sc, "--out", str(out)).returncode == 0
    assert run_cli("run", sc, "--out", str(out)).returncode == 0
    assert {"odometry.csv", "result.json"} <= set(contents(out))
    groups = json.loads((out / MANIFEST_FILE).read_text())["groups"]
    # odometry writes the run's files too (it calibrates); a later run leaves its odometry.csv alone
    assert "odometry.csv" in groups["odometry"] and "result.json" in groups["run"]


def test_a_manifest_cannot_point_the_clean_up_outside_the_folder(sim_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    victim = tmp_path / "victim.txt"
    victim.write_text("mine\n")
    crafted = {"files": ["../victim.txt", str(victim)], "groups": {"run": ["../victim.txt", str(victim)]}}
    (out / MANIFEST_FILE).write_text(json.dumps(crafted))
    assert run_cli("run", str(scenario(tmp_path, quick(sim_log))), "--out", str(out)).returncode == 0
    assert victim.read_text() == "mine\n"


def test_two_scenarios_with_one_name_are_an_error(sim_log: Path, tmp_path: Path) -> None:
    a = scenario(tmp_path, "name: same\n" + quick(sim_log), "a.yaml")
    b = scenario(tmp_path, "name: same\n" + quick(sim_log), "b.yaml")
    out = tmp_path / "out"
    proc = run_cli("run", str(a), str(b), "--out", str(out))
    assert_one_line_error(proc, 2, "two scenarios are named 'same'", "a.yaml", "b.yaml")
    assert_nothing_written(out)


def test_a_second_scenario_that_cannot_run_stops_the_call_before_the_first_is_solved(
    sim_log: Path, tmp_path: Path
) -> None:
    good = scenario(tmp_path, quick(sim_log), "good.yaml")
    bad = scenario(
        tmp_path, quick(sim_log).replace("horizon: 10", "horizon: 200") + "samples: {stop: 150}\n", "bad.yaml"
    )
    out = tmp_path / "out"
    assert_one_line_error(
        run_cli("run", str(good), str(bad), "--out", str(out)), 2, "bad.yaml", "residual.horizon"
    )
    assert not (out / "good" / "result.json").exists()


def test_simulate_never_replaces_an_existing_log_without_force(sim_log: Path, tmp_path: Path) -> None:
    log = tmp_path / "mine.txt"
    log.write_text("my real log\n")
    assert_one_line_error(run_cli("simulate", "--out", str(log)), 2, str(log), "--force")
    assert log.read_text() == "my real log\n"
    new = tmp_path / "new.txt"
    truth = tmp_path / "new.truth.json"
    truth.write_text("my notes\n")
    assert_one_line_error(run_cli("simulate", "--out", str(new)), 2, str(truth))
    assert truth.read_text() == "my notes\n" and not new.exists()
    assert run_cli("simulate", "--out", str(log), "--records", "50", "--force").returncode == 0
    assert log.read_text().startswith("#kinematic_model")


@pytest.mark.parametrize("command", ["run", "odometry", "codegen"])
def test_an_empty_out_is_an_error_not_the_current_folder(command: str, sim_log: Path, tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONWARNINGS="ignore", PYTHONPATH=str(REPO))  # this checkout, from elsewhere
    proc = subprocess.run(
        [sys.executable, "-m", "nlp_calib", command, str(scenario(tmp_path, quick(sim_log))), "--out", ""],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert_one_line_error(proc, 2, "argument --out: expected a path, got ''")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.yaml"]


# ------------------------------------------------------------------------ 4. YAML that says one thing


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (
            "dataset: x.txt\nresidual: {horizon: 10}\nsamples: {}\nresidual: {horizon: 5}\n",
            "case.yaml:4: not valid YAML (duplicate key 'residual' at lines 2 and 4;",
        ),
        (
            "dataset: x.txt\nresidual: {horizon: 10, horizon: 5}\n",
            "case.yaml:2: not valid YAML (duplicate key 'horizon' at lines 2 and 2;",
        ),
        (
            "dataset: x.txt\nipopt:\n  options:\n    mu_init: 0.1\n    mu_init: 0.2\n",
            "case.yaml:5: not valid YAML (duplicate key 'mu_init' at lines 4 and 5;",
        ),
        ("dataset: x.txt\ndataset: y.txt\n", "duplicate key 'dataset' at lines 1 and 2;"),
    ],
)
def test_a_duplicate_key_is_an_error_naming_it_and_both_lines(text: str, needle: str, tmp_path: Path) -> None:
    with pytest.raises(ScenarioError) as exc:
        load_scenario(scenario(tmp_path, text))
    assert needle in str(exc.value)


def test_merge_keys_may_override_what_they_merge() -> None:
    assert parse_yaml("base: &b {a: 1, b: 2}\nuse: {<<: *b, a: 3}\n", "x")["use"] == {"a": 3, "b": 2}


@pytest.mark.parametrize(
    ("text", "expected"),
    [("1e-2", 0.01), ("1E-3", 0.001), ("5e1", 50.0), ("-2.5e+1", -25.0), (".5", 0.5), ("1.0e-2", 0.01)],
)
def test_yaml_numbers_in_exponent_form_are_numbers(text: str, expected: float) -> None:
    assert parse_yaml(f"value: {text}\n", "x") == {"value": expected}


def test_every_yaml_example_in_the_docs_loads() -> None:
    blocks = []
    for page in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        blocks += re.findall(r"```yaml\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.S)
    assert blocks
    for block in blocks:
        doc = parse_yaml(block, "example")
        if isinstance(doc, dict) and isinstance(doc.get("dataset"), str):  # a scenario
            scenario_from_mapping(doc, "example", REPO)


def test_nan_inside_an_initial_guess_mapping_says_what_is_wrong(tmp_path: Path) -> None:
    with pytest.raises(ScenarioError) as exc:
        load_scenario(scenario(tmp_path, "dataset: x.txt\ninitial_guess: {axis_length: .nan}\n"))
    assert "initial_guess.axis_length: expected a finite number, got nan" in str(exc.value)
    assert "expected a string" not in str(exc.value)


@pytest.mark.parametrize(
    ("options", "needle"),
    [
        ("{mu_init: [1, 2]}", "ipopt.options.mu_init: expected a finite number, a string or true/false"),
        ("{mu_init: .nan}", "ipopt.options.mu_init"),
        ("{max_iter: " + "9" * 30 + "}", "ipopt.options.max_iter"),
    ],
)
def test_ipopt_passthrough_options_are_plain_values(options: str, needle: str, tmp_path: Path) -> None:
    with pytest.raises(ScenarioError, match=re.escape(needle)):
        load_scenario(scenario(tmp_path, f"dataset: x.txt\nipopt: {{options: {options}}}\n"))


# ------------------------------------------------------------------------ 5. option values


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (("simulate", "--noise-xy", "-0.1"), ("argument --noise-xy", "[0, 1]", "'-0.1'")),
        (("simulate", "--seed", "-1"), ("argument --seed", "whole number in [0, 4294967295]")),
        (("simulate", "--records", "10000000000"), ("argument --records", "[3, 1000000000]")),
        (("simulate", "--outliers", "nan"), ("argument --outliers", "[0, 1)")),
        (("simulate", "--latency", "abc"), ("argument --latency", "'abc'")),
        (("odometry", "SC", "--sigma", "-3"), ("argument --sigma", "(0, 10]")),
        (("odometry", "SC", "--sigma", "0"), ("argument --sigma", "(0, 10]")),
        (("odometry", "SC", "--sigma", "nan"), ("argument --sigma", "'nan'")),
    ],
)
def test_every_bad_option_value_is_exit_2_naming_the_option_and_range(
    args: tuple[str, ...], needles: tuple[str, ...], sim_log: Path, tmp_path: Path
) -> None:
    sc = str(scenario(tmp_path, quick(sim_log)))
    out = tmp_path / "out"
    argv = [sc if a == "SC" else a for a in args]
    proc = run_cli(*argv, "--out", str(out / "s.txt" if args[0] == "simulate" else out))
    assert_one_line_error(proc, 2, *needles)
    assert_nothing_written(out)


def test_a_simulation_config_beyond_the_limits_is_refused(tmp_path: Path) -> None:
    config = tmp_path / "sim.yaml"
    for text, needle in [
        ("records: 10000000000\n", "records must be a whole number in [3, 1000000000]"),
        ("substeps: 5000\n", "substeps must be a whole number in [1, 1000]"),
        ("truth: {k_traction: 0}\n", "truth.k_traction must be a number in [0.0001, 10]"),
        ("rate_hz: 1e-300\n", "rate_hz must be a number in [1, 1000]"),
    ]:
        config.write_text(text)
        assert_one_line_error(
            run_cli("simulate", "--config", str(config), "--out", str(tmp_path / "s.txt")), 2, needle
        )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sim.yaml"]


def test_a_linear_solver_that_is_not_installed_is_an_input_error(sim_log: Path, tmp_path: Path) -> None:
    text = f"dataset: {sim_log}\nresidual: {{horizon: 10}}\nipopt: {{linear_solver: ma57}}\n"
    out = tmp_path / "out"
    proc = run_cli("run", str(scenario(tmp_path, text)), "--out", str(out))
    assert_one_line_error(proc, 2, "ipopt", "'ma57'", "installed")
    assert_nothing_written(out)


def test_a_failed_odometry_run_writes_nothing(sim_log: Path, tmp_path: Path) -> None:
    text = quick(sim_log) + "gauss_newton: {max_iterations: 1}\n"
    out = tmp_path / "out"
    proc = run_cli("odometry", str(scenario(tmp_path, text)), "--out", str(out), "--report")
    assert_one_line_error(proc, 1, "did not converge", "no odometry")
    assert_nothing_written(out)


def test_docs_examples_of_the_command_line_parse() -> None:
    """The synopsis in docs/cli.md names options the parser accepts."""
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    options = set(re.findall(r"(--[a-z][a-z-]+)", text))
    # One command's help from the tool's own process; the others from its entry point in this one
    # (the same parser, without an interpreter's start for each).
    helps = [
        subprocess.run(
            [sys.executable, "-m", "nlp_calib", "run", "--help"], cwd=REPO, capture_output=True, text=True
        ).stdout
    ]
    helps += [
        run_cli(cmd, "--help").stdout
        for cmd in (
            "compare",
            "validate",
            "odometry",
            "codegen",
            "simulate",
            "import-bag",
            "check",
            "batch",
            "preflight",
            "init",
        )
    ]
    assert all(h.startswith("usage: ") for h in helps), helps
    help_text = " ".join(helps)
    assert options and all(o in help_text or o == "--debug" for o in options), sorted(options)
