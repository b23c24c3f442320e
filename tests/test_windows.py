"""Windows from prefix poses: the fast path equals the residual as defined, window by window, for
any selection of windows and several logs; the linear-time uncertainty equals the direct sum."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from conftest import assert_close, parse_lines

from nlp_calib.analysis import uncertainty as unc
from nlp_calib.analysis.inputs_bias import _increment_variance
from nlp_calib.core.numeric import PIECE_SIZES
from nlp_calib.logs import Log
from nlp_calib.models import get_model
from nlp_calib.problem import (
    ProblemFunctions,
    ProblemSpec,
    ResidualData,
    ResidualOptions,
    build,
    build_residual_data,
    joined,
)
from nlp_calib.simulation import SimulationOptions, simulate
from nlp_calib.solvers import ProblemEvaluator


def sim_log(model: str, records: int, seed: int, **kwargs: object) -> Log:
    text = simulate(SimulationOptions.of(model=model, records=records, seed=seed, **kwargs)).text()  # type: ignore[arg-type]
    return parse_lines(text.splitlines(), model=model)


def truth(model: str) -> np.ndarray:
    return np.array(list(get_model(model).drive.default_truth.values()))


def evaluator(
    fns: ProblemFunctions, data: object, x_fixed: np.ndarray, delta: float = 0.05
) -> ProblemEvaluator:
    return ProblemEvaluator(fns, data, x_fixed=x_fixed, omega=np.array([1.0, 2.0, 3.0]), delta=delta)  # type: ignore[arg-type]


@pytest.mark.parametrize("model", ["tricycle", "diff_drive"])
@pytest.mark.parametrize("horizon", [1, 4])
@pytest.mark.parametrize("fixed", [(), ("sensor_theta",)])
def test_windows_match_the_defining_residual_for_any_selection(
    model: str, horizon: int, fixed: tuple[str, ...]
) -> None:
    m = get_model(model)
    fns = build(m, ProblemSpec(horizon=horizon, fixed=fixed))
    data = build_residual_data(fns, sim_log(model, 150, 1), ResidualOptions(horizon=horizon, stride=2))
    rng = np.random.default_rng(0)
    data = data.select(np.sort(rng.choice(data.n_residuals, data.n_residuals // 2, replace=False)))
    p = truth(model) * rng.uniform(0.9, 1.1, len(fns.names))
    x = np.array([v for n, v in zip(fns.names, p) if n not in fixed])
    x_fixed = np.array([v for n, v in zip(fns.names, p) if n in fixed])
    ev = evaluator(fns, data, x_fixed)
    e, _, _ = ev.robust_terms(x)
    J = np.concatenate([blk.J for _, blk in ev.sensitivities(x)])
    columns = data.columns
    e_ref, J_ref = (np.asarray(v) for v in fns.residual_jacobian.map(data.n_residuals)(x, x_fixed, columns))
    assert_close(e, e_ref, rtol=1e-9, atol=1e-12, what="e")
    J_ref = J_ref.reshape(3, data.n_residuals, -1).transpose(1, 0, 2)
    assert_close(J, J_ref, rtol=1e-8, atol=1e-10 * np.abs(J_ref).max(), what="J")


def test_two_logs_end_to_end_are_the_sum_of_each_log() -> None:
    fns = build(get_model("tricycle"), ProblemSpec(horizon=5))
    opts = ResidualOptions(horizon=5)
    a, b = sim_log("tricycle", 120, 2), sim_log("tricycle", 90, 3, latency_s=0.01)
    both = build_residual_data(fns, [a, b], opts)
    assert both.offsets == (0, 120) and both.n_records == 210
    # No window crosses from one log into the next.
    assert np.all((both.stops < 120) | (both.starts >= 120))
    assert both.n_residuals == (120 - 5) + (90 - 5)
    x = truth("tricycle") * 1.02
    ne = [
        evaluator(fns, d, np.zeros(0)).normal_equations(x)
        for d in (both, *(build_residual_data(fns, lg, opts) for lg in (a, b)))
    ]
    assert_close(ne[0].H, ne[1].H + ne[2].H, rtol=1e-10)
    assert_close(ne[0].g, ne[1].g + ne[2].g, rtol=1e-10, atol=1e-14)
    assert ne[0].cost == pytest.approx(ne[1].cost + ne[2].cost, rel=1e-12)


def test_joining_each_logs_windows_equals_building_them_end_to_end() -> None:
    fns = build(get_model("tricycle"), ProblemSpec(horizon=5))
    opts = ResidualOptions(horizon=5, stride=2)
    logs = [sim_log("tricycle", 120, 2), sim_log("tricycle", 90, 3), sim_log("tricycle", 60, 4)]
    built = build_residual_data(fns, logs, opts)
    glued = joined([build_residual_data(fns, lg, opts) for lg in logs])
    assert glued.offsets == built.offsets and glued.n_records == built.n_records
    for name in ("inputs", "T_world_sensor", "starts", "stops", "z"):
        np.testing.assert_array_equal(getattr(glued, name), getattr(built, name), err_msg=name)


def test_windows_touching_flagged_intervals_can_be_dropped() -> None:
    fns = build(get_model("tricycle"), ProblemSpec(horizon=3))
    data = build_residual_data(fns, sim_log("tricycle", 50, 4), ResidualOptions(horizon=3))
    flagged = np.zeros(data.inputs.shape[1], dtype=bool)
    flagged[[10, 30]] = True
    counts = data.interval_counts(flagged)
    assert counts.tolist() == [int(s <= 10 < e) + int(s <= 30 < e) for s, e in zip(data.starts, data.stops)]
    kept = data.select(counts == 0)
    assert kept.n_residuals == data.n_residuals - 6
    assert_close(kept.z, data.z[:, counts == 0], rtol=0.0)


def _by_reading(F: np.ndarray, counted: np.ndarray, data: ResidualData | None = None) -> np.ndarray:
    """Each window's map ``(w, h, c, i)`` from its intervals' inputs to its error, written over the
    readings ``h = 0..H`` of its intervals' ends: a counted input's interval ``h`` is the reading
    ``h + 1`` less the reading ``h`` (with ``data``, each interval's share of two readings' noise
    as the noise-bias step gives it, less where the counter stood; without, two readings' as the
    uncertainty takes it); another input's interval is its own (the reading ``h``)."""
    Fs = F
    if data is not None:
        v = _increment_variance(data, counted)  # (inputs, intervals)
        H = F.shape[1]
        scale = np.sqrt(v[:, data.starts[:, None] + np.arange(H)] / 2.0).transpose(1, 2, 0)  # (w, h, i)
        Fs = np.where(counted, F * scale[:, :, None, :], F)
    own = np.concatenate([F, np.zeros_like(F[:, :1])], axis=1)
    read = np.concatenate([-Fs[:, :1], Fs[:, :-1] - Fs[:, 1:], Fs[:, -1:]], axis=1)
    return np.where(counted, read, own)


def _column_jacobian(fns: ProblemFunctions, data: ResidualData, x: np.ndarray) -> np.ndarray:
    """Each window's error's derivatives with respect to its own data column, ``(3, N, rows)``."""
    N = data.n_residuals
    col = ca.SX.sym("col", fns.column_rows)
    d_col = ca.Function("d", [col], [ca.jacobian(fns.residual(x, [], col), col)]).map(N)
    return np.asarray(d_col(data.columns)).reshape(3, N, -1)


@pytest.mark.parametrize("H", [1, 5])
def test_the_inputs_share_of_the_cost_is_the_sum_over_every_window_and_reading(H: int) -> None:
    """``T(x)``, the counts' expected share of the robust cost, against the direct sum over each
    window's readings: ``Σ_w ρ'_w Σ_c Ω_c Σ_r (F_w^{r−1} − F_w^r)² σ²``."""
    from nlp_calib.analysis.inputs_bias import noise_share

    fns = build(get_model("diff_drive"), ProblemSpec(horizon=H, kernel="huber"))
    data = build_residual_data(fns, sim_log("diff_drive", 300, 7), ResidualOptions(horizon=H))
    ev = evaluator(fns, data, np.zeros(0), delta=0.05)
    x, sigma_in, counted = truth("diff_drive") * 1.001, np.array([0.3, 0.5]), np.array([True, True])
    _, _, weight = ev.robust_terms(x)
    D = _column_jacobian(fns, data, x)
    F = D[:, :, : fns.n_inputs * H].reshape(3, data.n_residuals, H, fns.n_inputs).transpose(1, 2, 0, 3)
    direct = np.einsum("w,c,whci,i->", weight, ev.omega, _by_reading(F, counted, data) ** 2, sigma_in**2)
    assert noise_share(ev, x, weight, (sigma_in, counted)) == pytest.approx(direct, rel=1e-9)


@pytest.mark.parametrize("H", [1, 5])
def test_some_windows_shares_of_the_cost_are_their_terms_of_the_direct_sum(H: int) -> None:
    """The inputs' share of the cost, window by window, on a subset of the windows (overlapping,
    apart, the last: their intervals alone are integrated) against each one's direct sum."""
    from nlp_calib.analysis.inputs_bias import window_shares

    fns = build(get_model("diff_drive"), ProblemSpec(horizon=H, kernel="huber"))
    data = build_residual_data(fns, sim_log("diff_drive", 300, 7), ResidualOptions(horizon=H))
    ev = evaluator(fns, data, np.zeros(0), delta=0.05)
    x, sigma_in, counted = truth("diff_drive") * 1.001, np.array([0.3, 0.5]), np.array([True, False])
    _, _, weight = ev.robust_terms(x)
    D = _column_jacobian(fns, data, x)
    F = D[:, :, : fns.n_inputs * H].reshape(3, data.n_residuals, H, fns.n_inputs).transpose(1, 2, 0, 3)
    direct = np.einsum("w,c,whci,i->w", weight, ev.omega, _by_reading(F, counted, data) ** 2, sigma_in**2)
    picked = np.array([2, 3, 5, 40, 41, 120, data.n_residuals - 1])
    shares = window_shares(ev, x, weight, (sigma_in, counted), picked)
    assert_close(shares, direct[picked], rtol=1e-9)


def _moved(ev: ProblemEvaluator, x: np.ndarray, i: int, by: float) -> np.ndarray:
    return ev.boxplus(x, np.where(np.arange(x.size) == i, by, 0.0))


@pytest.mark.parametrize("model", ["tricycle", "diff_drive"])
@pytest.mark.parametrize("horizon", [1, 4])
@pytest.mark.parametrize("some", [False, True], ids=["every window", "some windows"])
def test_the_ends_sensitivity_alone_is_the_sensitivities_own(model: str, horizon: int, some: bool) -> None:
    """``∂e/∂end`` of its own Function, on the scan of values alone, is the full sensitivities'
    to the bit (the inputs' noise share takes it so), of every window or of some."""
    fns = build(get_model(model), ProblemSpec(horizon=horizon))
    data = build_residual_data(fns, sim_log(model, 150, 3), ResidualOptions(horizon=horizon))
    ev = evaluator(fns, data, np.zeros(0))
    x = truth(model) * np.random.default_rng(1).uniform(0.9, 1.1, fns.n_free)
    windows = np.array([0, 1, 7, 30, data.n_residuals - 1]) if some else None
    full = np.concatenate([s.de_dend for _, s in ev.sensitivities(x, windows)])
    alone = np.concatenate([d for _, d in ev.end_sensitivities(x, windows)])
    end_rows = 3 if fns.prefix else fns.n_inputs  # a prefix window's end pose; else its inputs
    assert full.shape == (data.n_residuals if windows is None else windows.size, 3, end_rows)
    assert np.array_equal(alone, full)


@pytest.mark.parametrize("model", ["tricycle", "diff_drive"])
def test_the_intervals_sensitivity_moves_with_the_interval_coordinates_alone(model: str) -> None:
    """``D`` changes along each kinematic coordinate and keeps every bit along the mount's."""
    m = get_model(model)
    fns = build(m, ProblemSpec(horizon=4))
    data = build_residual_data(fns, sim_log(model, 100, 4), ResidualOptions(horizon=4))
    ev = evaluator(fns, data, np.zeros(0))
    x = truth(model)
    kinematic = [i for i, n in enumerate(fns.free) if n in m.kinematic_params]
    assert fns.interval_coordinates.tolist() == kinematic
    D = ev.interval_sensitivity(x)
    for i in range(fns.n_free):
        moved = ev.interval_sensitivity(_moved(ev, x, i, 1e-3))
        assert np.array_equal(moved, D) == (i not in kinematic), fns.free[i]
    assert not build(m, ProblemSpec(horizon=1)).interval_coordinates.size


def test_prefix_jets_kept_across_a_mount_step_are_a_fresh_integrations() -> None:
    """The scans integrate again only where a kinematic coordinate moved: along a run of points
    (the mount, a kinematic coordinate, the mount again) one evaluator's normal equations and
    poses are those of a fresh evaluator at each, to the bit."""
    fns = build(get_model("tricycle"), ProblemSpec(horizon=4))
    data = build_residual_data(fns, sim_log("tricycle", 120, 5), ResidualOptions(horizon=4))
    ev = evaluator(fns, data, np.zeros(0))
    x = truth("tricycle")
    mount, kinematic = fns.free.index("sensor_theta"), fns.free.index("axis_length")
    points = [x, _moved(ev, x, mount, 0.01), _moved(ev, x, kinematic, 0.01), _moved(ev, x, mount, -0.01)]
    for p in points:
        kept, fresh = ev.normal_equations(p), evaluator(fns, data, np.zeros(0)).normal_equations(p)
        assert np.array_equal(kept.H, fresh.H) and np.array_equal(kept.g, fresh.g)
        D = evaluator(fns, data, np.zeros(0)).interval_sensitivity(p)
        assert np.array_equal(ev.interval_sensitivity(p), D)


@pytest.mark.parametrize("some", [False, True], ids=["every window", "some windows"])
def test_the_shares_at_a_run_of_points_are_each_points_own(some: bool) -> None:
    """The gradient's passes keep the ends' noise while the kinematic coordinates stay: at points
    moved along the mount, then a kinematic coordinate, then the mount again, each pass's shares
    are those of a fresh evaluation there, to the bit."""
    from nlp_calib.analysis.inputs_bias import _Shares, window_shares

    fns = build(get_model("diff_drive"), ProblemSpec(horizon=5, kernel="huber"))
    data = build_residual_data(fns, sim_log("diff_drive", 300, 8), ResidualOptions(horizon=5))
    ev = evaluator(fns, data, np.zeros(0))
    x = truth("diff_drive") * 1.001
    noise = (np.array([0.3, 0.5]), np.array([True, False]))
    _, _, weight = ev.robust_terms(x)
    windows = np.array([2, 3, 40, data.n_residuals - 1]) if some else None
    mount, kinematic = fns.free.index("sensor_x"), fns.free.index("baseline")
    points = [x, _moved(ev, x, mount, 0.01), _moved(ev, x, kinematic, 0.01), _moved(ev, x, mount, -0.01)]
    shares = _Shares(ev, weight, noise, windows)
    runs = [shares(p) for p in points]
    for p, run in zip(points, runs):
        assert np.array_equal(run, window_shares(ev, p, weight, noise, windows))
    assert not np.array_equal(runs[2], runs[3])


@pytest.mark.parametrize(
    ("counted", "delta"),
    [(None, 0.05), (np.array([True, False]), 0.05), (None, 0.003)],
    ids=["per interval", "traction counted", "noise beyond delta"],
)
def test_linear_uncertainty_equals_the_sum_over_every_window_and_interval(
    counted: np.ndarray | None, delta: float
) -> None:
    """The running-sum propagation against the direct O(N·H) sum over each window's intervals (a
    counter's noise on the readings at their ends: adjacent windows share one); the log's outliers
    beyond the kernel's δ, which the noise does not explain, add their own pull."""
    model, H = get_model("tricycle"), 6
    fns = build(model, ProblemSpec(horizon=H, kernel="huber"))
    log = sim_log("tricycle", 300, 5, outlier_fraction=0.03)
    data = build_residual_data(fns, log, ResidualOptions(horizon=H))
    ev = evaluator(fns, data, np.zeros(0), delta=delta)
    x = truth("tricycle") * 1.001
    sigma_in = np.array([2e-4, 3e-3])
    got = unc.estimate(ev, x, data, sigma_in, counted=counted)

    # Reference: derivatives of the defining residual with respect to each window's own data.
    N, n_in, n = data.n_residuals, fns.n_inputs, fns.n_free
    D = _column_jacobian(fns, data, x)
    e, J = (np.asarray(v) for v in fns.residual_jacobian.map(N)(x, [], data.columns))
    J = J.reshape(3, N, n)
    s = np.einsum("cw,c,cw->w", e, ev.omega, e)
    weight = np.minimum(1.0, ev.delta / np.sqrt(s))
    poses = data.T_world_sensor
    Da, Db = (
        np.asarray(v).reshape(3, N, 3)
        for v in fns.between_jacobians.map(N)(poses[data.starts].T, poses[data.stops].T)
    )
    de_dz = D[:, :, n_in * H : n_in * H + 3]
    Ea, Eb = np.einsum("cwk,kwl->wcl", de_dz, Da), np.einsum("cwk,kwl->wcl", de_dz, Db)
    F = D[:, :, : n_in * H].reshape(3, N, H, n_in).transpose(1, 2, 0, 3)
    F = _by_reading(F, np.zeros(n_in, dtype=bool) if counted is None else counted)
    inside = s <= ev.delta**2
    E2 = Ea**2 + Eb**2
    coef = np.concatenate([E2[:, :, :2].sum(axis=2, keepdims=True), E2[:, :, 2:3]], axis=2)
    known = np.einsum("whci,i->wc", F**2, sigma_in**2)
    # The noise's variances over the windows it explains: within δ, or within the 99.9 % point of
    # what the noise gives a window's three rows (its weighted sum of squares as χ² of
    # (Σλ)²/Σλ² degrees of freedom), repeated until that set settles.
    use = inside
    for _ in range(8):
        m = 3 * int(use.sum())
        var = unc.nnls_small(coef[use].reshape(-1, 2), (e.T[use] ** 2 - known[use]).ravel()) * (m / (m - n))
        lam = ev.omega[None, :] * (known + coef @ var)
        k = lam.sum(axis=1) ** 2 / (lam**2).sum(axis=1)
        now = inside | (s <= lam.sum(axis=1) * unc.chi2_point(k, unc.EXPLAINED_Z) / k)
        if np.array_equal(now, use):
            break
        use = now
    # The kernel's mean slope a and its pulls' mean square over the residuals' b, as the noise
    # gives each window explained (its three rows' variances λ; the expectations themselves are
    # checked against the closed form in test_uncertainty_tail.py).
    mean_s = lam.sum(axis=1)[use]
    slope, pull2 = unc.expected_kernel_terms("huber", ev.delta, mean_s, np.full(mean_s.size, 3))
    a, b = slope.mean(), float(pull2.sum() / mean_s.sum())
    unit = np.einsum("cwi,c->wic", J, ev.omega)
    L = weight[:, None, None] * unit
    La, Lb = np.einsum("wic,wcl->wil", unit, Ea), np.einsum("wic,wcl->wil", unit, Eb)
    K = np.zeros((data.n_records, n, 3))
    np.add.at(K, data.starts, La)
    np.add.at(K, data.stops, Lb)
    Q = np.zeros((data.inputs.shape[1] + 1, n, n_in))
    intervals = data.starts[:, None] + np.arange(H + 1)[None, :]
    np.add.at(Q, intervals.ravel(), np.einsum("wic,whcl->whil", L, F).reshape(-1, n, n_in))
    Sigma_pose = np.array([var[0], var[0], var[1]])
    own = np.einsum("wik,k,wjk->ij", La, Sigma_pose, La) + np.einsum("wik,k,wjk->ij", Lb, Sigma_pose, Lb)
    meat = a**2 * np.einsum("pik,k,pjk->ij", K, Sigma_pose, K) + max(b - a**2, 0.0) * own
    meat += np.einsum("jik,k,jlk->il", Q, sigma_in**2, Q)
    g_out = np.einsum("wic,cw->iw", L[~use], e[:, ~use])
    meat += g_out @ g_out.T
    bread = np.linalg.inv(ev.normal_equations(x).H)
    M = np.asarray(fns.tangent_map(x))
    expected = M @ bread @ meat @ bread @ M.T

    assert not use.all()  # the outliers' own pull is exercised
    # ... and with a small δ, windows beyond it that the noise explains (their pull at the slope).
    assert delta > 0.01 or not np.array_equal(use, inside)
    assert got.noise["tracker_xy"] == pytest.approx(np.sqrt(var[0]), rel=1e-9)
    assert_close(got.covariance, expected, rtol=1e-7, atol=1e-9 * np.abs(expected).max())


def test_faulty_intervals_and_records_drop_their_windows() -> None:
    fns = build(get_model("tricycle"), ProblemSpec(horizon=4))
    log = sim_log("tricycle", 60, 6)
    bad_intervals = np.zeros(59, dtype=bool)
    bad_intervals[20] = True
    bad_records = np.zeros(60, dtype=bool)
    bad_records[40] = True
    data = build_residual_data(
        fns, log, ResidualOptions(horizon=4), bad_intervals=bad_intervals, bad_records=bad_records
    )
    spoiled = [s for s in range(56) if s <= 20 < s + 4 or s in (40, 36)]
    assert data.dropped_faulty == len(spoiled) == 6
    assert sorted(set(range(56)) - set(data.starts.tolist())) == spoiled


def test_over_columns_in_bound_buffers_gives_what_a_casadi_map_gives(monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks evaluated in buffers bound to numpy memory (a shared column, two outputs, a short
    last block) against one CasADi map over every column."""

    from nlp_calib.problem import windows

    p, u = ca.SX.sym("p", 2), ca.SX.sym("u", 3)
    f = ca.Function(
        "f", [p, u], [ca.vertcat(p[0] * u[0] + u[1], ca.sin(u[2]) * p[1]), ca.cross(u, ca.vertcat(p, 1.0)).T]
    )
    rng = np.random.default_rng(0)
    params, cols = rng.normal(size=2), rng.normal(size=(3, 1000))
    monkeypatch.setattr(windows, "BLOCK", 96)
    got = windows.over_columns(f, params, cols)
    want = f.map(1000)(params, cols)
    assert len(got) == 2
    for g, w in zip(got, want):
        assert np.array_equal(g, np.asarray(w))


def test_over_columns_interprets_by_maps_of_fixed_sizes_with_the_bits_of_one_map(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Interpreted, any number of columns is evaluated by maps of the fixed sizes alone (each built
    once, whatever the count), giving what one CasADi map over every column gives, bit for bit."""
    from nlp_calib.problem import windows

    p, u = ca.SX.sym("p", 2), ca.SX.sym("u", 3)
    f = ca.Function("f", [p, u], [ca.vertcat(p[0] * u[0] + u[1], ca.sin(u[2]) * p[1]), u * p[1]])
    built: list[int] = []
    mapped = windows._mapped

    def recording(fn: ca.Function, n: int) -> ca.Function:
        built.append(n)
        return mapped(fn, n)

    monkeypatch.setattr(windows, "_mapped", recording)
    rng = np.random.default_rng(4)
    params = rng.normal(size=2)
    for n in (531, 300, 17):
        cols = rng.normal(size=(3, n))
        got = windows.over_columns(f, params, cols)
        for g, w in zip(got, f.map(n)(params, cols)):
            assert np.array_equal(g, np.asarray(w))
    assert set(built) <= set(PIECE_SIZES)


def test_over_columns_with_an_empty_shared_column() -> None:
    """A shared input with no rows (a model without free parameters of a kind) fills nothing."""
    from nlp_calib.problem import windows

    p, u = ca.SX.sym("p", 0), ca.SX.sym("u", 2)
    f = ca.Function("f", [p, u], [u[0] * u[1]])
    cols = np.random.default_rng(1).normal(size=(2, 300))
    (got,) = windows.over_columns(f, np.zeros(0), cols)
    assert np.array_equal(got[0], cols[0] * cols[1])


def test_the_weighted_gram_by_blocks_is_the_one_product(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    A, w = rng.normal(size=(1001, 5, 3)), rng.uniform(0.1, 2.0, 3)
    want = np.einsum("pik,k,pjk->ij", A, w, A)
    monkeypatch.setattr(unc, "STEP", 64)
    np.testing.assert_allclose(unc._weighted_gram(A, w), want, rtol=1e-12)
    np.testing.assert_array_equal(unc._weighted_gram(A[:0], w), np.zeros((5, 5)))


@pytest.mark.parametrize("counted", [None, np.array([True, False])], ids=["per interval", "traction counted"])
def test_uncertainty_summed_block_by_block_is_the_one_sum(
    monkeypatch: pytest.MonkeyPatch, counted: np.ndarray | None
) -> None:
    """The noise maps summed a few rows at a time, as windows arrive a block at a time (rows let go
    of once no later window adds to them), give the covariance of one sum over every row."""
    from nlp_calib.solvers import blocks

    model, H = get_model("tricycle"), 5
    fns = build(model, ProblemSpec(horizon=H, kernel="huber"))
    log = sim_log("tricycle", 400, 6, outlier_fraction=0.03)
    data = build_residual_data(fns, log, ResidualOptions(horizon=H))
    x, sigma_in = truth("tricycle") * 1.001, np.array([2e-4, 3e-3])
    want = unc.estimate(evaluator(fns, data, np.zeros(0)), x, data, sigma_in, counted=counted)
    monkeypatch.setattr(unc, "STEP", 16)
    monkeypatch.setattr(blocks, "BLOCK", 64)
    got = unc.estimate(evaluator(fns, data, np.zeros(0)), x, data, sigma_in, counted=counted)
    assert_close(got.covariance, want.covariance, rtol=1e-10, what="covariance")
    assert got.noise == pytest.approx(want.noise, rel=1e-10)


@pytest.mark.parametrize("counted", [None, np.array([True, False])], ids=["per interval", "traction counted"])
def test_uncertainty_of_windows_spread_over_the_log_summed_stretch_by_stretch(
    monkeypatch: pytest.MonkeyPatch, counted: np.ndarray | None
) -> None:
    """Issue 41: windows spread over a log (the pre-flight judges such a subsample) leave most rows
    of the noise maps empty: summed only where something is, stretch by stretch from the running
    sums, the covariance is the row-by-row sum's (with blocks and steps small enough to release
    rows many times), a counter's noise on its readings too."""
    from nlp_calib.solvers import blocks

    model, H = get_model("tricycle"), 5
    fns = build(model, ProblemSpec(horizon=H, kernel="huber"))
    log = sim_log("tricycle", 1200, 6, outlier_fraction=0.03)
    whole = build_residual_data(fns, log, ResidualOptions(horizon=H))
    data = whole.select(np.arange(0, whole.n_residuals, 23))
    # A coarse counter (its readings' noise 5e-2): the terms of the readings inside a stretch are
    # then well above the comparison's 1e-10 (leaving them out changes the covariance by 4e-8).
    x = truth("tricycle") * 1.001
    sigma_in = np.array([2e-4 if counted is None else 5e-2, 3e-3])
    monkeypatch.setattr(unc, "STEP", 64)
    monkeypatch.setattr(blocks, "BLOCK", 16)
    monkeypatch.setattr(unc, "SPARSE", 10**9)  # never: every row summed
    want = unc.estimate(evaluator(fns, data, np.zeros(0)), x, data, sigma_in, counted=counted)
    monkeypatch.setattr(unc, "SPARSE", 2)
    got = unc.estimate(evaluator(fns, data, np.zeros(0)), x, data, sigma_in, counted=counted)
    assert np.all(np.isfinite(want.covariance)) and np.any(want.covariance != 0)
    assert_close(got.covariance, want.covariance, rtol=1e-10, what="covariance")
    assert got.noise == pytest.approx(want.noise, rel=1e-10)


def test_the_end_noise_held_a_few_blocks_at_a_time_is_the_direct_sum(monkeypatch: pytest.MonkeyPatch) -> None:
    """The input noise at each window's end, from running sums kept a few blocks at a time (asked
    in any order, blocks let go of and summed again), is the sum written out interval by interval
    and reading by reading."""
    rng = np.random.default_rng(7)
    n, m = 203, 3
    D = rng.normal(size=(n, m, 2))
    own, reading = np.array([4e-4, 0.0]), np.array([0.0, 9e-3])
    a = rng.integers(0, n - 1, 300)
    b = np.minimum(a + rng.integers(1, 40, a.size), n)

    def direct(lo: int, hi: int) -> np.ndarray:
        total = sum((D[j] * own) @ D[j].T for j in range(lo, hi))
        # A counter's readings: the first and last interval's, and each step between two inside.
        total = total + (D[lo] * reading) @ D[lo].T + (D[hi - 1] * reading) @ D[hi - 1].T
        for r in range(lo + 1, hi):
            d = D[r - 1] - D[r]
            total = total + (d * reading) @ d.T
        return np.asarray(total)

    monkeypatch.setattr(unc, "STEP", 8)
    monkeypatch.setattr(unc._Prefix, "KEPT", 2)
    ends = unc.EndNoise(D, (own, reading))
    got = ends.between(a, b)
    want = np.stack([direct(int(lo), int(hi)) for lo, hi in zip(a, b)])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-14)
    assert len(ends.own.kept) <= 2
    # Without a counter's readings: the intervals' own noise alone.
    alone = unc.EndNoise(D, (own, np.zeros(2))).between(a, b)
    own_only = np.stack([sum((D[j] * own) @ D[j].T for j in range(lo, hi)) for lo, hi in zip(a, b)])
    np.testing.assert_allclose(alone, own_only, rtol=1e-9, atol=1e-14)
