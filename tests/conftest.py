"""Shared fixtures and helpers."""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import io
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pytest
import yaml

from nlp_calib.codegen.compiler import writable_by_others
from nlp_calib.core import poses3d
from nlp_calib.core.threads import native_one_thread_by_default
from nlp_calib.logs import Log, parse_log
from nlp_calib.models import get_model
from nlp_calib.pipeline import Calibration, Scenario, load_scenario, scenario_from_mapping
from nlp_calib.results import CalibrationRun
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"


def _bytecode_folder() -> str:
    """The user's cache folder for the tests' bytecode, kept between sessions (Python and pytest
    check each entry against its source's time and size, so an edited file is compiled again);
    where it cannot be made or another user could write into it, a private temporary folder
    removed at exit."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    folder = Path(base) / "nlp_calib-test-bytecode"
    with contextlib.suppress(OSError):
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        st = folder.lstat()
        if stat.S_ISDIR(st.st_mode) and writable_by_others(st) is None:
            return str(folder)
    private = tempfile.mkdtemp(prefix="nlp_calib_test_pyc_")
    atexit.register(shutil.rmtree, private, ignore_errors=True)
    return private


def _cache_bytecode() -> None:
    """This process, its test workers and the tool's processes the tests start keep their compiled
    bytecode (pytest's rewritten test modules too) in :func:`_bytecode_folder`, never in the
    checkout: where the environment says not to write bytecode, each would otherwise compile from
    source what it imports (half of a child's import time; a worker's collection of the suite took
    27 s of CPU into a fresh folder, 7 s from a filled one)."""
    if os.environ.get("PYTHONDONTWRITEBYTECODE") and "PYTHONPYCACHEPREFIX" not in os.environ:
        folder = _bytecode_folder()
        del os.environ["PYTHONDONTWRITEBYTECODE"]
        os.environ["PYTHONPYCACHEPREFIX"] = folder
        sys.pycache_prefix, sys.dont_write_bytecode = folder, False


_cache_bytecode()
# The test workers (started after this file is read) and the tool's processes the tests start load
# their native libraries on one thread, as the command does: two workers on two cores, no spinning.
native_one_thread_by_default()


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """One worker more than ``-n auto`` would start (one per core): some tests wait on the tool's
    own processes, timers and signals (a fifth of the suite's wall time left two workers idle on
    two cores), and the extra worker runs while they wait."""
    from xdist.plugin import pytest_xdist_auto_num_workers as per_core

    return int(per_core(config)) + 1


def _find_real_log() -> Path:
    """``$NLP_CALIB_REAL_LOG``, else ``shared/data/dataset.txt`` beside the checkout or above it."""
    if "NLP_CALIB_REAL_LOG" in os.environ:
        return Path(os.environ["NLP_CALIB_REAL_LOG"])
    for parent in REPO.parents:
        candidate = parent / "shared" / "data" / "dataset.txt"
        if candidate.is_file():
            return candidate
    return REPO.parent / "shared" / "data" / "dataset.txt"


REAL_LOG = _find_real_log()


def assert_close(
    actual: object, expected: object, *, rtol: float = 1e-9, atol: float = 0.0, what: str = ""
) -> None:
    """``np.testing.assert_allclose`` that also fails when either side holds NaN or infinity."""
    a = np.asarray(actual, dtype=float)
    e = np.asarray(expected, dtype=float)
    assert np.all(np.isfinite(a)), f"{what}: non-finite values in actual: {a}"
    assert np.all(np.isfinite(e)), f"{what}: non-finite values in expected: {e}"
    np.testing.assert_allclose(a, e, rtol=rtol, atol=atol, err_msg=what)


#: The shared data folder the real log lies in (OptiOdom's runs lie beside it, under real4/).
SHARED_DATA = REAL_LOG.parent


def shared_scenario(name: str) -> Scenario:
    """A shipped scenario that reads the shared data folder (``../../shared/data/`` from
    ``scenarios/``), pointed at wherever that folder was found; skipped when it is absent."""
    text = (SCENARIOS / f"{name}.yaml").read_text()
    prefix = "../../shared/data/"
    first = text.split(prefix, 1)[1].split(",", 1)[0].split("}", 1)[0].strip() if prefix in text else ""
    if not (SHARED_DATA / first).is_file():
        pytest.skip(f"{name}'s data are not at {SHARED_DATA / first} (set NLP_CALIB_REAL_LOG beside them)")
    raw = yaml.safe_load(text.replace(prefix, f"{SHARED_DATA.as_posix()}/"))
    return scenario_from_mapping(raw, name, SCENARIOS)


@pytest.fixture(scope="session")
def real_log() -> Path:
    if not REAL_LOG.is_file():
        pytest.skip(f"the real log is not at {REAL_LOG} (set NLP_CALIB_REAL_LOG to its path)")
    return REAL_LOG


def parse_lines(
    lines: Sequence[str], path: str = "<log>", *, strict: bool = True, model: str = "tricycle"
) -> Log:
    """``parse_log`` with the encoder kinds of ``model``."""
    return parse_log(lines, get_model(model).encoder_kinds, path, strict=strict)


def highway_dataset(joints: Path, poses: Path) -> dict[str, object]:
    """The dataset entry of a simulated highway car's files (wheel speeds, the device's poses)."""
    wheels = ("steering", "rear_left_wheel", "rear_right_wheel")
    return {
        "joints": str(joints),
        "poses": str(poses),
        "form": "speeds",
        "encoders": dict(zip(wheels, wheels)),
    }


def run_fitting_the_lag(sc: Scenario) -> CalibrationRun:
    """``sc`` run with every warning caught, its tracker lag fitted: no warning that no fit
    converged at any lag, and an estimate that converged and is not pinned."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = Calibration(sc).run()
    said = [str(w.message) for w in caught]
    assert not [w for w in said if "no fit converged" in w], said
    estimate = run.data.lag_estimate
    assert estimate is not None and estimate.converged and not estimate.pinned
    return run


def write_sim(tmp_path: Path, name: str = "sim.txt", **kwargs: object) -> Path:
    """Simulate a log with the given options into ``tmp_path``; returns its path."""
    log, _ = write_simulation(simulate(SimulationOptions.of(**kwargs)), tmp_path / name)  # type: ignore[arg-type]
    return log


@pytest.fixture(scope="session")
def demo() -> Scenario:
    """The shipped demo scenario (a simulated tricycle log with known truth)."""
    return load_scenario(SCENARIOS / "demo.yaml")


@pytest.fixture(scope="session")
def small_demo(demo: Scenario) -> Scenario:
    """The demo scenario on its first 500 records: the quick case of solver and report tests."""
    return demo.with_options(samples=dataclasses.replace(demo.log.samples, stop=500))


@pytest.fixture(scope="session")
def noiseless_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated log without tracker noise, jitter-free, with the wrap."""
    return write_sim(
        tmp_path_factory.mktemp("noiseless"),
        records=800,
        seed=3,
        tracker_noise_xy=0.0,
        tracker_noise_theta=0.0,
        jitter_s=0.0,
    )


def cli(*args: str, cwd: Path = REPO, isolated: bool = False) -> subprocess.CompletedProcess[str]:
    """Run ``nlp-calib ARGS`` in ``cwd``; its exit code, stdout and stderr as a completed process.

    In this process by default, through the same entry point a program's ``main`` is (a fresh
    interpreter costs about a second of imports per call, hundreds of times over the suite);
    ``isolated`` starts ``python -m nlp_calib`` where the process itself is what is tested."""
    if isolated:
        env = dict(os.environ, PYTHONWARNINGS="ignore")
        return subprocess.run(
            [sys.executable, "-m", "nlp_calib", *args],
            capture_output=True,
            text=True,
            cwd=cwd,
            env=env,
            timeout=300,
        )
    from nlp_calib.cli import main

    out, err = io.StringIO(), io.StringIO()
    here = os.getcwd()
    os.chdir(cwd)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as exc:  # argparse: --help, --version, a usage error
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if exc.code is not None and not isinstance(exc.code, int):
                    print(exc.code, file=sys.stderr)  # as the interpreter does on its way out
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["nlp-calib", *args], code, out.getvalue(), err.getvalue())


# SE(2) written independently in numpy (homogeneous matrices), the reference the tests check
# the CasADi expressions against.
def mat(v: Sequence[float] | np.ndarray) -> np.ndarray:
    """Homogeneous matrix of ``(x, y, theta)``."""
    x, y, t = v
    return np.array([[np.cos(t), -np.sin(t), x], [np.sin(t), np.cos(t), y], [0.0, 0.0, 1.0]])


def vec(T: np.ndarray) -> np.ndarray:
    """``(x, y, theta)`` of a homogeneous matrix."""
    return np.array([T[0, 2], T[1, 2], np.arctan2(T[1, 0], T[0, 0])])


def boxplus_numpy(x: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Kinematic parameters plus delta; the sensor pose (last three) ``v2t(delta)·T``."""
    out = x + delta
    out[-3:] = vec(mat(delta[-3:]) @ mat(x[-3:]))
    return out


#: The two-sinusoid drive's scenario (the files :func:`two_sinusoids` writes), before its options.
SINUSOIDS_HEAD = (
    "name: sinusoids\nmodel: diff_drive\nsensor: 3d\ninitial_guess: auto\nknown: {sensor_z: 0.10}\n"
    "dataset: {poses: cam.tum, joints: cam.joints.csv,\n"
    "          encoders: {left_wheel: left_wheel_joint, right_wheel: right_wheel_joint}}\n"
)
#: A camera's formulation as docs/camera.md gives it: quarter-second windows, its information, Huber.
CAMERA_FORMULATION = (
    "residual: {horizon_s: 0.25}\ninformation: {translation: 1.0e+6, rotation: 3.0e+5}\n"
    "robust: {kernel: huber, delta: 10.0}\n"
)


def sinusoids_scenario(
    folder: Path,
    alignment: str = "{tracker_lag: auto, search: [-0.05, 0.05]}",
    formulation: str = CAMERA_FORMULATION,
) -> Path:
    """``folder/cam.yaml``: the two-sinusoid drive's scenario with ``alignment`` ("" for the
    default) and ``formulation``, Gauss-Newton alone."""
    path = folder / "cam.yaml"
    align = f"alignment: {alignment}\n" if alignment else ""
    path.write_text(SINUSOIDS_HEAD + align + formulation + "solvers: [gauss_newton]\n")
    return path


def two_sinusoids(
    folder: Path,
    stamp_offset_s: float = -0.01,
    beat: float = 0.0,
    wobble: float = 0.0,
    right_rate: float = 1.0,
) -> dict[str, float]:
    """A differential drive whose wheels turn at 2·cos t and 2·sin t rad/s for 30 s (radii 0.1 m,
    separation 0.57 m), joints at 100 Hz, a camera at 50 Hz whose image of time t is stamped
    ``t - stamp_offset_s`` (the default: 10 ms late, a tracker_lag of +0.01 s), its poses and joints
    printed to six decimals: a drive on which a time shift is a mix of the two
    wheels. ``beat``: rad/s of ``sin 0.37t`` added to the right wheel (a time shift is then nearly,
    not exactly, a mix); ``wobble``: each wheel's rolling radius varies along the drive by this
    fraction (``sin 0.37t``, ``cos 0.23t``; the truth is the mean), an error a white-noise σ
    does not count; ``right_rate``: the right wheel turns at 2·sin(right_rate·t) (off 1, the
    drive nearly repeats every 2π s, not exactly)."""
    r, b, dt, mount = 0.1, 0.57, 0.01, (0.36, 0.06, 0.10, -1.58, 0.012, -1.55)
    t = np.arange(3001) * dt
    wl, wr = 2.0 * np.cos(t[:-1]), 2.0 * np.sin(right_rate * t[:-1]) + beat * np.sin(0.37 * t[:-1])
    gl, gr = 1.0 + wobble * np.sin(0.37 * t[:-1]), 1.0 + wobble * np.cos(0.23 * t[:-1])
    travel, turn = 0.5 * r * (wl * gl + wr * gr) * dt, r * (wr * gr - wl * gl) / b * dt
    planar = np.zeros((t.size, 3))
    for k in range(t.size - 1):
        x, y, th = planar[k]
        c = np.sinc(turn[k] / (2 * np.pi)) * travel[k]
        planar[k + 1] = (x + c * np.cos(th + turn[k] / 2), y + c * np.sin(th + turn[k] / 2), th + turn[k])
    poses = poses3d.compose(poses3d.from_planar(planar), poses3d.mount_pose(np.array(mount)))
    images = np.arange(0, t.size, 2)
    stamps = t[images] - stamp_offset_s
    with (folder / "cam.tum").open("w") as f:
        for s, p in zip(stamps, poses[images]):
            f.write(f"{1e9 + s:.6f} " + " ".join(f"{v:.6f}" for v in p) + "\n")
    joints = np.column_stack(
        [t, np.concatenate([[0], np.cumsum(wl * dt)]), np.concatenate([[0], np.cumsum(wr * dt)])]
    )
    with (folder / "cam.joints.csv").open("w") as f:
        f.write("time,left_wheel_joint,right_wheel_joint\n")
        for row in joints:
            f.write(f"{1e9 + row[0]:.6f},{row[1]:.6f},{row[2]:.6f}\n")
    return dict(
        left_wheel_radius=r,
        right_wheel_radius=r,
        wheel_separation=b,
        sensor_x=0.36,
        sensor_y=0.06,
        sensor_roll=-1.58,
        sensor_pitch=0.012,
        sensor_yaw=-1.55,
        tracker_lag=-stamp_offset_s,
    )


def steering_step(log_path: Path, truth: dict[str, float], sample: str) -> dict[str, float]:
    """Each parameter's Gauss-Newton step from the truth (the lag at 0) on a noise-free tricycle
    log with its steer angle read as ``sample`` (the demo's residual options): the bias the interval
    model's error gives it."""
    from nlp_calib.models import load_log
    from nlp_calib.problem import ProblemSpec, build, build_residual_data
    from nlp_calib.problem.windows import ResidualOptions
    from nlp_calib.solvers import ProblemEvaluator

    model = get_model("tricycle")
    fns = build(model, ProblemSpec(horizon=10, lags=1))
    data = build_residual_data(
        fns, load_log(log_path, model), ResidualOptions(horizon=10, steering_sample=sample)
    )
    ev = ProblemEvaluator(fns, data, x_fixed=np.zeros(0), omega=np.ones(3), delta=1e9)
    ne = ev.normal_equations(np.array([*(truth[n] for n in fns.names[:-1]), 0.0]))
    return dict(zip(fns.names, map(float, -np.linalg.solve(ne.H, ne.g))))
