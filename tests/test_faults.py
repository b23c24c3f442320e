"""Bad input, faults and failure modes: clear errors, nothing lost, no silent nonsense.

Each case runs the command line in a subprocess where it can (exit code, one line ``error: ...``
on stderr naming the problem, no traceback, no partial result), or the library directly where
the point is what it returns. Logs come from the simulator, mutated line by line.
"""

from __future__ import annotations

import json
import subprocess
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import cli as run_cli
from conftest import parse_lines, write_sim

from nlp_calib import cli
from nlp_calib.core import files
from nlp_calib.core.errors import DatasetError, SolverError
from nlp_calib.core.numeric import COUNTER_MODULUS
from nlp_calib.logs.checks import JUMP_FACTOR, counter_jumps
from nlp_calib.outputs.outdir import MANIFEST_FILE
from nlp_calib.pipeline import Calibration
from nlp_calib.pipeline.fit import Fit
from nlp_calib.pipeline.scenario import load_scenario
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.simulation.simulate import truth_path
from nlp_calib.sources import load_log

N_HEADER = 8  # '#' lines of a simulated log


def assert_one_line_error(proc: subprocess.CompletedProcess[str], code: int, *needles: str) -> str:
    """Exit ``code``, exactly one stderr line ``error: ...`` containing every needle, no traceback;
    any other stderr line is a ``warning: ...`` printed as it happened."""
    assert proc.returncode == code, proc.stderr
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    errors = [ln for ln in lines if ln.startswith("error: ")]
    assert len(errors) == 1 and all(ln.startswith(("error: ", "warning: ")) for ln in lines), proc.stderr
    for needle in needles:
        assert needle in errors[0], f"{needle!r} not in {errors[0]!r}"
    return errors[0]


def assert_nothing_written(out: Path) -> None:
    assert not out.exists() or not any(out.iterdir()), list(out.iterdir())


@pytest.fixture(scope="module")
def log_lines() -> list[str]:
    """A short simulated log (300 records, turns and reversals) as lines."""
    return simulate(SimulationOptions.of(records=300, seed=5)).text().splitlines()


def scenario(tmp_path: Path, log: Path | str, extra: str = "", name: str = "case.yaml") -> Path:
    """A scenario on ``log`` with short windows (fast), plus ``extra`` YAML lines."""
    path = tmp_path / name
    path.write_text(f"dataset: {log}\nresidual: {{horizon: 10}}\n{extra}")
    return path


def write_log(tmp_path: Path, lines: list[str], name: str = "log.txt", newline: bool = True) -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + ("\n" if newline else ""))
    return path


def set_field(line: str, index: int, value: str) -> str:
    """The record ``line`` with its whitespace-separated token ``index`` replaced."""
    tokens = line.split()
    tokens[index] = value
    return " ".join(tokens)


# Token positions in a record: time: T ticks: S C model_pose: x y th tracker_pose: x y th
TIME, STEER, TRACTION, TRACKER_X = 1, 3, 4, 10


# ----------------------------------------------------------------------------------- 1. reader


def reader_case(
    tmp_path: Path, lines: list[str], **kw: bool
) -> tuple[Path, subprocess.CompletedProcess[str]]:
    log = write_log(tmp_path, lines, **kw)
    out = tmp_path / "out"
    return log, run_cli("run", str(scenario(tmp_path, log)), "--out", str(out))


READER_CASES: dict[str, tuple[Callable[[list[str]], list[str]], tuple[str, ...]]] = {
    "empty file": (lambda ls: [], ("the file is empty",)),
    "records without a header": (lambda ls: ls[N_HEADER:], (":1:", "no '#' header before this record")),
    "header only": (lambda ls: ls[:N_HEADER], (":8:", "ends after the header")),
    "missing header field": (
        lambda ls: [ln for ln in ls if not ln.startswith("#joints_max_enc_values")],
        ("#joints_max_enc_values: ...' is missing",),
    ),
    "unparsable header field": (
        lambda ls: [
            ln.replace("8192", "inf") if ln.startswith("#joints_max_enc_values") else ln for ln in ls
        ],
        (":5:", "'inf 5000'", "expected finite numbers"),
    ),
    "nan initial guess in header": (
        lambda ls: [ln.replace(" 0.5 ", " nan ") if ln.startswith("#parameter_values") else ln for ln in ls],
        (":3:", "#parameter_values: expected finite numbers"),
    ),
    "too few fields": (
        lambda ls: [*ls[:20], ls[20].rsplit(" ", 1)[0], *ls[21:]],
        (":21:", "'tracker_pose:' needs 3 value(s), found 2", "time: 17"),
    ),
    "non-numeric field": (
        lambda ls: [*ls[:20], set_field(ls[20], TRACKER_X, "0.1x"), *ls[21:]],
        (":21:", "tracker_pose: expected numbers", "0.1x"),
    ),
    "nan pose": (
        lambda ls: [*ls[:30], set_field(ls[30], TRACKER_X, "nan"), *ls[31:]],
        (":31:", "tracker_pose is nan", "strict: false"),
    ),
    "infinite pose": (
        lambda ls: [*ls[:30], set_field(ls[30], TRACKER_X + 1, "-inf"), *ls[31:]],
        (":31:", "-inf", "expected finite numbers"),
    ),
    "nan time": (
        lambda ls: [*ls[:30], set_field(ls[30], TIME, "nan"), *ls[31:]],
        (":31:", "time: expected seconds", "'nan'"),
    ),
    "steering out of range": (
        lambda ls: [*ls[:40], set_field(ls[40], STEER, "8192"), *ls[41:]],
        (":41:", "encoder 'steering' reads 8192, outside [0, 8192)"),
    ),
    "time goes back": (
        lambda ls: [*ls[:51], ls[52], ls[51], *ls[53:]],
        (":53:", "goes back from", "(line 52)"),
    ),
    "duplicate record": (
        lambda ls: [*ls[:50], ls[50], *ls[50:]],
        (":52:", "duplicates the previous record's", "(line 51)"),
    ),
    "traction jump": (
        lambda ls: [*ls[:60], set_field(ls[60], TRACTION, "123456789"), *ls[61:]],
        (":61:", "counter 'traction_wheel' steps", "123456789", "typical step", "strict: false"),
    ),
    "truncated last line": (
        lambda ls: [*ls[:-1], ls[-1][:45]],
        (":308:", "needs", "cut short by a crashed logger", "strict: false"),
    ),
}


@pytest.mark.parametrize("case", list(READER_CASES))
def test_malformed_log_is_a_one_line_error_naming_file_and_line(
    case: str, log_lines: list[str], tmp_path: Path
) -> None:
    mutate, needles = READER_CASES[case]
    log, proc = reader_case(tmp_path, mutate(log_lines), newline=case != "truncated last line")
    message = assert_one_line_error(proc, 2, str(log), *needles)
    assert message.startswith(f"error: {log}")
    assert_nothing_written(tmp_path / "out")


def _parse_quietly(lines: list[str]) -> tuple[object, list[str]]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ds = parse_lines(lines, "log.txt", strict=False)
    return ds, [str(w.message) for w in caught]


@pytest.mark.parametrize(
    "case",
    [
        "too few fields",
        "non-numeric field",
        "nan pose",
        "infinite pose",
        "nan time",
        "steering out of range",
        "duplicate record",
        "traction jump",
        "truncated last line",
    ],
)
def test_non_strict_read_drops_the_bad_record_and_says_so(case: str, log_lines: list[str]) -> None:
    mutate, needles = READER_CASES[case]
    lines = mutate(log_lines)
    ds, caught = _parse_quietly(lines)
    n_records = len(lines) - N_HEADER
    assert ds.n_records == n_records - 1  # type: ignore[attr-defined]
    (dropped,) = ds.dropped  # type: ignore[attr-defined]
    line = int(needles[0].strip(":"))
    assert dropped.line == line
    assert len(caught) == 1 and f"dropped 1 of {n_records} records" in caught[0] and str(line) in caught[0]


def test_time_going_back_drops_the_out_of_order_record(log_lines: list[str]) -> None:
    ds, _ = _parse_quietly(READER_CASES["time goes back"][0](log_lines))
    assert [d.line for d in ds.dropped] == [53]  # type: ignore[attr-defined]
    assert np.all(np.diff(ds.time_s) > 0)  # type: ignore[attr-defined]


def test_header_problems_are_errors_even_when_not_strict(log_lines: list[str]) -> None:
    for case in ("empty file", "header only", "missing header field", "unparsable header field"):
        with pytest.raises(DatasetError):
            _parse_quietly(READER_CASES[case][0](log_lines))


def test_a_glitched_traction_reading_is_dropped_alone(log_lines: list[str]) -> None:
    clean = parse_lines(log_lines)
    for k in (0, 60, 61, len(log_lines) - N_HEADER - 1):  # first, middle, adjacent, last record
        lines = list(log_lines)
        lines[N_HEADER + k] = set_field(lines[N_HEADER + k], TRACTION, "4000000000")
        ds, _ = _parse_quietly(lines)
        assert [d.line for d in ds.dropped] == [N_HEADER + k + 1]  # type: ignore[attr-defined]
        keep = np.delete(np.arange(clean.n_records), k)
        np.testing.assert_array_equal(ds.ticks, clean.ticks[keep])  # type: ignore[attr-defined]


def test_a_run_of_glitched_readings_is_bridged(log_lines: list[str]) -> None:
    lines = list(log_lines)
    for k in range(100, 103):
        lines[N_HEADER + k] = set_field(lines[N_HEADER + k], TRACTION, str(2_000_000_000 + k))
    ds, _ = _parse_quietly(lines)
    assert [d.line for d in ds.dropped] == [N_HEADER + k + 1 for k in range(100, 103)]  # type: ignore[attr-defined]
    assert "corrupt reading" in ds.dropped[0].reason  # type: ignore[attr-defined]


def test_a_counter_reset_keeps_the_longest_part_of_the_log(log_lines: list[str]) -> None:
    lines = list(log_lines)
    for k in range(N_HEADER + 200, len(lines)):  # an offset from record 200 on that never returns
        ticks = (int(lines[k].split()[TRACTION]) + 50_000_000) % COUNTER_MODULUS
        lines[k] = set_field(lines[k], TRACTION, str(ticks))
    ds, caught = _parse_quietly(lines)
    assert ds.n_records == 200  # type: ignore[attr-defined]
    assert len(ds.dropped) == 100 and "counter reset" in ds.dropped[0].reason  # type: ignore[attr-defined]
    assert "dropped 100 of 300 records" in caught[0]


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize(
    "options",
    [{}, {"latency_s": 0.06, "outlier_fraction": 0.1}, {"trajectory": "no_reversals"}, {"jitter_s": 0.015}],
)
def test_simulated_logs_have_no_counter_jumps(seed: int, options: dict[str, object]) -> None:
    sim = simulate(SimulationOptions.of(records=800, seed=seed, **options))  # type: ignore[arg-type]
    assert counter_jumps(sim.ticks[:, 1], sim.time_ns, COUNTER_MODULUS) == []
    parse_lines(sim.text().splitlines())  # strict: no error


def test_real_log_has_no_counter_jumps_but_a_ten_times_larger_step_is_one(real_log: Path) -> None:
    ds = load_log(real_log)  # strict: the real log's own faults (records 561, 882, 1204) are in range
    traction = ds.encoder("traction_wheel")
    t_ns = np.round(ds.time_s * 1e9).astype(np.int64)
    assert counter_jumps(traction, t_ns, COUNTER_MODULUS) == []
    # The same log with one step made JUMP_FACTOR times its largest is caught.
    bumped = traction.copy()
    steps = ds.increments("traction_wheel")
    k = int(np.argmax(np.abs(steps)))
    bumped[k + 1 :] = (bumped[k + 1 :] + int(JUMP_FACTOR * steps[k])) % COUNTER_MODULUS
    assert [j.index for j in counter_jumps(bumped, t_ns, COUNTER_MODULUS)] == [k]


def test_non_strict_run_reports_dropped_records_in_result_and_terminal(
    log_lines: list[str], tmp_path: Path
) -> None:
    lines = READER_CASES["traction jump"][0](log_lines)
    lines = READER_CASES["nan pose"][0](lines)
    log = write_log(tmp_path, lines)
    out = tmp_path / "out"
    proc = run_cli(
        "run", str(scenario(tmp_path, log, "strict: false\nsolvers: [gauss_newton]\n")), "--out", str(out)
    )
    assert proc.returncode == 0, proc.stderr
    assert "log: dropped 2 of 300 records (strict: false) at line(s) 31, 61" in proc.stdout
    assert "warning: " in proc.stderr and "dropped 2 of 300 records" in proc.stderr
    doc = json.loads((out / "result.json").read_text())
    assert doc["dataset"]["records"] == 298
    assert [d["line"] for d in doc["dataset"]["dropped_records"]] == [31, 61]
    assert "tracker_pose is nan" in doc["dataset"]["dropped_records"][0]["reason"]


# ------------------------------------------------------------------------- 2. scenario and CLI


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_sim(tmp_path_factory.mktemp("faults"), records=300, seed=5)


SCENARIO_CASES: dict[str, tuple[str, tuple[str, ...]]] = {
    "unreadable yaml": ("robust: {kernel: huber\n", ("case.yaml:", "not valid YAML")),
    "wrong type": (
        "validation: {rpe_window: ten}\n",
        ("validation.rpe_window: expected an integer", "'ten'"),
    ),
    "unknown key": ("robustness: {}\n", ("robustness: unknown key", "valid keys are")),
    "empty bounds": ("bounds: {axis_length: []}\n", ("bounds.axis_length", "list of 2 values")),
    "inconsistent bounds": ("bounds: {axis_length: [3.0, 1.0]}\n", ("bounds.axis_length", "lo < hi")),
    "guess outside bounds": (
        "initial_guess: {axis_length: 5.0}\nbounds: {axis_length: [0.5, 3.0]}\n",
        ("bounds.axis_length", "initial guess 5 lies outside [0.5, 3]"),
    ),
    "header guess outside bounds": (
        "bounds: {axis_length: [2.0, 3.0]}\n",
        ("bounds.axis_length", "initial guess 1.4 lies outside [2, 3]", "log header"),
    ),
    "unknown solver": ("solvers: [newton]\n", ("solvers: 'newton' is not one of gauss_newton, ipopt",)),
    "unknown kernel": ("robust: {kernel: tukey}\n", ("robust.kernel: 'tukey' is not one of",)),
    "huge number": ("robust: {delta: " + "9" * 400 + "}\n", ("robust.delta: expected a finite number",)),
    "name with a slash": ("name: ../elsewhere\n", ("name: must be a plain folder name",)),
    "unknown ipopt option": (
        "solvers: [ipopt]\nipopt: {options: {no_such_option: 1}}\n",
        ("ipopt: IPOPT cannot be set up", "no_such_option"),
    ),
    "lag beyond the log": ("alignment: {tracker_lag: 1000.0}\n", ("alignment.tracker_lag",)),
}


@pytest.mark.parametrize("case", list(SCENARIO_CASES))
def test_bad_scenario_is_a_one_line_usage_error(case: str, sim_log: Path, tmp_path: Path) -> None:
    extra, needles = SCENARIO_CASES[case]
    out = tmp_path / "out"
    proc = run_cli("run", str(scenario(tmp_path, sim_log, extra)), "--out", str(out))
    assert_one_line_error(proc, 2, *needles)
    assert_nothing_written(out)


def test_missing_dataset_is_a_usage_error(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = run_cli("run", str(scenario(tmp_path, "nope.txt")), "--out", str(out))
    assert_one_line_error(proc, 2, str(tmp_path / "nope.txt"), "no such file")
    assert_nothing_written(out)


def test_missing_or_unreadable_scenario_file(tmp_path: Path) -> None:
    assert_one_line_error(
        run_cli("run", str(tmp_path / "none.yaml")), 2, "none.yaml", "no such scenario file"
    )
    assert_one_line_error(run_cli("run", str(tmp_path)), 2, "cannot read the scenario file")


def test_output_folder_that_cannot_be_written(sim_log: Path, tmp_path: Path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder\n")
    sc = scenario(tmp_path, sim_log)
    for out in (blocker / "sub", blocker):
        proc = run_cli("run", str(sc), "--out", str(out))
        assert_one_line_error(proc, 2, "cannot write to the output folder", str(out))
    assert blocker.read_text() == "not a folder\n"
    proc = run_cli("simulate", "--out", str(blocker / "sim.txt"))
    assert_one_line_error(proc, 2, "cannot write to the output folder")


def test_runtime_failure_exits_1_in_one_line_and_debug_shows_the_traceback(
    sim_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    sc = scenario(tmp_path, sim_log, "solvers: [gauss_newton]\n")

    def broken(self: Fit, solver: str, from_estimate: bool = False) -> None:
        raise SolverError(f"{solver} could not run")

    monkeypatch.setattr(Fit, "solve", broken)
    assert cli.main(["run", str(sc), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err == "error: gauss_newton could not run\n"
    assert_nothing_written(tmp_path / "out")

    def crash(self: Fit, solver: str, from_estimate: bool = False) -> None:
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(Fit, "solve", crash)
    assert cli.main(["run", str(sc), "--out", str(tmp_path / "out")]) == 1
    err = capsys.readouterr().err
    assert err.startswith("error: internal error: ZeroDivisionError: boom") and "Traceback" not in err
    assert cli.main(["--debug", "run", str(sc), "--out", str(tmp_path / "out")]) == 1
    assert "Traceback" in capsys.readouterr().err


# ------------------------------------------------------------------------------------ 3. solvers


def solver_case(
    tmp_path: Path, log: Path, extra: str, *options: str
) -> tuple[subprocess.CompletedProcess[str], dict]:
    out = tmp_path / "out"
    proc = run_cli("run", str(scenario(tmp_path, log, extra)), "--out", str(out), *options)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    return proc, json.loads((out / "result.json").read_text())


def assert_not_converged(proc: subprocess.CompletedProcess[str], doc: dict, solver: str, reason: str) -> None:
    res = doc["solvers"][solver]
    assert res["converged"] is False and reason in res["reason"], res["reason"]
    assert (
        f"WARNING: {solver} did not converge: " in proc.stdout and "Do not use its parameters" in proc.stdout
    )
    assert any(w.startswith(f"{solver}: ") for w in doc["warnings"])


def test_nan_residual_is_reported_by_both_solvers(sim_log: Path, tmp_path: Path) -> None:
    proc, doc = solver_case(tmp_path, sim_log, "initial_guess: {axis_length: 0.0}\n")
    for solver in ("gauss_newton", "ipopt"):
        assert_not_converged(proc, doc, solver, "NaN or infinite at the initial guess")
        assert all(v is None for v in doc["solvers"][solver]["std"].values())
    assert not (tmp_path / "out" / "calibration.yaml").exists()
    assert "no solver converged" in proc.stderr
    # Judged by a model that gives NaN every interval would look faulty: the check says it did not run.
    assert doc["faults"]["checked"] is False and doc["faults"]["found"] == []
    assert "encoder faults not checked" in proc.stderr


def test_iteration_limit_is_reported(sim_log: Path, tmp_path: Path) -> None:
    proc, doc = solver_case(tmp_path, sim_log, "gauss_newton: {max_iterations: 1}\nipopt: {max_iter: 1}\n")
    assert_not_converged(proc, doc, "gauss_newton", "iteration limit (1) reached")
    assert_not_converged(proc, doc, "ipopt", "Maximum_Iterations_Exceeded")


def test_singular_normal_matrix_is_reported(tmp_path: Path) -> None:
    straight = write_sim(tmp_path, "straight.txt", records=300, seed=5, trajectory="straight")
    # The pre-flight would stop the run before any fit (tests/test_preflight.py): past it, the
    # solvers say the same in their own words.
    proc, doc = solver_case(tmp_path, straight, "", "--skip-preflight")
    for solver in ("gauss_newton", "ipopt"):
        assert_not_converged(proc, doc, solver, "singular normal matrix")
    assert "no turning" in proc.stdout


def test_non_convergence_of_one_solver_keeps_the_other(sim_log: Path, tmp_path: Path) -> None:
    proc, doc = solver_case(tmp_path, sim_log, "ipopt: {options: {max_cpu_time: 1.0e-9}}\n")
    assert_not_converged(proc, doc, "ipopt", "IPOPT stopped: Maximum_CpuTime_Exceeded")
    assert doc["solvers"]["gauss_newton"]["converged"] is True
    assert "solver: gauss_newton" in (tmp_path / "out" / "calibration.yaml").read_text()


def test_ipopt_reports_a_nan_start_instead_of_raising(sim_log: Path, tmp_path: Path) -> None:
    calib = Calibration.setup(
        load_scenario(scenario(tmp_path, sim_log, "initial_guess: {axis_length: 0.0}\n"))
    )
    results = [calib.solve(s) for s in ("gauss_newton", "ipopt")]
    assert [r.converged for r in results] == [False, False]
    assert results[0].reason == results[1].reason


# -------------------------------------------------------------------------------- 4. nothing lost


def listing(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def test_second_run_into_the_same_folder_does_not_mix_files(sim_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine\n")  # the user's own file: never touched
    # sensor_y given: on this 12 s log a lag fitted, or held with its plausible error in the σ,
    # leaves it to ±8 cm, and the URDF files whose replacement this test follows would be left out
    # (the subject here is the folder, not the mount).
    truth = json.loads(truth_path(sim_log).read_text())["params"]
    given = f"known: {{sensor_y: {truth['sensor_y']}}}\n"
    sc = scenario(tmp_path, sim_log, "solvers: [gauss_newton]\nalignment: {tracker_lag: 0.0}\n" + given)
    assert run_cli("run", str(sc), "--out", str(out), "--report").returncode == 0
    first = listing(out)
    assert {"trajectory.png", "report.md", "calibration.yaml", MANIFEST_FILE} <= first
    assert run_cli("run", str(sc), "--out", str(out)).returncode == 0
    expected = {"result.json", "calibration.yaml", "sensor_mount.urdf.xml", "robot.urdf", "ros2_control.yaml"}
    assert listing(out) == expected | {MANIFEST_FILE, "notes.txt"}
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    assert manifest["files"] == sorted(expected)
    # A run where no solver converges removes the now stale hand-off files too.
    failing = scenario(
        tmp_path, sim_log, "solvers: [gauss_newton]\ngauss_newton: {max_iterations: 1}\n", "f.yaml"
    )
    assert run_cli("run", str(failing), "--out", str(out)).returncode == 1
    assert listing(out) == {"result.json", MANIFEST_FILE, "notes.txt"}
    assert (out / "notes.txt").read_text() == "mine\n"


def test_interrupted_run_keeps_the_previous_result_and_leaves_no_partial_files(
    sim_log: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    sc = scenario(tmp_path, sim_log, "solvers: [gauss_newton]\n")
    assert cli.main(["run", str(sc), "--out", str(out)]) == 0
    before = {name: (out / name).read_bytes() for name in listing(out)}

    from nlp_calib.outputs import registry

    real = registry.write

    def interrupted(outputs: Any, runs: Any, top: Any, options: Any) -> list[Path]:
        real([o for o in outputs if o.group == "result"], runs, top, options)
        raise KeyboardInterrupt  # after result.json was written, before the hand-off files

    monkeypatch.setattr(registry, "write", interrupted)
    assert cli.main(["run", str(sc), "--out", str(out)]) == 130
    assert {name: (out / name).read_bytes() for name in listing(out)} == before
    # And into a fresh folder: nothing at all, not even temporary files.
    fresh = tmp_path / "fresh"
    assert cli.main(["run", str(sc), "--out", str(fresh)]) == 130
    assert listing(fresh) == set()
    capsys.readouterr()


def test_atomic_write_that_fails_leaves_the_old_file_and_no_temporary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    target = tmp_path / "result.json"
    target.write_text("old\n")

    def no_replace(src: str, dst: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(files.os, "replace", no_replace)
    with pytest.raises(OSError, match="disk full"):
        files.atomic_write_text(target, "new\n")
    assert target.read_text() == "old\n"
    assert listing(tmp_path) == {"result.json"}


def test_a_sound_increment_where_the_turn_rate_jumps_is_judged_at_the_references_lag() -> None:
    """Scans stamped 12 ms late over a drive whose turn rate jumps: judged at the stamps as logged,
    sound increments across a jump disagree with the wheels by the lag's share (many times the
    matcher's scatter); at the lag the screen fits in its range (12 ms, recovered), only the bad
    match does."""
    from types import SimpleNamespace

    from nlp_calib.analysis.faults import MATCH_SCATTER, _disagreement, _screen_lag
    from nlp_calib.core import poses
    from nlp_calib.core.numeric import robust_spread
    from nlp_calib.logs.relative import RelativeMotions

    rng = np.random.default_rng(5)
    fine = np.arange(0.0, 60.0, 0.001)
    turn = np.repeat(rng.uniform(-0.6, 0.6, 30), 2000)  # a new turn rate every 2 s
    speed = 0.3 + 0.1 * np.sin(fine)
    heading = np.concatenate([[0.0], np.cumsum(turn[:-1] * 0.001)])
    path = np.column_stack(
        [np.cumsum(speed * np.cos(heading)) * 0.001, np.cumsum(speed * np.sin(heading)) * 0.001, heading]
    )

    def pose(t: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, fine, path[:, i]) for i in range(3)])

    late, t = 0.012, np.arange(0.5, 59.5, 0.1)
    seen = pose(t - late)  # each scan taken 12 ms before its stamp
    z = poses.between(seen[:-1], seen[1:]) + rng.normal(0.0, [3e-4, 3e-4, 1e-4], (t.size - 1, 3))
    z[200] += [0.02, 0.0, 0.01]  # one bad match
    k = np.arange(t.size - 1)
    inc = RelativeMotions(k, k + 1, z, k + 1)

    def at(lag_s: float) -> tuple[np.ndarray, tuple[str, ...], np.ndarray, np.ndarray, tuple[int, int]]:
        wheels = pose(t - lag_s)  # the encoders read lag_s earlier
        return (*_disagreement(inc, z, poses.between(wheels[:-1], wheels[1:])), (0, t.size))

    at.log = SimpleNamespace(motions=inc)  # type: ignore[attr-defined]

    def flagged(lag_s: float) -> set[int]:
        e = at(lag_s)[0]
        centre, spread = robust_spread(e)
        return set(np.flatnonzero(np.max(np.abs(e - centre) / spread, axis=1) > MATCH_SCATTER).tolist())

    assert 200 in flagged(0.0) and len(flagged(0.0)) > 3  # the jumps' sound increments too
    fitted = _screen_lag(at, np.ones(inc.n, dtype=bool), (-0.5, 0.5))  # type: ignore[arg-type]
    assert fitted == pytest.approx(late, abs=0.002)
    assert flagged(fitted) == {200}
    assert _screen_lag(at, np.ones(inc.n, dtype=bool), 0.03) == 0.03  # type: ignore[arg-type]
