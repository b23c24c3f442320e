"""Hostile machinery, round three: what runs around a calibration must not make it fail.

The compile cache (cut-short, empty, swapped or unloadable shared objects; concurrent cold runs),
C compilers that hang, fail or write something else, signals from the first instruction of the
tool to the last, ``nohup``, a stdout that is closed early, full or cannot encode ``σ``, address
space limited with ``ulimit -v``, and the messages of validate, the lag search and ``samples``.
Runs are real processes; signals are real signals, sent once the child has installed its
handlers (read from ``/proc``: the tool, unlike Python, catches SIGTERM), at delays spread over
the first half of a run. No test asserts on a time; a hang fails by the subprocess timeout.
"""

from __future__ import annotations

import io
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml
from conftest import REPO, write_sim
from test_faults import assert_one_line_error
from test_hostile import contents, scenario, staging_folders

from nlp_calib import cli
from nlp_calib.cli import commands, streams
from nlp_calib.codegen import compiler
from nlp_calib.core import interrupts, memory
from nlp_calib.core.errors import ResourceError
from nlp_calib.solvers import ipopt

LINUX_PROC = Path("/proc/self/status").is_file()
needs_proc = pytest.mark.skipif(not LINUX_PROC, reason="reads the child's signal masks from /proc")
needs_compiler = pytest.mark.skipif(compiler.find_compiler() is None, reason="no C compiler")
#: Seconds any child may take before the test calls it a hang.
HANG_S = 120


def env_for(cache: Path, **extra: str) -> dict[str, str]:
    """The environment of a child: this checkout, its own compile cache, warnings as the CLI prints."""
    env = dict(os.environ, PYTHONPATH=str(REPO), NLP_CALIB_CACHE=str(cache), PYTHONWARNINGS="ignore")
    env.pop("CC", None)
    return {**env, **extra}


def default_signals() -> None:
    """In the child: SIGINT and SIGHUP as a shell gives them, whatever this test process inherited."""
    for s in (signal.SIGINT, signal.SIGHUP):
        signal.signal(s, signal.SIG_DFL)


def nlp(*args: str, cache: Path, **extra: str) -> subprocess.CompletedProcess[str]:
    """A run of the tool; its output read in the encoding it was told to use (UTF-8 by default)."""
    return subprocess.run(
        [sys.executable, "-m", "nlp_calib", *args],
        cwd=REPO,
        env=env_for(cache, **extra),
        capture_output=True,
        encoding=extra.get("PYTHONIOENCODING", "utf-8"),
        timeout=HANG_S,
    )


def start(*args: str, cache: Path, preexec: Callable[[], None] = default_signals) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "nlp_calib", *args],
        cwd=REPO,
        env=env_for(cache),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=preexec,
    )


def signal_mask(pid: int, field: str) -> int:
    status = Path(f"/proc/{pid}/status").read_text()
    found = re.search(rf"^{field}:\s*([0-9a-f]+)", status, re.M)
    return int(found.group(1), 16) if found else 0


def wait_for_handlers(proc: subprocess.Popen[str]) -> None:
    """Until the child catches SIGTERM: nlp_calib's handlers are in place (Python's are not)."""
    deadline = time.monotonic() + HANG_S
    while not signal_mask(proc.pid, "SigCgt") >> (signal.SIGTERM - 1) & 1:
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the child never installed its signal handlers"
        time.sleep(0.002)


def warning_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("warning: ")]


def parameters(out: Path) -> dict[str, float]:
    params: dict[str, float] = yaml.safe_load((out / "calibration.yaml").read_text())["parameters"]
    return params


@dataclass(frozen=True)
class Warm:
    """A scenario, a compile cache filled by one run of it, and that run's parameters."""

    scenario: Path
    cache: Path
    params: dict[str, float]


@pytest.fixture(scope="module")
def warm(tmp_path_factory: pytest.TempPathFactory) -> Warm:
    folder = tmp_path_factory.mktemp("machinery")
    log = write_sim(folder, records=300, seed=5)
    sc = scenario(folder, f"dataset: {log}\nresidual: {{horizon: 10}}\nsolvers: [gauss_newton, ipopt]\n")
    cache = folder / "cache"
    proc = nlp("run", str(sc), "--out", str(folder / "out"), cache=cache)
    assert proc.returncode == 0, proc.stderr
    return Warm(sc, cache, parameters(folder / "out"))


# ------------------------------------------------------------------------ 1. the compile cache


def damage(entries: Sequence[Path], how: str) -> None:
    if how == "truncated":  # a full disk, an interrupted copy: mapping it would SIGBUS
        for p in entries:
            os.truncate(p, 1000)
    elif how == "empty":
        for p in entries:
            p.write_bytes(b"")
    elif how == "swapped":  # another entry's file: whole, but the wrong code
        first, second = entries[0].read_bytes(), entries[1].read_bytes()
        entries[0].write_bytes(second)
        entries[1].write_bytes(first)
    elif how == "sealed_junk":  # a checksum that matches, over bytes that are no shared object
        for p in entries:
            junk = b"not a shared object\n" * 50
            p.write_bytes(junk + compiler._seal(p.stem.rsplit("-", 1)[1], junk))


@needs_compiler
@pytest.mark.parametrize("how", ["truncated", "empty", "swapped", "sealed_junk"])
def test_a_damaged_compile_cache_is_rebuilt_with_one_warning_and_the_runs_succeed(
    how: str, warm: Warm, tmp_path: Path
) -> None:
    cache = tmp_path / "cache"
    shutil.copytree(warm.cache, cache)
    entries = sorted(cache.glob("*.so"))
    assert len(entries) >= 2
    damage(entries, how)
    out = tmp_path / "out"
    first = nlp("run", str(warm.scenario), "--out", str(out), cache=cache)
    assert first.returncode == 0, first.stderr
    (warned,) = warning_lines(first.stderr)
    assert f"the compile cache {cache} held a damaged file" in warned
    assert f"delete the folder {cache}" in warned
    assert parameters(out) == warm.params  # the same compiled code
    again = nlp("run", str(warm.scenario), "--out", str(out), cache=cache)
    assert again.returncode == 0 and warning_lines(again.stderr) == [], again.stderr
    assert parameters(out) == warm.params
    for p in cache.glob("*.so"):
        assert compiler.entry_problem(p, p.stem.rsplit("-", 1)[1]) is None, p


@needs_compiler
def test_concurrent_cold_runs_share_one_cache(warm: Warm, tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    procs = [
        start("run", str(warm.scenario), "--out", str(tmp_path / f"out{k}"), cache=cache) for k in range(3)
    ]
    for proc in procs:
        _, err = proc.communicate(timeout=HANG_S)
        assert proc.returncode == 0 and warning_lines(err) == [], err
    assert [parameters(tmp_path / f"out{k}") for k in range(3)] == [warm.params] * 3
    assert sorted(p.name for p in cache.glob("*.so")) == sorted(p.name for p in warm.cache.glob("*.so"))
    assert not list(cache.glob(".build-*")) and not list(cache.glob(".probe-*"))


STALLING_CC = '#!/bin/sh\nsleep 600 &\necho $! > "$(dirname "$0")/child.pid"\nwait\n'
TEXT_CC = (
    '#!/bin/sh\nwhile [ $# -gt 0 ]; do [ "$1" = -o ] && { shift; echo "no object" > "$1"; }; shift; done\n'
)
FAILING_CC = '#!/bin/sh\necho "fatal error: no licence for this compiler" >&2\nexit 3\n'


@pytest.mark.parametrize(
    ("script", "needle"),
    [
        (STALLING_CC, f"did not finish within {compiler.PROBE_TIMEOUT_S:.0f} s"),
        (TEXT_CC, "a shared object that cannot be loaded"),
        (FAILING_CC, "failed: fatal error: no licence for this compiler"),
    ],
    ids=["stalls", "writes_text", "fails"],
)
def test_a_compiler_that_hangs_fails_or_writes_junk_leaves_the_run_to_the_interpreter(
    script: str, needle: str, warm: Warm, tmp_path: Path
) -> None:
    cc = tmp_path / "cc"
    cc.write_text(script)
    cc.chmod(0o755)
    out = tmp_path / "out"
    proc = nlp("run", str(warm.scenario), "--out", str(out), cache=tmp_path / "cache", CC=str(cc))
    assert proc.returncode == 0, proc.stderr
    (warned,) = warning_lines(proc.stderr)
    assert needle in warned and "evaluating with CasADi's interpreter" in warned, warned
    got = parameters(out)
    assert all(got[n] == pytest.approx(v, rel=1e-8, abs=1e-12) for n, v in warm.params.items())
    assert not list((tmp_path / "cache").glob("*.so"))
    if (tmp_path / "child.pid").exists():  # the stalled compiler's own child was ended with it
        assert ended(int((tmp_path / "child.pid").read_text()))


def ended(pid: int) -> bool:
    """Whether process ``pid`` has ended (gone, or a zombie waiting to be reaped), within a while."""
    deadline = time.monotonic() + HANG_S
    while time.monotonic() < deadline:
        try:
            if Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z":
                return True
        except OSError:
            return True
        time.sleep(0.05)
    return False


# ------------------------------------------------------------------------ 2. signals at any moment


def _held_at_first_output(*args: str, cache: Path) -> tuple[subprocess.Popen[str], int]:
    """The tool started with its stdout a pipe this test has filled: its first line of output (the
    fit's table, printed before any file is written) blocks until the pipe is read, a stage marker
    that no load on the machine can move. Returns the process and the pipe's read end."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    for size in (4096, 1):  # pages, then the last bytes of a page
        try:
            while True:
                os.write(write_end, b"." * size)
        except BlockingIOError:
            pass
    os.set_blocking(write_end, True)  # the tool's writes wait
    proc = subprocess.Popen(
        [sys.executable, "-m", "nlp_calib", *args],
        cwd=REPO,
        env={**env_for(cache), "PYTHONUNBUFFERED": "1"},
        stdout=write_end,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_signals,
    )
    os.close(write_end)
    return proc, read_end


def _blocked_writing(pid: int) -> bool:
    """Whether the process sleeps in a write to a full pipe (its only thread's kernel wait channel)."""
    wchan = Path(f"/proc/{pid}/wchan")
    return wchan.is_file() and "pipe" in wchan.read_text()


def _drain(fd: int) -> None:
    """Read a pipe to its end (the tool's exit flushes what it printed)."""
    with os.fdopen(fd, "rb") as f:
        while f.read(65536):
            pass


@needs_proc
def test_signals_from_the_tools_first_instruction_end_the_run_and_keep_the_previous_files(
    warm: Warm, tmp_path: Path
) -> None:
    """Each signal at two stage markers, never at a fraction of a measured duration: as soon as the
    tool's handlers are in place, and while it is held at its first line of output (the fit done,
    no file written)."""
    out = tmp_path / "out"
    args = ("run", str(warm.scenario), "--out", str(out))
    assert nlp(*args, cache=warm.cache).returncode == 0
    before = contents(out)
    seen = []
    for k, signum in enumerate([signal.SIGINT, signal.SIGTERM, signal.SIGHUP] * 2):
        if k < 3:
            proc, read_end = start(*args, cache=warm.cache), None
            wait_for_handlers(proc)
        else:
            proc, read_end = _held_at_first_output(*args, cache=warm.cache)
            deadline = time.monotonic() + HANG_S
            while not _blocked_writing(proc.pid):
                assert proc.poll() is None, proc.communicate()
                assert time.monotonic() < deadline, "the tool never printed"
                time.sleep(0.01)
        proc.send_signal(signum)
        if read_end is not None:
            _drain(read_end)
        _, err = proc.communicate(timeout=HANG_S)
        seen.append(proc.returncode)
        lines = err.strip().splitlines()
        assert proc.returncode == 128 + signum, (k, err)
        assert "Traceback" not in err and len(lines) <= 1, (k, err)
        assert all(ln.startswith(f"error: interrupted ({signal.Signals(signum).name})") for ln in lines), err
        assert contents(out) == before and staging_folders(out) == [], k
    assert sorted(set(seen)) == [129, 130, 143]


def test_a_signal_before_the_tool_starts_never_looks_like_success(warm: Warm, tmp_path: Path) -> None:
    out = tmp_path / "out"
    args = ("run", str(warm.scenario), "--out", str(out))
    assert nlp(*args, cache=warm.cache).returncode == 0
    before = contents(out)
    for signum in (signal.SIGTERM, signal.SIGINT):
        proc = start(*args, cache=warm.cache)
        proc.send_signal(signum)  # the interpreter itself is starting: Python's own behaviour
        proc.communicate(timeout=HANG_S)
        assert proc.returncode != 0
        assert contents(out) == before


@needs_proc
def test_nohup_keeps_sighup_ignored_and_the_run_completes(warm: Warm, tmp_path: Path) -> None:
    def nohup() -> None:  # what nohup does before it starts the command
        default_signals()
        signal.signal(signal.SIGHUP, signal.SIG_IGN)

    out = tmp_path / "out"
    proc = start("run", str(warm.scenario), "--out", str(out), cache=warm.cache, preexec=nohup)
    wait_for_handlers(proc)
    assert signal_mask(proc.pid, "SigIgn") >> (signal.SIGHUP - 1) & 1  # still ignored
    for _ in range(3):  # the terminal closes, and closes again
        if proc.poll() is None:
            proc.send_signal(signal.SIGHUP)
        time.sleep(0.05)
    _, err = proc.communicate(timeout=HANG_S)
    assert proc.returncode == 0, err
    assert parameters(out) == warm.params


_STUCK = """
import ctypes, sys
from nlp_calib.cli import commands, streams
from nlp_calib.cli.main import main

def stuck(args):
    print("ready", flush=True)
    mutex = ctypes.create_string_buffer(64)  # zeroed: a default glibc mutex
    ctypes.CDLL(None).pthread_mutex_lock(mutex)
    ctypes.CDLL(None).pthread_mutex_lock(mutex)  # native code that waits forever, deaf to signals
    return 0

commands.COMMANDS["run"] = stuck
sys.argv = ["nlp-calib", "run", "x.yaml"]
sys.exit(main())
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="a glibc mutex stands for stuck native code")
@pytest.mark.parametrize(("signum", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_run_stuck_in_native_code_still_ends_on_a_signal(signum: int, code: int, tmp_path: Path) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-c", _STUCK],
        cwd=REPO,
        env=env_for(tmp_path / "cache"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_signals,
    )
    assert proc.stdout is not None and proc.stdout.readline() == "ready\n"
    time.sleep(0.1)  # inside the second lock
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=HANG_S)
    assert proc.returncode == code
    assert err.strip() == (
        f"error: interrupted ({signal.Signals(signum).name}); the run did not stop within 3 s (busy in "
        "native code) and was ended; the files in progress were discarded"
    )


@pytest.mark.parametrize("then", ["returns", "raises"])
def test_a_signal_a_library_swallowed_still_decides_the_exit_code(
    then: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def swallowing(args: object) -> int:
        try:
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
        except BaseException:  # what SWIG or a C++ library does with the exception
            pass
        if then == "raises":  # e.g. "<built-in method> returned a result with an exception set"
            raise SystemError("<built-in method call> returned a result with an exception set")
        return 0

    monkeypatch.setitem(commands.COMMANDS, "run", swallowing)
    assert cli.main(["run", "x.yaml"]) == 143
    assert capsys.readouterr().err == "error: interrupted (SIGTERM); the files in progress were discarded\n"


def test_casadis_echo_of_a_signal_is_not_shown(monkeypatch: pytest.MonkeyPatch) -> None:
    sink = io.StringIO()
    err = streams._Guarded(sink, streams._echo_of_a_signal)
    pieces = ["CasADi - ", '2026-01-01 WARNING("KeyboardInterruptException") [ipopt_nlp.cpp:95]', "\n"]
    err.write("".join(pieces) + "\n")  # before a signal: shown
    monkeypatch.setattr(interrupts, "_pending", signal.SIGTERM)
    for piece in [*pieces, "CasADi - x\nerror: interrupted (SIGTERM)", "\n"]:
        err.write(piece)
    assert sink.getvalue() == "".join(pieces) + "\n" + "error: interrupted (SIGTERM)\n"


# ------------------------------------------------------------------------ 3. output that never kills the work


@pytest.mark.skipif(shutil.which("bash") is None or shutil.which("head") is None, reason="a shell pipeline")
def test_a_pipe_closed_early_loses_no_result(warm: Warm, tmp_path: Path) -> None:
    out = tmp_path / "out"
    command = f"set -o pipefail; {sys.executable} -m nlp_calib compare {warm.scenario} --out {out} --report"
    proc = subprocess.run(
        ["bash", "-c", command + " | head -1"],
        cwd=REPO,
        env=env_for(warm.cache),
        capture_output=True,
        text=True,
        timeout=HANG_S,
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("scenario ") and proc.stdout.count("\n") == 1
    assert proc.stderr.strip().splitlines()[-1].startswith("note: stdout was closed (a pipe into head?)")
    assert "Traceback" not in proc.stderr and "error" not in proc.stderr
    assert parameters(out) == warm.params and (out / "report.md").is_file()


@pytest.mark.parametrize("encoding", ["ascii", "latin-1"])
def test_a_stdout_that_cannot_encode_sigma_loses_no_result(encoding: str, warm: Warm, tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = nlp("run", str(warm.scenario), "--out", str(out), cache=warm.cache, PYTHONIOENCODING=encoding)
    assert proc.returncode == 0, proc.stderr
    assert "1sigma: the white-noise sigma, or the sigma of" in proc.stdout
    assert proc.stderr.strip().startswith("note: the terminal's encoding cannot show some characters")
    assert parameters(out) == warm.params


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_stdout_on_a_full_disk_loses_no_result(warm: Warm, tmp_path: Path) -> None:
    out = tmp_path / "out"
    with open("/dev/full", "w") as full:
        proc = subprocess.run(
            [sys.executable, "-m", "nlp_calib", "run", str(warm.scenario), "--out", str(out)],
            cwd=REPO,
            env=env_for(warm.cache),
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
            timeout=HANG_S,
        )
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr.strip() == (
        "note: stdout failed (No space left on device) before the command finished; the rest of its "
        "output was dropped"
    )
    assert parameters(out) == warm.params


# ------------------------------------------------------------------------ 4. memory limits


def test_too_little_address_space_is_a_one_line_error_naming_the_limit(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(memory, "address_space_limit", lambda: 600_000 * 1024)
    with pytest.raises(ResourceError) as exc:
        memory.require_address_space(1 << 50, "the thing", "do without it")  # more than any machine maps
    message = str(exc.value)
    assert message.startswith("the address space is limited to 585 MiB (ulimit -v 600000), which leaves less")
    assert "the thing needs; raise the limit (ulimit -v unlimited" in message and message.endswith(
        "do without it"
    )
    memory.require_address_space(1 << 20, "a little", "nothing")  # room for that


def test_ipopt_refuses_to_start_without_room_for_its_linear_algebra(
    warm: Warm, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setattr(memory, "address_space_limit", lambda: 600_000 * 1024)
    monkeypatch.setattr(ipopt, "_ADDRESS_SPACE", 1 << 50)
    monkeypatch.setattr(ipopt.Ipopt, "_buffer_held", False)
    out = tmp_path / "out"
    monkeypatch.setenv("NLP_CALIB_CACHE", str(warm.cache))
    assert cli.main(["run", str(warm.scenario), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: the address space is limited to 585 MiB (ulimit -v 600000)"), err
    assert "IPOPT's linear algebra needs" in err and "solvers: [gauss_newton]" in err
    assert "\n" not in err and not (out / "result.json").exists()


@needs_proc
@pytest.mark.parametrize("limit_kb", [320_000, 600_000])
def test_under_ulimit_v_a_run_succeeds_or_says_why_and_a_signal_still_ends_it(
    limit_kb: int, warm: Warm, tmp_path: Path
) -> None:
    def limited() -> None:
        default_signals()
        resource.setrlimit(resource.RLIMIT_AS, (limit_kb * 1024, limit_kb * 1024))

    out = tmp_path / "out"
    args = ("compare", str(warm.scenario), "--out", str(out))
    proc = start(*args, cache=warm.cache, preexec=limited)
    _, err = proc.communicate(timeout=HANG_S)
    if proc.returncode != 0:
        completed = subprocess.CompletedProcess(proc.args, proc.returncode, "", err)
        assert_one_line_error(completed, 1, "ulimit -v")
    else:
        assert parameters(out) == warm.params
    before = contents(out)
    proc = start(*args, cache=warm.cache, preexec=limited)
    wait_for_handlers(proc)
    time.sleep(0.3)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=HANG_S)
    assert proc.returncode in (143, 1), err  # 1: it had already failed as above
    assert contents(out) == before


# ------------------------------------------------------------------------ 5. messages that name key and file


def test_validate_on_too_short_a_log_says_so(tmp_path: Path) -> None:
    lines = write_sim(tmp_path, records=10, seed=1).read_text().splitlines()
    records = [ln for ln in lines if ln.startswith("time:")]
    log = tmp_path / "two.txt"
    log.write_text("\n".join([*(ln for ln in lines if ln.startswith("#")), *records[:2]]) + "\n")
    fixed = "[k_steer, k_traction, axis_length, steer_offset, sensor_x, sensor_y]"
    # One parameter free (the time offset held: two records cannot re-sample the encoders).
    body = f"dataset: {log}\nresidual: {{horizon: 1}}\nfixed: {fixed}\nalignment: {{tracker_lag: 0.0}}\n"
    sc = scenario(tmp_path, body)
    proc = nlp("validate", str(sc), "--out", str(tmp_path / "out"), cache=tmp_path / "cache")
    assert_one_line_error(proc, 1, "case.yaml: two.txt: the log is too short to cross-validate", "2 fitted")


@pytest.mark.parametrize(
    ("block", "needles"),
    [
        ("samples: {start: 500}", ("case.yaml: samples: [500, 300) exceeds the log's 300 records",)),
        (
            "alignment: {tracker_lag: auto, search: [-100, 100]}",
            ("case.yaml: alignment.step: 0.01 s over search [-100, 100] makes 20000 lags", "at least 0.2 s"),
        ),
        (
            "alignment: {tracker_lag: auto, search: [0.2, -0.2]}",
            ("case.yaml: alignment.search: needs [lo, hi]",),
        ),
        ("alignment: {tracker_lag: auto, step: 0}", ("case.yaml: alignment.step: must be > 0 s, got 0",)),
    ],
)
def test_sample_and_lag_search_errors_name_the_file_and_the_key(
    block: str, needles: tuple[str, ...], warm: Warm, tmp_path: Path
) -> None:
    log = yaml.safe_load(warm.scenario.read_text())["dataset"]
    sc = scenario(tmp_path, f"dataset: {log}\n{block}\n")
    proc = nlp("run", str(sc), "--out", str(tmp_path / "out"), cache=warm.cache)
    assert_one_line_error(proc, 2, *needles)
