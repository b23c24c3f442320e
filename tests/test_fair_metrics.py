"""Fault-robust trajectory figures, checked against independent computations and the TUM export."""

from __future__ import annotations

import itertools
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import assert_close, cli, mat, vec

from nlp_calib.analysis.crossval import blocks, jackknife_std
from nlp_calib.analysis.metrics import ErrorStats, aligned_errors, distance_pairs, segments
from nlp_calib.simulation import SimulationOptions, simulate, write_simulation


def test_segments_split_at_bad_intervals_and_drop_lone_records() -> None:
    bad = np.zeros(19, dtype=bool)  # 20 records, 19 intervals
    assert segments(20, bad) == [(0, 20)]
    bad[[5, 6, 7, 12]] = True
    # Records 6 and 7 lie inside the run 5..7; the fault intervals' end records start anew.
    assert segments(20, bad) == [(0, 6), (8, 13), (13, 20)]
    assert segments(1, None) == []


def test_aligned_errors_undo_a_rigid_motion_and_pass_nan_through() -> None:
    rng = np.random.default_rng(0)
    ref = np.column_stack([rng.normal(size=(30, 2)), rng.normal(size=30)])
    c, s = np.cos(0.7), np.sin(0.7)
    est = ref.copy()
    est[:, :2] = ref[:, :2] @ np.array([[c, -s], [s, c]]).T + [3.0, -1.0]
    assert_close(aligned_errors(est, ref), np.zeros(30), atol=1e-12)
    est[4, 0] = np.nan  # a diverged calibration: figures are NaN, not an exception
    assert np.isnan(aligned_errors(est, ref)[4])


def _tricycle_drive(
    seed: int, n: int, traction: tuple[float, float]
) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray]:
    """A horizon-1 tricycle's Functions, its parameters, ``n - 1`` random intervals' inputs (the
    traction's increments uniform over ``traction``) and its dead-reckoned track with 1 cm of noise."""
    from nlp_calib.analysis import metrics
    from nlp_calib.models import get_model
    from nlp_calib.problem import ProblemSpec, build

    fns = build(get_model("tricycle"), ProblemSpec(horizon=1))
    p = np.array([0.5, 0.01, 1.5, 0.0, 1.0, 0.0, 0.0])
    rng = np.random.default_rng(seed)
    inputs = np.vstack([rng.uniform(*traction, n - 1), rng.uniform(-0.3, 0.3, n - 1)])
    return fns, p, inputs, metrics.integrate(fns, p, inputs, np.zeros(3)) + rng.normal(0.0, 0.01, (n, 3))


def test_parameter_sets_scored_together_score_as_alone() -> None:
    """The reference's side computed once for several parameter sets gives each set's figures
    exactly, on a stretch with bad intervals and bad records."""
    from nlp_calib.analysis.metrics import each_metrics, trajectory_metrics

    n = 400
    fns, p, inputs, ref = _tricycle_drive(3, n, (0.5, 1.5))
    bad_i, bad_r = np.zeros(n - 1, dtype=bool), np.zeros(n, dtype=bool)
    bad_i[[90, 250]], bad_r[[30, 301]] = True, True
    sets = [p, p * 1.01, p * 0.98]
    kw = {"start": 20, "stop": 380, "rpe_window": 10, "bad_intervals": bad_i, "bad_records": bad_r}
    together = each_metrics(fns, sets, inputs, ref, **kw)
    alone = [trajectory_metrics(fns, q, inputs, ref, **kw) for q in sets]
    assert repr(together) == repr(alone)  # every digit, NaN (an empty statistic) included
    assert together[0].segments == 3 and repr(together[1]) != repr(together[0])


def test_figures_computed_a_few_motions_at_a_time_are_the_one_pass(monkeypatch: pytest.MonkeyPatch) -> None:
    """The RPE's motions compared a chunk at a time (bounded temporaries at 10^6 records) give
    every figure of the one pass, digit for digit, with faults in the stretch."""
    from nlp_calib.analysis import metrics

    n = 600
    fns, p, inputs, ref = _tricycle_drive(11, n, (0.5, 1.5))
    bad_i, bad_r = np.zeros(n - 1, dtype=bool), np.zeros(n, dtype=bool)
    bad_i[[140, 333]], bad_r[[50, 401]] = True, True
    kw = {"rpe_window": 10, "bad_intervals": bad_i, "bad_records": bad_r}
    whole = metrics.each_metrics(fns, [p * 1.01], inputs, ref, **kw)
    monkeypatch.setattr(metrics, "CHUNK", 7)
    chunked = metrics.each_metrics(fns, [p * 1.01], inputs, ref, **kw)
    assert repr(chunked) == repr(whole)
    assert whole[0].rpe_distance[1.0].n > 100 and np.isfinite(whole[0].rpe_trans)


def test_a_fault_free_stretch_takes_each_statistic_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """One part over every record: its segment ATE is the full run's (the same records, the same
    track), computed once; the windowed RPE is a mean alone. Each figure against its own
    computation, to the bit, and only the statistics read are computed."""
    from nlp_calib.analysis import metrics
    from nlp_calib.results.figures import RPE_DISTANCES

    fns, p, inputs, ref = _drive()
    q = p * 1.01
    counted: list[int] = []
    of = ErrorStats.of.__func__  # type: ignore[attr-defined]
    monkeypatch.setattr(ErrorStats, "of", classmethod(lambda cls, e: counted.append(len(e)) or of(cls, e)))
    m = metrics.trajectory_metrics(fns, q, inputs, ref, rpe_window=5)
    track = metrics.integrate(fns, q, inputs, ref[0])
    err = np.linalg.norm(track[:, :2] - ref[:, :2], axis=1)
    assert m.ate.median == pytest.approx(float(np.median(err)), rel=1e-12) and m.ate.n == err.size
    assert repr(m.segment_ate) == repr(m.ate)
    g = metrics.PLANAR
    rel = [
        g.between(g.between(ref[i], ref[i + 5]), g.between(track[i], track[i + 5]))
        for i in range(err.size - 5)
    ]
    assert m.rpe_trans == pytest.approx(float(np.linalg.norm(np.array(rel)[:, :2], axis=1).mean()), rel=1e-12)
    # The full run's, the aligned segments' and each distance's RPE: no median nobody reads.
    assert len(counted) == 2 + len(RPE_DISTANCES)


def _evo_pairs(dist: np.ndarray, delta: float, tol: float) -> list[tuple[int, int]]:
    """The all-pairs rule written out: for each i, the j > i nearest delta further on."""
    pairs = []
    for i in range(dist.size - 1):
        rest = dist[i + 1 :] - dist[i]
        j = int(np.argmin(np.abs(rest - delta)))
        if abs(rest[j] - delta) <= tol:
            pairs.append((i, i + 1 + j))
    return pairs


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_distance_pairs_follow_the_all_pairs_rule(seed: int) -> None:
    rng = np.random.default_rng(seed)
    steps = np.where(rng.random(400) < 0.2, 0.0, rng.uniform(0.0, 0.05, 400))  # stops: equal distances
    dist = np.concatenate([[0.0], np.cumsum(steps)])
    for delta in (0.3, 1.0, 2.5):
        i, j = distance_pairs(dist, delta, 0.1 * delta)
        assert list(zip(i.tolist(), j.tolist())) == _evo_pairs(dist, delta, 0.1 * delta)


def test_distance_pairs_first_of_equal_distances_is_the_binary_searchs() -> None:
    """The first record of each run of equal distances, taken by a running maximum, is the one a
    binary search over every record finds (stops: runs of equal distances; a NaN tail, where the
    two differ on the first record of a run, but no pair is kept)."""
    rng = np.random.default_rng(71)
    steps = np.where(rng.random(3000) < 0.3, 0.0, rng.uniform(0.0, 0.05, 3000))
    dist = np.concatenate([[0.0], np.cumsum(steps)])
    dist[-40:] = np.nan
    for delta in (0.2, 1.0, 5.0):
        target, n, tol = dist[:-1] + delta, dist.size, 0.1 * delta
        i = np.arange(n - 1)
        j_hi = np.clip(np.searchsorted(dist, target, side="left"), i + 1, n - 1)
        j_lo = np.clip(j_hi - 1, i + 1, n - 1)
        j = np.where(np.abs(dist[j_lo] - target) <= np.abs(dist[j_hi] - target), j_lo, j_hi)
        j = np.maximum(np.searchsorted(dist, dist[j], side="left"), i + 1)
        keep = np.abs(dist[j] - target) <= tol
        got = distance_pairs(dist, delta, tol)
        assert np.array_equal(got[0], i[keep]) and np.array_equal(got[1], j[keep])
        assert got[0].size > 1000


@pytest.mark.parametrize("group", ["SE(2)", "SE(3)"])
def test_aligned_errors_a_block_of_rows_at_a_time_are_the_one_product(
    monkeypatch: pytest.MonkeyPatch, group: str
) -> None:
    """Aligned errors taken a few rows at a time (one BLAS call over 10^6 rows cost several times the
    CPU in its threads) are the product over every row at once, bit for bit, the last block short."""
    from nlp_calib.analysis import metrics

    g = metrics.GEOMETRIES[group]
    rng = np.random.default_rng(5)
    ref = rng.normal(0.0, 10.0, (1003, 7))
    est = ref + rng.normal(0.0, 0.5, ref.shape)
    d = g.dims
    R, t = g.align(est[:, :d], ref[:, :d])
    want = np.linalg.norm(est[:, :d] @ R.T + t - ref[:, :d], axis=1)
    monkeypatch.setattr(metrics, "CHUNK", 10)
    assert np.array_equal(metrics.aligned_errors(est, ref, g), want)


def test_error_stats_are_evo_s() -> None:
    e = np.array([0.1, 0.4, 0.2, 0.9])
    s = ErrorStats.of(e)
    assert_close(
        [s.rmse, s.mean, s.median, s.std, s.min, s.max],
        [np.sqrt(np.mean(e**2)), 0.4, 0.3, np.std(e), 0.1, 0.9],
    )
    assert ErrorStats.of(np.zeros(0)).n == 0


def _read_tum(path: Path) -> tuple[np.ndarray, np.ndarray]:
    rows = np.loadtxt(path, ndmin=2)
    theta = 2.0 * np.arctan2(rows[:, 6], rows[:, 7])
    return rows[:, 0], np.column_stack([rows[:, 1], rows[:, 2], theta])


def _aligned_errors(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Planar Umeyama without scale, written with homogeneous matrices."""
    P, Q = est[:, :2], ref[:, :2]
    cp, cq = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((Q - cq).T @ (P - cp))
    S = np.diag([1.0, np.linalg.det(U @ Vt)])
    R = U @ S @ Vt
    return np.linalg.norm((P - cp) @ R.T + cq - Q, axis=1)


def _rpe(est: np.ndarray, ref: np.ndarray, delta: float) -> np.ndarray:
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(ref[:, :2], axis=0), axis=1))])
    out = []
    for i, j in _evo_pairs(dist, delta, 0.1 * delta):
        E = np.linalg.inv(np.linalg.inv(mat(ref[i])) @ mat(ref[j])) @ (
            np.linalg.inv(mat(est[i])) @ mat(est[j])
        )
        out.append(np.hypot(*vec(E)[:2]))
    return np.array(out)


@pytest.mark.slow
def test_tum_files_reproduce_the_reported_figures(tmp_path: Path) -> None:
    """Read back every exported file and recompute ATE, segment ATE (raw and aligned) and RPE."""
    log, _ = write_simulation(
        simulate(SimulationOptions.of(records=1500, seed=6, counter_faults=2)), tmp_path / "f.txt"
    )
    sc = tmp_path / "s.yaml"
    sc.write_text(
        f"dataset: {log}\nsolvers: [gauss_newton]\nresidual: {{horizon: 10}}\n"
        "robust: {kernel: huber, delta: 0.25}\nvalidation: {blocks: 0}\n"
    )
    out = tmp_path / "out"
    proc = cli("run", str(sc), "--out", str(out), "--report")
    assert proc.returncode == 0, proc.stderr
    metrics = json.loads((out / "result.json").read_text())["solvers"]["gauss_newton"]["metrics"]
    folder = out / "trajectories"
    _, ref = _read_tum(folder / "tracker.tum")
    _, est = _read_tum(folder / "gauss_newton.tum")
    assert_close(np.linalg.norm(est[:, :2] - ref[:, :2], axis=1).mean(), metrics["ate_mean"], rtol=1e-6)
    k = 1
    ate, aligned, rpe1, rpe5 = [], [], [], []
    while (folder / f"segment{k}_tracker.tum").exists():
        t_ref, seg_ref = _read_tum(folder / f"segment{k}_tracker.tum")
        t_est, seg_est = _read_tum(folder / f"segment{k}_gauss_newton.tum")
        assert np.array_equal(t_ref, t_est)
        assert_close(seg_est[0, :2], seg_ref[0, :2], atol=1e-9)  # restarted from the tracker
        ate.append(np.linalg.norm(seg_est[:, :2] - seg_ref[:, :2], axis=1))
        aligned.append(_aligned_errors(seg_est, seg_ref))
        rpe1.append(_rpe(seg_est, seg_ref, 1.0))
        rpe5.append(_rpe(seg_est, seg_ref, 5.0))
        k += 1
    assert k - 1 == metrics["segments"] >= 3  # two faults: three segments
    assert_close(np.concatenate(ate).mean(), metrics["segment_ate"]["mean"], rtol=1e-6)
    assert_close(np.concatenate(aligned).mean(), metrics["segment_ate_aligned"]["mean"], rtol=1e-6)
    assert_close(np.concatenate(rpe1).mean(), metrics["rpe_1m"]["mean"], rtol=1e-6)
    assert_close(np.concatenate(rpe5).mean(), metrics["rpe_5m"]["mean"], rtol=1e-6)
    assert np.concatenate(rpe5).size == metrics["rpe_5m"]["n"]


def test_jackknife_and_blocks() -> None:
    est = np.array([[1.0, 10.0], [2.0, 10.0], [3.0, 13.0], [6.0, 11.0]])
    K = est.shape[0]
    expected = np.sqrt((K - 1) / K * ((est - est.mean(axis=0)) ** 2).sum(axis=0))
    assert_close(jackknife_std(est), expected)
    parts = blocks(2, 2434, 10)
    assert parts[0][0] == 2 and parts[-1][1] == 2434 and len(parts) == 10
    assert all(b == c for (_, b), (c, _) in itertools.pairwise(parts))


# --- records that do not connect (#43 item 6) ----------------------------------------------------


def _drive(n: int = 80) -> tuple[object, np.ndarray, np.ndarray, np.ndarray]:
    """A tricycle's track (its tracker the model's own poses, with a jump of 3 m at record 40 as a
    gap leaves: after it the tracker goes on from elsewhere) and the model's inputs."""
    from nlp_calib.analysis.metrics import integrate
    from nlp_calib.models import get_model
    from nlp_calib.problem import ProblemSpec, build

    fns = build(get_model("tricycle"), ProblemSpec(horizon=1))
    p = np.array([0.5, 0.01, 1.5, 0.0, 1.0, 0.0, 0.0])
    inputs = np.vstack([np.full(n - 1, 1.0), np.full(n - 1, 0.1)])
    ref = integrate(fns, p, inputs, np.zeros(3))
    ref[40:, :2] += 3.0
    return fns, p, inputs, ref


def test_records_that_do_not_connect_have_no_full_run_figure_and_no_rpe_across() -> None:
    """Across a gap the full-run track chains what does not connect (it was 3 m off from the gap
    on); the segment figures restart there and the windowed RPE pairs no records across it."""
    from nlp_calib.analysis.metrics import trajectory_metrics

    fns, p, inputs, ref = _drive()
    gap = np.zeros(ref.shape[0] - 1, dtype=bool)
    gap[39] = True
    chained = trajectory_metrics(fns, p, inputs, ref, rpe_window=5)
    assert chained.ate.max == pytest.approx(np.hypot(3.0, 3.0), rel=1e-9)
    apart = trajectory_metrics(fns, p, inputs, ref, rpe_window=5, bad_intervals=gap, breaks=gap)
    assert apart.ate.n == 0 and np.isnan(apart.ate_final)
    assert apart.segments == 2 and apart.segment_ate.max == pytest.approx(0.0, abs=1e-9)
    # The windows of 5 records: 75 pairs, of which the 5 across the gap are left out (their error
    # is the jump); every other pair is exact.
    assert apart.rpe_trans == pytest.approx(0.0, abs=1e-9) and chained.rpe_trans > 0.1
    # A fault (not a break): the records connect, so the full-run figure is kept (it measures the
    # fault), while the windowed RPE still pairs nothing across it.
    faulty = trajectory_metrics(fns, p, inputs, ref, rpe_window=5, bad_intervals=gap)
    assert faulty.ate.n == ref.shape[0] and faulty.rpe_trans == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("group", ["SE(2)", "SE(3)", "rate"])
def test_the_rpe_compares_the_translations_of_the_whole_motions_to_the_bit(group: str) -> None:
    """The RPE over a distance takes a motion's translation alone: the whole motion's (``between``)
    first columns, the same bits, and so the same figure as the whole motions compared."""
    from nlp_calib.analysis import metrics
    from nlp_calib.core import poses3d

    g = metrics.GEOMETRIES[group]
    rng = np.random.default_rng(5)
    n = 400
    if group == "SE(3)":
        q = rng.normal(size=(n, 4))
        T = np.hstack(
            [np.cumsum(rng.normal(0.0, 0.1, (n, 3)), axis=0), q / np.linalg.norm(q, axis=1)[:, None]]
        )
        est = np.hstack(
            [
                T[:, :3] + rng.normal(0.0, 0.01, (n, 3)),
                poses3d.quat_multiply(T[:, 3:], q[:1] / np.linalg.norm(q[0])),
            ]
        )
    else:
        T = np.cumsum(rng.normal(0.0, 0.1, (n, 4 if group == "rate" else 3)), axis=0)
        est = T + rng.normal(0.0, 0.01, T.shape)
    i, j = np.arange(n - 30), np.arange(30, n)
    assert (
        g.moved(est[i], est[j]).tobytes()
        == np.ascontiguousarray(g.between(est[i], est[j])[:, : g.dims]).tobytes()
    )
    pairs = metrics.rpe_pairs(T, [np.arange(n)], [0.5], g)[0.5]
    assert pairs[0][0].size > 100
    whole = [
        np.linalg.norm(g.between(est[a], est[b])[:, : g.dims] - g.between(T[a], T[b])[:, : g.dims], axis=1)
        for a, b, _ in pairs
    ]
    assert repr(metrics.rpe_of(est, pairs, g)) == repr(ErrorStats.of(np.concatenate(whole)))


# --- the figures' arithmetic per parameter set (#41 at 10^6 records) ------------------------------


def _former_figures(fns: object, p: np.ndarray, inputs: np.ndarray, T: np.ndarray, where: dict) -> tuple:
    """The planar figures as the scoring computed them before the reference's side was gathered once
    and rows' lengths taken a column at a time: every figure from ``np.linalg.norm`` over gathered
    rows and ``poses.align`` on each segment (one parameter set, the whole stretch)."""
    from nlp_calib.analysis import metrics
    from nlp_calib.core import poses

    bad_i, bad_r, breaks, W = (
        where["bad_intervals"],
        where["bad_records"],
        where["breaks"],
        where["rpe_window"],
    )
    n = T.shape[0]
    good = ~bad_r
    step = metrics.steps(fns, p, inputs)
    track = poses.accumulate(T[0], step)
    full = good if not breaks.any() else np.zeros(n, dtype=bool)
    err = np.linalg.norm(track[full, :2] - T[full, :2], axis=1)
    crossed = np.r_[0, np.cumsum(bad_i)]
    pair = good[:-W] & good[W:] & (crossed[W:] == crossed[:-W])
    i = np.flatnonzero(pair)
    rel = poses.between(poses.between(T[i], T[i + W]), poses.between(track[i], track[i + W]))
    parts = metrics.segments(n, bad_i)
    seg = metrics.restarted(step, T, parts)
    idx = [a + np.flatnonzero(good[a:b]) for a, b in parts]
    aligned = []
    for k in idx:
        R, t = poses.align(seg[k, :2], T[k, :2])
        aligned.append(np.linalg.norm(seg[k, :2] @ R.T + t - T[k, :2], axis=1))
    scored = np.concatenate(idx)
    rpe = []
    for delta in (1.0, 5.0):
        e = []
        for k in idx:
            a, b = metrics.distance_pairs(metrics.path_distance(T[k]), delta, 0.1 * delta)
            e.append(
                np.linalg.norm(poses.moved(seg[k[a]], seg[k[b]]) - poses.moved(T[k[a]], T[k[b]]), axis=1)
            )
        rpe.append(ErrorStats.of(np.concatenate(e)))
    return (
        ErrorStats.of(err),
        float(np.linalg.norm(rel[:, :2], axis=1).mean()),
        float(np.abs(rel[:, 2]).mean()),
        ErrorStats.of(np.linalg.norm(seg[scored, :2] - T[scored, :2], axis=1)),
        ErrorStats.of(np.concatenate(aligned)),
        *rpe,
    )


@pytest.mark.parametrize("stretch", ["clean", "faults", "gap", "logs"])
def test_each_sets_figures_are_the_former_arithmetic_to_the_bit(
    monkeypatch: pytest.MonkeyPatch, stretch: str
) -> None:
    """Several parameter sets scored together against one reference give each set's figures as the
    former arithmetic did, to the bit (faults, bad tracker poses, a gap, logs end to end), with no
    row-wise ``np.linalg.norm`` over the tracks (the lengths a column at a time, several times
    faster, the same bits) and the reference's side of each segment's alignment taken once, not
    per parameter set."""
    from nlp_calib.analysis import metrics

    n = 900
    fns, p, inputs, T = _tricycle_drive(17, n, (0.05, 0.15))
    bad_i, bad_r, breaks = np.zeros(n - 1, dtype=bool), np.zeros(n, dtype=bool), np.zeros(n - 1, dtype=bool)
    if stretch == "faults":
        bad_i[[150, 151, 600]], bad_r[[40, 41, 333, 899]] = True, True
    if stretch in ("gap", "logs"):
        T[500:, :2] += 2.0  # from the gap (or the second log) on, the tracker goes on from elsewhere
        bad_i[499] = breaks[499] = True
    if stretch == "logs":
        bad_i[299] = breaks[299] = True
        bad_r[[10, 700]] = True
    where = {"rpe_window": 10, "bad_intervals": bad_i, "bad_records": bad_r, "breaks": breaks}
    sets = [p, p * 1.01, p * 0.98]
    norms: list[int] = []
    norm = np.linalg.norm
    monkeypatch.setattr(np.linalg, "norm", lambda *a, **k: norms.append(1) or norm(*a, **k))
    centred: list[int] = []
    side = metrics.centred
    monkeypatch.setattr(metrics, "centred", lambda *a: centred.append(1) or side(*a))
    got = metrics.each_metrics(fns, sets, inputs, T, **where)
    assert not norms
    assert len(centred) == got[0].segments  # once per segment, for the three sets
    monkeypatch.setattr(np.linalg, "norm", norm)
    for q, m in zip(sets, got):
        want = _former_figures(fns, q, inputs, T, where)
        have = (m.ate, m.rpe_trans, m.rpe_rot, m.segment_ate, m.segment_ate_aligned, *m.rpe_distance.values())
        assert repr(have) == repr(want)
    assert got[0].segments == {"clean": 1, "faults": 3, "gap": 2, "logs": 3}[stretch]
    assert (got[0].ate.n == 0) == (stretch in ("gap", "logs")) and got[0].rpe_distance[5.0].n > 50
