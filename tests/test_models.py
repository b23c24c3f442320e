"""One suite, every kinematic model: Jacobians, solver agreement, C export, recovery, odometry
covariance, symmetries and the data-driven start."""

from __future__ import annotations

import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from conftest import SCENARIOS, assert_close, boxplus_numpy, parse_lines

from nlp_calib.analysis.odometry import propagate
from nlp_calib.codegen.compiler import find_compiler
from nlp_calib.codegen.export import Example, build_for_export, export_functions, generate
from nlp_calib.core.numeric import wrap_angle
from nlp_calib.logs import Log
from nlp_calib.models import MODELS, canonical, get_model, param_names
from nlp_calib.pipeline import Calibration
from nlp_calib.pipeline.scenario import RobustOptions, Scenario
from nlp_calib.problem import ProblemSpec, ResidualOptions, build, build_residual_data
from nlp_calib.simulation import SimulationOptions, simulate

ALL_MODELS = sorted(MODELS)
# Stated tolerances, per parameter kind: gains 1 % (tricycle steering 2 %), lengths 2 %,
# steering offset 0.01 rad, sensor position 2 cm, sensor angle 0.01 rad.
RELATIVE = {
    "k_traction": 0.01,
    "k_left": 0.01,
    "k_right": 0.01,
    "k_steer": 0.02,
    "axis_length": 0.02,
    "baseline": 0.02,
    "wheelbase": 0.02,
    "steering_track": 0.02,
}
ABSOLUTE = {
    "steer_offset": 0.01,
    "k_steer_reverse": 0.01,
    "turn_slip": 0.02,
    "sensor_x": 0.02,
    "sensor_y": 0.02,
    "sensor_theta": 0.01,
}
# A car's rear track enters its odometry only through the correction of the wheels' travel in
# turns (a second-order effect, see models/car_like.py): 3σ on this drive is about 10 cm.
ABSOLUTE["rear_track"] = 0.1
# A car steers by tan φ: its steering gain and wheelbase part only through tan's curvature, to about
# 2 % each on this drive (their ratio to 0.1 %); 3σ of that.
_CAR = {"k_steer": 0.06, "wheelbase": 0.06}
PER_MODEL = {"car_like": _CAR, "car_like_ackermann": _CAR, "car_like_bicycle": _CAR}


def tolerance(model: str, name: str, true: float) -> float:
    """The stated tolerance of parameter ``name`` of ``model`` at its true value."""
    relative = {**RELATIVE, **PER_MODEL.get(model, {})}
    return relative[name] * abs(true) if name in relative else ABSOLUTE[name]


def truth(model: str) -> np.ndarray:
    m = get_model(model)
    return np.array([m.drive.default_truth[n] for n in param_names(m)])


def sim_log(model: str, **kwargs: object) -> Log:
    opts = {"records": 1000, "seed": 3, **kwargs}
    return parse_lines(
        simulate(SimulationOptions.of(model=model, **opts)).text().splitlines(), f"sim-{model}"
    )  # type: ignore[arg-type]


def scenario(model: str, **changes: object) -> Scenario:
    base = Scenario.of(
        name=model,
        dataset=Path("sim"),
        model=model,
        robust=RobustOptions("huber", 0.05),
        residual=ResidualOptions(horizon=5, steering_sample="mean"),
    )
    return base.with_options(**changes)  # type: ignore[arg-type]


@pytest.mark.parametrize("model", ALL_MODELS)
def test_manifold_jacobian_matches_central_differences(model: str) -> None:
    m = get_model(model)
    fns = build(m, ProblemSpec(horizon=4))
    # The steering held from each interval's start: these windows' values (the Jacobian's
    # function does not depend on where its inputs were read).
    options = ResidualOptions(horizon=4, steering_sample="start")
    columns = build_residual_data(fns, sim_log(model, records=600), options).columns
    rng = np.random.default_rng(1)
    n_in = len(m.input_names)
    intervals = columns[: 4 * n_in].reshape(n_in, -1, order="F")  # interval after interval
    moving = m.moving(intervals).reshape(-1, 4).all(axis=1)
    backwards = (m.travel_direction(intervals).reshape(-1, 4) < 0).any(axis=1)
    # Windows driving forward and windows reversing: a model may treat the two differently.
    picks = [rng.choice(np.flatnonzero(moving & sel), 8, replace=False) for sel in (~backwards, backwards)]
    # The Ackermann car's steering track moves the residual only at second order (its column is
    # below the finite differences' rounding): the model always holds it, no fit has its column.
    fitted = [i for i, n in enumerate(param_names(m)) if n != "steering_track"]
    for k in np.concatenate(picks):
        x = truth(model) * rng.uniform(0.8, 1.2, truth(model).size)
        data = columns[:, k]
        _, J = (np.asarray(v) for v in fns.residual_jacobian(x, [], data))
        J, J_fd = J[:, fitted], np.zeros_like(J)
        for i in fitted:
            d = np.zeros(x.size)
            d[i] = 1e-4 * max(abs(x[i]), 1e-3)

            def e(step: np.ndarray, x: np.ndarray = x, data: np.ndarray = data) -> np.ndarray:
                return np.asarray(fns.residual(boxplus_numpy(x, step), [], data)).ravel()

            # Five-point central stencil: truncation O(h⁴), so h can stay clear of round-off.
            J_fd[:, i] = (-e(2 * d) + 8 * e(d) - 8 * e(-d) + e(-2 * d)) / (12 * d[i])
        J_fd = J_fd[:, fitted]
        # Per column: the parameters' scales differ by orders of magnitude (metres per tick).
        col = np.abs(J).max(axis=0)
        # A column that is exactly zero here (a parameter this window does not touch) is compared
        # absolutely, far below any entry that is not: finite differences leave round-off there.
        scale = np.maximum(np.abs(J), np.maximum(np.maximum(1e-3 * col, 1e-9 * col.max()), 1e-7))
        assert (np.abs(J - J_fd) / scale).max() <= 1e-6


@pytest.mark.parametrize("model", ALL_MODELS)
def test_solvers_agree_and_recover_truth(model: str) -> None:
    calib = Calibration(scenario(model), log=sim_log(model, records=1500, outlier_fraction=0.01))
    gn, ip = calib.solve("gauss_newton"), calib.solve("ipopt")
    for res in (gn, ip):
        assert res.converged, res.reason
    assert_close(gn.params, ip.params, rtol=1e-4, atol=1e-10)
    assert gn.cost == pytest.approx(ip.cost, rel=1e-6)
    for name, value, true in zip(gn.names, gn.params, truth(model)):
        assert abs(value - true) <= tolerance(model, name, true), f"{model} {name}: {value} vs {true}"


@pytest.mark.parametrize("model", ALL_MODELS)
def test_auto_start_needs_no_guess(model: str) -> None:
    wild = {n: 1.0 for n in get_model(model).drive.default_truth}
    calib = Calibration(scenario(model, initial_guess="auto"), log=sim_log(model, records=1500, guess=wild))
    res = calib.solve("gauss_newton")
    assert res.converged, res.reason
    rtol = [PER_MODEL.get(model, {}).get(n, 0.02) for n in res.names]
    for name, value, true, r in zip(res.names, res.params, truth(model), rtol):
        assert_close(value, true, rtol=r, atol=0.02, what=f"{model} {name}")


@pytest.mark.parametrize("model", ALL_MODELS)
def test_every_symmetry_is_exact_and_maps_back_to_canonical_form(model: str) -> None:
    m = get_model(model)
    p = dict(m.drive.default_truth)
    fns = build(m, ProblemSpec(horizon=3))
    columns = build_residual_data(fns, sim_log(model, records=100), ResidualOptions(horizon=3)).columns
    x = truth(model)
    e = np.asarray(fns.residual.map(columns.shape[1])(x, [], columns))
    assert m.symmetries
    for sym in m.symmetries:
        image = sym.apply(p)
        assert image[sym.sign] < 0
        xm = np.array([image[n] for n in p])
        em = np.asarray(fns.residual.map(columns.shape[1])(xm, [], columns))
        assert_close(em, e, rtol=1e-9, atol=1e-12, what=sym.description)  # an exact symmetry
        canon = canonical(m, image)
        assert_close([canon[n] for n in p], x, rtol=1e-12, atol=1e-12, what=sym.description)
        kept = canonical(m, image, fixed=(sym.sign,))  # the symmetry may not move a fixed parameter
        assert kept == {**image, **{a: float(wrap_angle(image[a])) for a in m.angle_params}}


@pytest.mark.parametrize("model", ALL_MODELS)
def test_odometry_covariance_matches_monte_carlo(model: str) -> None:
    """Each diagonal term of the final pose's covariance within 10 % of 2,000 Monte-Carlo runs."""
    m = get_model(model)
    fns = build(m, ProblemSpec())
    ds = sim_log(model, records=300, seed=2)
    u = m.inputs(ds, "start")
    p = truth(model)
    noise = {enc: 2.5 if kind == "counter" else 0.65 for enc, kind in m.encoder_kinds.items()}
    sigma = m.input_noise_std(ds, noise)
    _, P = propagate(fns, p, u, np.zeros(3), sigma)
    fold = fns.odometry_step.mapaccum("mc", u.shape[1])
    # The constant arguments made CasADi matrices once, and each run's final pose alone read back
    # (converting them and the whole accumulated track on every call was half the test's time).
    start, reps, zero = (
        ca.DM.zeros(12),
        ca.DM(np.repeat(p[:, None], u.shape[1], axis=1)),
        ca.DM.zeros(*u.shape),
    )
    rng = np.random.default_rng(0)

    def end(noisy: np.ndarray) -> np.ndarray:
        return np.asarray(fold.call([start, reps, ca.DM(noisy), zero])[0][:3, -1].full()).ravel()

    ends = np.array([end(u + rng.normal(0, 1, u.shape) * sigma[:, None]) for _ in range(2000)])
    ratio = np.var(ends, axis=0) / np.diag(P[-1])
    assert np.all(np.abs(ratio - 1.0) <= 0.10), ratio


@pytest.mark.skipif(find_compiler() is None, reason="no C compiler found ($CC, cc, gcc or clang)")
@pytest.mark.parametrize("model", ALL_MODELS)
def test_c_export_equals_python(model: str, tmp_path: Path) -> None:
    m = get_model(model)
    problems = build_for_export(m, 3, "exact")
    columns = build_residual_data(
        problems[-1], sim_log(model, records=50), ResidualOptions(horizon=3)
    ).columns
    generate(problems, tmp_path, Example(truth(model), "truth", columns[:, 10], "window 10"), f"test {model}")
    lib = tmp_path / "lib.so"
    subprocess.run(
        [str(find_compiler()), "-O2", "-fPIC", "-shared", "-o", str(lib), "nlp_calib_residual.c", "-lm"],
        cwd=tmp_path,
        check=True,
        capture_output=True,
    )
    rng = np.random.default_rng(4)
    for fns in problems:
        H = fns.spec.horizon
        for exp in export_functions(fns):
            ext = ca.external(exp.function.name(), str(lib))
            for k in rng.choice(columns.shape[1], 5, replace=False):
                U = columns[: m.input_names.__len__() * H, k].reshape(len(m.input_names), H, order="F")
                args = (truth(model), U, columns[len(m.input_names) * 3 : len(m.input_names) * 3 + 3, k])
                for a, b in zip(ext.call(list(args)), exp.function.call(list(args))):
                    assert_close(
                        np.asarray(a),
                        np.asarray(b),
                        rtol=1e-12,
                        atol=1e-12 * max(float(np.abs(np.asarray(b)).max()), 1.0),
                    )


def test_each_models_radians_form_is_one_object_and_its_problem_is_built_once() -> None:
    from nlp_calib.models.radians import InRadians, in_units
    from nlp_calib.pipeline import load_scenario

    for name in MODELS:
        model = get_model(name)
        form = in_units(model, "radians")
        assert isinstance(form, InRadians) and form.model is model
        assert in_units(model, "radians") is form and in_units(form, "radians") is form
        assert in_units(form, "counts") is model
    # Two set-ups of a scenario of joints in radians share its problems' Functions.
    a, b = (load_scenario(SCENARIOS / "optiodom_tricycle_square.yaml").model_form() for _ in range(2))
    assert a is b
    spec = ProblemSpec()
    assert build(a, spec) is build(b, spec)
