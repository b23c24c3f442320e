"""Gauss-Newton and IPOPT: status, final cost, agreement with each other, recovery of truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import SCENARIOS, assert_close

from nlp_calib.pipeline import Calibration
from nlp_calib.pipeline.scenario import FaultOptions, RobustOptions, Scenario, load_scenario
from nlp_calib.pipeline.truth import read_truth
from nlp_calib.problem import ResidualOptions
from nlp_calib.solvers import IpoptOptions
from nlp_calib.solvers.ipopt import Ipopt

TRUTH_TOL = {  # absolute tolerances on a noiseless log
    "k_steer": 1e-3,
    "k_traction": 1e-6,
    "axis_length": 1e-3,
    "steer_offset": 5e-4,
    "sensor_x": 5e-4,
    "sensor_y": 5e-4,
    "sensor_theta": 5e-4,
    # The log has no latency; fitted by default, the lag takes up the first-order clock correction
    # and the steering's interpolation: a quarter of the 2 ms a calibration needs at 1 m/s.
    "tracker_lag": 5e-4,
}


def agree(a, b, params_rtol: float = 1e-4, cost_rtol: float = 1e-6) -> None:  # type: ignore[no-untyped-def]
    assert a.converged, a.reason
    assert b.converged, b.reason
    assert_close(a.params, b.params, rtol=params_rtol, atol=1e-8, what="parameters")
    assert abs(a.cost - b.cost) <= cost_rtol * abs(b.cost), (a.cost, b.cost)


@pytest.fixture(scope="module")
def real_calibration(real_log: Path) -> Calibration:
    return Calibration.setup(load_scenario(SCENARIOS / "real_tricycle.yaml"), data=real_log)


@pytest.mark.slow
def test_real_log_solvers_agree(real_calibration: Calibration) -> None:
    gn = real_calibration.solve("gauss_newton")
    ip = real_calibration.solve("ipopt")
    agree(gn, ip)
    assert ip.trace.stats["return_status"] == "Solve_Succeeded"
    # The fit reduces the cost from the header's guess by more than an order of magnitude.
    assert gn.cost < 0.1 * real_calibration.evaluator.cost(real_calibration.x0)
    assert gn.trace.history[-1].cost == pytest.approx(gn.cost)


def test_single_step_seed_formulation_converges_from_header_guess(real_log: Path) -> None:
    sc = load_scenario(SCENARIOS / "real_tricycle.yaml")
    sc = sc.with_options(residual=ResidualOptions(horizon=1, integration="euler"))
    calib = Calibration.setup(sc, data=real_log)
    agree(calib.solve("gauss_newton"), calib.solve("ipopt"))


@pytest.mark.parametrize("kernel", ["none", "huber", "cauchy", "pseudo_huber"])
def test_solvers_agree_for_every_kernel(small_demo: Scenario, kernel: str) -> None:
    sc = small_demo.with_options(robust=RobustOptions(kernel=kernel, delta=0.03))
    calib = Calibration.setup(sc)
    agree(calib.solve("gauss_newton"), calib.solve("ipopt"))


@pytest.mark.parametrize("kernel", ["none", "huber", "cauchy", "pseudo_huber"])
def test_ipopt_gauss_newton_hessian_reaches_the_exact_hessians_optimum(
    small_demo: Scenario, kernel: str
) -> None:
    """IPOPT's default Hessian is Gauss-Newton's (no second-order prefix jets to integrate or
    compile); it meets the optimum of the exact Hessian, which stays an option, to 1e-8 of each
    parameter (measured: 1e-12 free, 1e-10 at a bound) for every kernel."""
    assert IpoptOptions().hessian == "gauss_newton"
    sc = small_demo.with_options(robust=RobustOptions(kernel=kernel, delta=0.03))
    calib = Calibration.setup(sc)
    start = calib.fitting.problem.start
    lower = np.full(start.x0.size, -np.inf) if start.lower is None else start.lower.copy()
    upper = np.full(start.x0.size, np.inf) if start.upper is None else start.upper.copy()
    axis = calib.fns.free.index("axis_length")
    for bounded in (False, True):
        exact = Ipopt(calib.evaluator, IpoptOptions(hessian="exact")).solve(start.x0, lower, upper)
        default = Ipopt(calib.evaluator).solve(start.x0, lower, upper)
        agree(exact, default, params_rtol=1e-8, cost_rtol=1e-10)
        if bounded:
            assert default.x[axis] == pytest.approx(upper[axis], abs=1e-7)
        # The second round with this bound active (and its mirror image out of reach).
        lower[axis], upper[axis] = 1.0, abs(exact.x[axis]) - 0.05


def test_lifted_huber_reaches_the_direct_optimum(small_demo: Scenario) -> None:
    # The tracker outliers are kept in the fit (not left out as faults) so the kernel meets them.
    sc = small_demo.with_options(
        robust=RobustOptions(kernel="huber", delta=0.02), faults=FaultOptions(handling="keep")
    )
    direct = Calibration.setup(sc).solve("ipopt")
    lifted_sc = sc.with_solver_options("ipopt", IpoptOptions(huber_formulation="lifted"))
    lifted = Calibration.setup(lifted_sc).solve("ipopt")
    assert lifted.trace.stats["formulation"] == "lifted"
    agree(direct, lifted, params_rtol=1e-6, cost_rtol=1e-9)
    assert direct.inliers < direct.n_residuals  # the threshold is active, so the test means something


def test_active_bound_is_respected_by_ipopt(small_demo: Scenario) -> None:
    free = Calibration.setup(small_demo).solve("ipopt")
    hi = free.param_dict()["axis_length"] - 0.05
    sc = small_demo.with_options(bounds={"axis_length": (1.0, hi)})
    bounded = Calibration.setup(sc).solve("ipopt")
    assert bounded.converged
    assert bounded.param_dict()["axis_length"] == pytest.approx(hi, abs=1e-7)
    assert bounded.cost > free.cost


@pytest.mark.parametrize("integration", ["exact", "euler"])
def test_recovers_truth_from_noiseless_log(noiseless_log: Path, integration: str) -> None:
    sc = Scenario.of(
        name="noiseless",
        dataset=noiseless_log,
        robust=RobustOptions(kernel="none"),
        residual=ResidualOptions(horizon=1, integration=integration, steering_sample="mean"),
    )
    truth = read_truth(noiseless_log)
    assert truth is not None
    calib = Calibration.setup(sc)
    for solver in ("gauss_newton", "ipopt"):
        res = calib.solve(solver)
        assert res.converged, res.reason
        for name, value in res.param_dict().items():
            # Euler integration carries a first-order model error of its own (its lateral step is
            # zero), which shifts the estimate by a few millimetres even without noise.
            tol = TRUTH_TOL[name] * (1 if integration == "exact" else 10)
            assert abs(value - truth[name]) <= tol, (
                f"{solver} {integration}: {name} = {value}, truth {truth[name]}"
            )


def test_gauss_newton_reports_nan_instead_of_a_result(small_demo: Scenario) -> None:
    sc = small_demo.with_options(initial_guess={"axis_length": 0.0})
    res = Calibration.setup(sc).solve("gauss_newton")
    assert not res.converged
    assert "NaN" in res.reason


def test_iteration_limit_is_not_convergence(small_demo: Scenario) -> None:
    from nlp_calib.solvers import GaussNewtonOptions

    sc = small_demo.with_solver_options("gauss_newton", GaussNewtonOptions(max_iterations=1))
    res = Calibration.setup(sc).solve("gauss_newton")
    assert not res.converged
    assert "iteration limit" in res.reason
    assert np.isfinite(res.cost)


def test_ipopt_takes_steps_below_rounding_without_a_line_search(small_demo: Scenario) -> None:
    """At the optimum a correct Newton step lowers the cost by less than its rounding: IPOPT is
    told to take steps below √ε without a line search (the real log's iterations went from 8 to
    18 with a lag 0.06 ms away), and lands where Gauss-Newton does; a scenario may override it."""
    from nlp_calib.solvers.ipopt import TINY_STEP_TOL, Ipopt

    calib = Calibration(small_demo)
    ipopt = Ipopt(calib.evaluator, IpoptOptions())
    assert ipopt._ipopt_options()["ipopt.tiny_step_tol"] == TINY_STEP_TOL == np.sqrt(np.finfo(float).eps)
    own = Ipopt(calib.evaluator, IpoptOptions(options={"tiny_step_tol": 1e-12}))
    assert own._ipopt_options()["ipopt.tiny_step_tol"] == 1e-12
    ip, gn = calib.solve("ipopt"), calib.solve("gauss_newton")
    assert ip.converged and gn.converged
    # Each relative to its value; the time offset (near 0) to its search's width.
    scale = np.maximum(np.abs(gn.x), 1e-3)
    scale[[n == "tracker_lag" for n in gn.names]] = np.ptp(small_demo.log.alignment.search)
    assert np.max(np.abs(ip.x - gn.x) / scale) < 1e-6


def test_a_released_evaluator_binds_again_with_the_same_results(small_demo: Scenario) -> None:
    """Letting go of the windows' buffers (a large fit's, while its refits run) changes nothing:
    evaluated again at another point, it gives what an evaluator never released gives there."""
    cal = Calibration(small_demo)
    ev, twin, x = cal.evaluator, Calibration(small_demo).evaluator, cal.x0
    ev.normal_equations(x), ev.cost(x), ev.robust_terms(x)
    ev.release()
    assert ev.data.n_residuals == ev.n_residuals > 0
    y = x * (1.0 + 1e-3)
    after, before = (
        (e.normal_equations(y), e.cost(y), [np.array(v) for v in e.robust_terms(y)]) for e in (ev, twin)
    )
    assert np.array_equal(before[0].H, after[0].H) and before[0].cost == after[0].cost
    assert before[1] == after[1]
    assert all(np.array_equal(a, b) for a, b in zip(before[2], after[2]))


def _counted(ev):  # type: ignore[no-untyped-def]
    """``ev`` with its evaluations of each per-window Function counted (``ev.calls``)."""
    calls: dict[str, int] = {}
    evaluate = ev._call

    def call(name, x):  # type: ignore[no-untyped-def]
        calls[name] = calls.get(name, 0) + 1
        return evaluate(name, x)

    ev._call, ev.calls = call, calls
    return ev


def test_an_evaluator_keeps_what_it_evaluated_at_recent_points_to_the_bit(small_demo: Scenario) -> None:
    """Both solvers start at one point and the analyses evaluate the estimate again: a point's
    normal equations and cost come back from the last points' without an evaluation, the same
    bits as an evaluator that never saw the point evaluates; the residual terms of the last point
    only while their buffers are bound; normal equations told at a point hold until the next
    evaluation (as the one point kept before did)."""
    cal = Calibration(small_demo)
    ev, twin, x = _counted(cal.evaluator), Calibration(small_demo).evaluator, cal.x0
    first = ev.normal_equations(x), ev.cost(x), [np.array(v) for v in ev.robust_terms(x)]
    for k in range(1, 9):  # a solver's iterations in between
        ev.normal_equations(x * (1.0 + 1e-4 * k)), ev.cost(x * (1.0 - 1e-4 * k))
    assert ev.calls == {"normal_equations": 9, "cost": 9, "robust_terms": 1}
    again = ev.normal_equations(x), ev.cost(x), ev.robust_terms(x)
    assert ev.calls == {"normal_equations": 9, "cost": 9, "robust_terms": 1}
    fresh = twin.normal_equations(x), twin.cost(x), twin.robust_terms(x)
    assert again[0] is first[0] and np.array_equal(again[0].H, fresh[0].H)
    assert again[0].g.tobytes() == fresh[0].g.tobytes() and again[1] == fresh[1] == first[1]
    assert all(np.array_equal(a, b) and np.array_equal(b, c) for a, b, c in zip(again[2], fresh[2], first[2]))
    ev.robust_terms(x * (1.0 + 1e-4))
    ev.robust_terms(x)
    assert ev.calls["robust_terms"] == 3  # the last point's alone
    ev.release()  # the residual terms are views of the buffers let go of: evaluated again
    assert all(np.array_equal(a, b) for a, b in zip(ev.robust_terms(x), first[2]))
    assert ev.calls["robust_terms"] == 4
    told = first[0].less(first[0])
    ev.remember(x, told)
    assert ev.normal_equations(x) is told and ev.calls["normal_equations"] == 9
    ev.normal_equations(x * 1.01)
    assert ev.normal_equations(x) is first[0] and ev.calls["normal_equations"] == 10
    ev.set_inputs(ev.data.inputs * 1.001)  # other inputs: nothing kept holds
    ev.normal_equations(x), ev.cost(x)
    assert ev.calls["normal_equations"] == 11 and ev.calls["cost"] == 10


def _twin(ev, **changed):  # type: ignore[no-untyped-def]
    """A new evaluator of ``ev``'s windows and settings (``changed``: some of them other)."""
    from nlp_calib.solvers.evaluation import ProblemEvaluator

    given = {"x_fixed": ev.x_fixed, "omega": ev.omega, "delta": ev.delta, "priors": ev.priors}
    return ProblemEvaluator(ev.fns, ev.data, backend=ev.backend, **{**given, **changed})


def test_a_gauss_newton_run_recalls_what_a_run_on_the_same_windows_evaluated_to_the_bit(
    small_demo: Scenario,
) -> None:
    """The screen's judging fit, the pre-flight's and the fit stage's start from one point on the
    same windows, each on its own evaluator: a run on an evaluator of the same contents takes the
    normal equations a recent run evaluated (no pass over the windows) and ends, its evaluator
    keeping the same points, where a run that evaluates every one ends, to the bit; on other
    contents (other weights) it evaluates its own."""
    from nlp_calib.solvers.gauss_newton import GaussNewton, solve

    cal = Calibration(small_demo)
    ev, x0 = cal.evaluator, cal.x0
    former = solve(_twin(ev), x0)  # the module's loop alone: nothing recalled, nothing kept for later
    first = GaussNewton(ev).solve(x0)
    twin = _counted(_twin(ev))
    again = GaussNewton(twin).solve(x0)
    assert former.converged and twin.calls == {}
    for res in (first, again):
        assert res.x.tobytes() == former.x.tobytes() and res.cost == former.cost
        assert res.trace.history == former.trace.history
    twin.normal_equations(x0), twin.normal_equations(again.x)  # kept as if evaluated here
    assert twin.calls == {}
    other = _counted(_twin(ev, omega=ev.omega * 2.0))
    weighed = GaussNewton(other).solve(x0)
    plain = _counted(_twin(ev, omega=ev.omega * 2.0))
    assert weighed.x.tobytes() == solve(plain, x0).x.tobytes()
    assert other.calls["normal_equations"] == plain.calls["normal_equations"] > 0


def test_ipopt_takes_its_cost_and_gradient_at_a_point_from_one_pass(small_demo: Scenario) -> None:
    """IPOPT asks for the cost at a trial point and, accepting it, for the gradient there: with the
    Gauss-Newton Hessian the normal equations answer both, so no cost-only pass is made but the
    start's check (a cost pass and a normal-equations pass per iteration before)."""
    cal = Calibration(small_demo)
    ev = _counted(cal.evaluator)
    res = cal.fitting.solver("ipopt").solve(cal.x0, cal.start.lower, cal.start.upper)
    assert res.converged and res.trace.iterations >= 3
    assert ev.calls.get("cost", 0) == 1
    # Every point IPOPT asked for once: its start's and one per accepted or rejected trial.
    assert ev.calls["normal_equations"] <= len(res.trace.history) + 1
    # The result's cost is the normal equations' at its estimate, as an evaluator that never saw
    # IPOPT's points gives it.
    assert res.cost == Calibration(small_demo).evaluator.normal_equations(res.x).cost


def test_the_estimate_is_evaluated_where_it_is_reported_and_the_analyses_evaluate_it_once(
    small_demo: Scenario,
) -> None:
    """A solver's estimate moved by the inputs' bias step is reported in the canonical form (an
    angle wrapped moves its last bits): its cost is the normal equations' there, which the
    observability, the uncertainty and the plan then take without a pass over the windows but
    the residual terms' one; the plan's residual variance is the observability's, after the
    uncertainty let the residual terms' buffers go."""
    from nlp_calib.analysis.observability import analyse
    from nlp_calib.pipeline.analyse import plan_setting, uncertainties

    cal = Calibration(small_demo)
    fit, twin = cal.fitting, Calibration(small_demo).evaluator
    res = fit.solve("gauss_newton")
    assert res.converged and fit.bias_taken()
    fresh = twin.normal_equations(res.x)
    assert (res.cost, res.chi2, res.inliers) == (fresh.cost, fresh.chi2, fresh.inliers)
    ev = _counted(fit.evaluator)
    analyse(ev, res.x, cal.data.T_world_sensor)
    uncertainties(fit, {"gauss_newton": res}, fit.noise, None)  # type: ignore[arg-type]
    setting = plan_setting(fit, {"gauss_newton": res}, {})
    assert setting is not None
    assert ev.calls.get("normal_equations", 0) == 0 and ev.calls["robust_terms"] == 1
    _, s, weight = twin.robust_terms(res.x)
    dof = fit.fns.error_rows * twin.n_residuals - fit.fns.n_free
    assert setting.sigma2 == float(np.sum(weight * s)) / dof


class _HuberLocation:
    """A location's Huber M-estimate (δ = 1) from 20 readings near 0 and 60 far off: most residuals
    past the kernel's threshold, where the reweighted normal equations lack the curvature of the
    weights, so plain Gauss-Newton steps approach the optimum linearly."""

    def __init__(self) -> None:
        rng = np.random.default_rng(0)
        self.y = np.r_[rng.normal(0.0, 0.3, 20), rng.uniform(3.0, 30.0, 60)]
        self.fns = type("Fns", (), {"names": ("x",)})()
        self.n_residuals = self.y.size

    def normal_equations(self, x: np.ndarray):  # type: ignore[no-untyped-def]
        from nlp_calib.solvers.evaluation import NormalEquations

        r = x[0] - self.y
        s = r**2
        w = np.where(s <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(s, 1e-300)))
        cost = float(np.sum(np.where(s <= 1.0, s, 2.0 * np.sqrt(s) - 1.0)))
        return NormalEquations(np.array([[np.sum(w)]]), np.array([np.sum(w * r)]), cost, float(s.sum()), 0)

    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        return x + dx

    def params(self, x: np.ndarray) -> np.ndarray:
        return x


def test_gauss_newton_reaches_a_robust_optimum_its_reweighting_approaches_linearly() -> None:
    """Undamped steps along one direction, each a steady share of the last: the rest of their
    geometric series is taken at once (without it the steps' predicted decrease fell under the
    tolerance 2e-6 short of the optimum, after 38 iterations)."""
    from nlp_calib.solvers.gauss_newton import GaussNewtonOptions, solve

    problem = _HuberLocation()
    res = solve(problem, np.array([0.0]), GaussNewtonOptions(max_iterations=30))  # type: ignore[arg-type]
    # The M-estimate independently: the root of Σ clip(x − y, −1, 1), bisected.
    lo, hi = -5.0, 30.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if np.sum(np.clip(mid - problem.y, -1.0, 1.0)) < 0 else (lo, mid)
    assert res.converged, res.reason
    assert abs(res.x[0] - lo) < 1e-9, (res.x[0], lo)


def test_a_buffer_binds_caller_memory_and_refuses_an_array_it_would_have_to_copy() -> None:
    import casadi as ca

    from nlp_calib.solvers.backends import Buffered

    u = ca.SX.sym("u", 2, 3)
    buf = Buffered(ca.Function("f", [u], [2 * u], ["u"], ["y"]))
    states = np.zeros((2, 10), order="F")
    inputs = np.asfortranarray(np.arange(20.0).reshape(2, 10))
    buf.rebind("u", inputs[:, 4:7])
    buf.rebind_output("y", states[:, 1:4])
    buf.evaluate()
    assert np.array_equal(states[:, 1:4], 2 * inputs[:, 4:7])  # written into the caller's array
    assert not states[:, 4:].any() and not states[:, 0].any()
    for wrong in (np.ascontiguousarray(inputs)[:, 4:7], inputs[:, 4:6], inputs[:, 4:7].astype(np.float32)):
        with pytest.raises(ValueError, match="cannot bind"):
            buf.rebind("u", wrong)
    with pytest.raises(KeyError):
        buf.rebind("v", inputs[:, 4:7])


def test_the_interpreters_unsummed_maps_have_fixed_sizes_and_the_bits_of_one_map(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Per-column outputs (the analyses' Functions below the compiled size) are evaluated by maps
    of the interpreter's fixed sizes alone, built once whatever the window count, giving what one
    map over every column gives, bit for bit; a summed map stays one map (its order of sums)."""
    import casadi as ca

    from nlp_calib.solvers import blocks
    from nlp_calib.solvers.backends.base import INTERPRETED, UNSUMMED_SIZES

    p, u = ca.SX.sym("p", 2), ca.SX.sym("u", 3)
    f = ca.Function(
        "f", [p, u], [ca.vertcat(p[0] * u[0] + u[1], ca.sin(u[2]) * p[1]), u * p[1]], ["p", "u"], ["a", "b"]
    )
    built: list[tuple[int, bool]] = []
    mapped = blocks._mapped

    def recording(
        backend: object, fn: ca.Function, n: int, names: tuple[str, ...], reduce: bool
    ) -> ca.Function:
        built.append((n, reduce))
        return mapped(backend, fn, n, names, reduce)  # type: ignore[arg-type]

    monkeypatch.setattr(blocks, "_mapped", recording)
    rng = np.random.default_rng(8)
    params = rng.normal(size=2)
    for n in (531, 300):
        cols = np.asfortranarray(rng.normal(size=(3, n)))
        want = [np.asarray(w) for w in f.map(n)(params, cols)]
        got = blocks.BlockMap(INTERPRETED, f, {"u": cols}, {"p": params}, reduce=False)(p=params)
        assert all(np.array_equal(g, w) for g, w in zip(got, want))
        ((_, streamed),) = list(blocks.stream(INTERPRETED, f, {"u": cols}, {"p": params}))
        assert all(np.array_equal(g, w) for g, w in zip(streamed, want))
        summed = blocks.BlockMap(INTERPRETED, f, {"u": cols}, {"p": params}, reduce=True)(p=params)
        assert all(
            np.array_equal(np.ravel(g), np.ravel(w))
            for g, w in zip(summed, f.map("whole", "serial", n, [0], [0, 1])(params, cols))
        )
    assert {n for n, reduce in built if not reduce} <= set(UNSUMMED_SIZES)
    assert {n for n, reduce in built if reduce} == {531, 300}
