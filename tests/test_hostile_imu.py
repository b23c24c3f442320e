"""Hostile gyro inputs (sensor_msgs/Imu in a bag, a CSV ``t,wx,wy,wz``): each fault is a one-line
error naming its cause and fix, or its samples are dropped, counted and said; never silent, never
an internal error."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import cli

from nlp_calib.core.errors import DatasetError, NlpCalibWarning, UsageError
from nlp_calib.logs.imu import GyroRates, read_gyro_csv, read_imu
from nlp_calib.simulation.imu import ImuSimulationOptions, simulate_imu, write_imu_simulation
from nlp_calib.simulation.options import DriveShape

pytest.importorskip("rosbags")

#: Samples at 100 Hz from T0 (s), turning up to 0.5 rad/s about z (a slow drive's rates).
N = 200
T0 = 1_700_000_000.0


def _clean() -> tuple[np.ndarray, np.ndarray]:
    t = T0 + np.arange(N) / 100.0
    w = np.column_stack([0.01 * np.sin(t), -0.01 * np.cos(t), 0.5 * np.sin(0.7 * (t - T0))])
    return t, w


def _nan(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    w[20, 0], w[21, 2], w[90] = np.nan, np.inf, -np.inf
    return t, w


def _repeated(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.insert(t, [30, 60, 61], t[[29, 59, 60]]), np.insert(w, [30, 60, 61], w[[29, 59, 60]], axis=0)


def _backwards(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t[[40, 41]] = t[[41, 40]]
    t[120] -= 0.505
    return t, w


def _one_stamp(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.full_like(t, t[0]), w


def _zero_stamp(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros_like(t), w


def _degrees(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return t, np.degrees(w)


def _all_nan(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return t, np.full_like(w, np.nan)


def _one_sample(t: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return t[:1], w[:1]


Fault = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
#: Faults whose samples are dropped or sorted, said: (fault, what the warning says, how many).
SAID: list[tuple[Fault, str, int]] = [
    (_nan, "have non-finite rates", 3),
    (_repeated, "repeat an earlier sample's stamp", 3),
]
#: Faults refused: (fault, the cause and fix the one-line error names).
REFUSED: list[tuple[Fault, str]] = [
    (_one_stamp, "carry one stamp"),
    (_zero_stamp, "carry one stamp (0.000000000 s)"),
    (_degrees, "degrees per second?"),
    (_all_nan, "has finite rates"),
    (_one_sample, "a gyro needs at least 2"),
]


def _bag(folder: Path, t: np.ndarray, w: np.ndarray, frame: str = "imu_link") -> Path:
    from nlp_calib.simulation.rosbag import imu, write_bag

    messages = []
    for k, (s, rate) in enumerate(zip(t, w)):
        m = imu(round(s * 1e9), frame, rate, (0.0, 0.0, 9.81))
        # Recorded in the order written, whatever the stamp says.
        messages.append((m[0], m[1], round((T0 + k * 0.01) * 1e9), m[3]))
    return write_bag(folder / "bag", messages)


def _csv(folder: Path, t: np.ndarray, w: np.ndarray) -> Path:
    path = folder / "gyro.csv"
    rows = "".join(f"{s!r},{a!r},{b!r},{c!r}\n" for s, (a, b, c) in zip(t.tolist(), w.tolist()))
    path.write_text("t,wx,wy,wz\n" + rows)
    return path


def _read(form: str, folder: Path, t: np.ndarray, w: np.ndarray) -> GyroRates:
    if form == "bag":
        return read_imu(_bag(folder, t, w), "/imu")
    return read_gyro_csv(_csv(folder, t, w))


def test_clean_rates_read_as_written(tmp_path: Path) -> None:
    t, w = _clean()
    with warnings.catch_warnings():
        warnings.simplefilter("error", NlpCalibWarning)
        rates = _read("bag", tmp_path, t, w)
    assert rates.n == N and np.allclose(rates.rates, w) and rates.frame == "imu_link"


@pytest.mark.parametrize(("fault", "said", "count"), SAID, ids=[f.__name__ for f, *_ in SAID])
def test_a_bags_faulty_samples_are_dropped_counted_and_said(
    fault: Fault, said: str, count: int, tmp_path: Path
) -> None:
    t, w = fault(*_clean())
    with pytest.warns(NlpCalibWarning, match=said) as caught:
        rates = _read("bag", tmp_path, t, w)
    message = str(caught[0].message)
    assert f"{count} of {t.size} samples" in message and "message " in message
    assert rates.n == t.size - count and np.all(np.isfinite(rates.rates))
    assert np.all(np.diff(rates.stamp_ns) > 0)
    # What is kept is what was written at those stamps.
    clean_t, clean_w = _clean()
    at = np.searchsorted(np.round(clean_t * 1e9).astype(np.int64), rates.stamp_ns)
    assert np.allclose(rates.rates, clean_w[at])


def test_a_bags_samples_stamped_out_of_order_are_sorted_and_said(tmp_path: Path) -> None:
    t, w = _backwards(*_clean())
    with pytest.warns(NlpCalibWarning, match="stamped before the sample received before them") as caught:
        rates = _read("bag", tmp_path, t, w)
    assert "2 of 200 samples" in str(caught[0].message) and "(first: message 42)" in str(caught[0].message)
    assert rates.n == N and np.all(np.diff(rates.stamp_ns) > 0)
    order = np.argsort(t, kind="stable")
    assert np.allclose(rates.rates, w[order])


@pytest.mark.parametrize(("fault", "cause"), REFUSED, ids=[f.__name__ for f, _ in REFUSED])
@pytest.mark.parametrize("form", ["bag", "csv"])
def test_a_gyro_that_cannot_be_right_is_refused_naming_the_cause(
    form: str, fault: Fault, cause: str, tmp_path: Path
) -> None:
    t, w = fault(*_clean())
    if form == "csv" and fault is _all_nan:
        cause = "non-finite value"  # a CSV's value is refused on its line, as in every table
    with pytest.raises(
        UsageError, match=cause.replace("(", r"\(").replace(")", r"\)").replace("?", r"\?")
    ) as e:
        _read(form, tmp_path, t, w)
    assert "\n" not in str(e.value)
    if fault in (_one_stamp, _zero_stamp):
        assert ("dataset.stamps: receive" if form == "bag" else "column t") in str(e.value)
    if fault is _degrees:
        top = np.quantile(np.linalg.norm(w, axis=1), 0.99)
        assert f"reach {top:.4g} rad/s" in str(e.value) and f"is {math.radians(top):.3g} rad/s" in str(
            e.value
        )


@pytest.mark.parametrize("fault", [_repeated, _backwards], ids=["repeated", "backwards"])
def test_a_csvs_stamps_out_of_order_are_refused_with_the_line(fault: Fault, tmp_path: Path) -> None:
    """A CSV follows every table's rule: times increase strictly, the first line out of order named."""
    t, w = fault(*_clean())
    with pytest.raises(DatasetError, match="is not after the previous one") as e:
        _read("csv", tmp_path, t, w)
    first = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
    assert e.value.line == first + 2  # the header is line 1


def test_an_empty_imu_topic_is_refused(tmp_path: Path) -> None:
    from nlp_calib.simulation.rosbag import imu, joint_state, write_bag

    bag = write_bag(tmp_path / "bag", [joint_state(round(T0 * 1e9), ["a"], [0.0])])
    with pytest.raises(UsageError, match="'/imu' is not in the bag; name a sensor_msgs/msg/Imu topic"):
        read_imu(bag, "/imu")
    only = write_bag(tmp_path / "one", [imu(round(T0 * 1e9), "imu_link", (0, 0, 0), (0, 0, 9.8))])
    with pytest.raises(UsageError, match="has 1 message"):
        read_imu(only, "/imu")


@pytest.mark.parametrize("degrees", [False, True])
def test_a_slow_robots_gyro_in_degrees_is_refused_against_the_wheels_turning(
    degrees: bool, tmp_path: Path
) -> None:
    """A robot turning below 0.21 rad/s: its gyro's degrees per second stay under the reader's 12 rad/s
    refusal; the gyro's turning against the wheels' (typical wheels: the lengths are not all known)
    is 180/π and the pre-flight refuses it with the fix (exit 2). The same drive in rad/s is not."""
    drive = DriveShape(max_speed=0.3, max_turn=0.15)
    sim = simulate_imu(ImuSimulationOptions(duration_s=40.0, seed=13, drive=drive))
    assert np.quantile(np.abs(sim.rates[:, 2]), 0.99) < 0.21
    bag, _ = write_imu_simulation(
        replace(sim, rates=np.degrees(sim.rates)) if degrees else sim, tmp_path / "slow"
    )
    dataset = {
        "bag": str(bag),
        "joint_states": "/joint_states",
        "joints": ["left_wheel_joint", "right_wheel_joint"],
    }
    scenario = {
        "model": "diff_drive",
        "sensor": "gyro",
        "dataset": {**dataset, "imu": "/imu"},
        "known": {"wheel_separation": 0.45},
        "initial_guess": "auto",
        "information": {"translation": 1.0e8, "rotation": 1.0e8},
        "solvers": ["gauss_newton"],
    }
    path = tmp_path / "slow.yaml"
    path.write_text(yaml.safe_dump(scenario))
    proc = cli("preflight", str(path))
    said = "degrees per second (180/π = 57.3); sensor_msgs/Imu holds rad/s (REP 103)"
    if degrees:
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert said in proc.stderr and "as far as typical wheels" in proc.stderr, proc.stderr
    else:
        assert said not in proc.stdout + proc.stderr
        assert "  left_wheel_radius: determined" in proc.stdout, proc.stdout
