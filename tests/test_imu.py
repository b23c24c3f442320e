"""A gyro as the reference: simulated Imu bags (bias, noise, a tilt, late stamps), the wheels' turning,
the gyro's biases and tilt and its clock offset fitted together; the lengths' scale said to be
what a gyro alone cannot determine."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml
from conftest import cli

from nlp_calib.core.errors import OptionsError
from nlp_calib.logs.imu import GyroRates, integrated
from nlp_calib.models import MODELS
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline import Calibration, scenario_from_mapping
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.problem.functions import ProblemFunctions, ProblemSpec, build
from nlp_calib.results.preflight import NOT_DETERMINED
from nlp_calib.simulation.imu import ImuSimulationOptions, simulate_imu, write_imu_simulation

pytest.importorskip("rosbags")

RADIANS = {"k_left": "left_wheel_radius", "k_right": "right_wheel_radius", "baseline": "wheel_separation"}
DATASET = {
    "joint_states": "/joint_states",
    "joints": ["left_wheel_joint", "right_wheel_joint"],
    "imu": "/imu",
}
SCENARIO = {
    "model": "diff_drive",
    "sensor": "gyro",
    "initial_guess": "auto",
    "alignment": {"tracker_lag": "auto"},
    "information": {"translation": 1.0e8, "rotation": 1.0e8},
    "robust": {"kernel": "huber", "delta": 3.0},
    "solvers": ["gauss_newton"],
}
#: A 5° roll, a gyro stamped 20 ms late.
ROLL, LATE = float(np.radians(5.0)), 0.02


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, float]]:
    """40 s of driving, the IMU rolled 5°, its driver stamping 20 ms late."""
    folder = tmp_path_factory.mktemp("imu")
    opts = ImuSimulationOptions(duration_s=40.0, seed=11, truth={"imu_roll": ROLL}, stamp_offset_s=LATE)
    bag, truth_file = write_imu_simulation(simulate_imu(opts), folder / "gyro")
    truth = {RADIANS.get(k, k): v for k, v in json.loads(truth_file.read_text())["params"].items()}
    return bag, truth


def _scenario(bag: Path, **more: object) -> object:
    return scenario_from_mapping(
        {**SCENARIO, **more, "dataset": {"bag": str(bag), **DATASET}}, "gyro", bag.parent
    )


def test_integration_intervals_add_up_the_rates() -> None:
    """Trapezoids of a known rate: ∫(a + b·t) over each interval, its duration last; a gap left out."""
    t = np.concatenate([np.arange(0.0, 1.0, 0.01), np.arange(1.5, 2.0, 0.01)])
    w = np.column_stack([0.1 + 0.0 * t, 2.0 * t, -t])
    rates = GyroRates("test", np.round(t * 1e9).astype(np.int64), w, np.arange(t.size))
    table = integrated(rates, 0.1)
    a, b = table.start_ns * 1e-9, table.end_ns * 1e-9
    assert np.all(b - a < 0.2)  # no interval across the half-second gap
    expected = np.column_stack([0.1 * (b - a), b**2 - a**2, -0.5 * (b**2 - a**2), b - a])
    np.testing.assert_allclose(table.z, expected, atol=1e-12)


def test_the_simulated_gyro_integrates_to_the_bases_heading_change() -> None:
    """A noise-free, untilted, unbiased simulated gyro: each trapezoid of its rates is the base's
    heading change between its samples (the drive's own fine grid), to well below the gyro's noise
    (2 mrad/s white: 7e-6 rad over a 5 ms interval). A grid holding each instant twice, 1e-17 s
    apart, had turned rounding into rates as far off as that noise (here 6.9e-6 rad per interval,
    RMS): a gyro's clock offset 0.15 ms early on a 60 s bag beside a lidar."""
    from nlp_calib.simulation.beside import simulate_beside
    from nlp_calib.simulation.imu import imu_times
    from nlp_calib.simulation.lidar import LidarSimulationOptions

    still = {"imu_roll": 0.0, "imu_pitch": 0.0, "gyro_bias_x": 0.0, "gyro_bias_y": 0.0, "gyro_bias_z": 0.0}
    gyro = ImuSimulationOptions(seed=17, rate_noise=0.0, truth=still)
    sim = simulate_beside(LidarSimulationOptions(duration_s=10.0, seed=17), gyro)
    t = imu_times(sim.imu.options)
    heading = np.interp(t, sim.lidar.fine_time_s, np.unwrap(sim.lidar.base_poses[:, 2]))
    rate = sim.imu.rates[:, 2]
    trapezoids = 0.5 * (rate[1:] + rate[:-1]) * np.diff(t)
    assert np.abs(np.diff(heading)).sum() > 0.3  # the drive turns (rad, all told)
    assert np.sqrt(np.mean((trapezoids - np.diff(heading)) ** 2)) < 1e-6


def test_a_gyro_with_a_known_length_calibrates_everything(drive: tuple[Path, dict[str, float]]) -> None:
    bag, truth = drive
    sc = _scenario(bag, known={"wheel_separation": truth["wheel_separation"]})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()  # type: ignore[arg-type]
    est, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    for name in ("left_wheel_radius", "right_wheel_radius", "gyro_bias_x", "gyro_bias_y", "gyro_bias_z"):
        assert abs(est[name] - truth[name]) < 3 * std[name], name
    # The 5° tilt recovered, and the 20 ms late stamps found within 2 ms.
    assert abs(est["imu_roll"] - ROLL) < 3 * std["imu_roll"] and abs(est["imu_roll"] - ROLL) < 0.005
    assert abs(est["imu_pitch"] - truth["imu_pitch"]) < 3 * std["imu_pitch"]
    assert abs(est["tracker_lag"] - LATE) < 0.002
    # The hand-off: the IMU's joint rotated by the tilt, its height from /tf_static.
    mount = run.reports["gauss_newton"].mount
    assert mount is not None and mount.child == "imu_link"
    assert mount.rpy[0] == pytest.approx(est["imu_roll"]) and mount.xyz[2] == pytest.approx(0.15)
    assert set(mount.calibrated) == {"roll", "pitch"}


def test_a_gyro_alone_leaves_the_lengths_scale_not_determined(drive: tuple[Path, dict[str, float]]) -> None:
    bag, truth = drive
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = preflight(_scenario(bag))  # type: ignore[arg-type]
    loose = {p.name for p in report.parameters if p.status == NOT_DETERMINED}
    assert {"left_wheel_radius", "right_wheel_radius", "wheel_separation"} <= loose
    assert not loose & {"gyro_bias_z", "imu_roll", "imu_pitch", "tracker_lag"}
    assert "known: {wheel_separation: <metres>}" in report.way_out
    # The ratios it does determine, stated with their values.
    ratio = truth["left_wheel_radius"] / truth["wheel_separation"]
    said = report.way_out.split("left_wheel_radius/wheel_separation = ")[1].split(",")[0]
    assert float(said) == pytest.approx(ratio, rel=2e-3)


def test_simulate_writes_a_gyro_bag_with_its_truth(tmp_path: Path) -> None:
    proc = cli("simulate", "--imu", "--out", str(tmp_path / "g"), "--duration", "5", "--latency", "0.02")
    assert proc.returncode == 0, proc.stderr
    truth = json.loads((tmp_path / "g.truth.json").read_text())["params"]
    assert truth["tracker_lag"] == 0.02 and {"gyro_bias_z", "imu_roll", "imu_pitch", "gyro_scale"} <= set(
        truth
    )
    assert "imu: /imu" in proc.stdout


def test_a_planar_sensor_refuses_a_gyros_increments(drive: tuple[Path, dict[str, float]]) -> None:
    bag, _ = drive
    sc = scenario_from_mapping(
        {**SCENARIO, "sensor": "planar", "dataset": {"bag": str(bag), **DATASET}}, "gyro", bag.parent
    )
    with (
        pytest.raises(Exception, match=r"a gyro's integrated rates .* need a gyro"),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")
        Calibration(sc).run()


def _simulated(folder: Path, name: str, seconds: float, **truth: float) -> tuple[Path, dict[str, float]]:
    opts = ImuSimulationOptions(duration_s=seconds, seed=17, truth=truth, stamp_offset_s=LATE)
    bag, truth_file = write_imu_simulation(simulate_imu(opts), folder / name)
    return bag, {RADIANS.get(k, k): v for k, v in json.loads(truth_file.read_text())["params"].items()}


def test_init_drafts_a_gyro_scenario_that_runs_once_a_length_is_given(tmp_path: Path) -> None:
    """``init`` on the simulator's own gyro bag: a gyro scenario; its pre-flight (and ``run``) stop
    on the lengths' scale with the line to complete; completed, ``run`` calibrates and ``check`` on
    the same data says STILL GOOD."""
    bag, truth = _simulated(tmp_path, "drive", 30.0)
    drafted = tmp_path / "drive.yaml"
    proc = cli("init", str(bag), "--out", str(drafted))
    assert proc.returncode == 0, proc.stderr
    assert "reference: the gyro's rates on /imu" in proc.stdout
    raw = yaml.safe_load(drafted.read_text())
    assert raw["sensor"] == "gyro" and raw["dataset"]["imu"] == "/imu" and "known" not in raw
    assert raw["dataset"]["joints"] == ["left_wheel_joint", "right_wheel_joint"]
    todo = "# known: {wheel_separation: <metres>}"
    assert todo in drafted.read_text()
    # NOT ENOUGH (exit 4): the pre-flight says so, and run stops on it before any fit.
    for command in ("preflight", "run"):
        proc = cli(command, str(drafted), *(("--out", str(tmp_path / "refused")) if command == "run" else ()))
        assert proc.returncode == 4, proc.stdout + proc.stderr
        assert "known: {wheel_separation: <metres>}" in proc.stdout + proc.stderr
        if command == "preflight":
            assert "no distance, speed or turn radius: the reference measures no position" in proc.stdout
            assert " m/s" not in proc.stdout
    completed = tmp_path / "known.yaml"
    completed.write_text(
        drafted.read_text().replace(todo, f"known: {{wheel_separation: {truth['wheel_separation']}}}")
    )
    proc = cli("run", str(completed), "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    # No figure in metres of a track that has no position: said once, with why.
    assert "[m]" not in proc.stdout and " m (tracker path)" not in proc.stdout
    assert "trajectory errors: none in metres (a gyro measures turning, no length" in proc.stdout
    assert "the heading spanned" in proc.stdout
    cal = yaml.safe_load((tmp_path / "out" / "calibration.yaml").read_text())
    for name in ("left_wheel_radius", "gyro_bias_z", "imu_roll", "imu_pitch"):
        assert abs(cal["parameters"][name] - truth[name]) < 3 * cal["std"][name], name
    proc = cli(
        "check", str(tmp_path / "out" / "calibration.yaml"), str(completed), "--out", str(tmp_path / "c")
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    doc = json.loads((tmp_path / "c" / "check.json").read_text())
    assert doc["verdict"] == "still good" and "STILL GOOD" in proc.stdout
    assert "fair figures on this log: none in metres" in proc.stdout
    # The robot judged (the tilt, the wheels); the bias refitted, a recording's own like its clock.
    assert set(doc["parameters"]) == {"imu_roll", "imu_pitch", "left_wheel_radius", "right_wheel_radius"}


def test_check_sees_an_imu_remounted_with_another_tilt(tmp_path: Path) -> None:
    """The gyro's tilt read back from calibration.yaml and judged: the IMU rolled 2° further on a
    second drive is a drift naming imu_roll; its bias, another after a power cycle, is refitted
    (a recording's own, like its clock), not judged."""
    bag, truth = _simulated(tmp_path, "first", 30.0)
    sc = {**SCENARIO, "known": {"wheel_separation": truth["wheel_separation"]}, "name": "gyro"}
    first = tmp_path / "first.yaml"
    first.write_text(yaml.safe_dump({**sc, "dataset": {"bag": str(bag), **DATASET}}))
    assert cli("run", str(first), "--out", str(tmp_path / "out")).returncode == 0
    power_cycled = {"gyro_bias_x": -0.004, "gyro_bias_z": -0.006}
    for name, roll, code in (("same", 0.02, 0), ("rolled", 0.02 + float(np.radians(2.0)), 3)):
        moved, _ = _simulated(tmp_path, name, 30.0, imu_roll=roll, **power_cycled)
        second = tmp_path / f"{name}.yaml"
        second.write_text(yaml.safe_dump({**sc, "dataset": {"bag": str(moved), **DATASET}}))
        out = tmp_path / f"c_{name}"
        proc = cli("check", str(tmp_path / "out" / "calibration.yaml"), str(second), "--out", str(out))
        assert proc.returncode == code, proc.stdout + proc.stderr
        doc = json.loads((out / "check.json").read_text())
        assert not {"gyro_bias_x", "gyro_bias_y", "gyro_bias_z"} & set(doc["parameters"])
        assert [n for n, p in doc["parameters"].items() if p["drifted"]] == (["imu_roll"] if code else [])
    assert doc["parameters"]["imu_roll"]["change"] == pytest.approx(np.radians(2.0), abs=0.005)


def test_the_layout_gives_each_log_its_own_bias_beside_a_shared_tilt() -> None:
    """A gyro over three logs: the tilt (and a free scale) once, the biases once per log, the clock
    once per log; each window's residual takes its own log's bias (checked against the one-log
    residual at that log's values), and ``mounts: per_log`` still gives each log the whole mount."""
    model = in_units(MODELS["diff_drive"], "radians")
    shared = ("imu_roll", "imu_pitch", "gyro_scale")
    layout = build(model, ProblemSpec(sensor="gyro", scale="free", lags=3, mounts=3, shared=shared)).layout
    assert [p.name for p in layout.parameters if p.block == "mount" and p.log is None] == list(shared)
    assert [p.name for p in layout.parameters if p.log == 1] == [
        "gyro_bias_x_2", "gyro_bias_y_2", "gyro_bias_z_2", "tracker_lag_2",
    ]  # fmt: skip
    whole = build(model, ProblemSpec(sensor="gyro", lags=3, mounts=3)).layout
    assert not [p for p in whole.parameters if p.block == "mount" and p.log is None]
    # The residual, without a clock: each window's data is [z, its log's one-hot row, w].
    fns = build(model, ProblemSpec(sensor="gyro", scale="free", mounts=3, shared=shared))
    one = build(model, ProblemSpec(sensor="gyro", scale="free"))
    values = dict(zip(fns.names, np.random.default_rng(3).normal(0.0, 0.01, len(fns.names))))
    values.update({n: 0.1 for n in model.kinematic_params}, gyro_scale=1.02)
    z, M = [0.01, -0.02, 0.3, 0.1], [0.05, 0.0, 0.29]
    for log in range(3):
        mine = fns.view_dict(values, log)
        assert (
            mine["gyro_bias_y"] == values[f"gyro_bias_y_{log + 1}"] and mine["imu_roll"] == values["imu_roll"]
        )
        expected = _residual(one, mine, [*z, 1.0], M)
        got = _residual(fns, values, [*z, *np.eye(3)[log], 1.0], M)
        np.testing.assert_allclose(got, expected, atol=1e-15)
        assert np.abs(expected).max() > 1e-3  # a residual the biases move


def _residual(
    fns: ProblemFunctions, values: dict[str, float], data: list[float], M: list[float]
) -> np.ndarray:
    """``fns``' residual at named ``values`` for one window's ``data`` and base motion ``M``."""
    params = ca.DM([values[n] for n in fns.names])
    return np.asarray(ca.evalf(fns._residual(ca.DM(data), params, ca.DM(M)))).ravel()


def test_a_fit_of_two_logs_gives_each_its_own_bias(tmp_path: Path) -> None:
    """Two drives of one robot, its gyro power-cycled between them (another bias), stamped 20 and
    10 ms late: one tilt, each log's own bias and lag, all within 3σ of the truth."""
    biases = ({"gyro_bias_x": 0.003, "gyro_bias_z": 0.004}, {"gyro_bias_x": -0.004, "gyro_bias_z": -0.006})
    bags, truths = [], []
    for i, (bias, late) in enumerate(zip(biases, (0.02, 0.01))):
        opts = ImuSimulationOptions(duration_s=30.0, seed=41 + i, truth=bias, stamp_offset_s=late)
        bag, truth_file = write_imu_simulation(simulate_imu(opts), tmp_path / f"drive{i}")
        bags.append(bag)
        truths.append({RADIANS.get(k, k): v for k, v in json.loads(truth_file.read_text())["params"].items()})
    raw = {
        **SCENARIO,
        "known": {"wheel_separation": truths[0]["wheel_separation"]},
        "datasets": [{"bag": str(b), **DATASET} for b in bags],
    }
    sc = scenario_from_mapping(raw, "two", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()  # type: ignore[arg-type]
    est, std = run.reports["gauss_newton"].result.param_dict(), run.std("gauss_newton")
    assert {"imu_roll", "imu_pitch", "gyro_bias_z_1", "gyro_bias_z_2"} <= set(
        est
    ) and "gyro_bias_z" not in est
    for i, truth in enumerate(truths):
        for key in ("gyro_bias_x", "gyro_bias_y", "gyro_bias_z", "tracker_lag"):
            name = f"{key}_{i + 1}"
            assert abs(est[name] - truth[key]) < 3 * std[name], name
    for name in ("left_wheel_radius", "right_wheel_radius", "imu_roll", "imu_pitch"):
        assert abs(est[name] - truths[0][name]) < 3 * std[name], name
    # One IMU joint in the hand-off: the tilt is shared, no mount per log.
    assert not run.reports["gauss_newton"].mounts


def test_a_steering_angle_over_an_interval_is_the_one_its_wheels_travelled() -> None:
    # Joints at 50 Hz, intervals of 0.1 s (a gyro's): each interval's angle is the mean of the
    # joints' linear interpolation weighted by the wheels' travel, computed here on a dense grid;
    # where the wheels stand, by time; an interval whose ends are the stream's own samples and
    # holds none between (the records at the joints' own samples) reads its two ends' mean.
    from nlp_calib.logs.log import JointStream

    rng = np.random.default_rng(5)
    time_s = np.arange(0.0, 2.0, 0.02)
    wheel = np.cumsum(np.concatenate([[0.0], rng.uniform(0.0, 0.3, time_s.size - 1)]))
    wheel[60:70] = wheel[60]  # standing still for 0.2 s
    angle = np.cumsum(rng.normal(0.0, 0.05, time_s.size))
    stream = JointStream(time_s, np.column_stack([angle, wheel]), (0.0, 0.0))
    t = np.arange(0.013, 1.9, 0.1)
    got = stream.travelled_angle(t, 0, [1])
    for k in range(t.size - 1):
        dense = np.linspace(t[k], t[k + 1], 20001)
        a = np.interp(0.5 * (dense[1:] + dense[:-1]), time_s, angle)
        w = np.abs(np.diff(np.interp(dense, time_s, wheel)))
        want = np.sum(w * a) / np.sum(w) if np.sum(w) > 1e-12 else np.mean(a)
        assert got[k] == pytest.approx(want, abs=1e-6), k
    both = 0.5 * (angle[1:] + angle[:-1])
    np.testing.assert_allclose(stream.travelled_angle(time_s, 0, [1]), both, rtol=0, atol=1e-12)
    assert abs(got[6] - 0.5 * (np.interp(t[6], time_s, angle) + np.interp(t[7], time_s, angle))) > 1e-3


def test_a_tricycles_gyro_finds_its_clock_and_check_reads_back_each_calibration(tmp_path: Path) -> None:
    """A tricycle's gyro alone (the wheelbase known), stamped 20 ms late: the clock offset found
    within 2 ms and 3σ, every fitted parameter within 3σ; ``check`` on the same data reads back
    the calibration with the offset fitted and the one with it held: STILL GOOD both."""
    opts = ImuSimulationOptions(
        model="tricycle", duration_s=60.0, seed=23, truth={"imu_roll": ROLL}, stamp_offset_s=LATE
    )
    bag, truth_file = write_imu_simulation(simulate_imu(opts), tmp_path / "tricycle")
    truth = getattr(in_units(MODELS["tricycle"], "radians"), "from_counts", dict)(
        json.loads(truth_file.read_text())["params"]
    )
    dataset = {"bag": str(bag), "joint_states": "/joint_states", "imu": "/imu"}
    dataset["joints"] = ["steering_joint", "traction_wheel_joint"]  # type: ignore[assignment]
    base = {
        **SCENARIO,
        "model": "tricycle",
        "dataset": dataset,
        "known": {"wheelbase": truth["wheelbase"]},
        "residual": {"horizon_s": 0.5, "steering_sample": "mean"},
    }
    for name, lag in (("fitted", "auto"), ("held", LATE)):
        scenario = tmp_path / f"{name}.yaml"
        scenario.write_text(yaml.safe_dump({**base, "name": name, "alignment": {"tracker_lag": lag}}))
        out = tmp_path / f"out_{name}"
        proc = cli("run", str(scenario), "--out", str(out))
        assert proc.returncode == 0, proc.stdout + proc.stderr
        cal = yaml.safe_load((out / "calibration.yaml").read_text())
        est, std = cal["parameters"], cal["std"]
        for param in ("k_steer", "wheel_radius", "steer_offset", "gyro_bias_z", "imu_roll", "imu_pitch"):
            assert abs(est[param] - truth[param]) < 3 * std[param], (name, param, est[param], truth[param])
        if name == "fitted":
            assert abs(est["tracker_lag"] - LATE) < min(0.002, 3 * std["tracker_lag"]), est["tracker_lag"]
        else:
            assert "tracker_lag" not in est
        checked = tmp_path / f"c_{name}"
        check = cli("check", str(out / "calibration.yaml"), str(scenario), "--out", str(checked))
        assert check.returncode == 0, check.stdout + check.stderr
        assert "STILL GOOD" in check.stdout, (name, check.stdout)


def test_the_gyros_noise_seed_draws_other_noise_on_the_same_drive() -> None:
    """``noise_seed``: the gyro's noise from a generator of its own, the drive (the joints and the
    noise-free rates) the same; without it the drive's generator draws the noise, as before."""
    base = ImuSimulationOptions(model="tricycle", duration_s=5.0, seed=322)
    quiet = simulate_imu(ImuSimulationOptions(model="tricycle", duration_s=5.0, seed=322, rate_noise=0.0))
    own, other = (simulate_imu(ImuSimulationOptions(**{**base.__dict__, "noise_seed": n})) for n in (11, 12))
    drawn = simulate_imu(base)
    for sim in (own, other, drawn):
        np.testing.assert_array_equal(sim.joint_positions, quiet.joint_positions)
        assert np.std(sim.rates - quiet.rates) == pytest.approx(base.rate_noise, rel=0.05)
    expected = np.random.default_rng(11).normal(0.0, base.rate_noise, quiet.rates.shape)
    np.testing.assert_allclose(own.rates - quiet.rates, expected, atol=1e-15)
    assert not np.allclose(own.rates, other.rates) and not np.allclose(own.rates, drawn.rates)
    with pytest.raises(OptionsError, match="noise_seed"):
        ImuSimulationOptions(noise_seed=-1)


@pytest.mark.parametrize("drive", range(10))
def test_a_known_radius_starts_the_gyros_fit_at_the_lengths_true_ratios(drive: int) -> None:
    """A gyro sees the lengths' ratios alone. With the left radius known, the closed-form start
    finds the separation and the right radius (and the IMU upright): the heading changes of a
    differential drive ``(r_R·Δφ_R − r_L·Δφ_L)/b`` computed here, the IMU rolled 5°, noise of a
    0.1 s interval. Held at its value while the others stepped from the guess, the known radius
    left them on a mirror far from the ratios on four of these ten drives (separation 50–280 m,
    right radius negative, the IMU upside down; simulated bags: seed 904's, and every tricycle's of
    seeds 901–904, whose pre-flight then stopped on the lengths)."""
    from nlp_calib.sensors.gyro_start import gyro_start

    model = in_units(MODELS["diff_drive"], "radians")
    truth = {"left_wheel_radius": 0.1, "right_wheel_radius": 0.1005, "wheel_separation": 0.45}
    rng = np.random.default_rng(drive)
    t = np.arange(1200) * 0.1
    waves = [(rng.normal(0, s), rng.uniform(0.01, 0.1), rng.uniform(0, 6)) for s in (1, 1, 1, 1)]
    speed = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in waves)
    waves = [(rng.normal(0, s), rng.uniform(0.01, 0.1), rng.uniform(0, 6)) for s in (0.5,) * 4]
    turn = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in waves)
    left, right = (speed - 0.225 * turn) * 0.1 / 0.1, (speed + 0.225 * turn) * 0.1 / 0.1005

    def base_motion(k: dict[str, float]) -> np.ndarray:
        heading = (k["right_wheel_radius"] * right - k["left_wheel_radius"] * left) / k["wheel_separation"]
        return np.vstack([np.zeros_like(t), np.zeros_like(t), heading])

    roll = 0.0873
    up = np.array([0.0, np.sin(roll), np.cos(roll)])  # the base's vertical in the IMU's frame
    bias = np.array([0.003, -0.002, 0.004])
    rates = up[:, None] * base_motion(truth)[2] + bias[:, None] * 0.1 + rng.normal(0, 4.4e-5, (3, t.size))
    z = np.vstack([rates, np.full(t.size, 0.1)])
    start = gyro_start(model, z, base_motion, {"left_wheel_radius": 0.1})
    assert start["left_wheel_radius"] == 0.1
    assert start["wheel_separation"] == pytest.approx(0.45, rel=1e-3)
    assert start["right_wheel_radius"] == pytest.approx(0.1005, rel=1e-3)
    assert start["imu_roll"] == pytest.approx(roll, abs=1e-3)
