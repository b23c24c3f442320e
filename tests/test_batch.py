"""``nlp-calib batch``: its jobs and their names, the per-log task on other processes and on a Dask
cluster, the workers it chooses, the summary table, a failing log, exit codes and signals."""

from __future__ import annotations

import csv
import json
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from conftest import REPO, SCENARIOS, cli, write_sim

from nlp_calib.cli import main
from nlp_calib.core import threads
from nlp_calib.core.errors import UsageError
from nlp_calib.fleet import (
    BatchOptions,
    BatchRow,
    Job,
    batch_jobs,
    local_workers,
    run_job,
    run_jobs,
    write_summary,
)
from nlp_calib.fleet.jobs import expand, job_names

DEMO_LOG = SCENARIOS / "data" / "demo_tricycle.txt"


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two robots' drives, both called drive.txt, and a file that is no log."""
    root = tmp_path_factory.mktemp("fleet")
    for robot, seed in (("robot1", 1), ("robot2", 2)):
        (root / robot).mkdir()
        write_sim(root / robot, "drive.txt", records=400, seed=seed)
    (root / "robot2" / "broken.txt").write_text("not a log\n")
    return root


def quick_scenario(folder: Path) -> Path:
    path = folder / "quick.yaml"
    path.write_text(
        "dataset: none.txt\nresidual: {horizon: 5}\nsolvers: [gauss_newton]\nvalidation: {blocks: 5}\n"
    )
    return path


def test_logs_of_the_same_name_get_their_folders_names() -> None:
    paths = [Path("/d/robot1/drive.txt"), Path("/d/robot2/drive.txt"), Path("/d/robot2/other.txt")]
    assert job_names(paths) == ["robot1_drive", "robot2_drive", "other"]
    # Same folder names further up: as many parents as it takes.
    paths = [Path("/a/x/day1/drive.txt"), Path("/b/x/day1/drive.txt")]
    assert job_names(paths) == ["a_x_day1_drive", "b_x_day1_drive"]
    # Files that differ only by their suffix, and names that are no plain folder names.
    assert job_names([Path("/d/run.txt"), Path("/d/run.bag")]) == ["run.txt", "run.bag"]
    assert job_names([Path("/d/my drive (1).txt")]) == ["my_drive_1_"]


def test_inputs_are_folders_globs_and_yaml_lists(logs: Path, tmp_path: Path) -> None:
    drives = [logs / "robot1" / "drive.txt", logs / "robot2" / "drive.txt"]
    assert expand([str(logs / "robot2")]) == [logs / "robot2" / "broken.txt", drives[1]]
    assert expand([str(logs / "**" / "drive.txt")]) == drives
    listed = tmp_path / "fleet.yaml"
    listed.write_text(f"- {os.path.relpath(drives[0], tmp_path)}\n- {drives[1]}\n- {drives[0]}\n")
    assert [p.resolve() for p in expand([str(listed)])] == drives  # each once
    with pytest.raises(UsageError, match="no file matches it"):
        expand([str(logs / "nothing*.txt")])


def test_the_task_runs_on_other_processes_and_a_failure_is_its_row(logs: Path, tmp_path: Path) -> None:
    """The job and the row cross process boundaries (pickled); a log that fails is a row with its
    one-line error, and the others are written. The workers are spawned: a process forked from one
    that has run calibrations (threads, CasADi's state) may hang."""
    options = BatchOptions(tmp_path / "out", scenario=quick_scenario(tmp_path))
    jobs = batch_jobs([str(logs / "**" / "*.txt")], options)
    assert [j.name for j in jobs] == ["robot1_drive", "broken", "robot2_drive"]
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        rows = list(pool.map(run_job, jobs))
    ok = {r.name: r for r in rows if r.ok}
    assert set(ok) == {"robot1_drive", "robot2_drive"}
    (failed,) = (r for r in rows if not r.ok)
    assert failed.verdict == "failed" and "broken.txt" in failed.error and "\n" not in failed.error
    for row in ok.values():
        assert set(row.parameters) == {"k_traction", "axis_length"}
        assert (Path(row.folder) / "calibration.yaml").is_file() and (
            Path(row.folder) / "result.json"
        ).is_file()
        assert row.figures["segment ATE mean [m]"] > 0
    paths = write_summary(rows, tmp_path / "out")
    table = list(csv.DictReader(paths[0].open()))
    assert [t["log"] for t in table] == ["robot1_drive", "broken", "robot2_drive"]
    assert table[1]["error"] == failed.error and float(table[0]["k_traction_std"]) > 0


def _results(out: Path) -> dict[str, dict[str, object]]:
    """Each log folder's result.json, without what differs from run to run (times)."""

    def timeless(doc: object) -> object:
        if isinstance(doc, dict):
            return {k: timeless(v) for k, v in doc.items() if "time" not in k}
        if isinstance(doc, list):
            return [timeless(v) for v in doc]
        return doc

    docs = {p.parent.name: json.loads(p.read_text()) for p in sorted(out.glob("*/result.json"))}
    return {name: timeless(doc) for name, doc in docs.items()}  # type: ignore[misc]


def _summary(out: Path) -> list[dict[str, str]]:
    """The summary's rows, without their folder (under ``out``) and time."""
    return [
        {k: v for k, v in row.items() if k not in ("folder", "seconds")}
        for row in csv.DictReader((out / "summary.csv").open())
    ]


def test_a_batch_on_a_dask_cluster_equals_one_at_a_time(logs: Path, tmp_path: Path) -> None:
    """``nlp-calib batch --dask`` on a local cluster of two worker processes: every log's result
    and summary row are those of ``--jobs 1``, and a failing log is its row there too."""
    from dask.distributed import LocalCluster

    scenario = str(quick_scenario(tmp_path))
    inputs = str(logs / "**" / "*.txt")
    one = main(["batch", inputs, "--scenario", scenario, "--out", str(tmp_path / "one"), "--jobs", "1"])
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    with cluster:
        args = ["--scenario", scenario, "--out", str(tmp_path / "dask"), "--dask", cluster.scheduler_address]
        on_dask = main(["batch", inputs, *args])
    assert one == on_dask == 1  # the broken log failed, the others ran
    results = _results(tmp_path / "one")
    assert set(results) == {"robot1_drive", "robot2_drive"}
    assert _results(tmp_path / "dask") == results
    assert _summary(tmp_path / "dask") == _summary(tmp_path / "one")


def test_dask_without_a_scheduler_is_one_line(logs: Path, tmp_path: Path) -> None:
    proc = cli("batch", str(logs / "robot1"), "--out", str(tmp_path / "o"), "--dask", "tcp://127.0.0.1:9")
    assert proc.returncode == 2 and "cannot reach a Dask scheduler" in proc.stderr, proc.stderr
    proc = cli("batch", str(logs / "robot1"), "--jobs", "2", "--dask", "tcp://127.0.0.1:9")
    assert proc.returncode == 2 and "not both" in proc.stderr


def test_workers_follow_the_free_cores() -> None:
    """Never more workers than cores free now (at least one), than asked for or than logs."""
    assert local_workers(None, 20, 2.0) == min(2, threads.cores())
    assert local_workers(2, 20, 1.2) == 1  # a busy machine: one at a time beats two on one core
    assert local_workers(4, 20, 0.1) == 1
    assert local_workers(2, 1, 2.0) == 1
    assert local_workers(1, 20, 8.0) == 1
    assert local_workers(3, 20, 2.6) == 3


def test_free_cores_read_the_idle_share_of_the_cpu_time(tmp_path: Path) -> None:
    """Two samples of /proc/stat: the idle and iowait share of what passed between them."""
    stat = tmp_path / "stat"
    samples = iter(["cpu  100 0 100 800 0 0 0 0 0 0\n", "cpu  200 0 200 900 100 0 0 0 0 0\n"])

    class Stat(type(stat)):  # type: ignore[misc]
        def read_text(self, *args: object, **kwargs: object) -> str:
            return next(samples)

    free = threads.free_cores(0.0, Stat(stat))
    cpus = os.cpu_count() or 1
    assert free == pytest.approx(min(threads.cores(), 0.5 * cpus))
    assert 0.0 <= threads.free_cores(0.05) <= threads.cores()


def crash_on_b(job: Job) -> BatchRow:
    """A task whose worker dies on job ``b`` (as a crash in native code would end it)."""
    if job.name == "b":
        os._exit(1)
    return BatchRow(job.name, str(job.path), str(job.folder), verdict="good")


def test_a_worker_that_dies_costs_only_its_log(tmp_path: Path) -> None:
    jobs = [Job(name, tmp_path / f"{name}.txt", BatchOptions(tmp_path)) for name in "abcd"]
    rows: dict[int, BatchRow] = {}
    run_jobs(jobs, 2, rows.__setitem__, task=crash_on_b)
    assert sorted(rows) == [0, 1, 2, 3]
    assert [rows[i].verdict for i in range(4)] == ["good", "failed", "good", "good"]
    assert "worker process died" in rows[1].error


def threads_seen(job: Job) -> BatchRow:
    """A task that reports the refit threads and the BLAS threads its process allows."""
    blas = os.environ.get("OPENBLAS_NUM_THREADS", "unset")
    return BatchRow(job.name, str(job.path), str(job.folder), detail=f"{threads.allowed(2)} {blas}")


def test_workers_take_one_core_each(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two workers on two cores: each runs its refits one at a time and its libraries on one thread,
    and this process's environment is as it was."""
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    jobs = [Job(name, tmp_path / f"{name}.txt", BatchOptions(tmp_path)) for name in "ab"]
    rows: dict[int, BatchRow] = {}
    run_jobs(jobs, 2, rows.__setitem__, task=threads_seen)
    assert [rows[i].detail for i in range(2)] == ["1 1", "1 1"]
    assert "OPENBLAS_NUM_THREADS" not in os.environ


def test_batch_writes_a_folder_per_log_and_the_summary(logs: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    scenario = str(quick_scenario(tmp_path))
    proc = cli("batch", str(logs / "**" / "*.txt"), "--scenario", scenario, "--out", str(out), "--jobs", "2")
    assert proc.returncode == 1, proc.stderr  # a log failed; the others ran
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["robot1_drive", "robot2_drive"]
    assert "| broken | failed |" in (out / "summary.md").read_text()
    assert "2 of 3 logs ran to the end" in proc.stdout
    again = cli(
        "batch", str(logs / "**" / "drive.txt"), "--scenario", scenario, "--out", str(out), "--jobs", "1"
    )
    assert again.returncode == 0, again.stderr
    assert len(list(csv.DictReader((out / "summary.csv").open()))) == 2


def test_batch_checks_each_log_against_a_calibration(tmp_path: Path) -> None:
    cal = tmp_path / "cal"
    assert (
        cli("run", str(SCENARIOS / "demo.yaml"), "--solver", "gauss_newton", "--out", str(cal)).returncode
        == 0
    )
    proc = cli("batch", str(DEMO_LOG), "--check", str(cal / "calibration.yaml"), "--out", str(tmp_path / "o"))
    assert proc.returncode == 0, proc.stdout + proc.stderr  # the log it was made from is still good
    row = next(csv.DictReader((tmp_path / "o" / "summary.csv").open()))
    assert row["verdict"] == "still good" and (tmp_path / "o" / row["log"] / "check.json").is_file()


def test_bad_batch_inputs_are_refused_before_any_work(logs: Path, tmp_path: Path) -> None:
    proc = cli("batch", str(logs / "nothing"), "--out", str(tmp_path / "o"))
    assert proc.returncode == 2 and "no file matches" in proc.stderr
    proc = cli("batch", str(logs), "--scenario", str(quick_scenario(tmp_path)), "--model", "tricycle")
    assert proc.returncode == 2 and "not both" in proc.stderr
    assert not (tmp_path / "o").exists()


#: A scenario whose IPOPT runs for minutes (the batch is interrupted while it runs).
SLOW = (
    "dataset: {log}\nresidual: {{horizon: 10}}\nsolvers: [ipopt]\n"
    "ipopt: {{hessian: limited_memory, max_iter: 1000000, tol: 1.0e-30, options: {{acceptable_iter: 0}}}}\n"
)


@pytest.mark.parametrize("group", [True, False], ids=["ctrl-c to the process group", "sigterm to the batch"])
def test_a_signal_stops_the_workers_and_keeps_the_finished_logs(group: bool, tmp_path: Path) -> None:
    quick = tmp_path / "a_quick.yaml"
    quick.write_text(f"dataset: {DEMO_LOG}\nresidual: {{horizon: 5}}\nsolvers: [gauss_newton]\n")
    for name in ("b_slow", "c_slow", "d_slow"):
        (tmp_path / f"{name}.yaml").write_text(SLOW.format(log=DEMO_LOG))
    out = tmp_path / "out"
    command = ["batch", str(tmp_path / "*.yaml"), "--out", str(out), "--jobs", "2"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "nlp_calib", *command],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 180
    while not (out / "a_quick" / "result.json").is_file():
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    time.sleep(1.0)  # the next slow log has started
    if group:
        os.killpg(proc.pid, signal.SIGINT)
    else:
        proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == (130 if group else 143), err
    assert "Traceback" not in err
    assert (out / "a_quick" / "calibration.yaml").is_file()
    leftovers = [p for p in out.rglob("*") if p.name.startswith(".nlp_calib_staging.")]
    assert leftovers == [] and not (out / "summary.csv").exists()
    assert not any((out / n).exists() for n in ("b_slow", "c_slow", "d_slow"))
