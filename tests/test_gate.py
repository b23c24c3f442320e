"""Issue 38: the pre-flight judges with what the fit will know, and the lag is found globally and
compared alike."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENARIOS, cli, write_sim

from nlp_calib.analysis import determinacy as det
from nlp_calib.analysis import observability as obs
from nlp_calib.analysis.verdict import lag_caveats
from nlp_calib.models import get_model
from nlp_calib.pipeline import Calibration, profile_check, scenario_from_mapping
from nlp_calib.pipeline import preflight as pf
from nlp_calib.pipeline.align import _global, _settled, apart, valleys
from nlp_calib.pipeline.build import Binder
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.pipeline.scenario import load_scenario
from nlp_calib.pipeline.units_check import _judged_by_fit
from nlp_calib.pipeline.validation import lag_alike
from nlp_calib.problem import ResidualData
from nlp_calib.results import CalibrationRun, codec
from nlp_calib.results.checks import CAVEAT, LagEstimate
from nlp_calib.results.preflight import NOT_DETERMINED, WEAKLY, Preflight, UnitFinding
from nlp_calib.results.run import CAVEATS, UNDETERMINED
from nlp_calib.solvers.evaluation import NormalEquations

REAL = Path("/work/shared/data/dataset.txt")


def test_a_mirrored_wheel_stops_a_run_only_where_the_fit_confirms_it() -> None:
    model = get_model("diff_drive")
    finding = UnitFinding("mirrored", "left_ticks", "one wheel's axis is mirrored")
    plausible = {"k_left": 1e-4, "k_right": 1e-4, "baseline": 0.3, "sensor_x": 0.1, "sensor_y": 0.0}
    kept = _judged_by_fit(finding, model, plausible)
    assert not kept.blocking and "goes on" in kept.words
    assert _judged_by_fit(finding, model, {**plausible, "k_left": -1e-4}).blocking
    assert _judged_by_fit(finding, model, None).blocking  # no converged fit: the finding stands
    degrees = UnitFinding("degrees", "left_ticks", "degrees")
    assert _judged_by_fit(degrees, model, plausible).blocking


def test_the_profiles_valleys_lowest_first_and_a_ridge_between_two() -> None:
    grid = np.linspace(-0.5, 0.5, 101)
    costs = 1.0 + np.minimum((grid + 0.01) ** 2, 0.9 * (grid - 0.18) ** 2 - 0.001) * 50
    found = valleys(grid, costs)
    assert found[0] == pytest.approx(0.18) and found[1] == pytest.approx(-0.01)
    assert apart(grid, costs, found[0], found[1])
    assert not apart(grid, costs, 0.17, 0.19)  # one valley


class _FlatValley:
    """A lag's fits on a flat cost (a real tricycle's square, 140120211446 run 1): fits settle at
    293 ms from below 310 ms and at 365 ms, 1.4 % lower, from above; the profile at the first fit's
    other parameters is one smooth valley, lowest at 325 ms."""

    column = 0

    def profile(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        grid = np.linspace(-0.5, 0.5, 41)
        return grid, 0.57 + (grid - 0.325) ** 2

    def settle(self, x: np.ndarray) -> tuple[np.ndarray, list[float], list[float], bool]:
        lag, cost = (0.293, 0.5709) if x[0] < 0.31 else (0.365, 0.5631)
        return np.array([lag]), [float(x[0])], [cost], True


def test_the_lag_search_fits_from_the_profiles_lowest_point_a_step_or_more_away() -> None:
    fits = _FlatValley()
    first = _settled(fits, np.array([0.0]))  # type: ignore[arg-type]
    best, runner, _ = _global(fits, first)  # type: ignore[arg-type]
    assert best.x[0] == pytest.approx(0.365) and best.cost < first.cost
    assert runner is None  # no ridge between the two: one valley, its lowest point kept


def test_a_fold_and_the_sets_it_is_compared_with_share_its_lags() -> None:
    start, fold = np.array([1.0, 2.0, 0.0, 3.0]), np.array([1.1, 2.1, 0.03, 3.1])
    assert np.array_equal(lag_alike(start, fold, [2]), [1.0, 2.0, 0.03, 3.0])
    assert lag_alike(start, fold, []) is start


def test_a_pinned_or_ambiguous_lag_is_a_caveat_naming_its_log() -> None:
    edge = LagEstimate(-0.2, (0.0, -0.2), (1.0, 0.9), at_edge=True)
    (words,) = lag_caveats("/data/run-07.csv", edge)
    assert "run-07.csv" in words and "pinned" in words and "±" not in words
    two = LagEstimate(-0.01, (0.0,), (1.0,), other=(0.18, 1.02, 1.0))
    (words,) = lag_caveats("/data/run-07.csv", two)
    assert "ambiguous: -10 ms or 180 ms" in words
    assert lag_caveats("x", LagEstimate(0.01, (0.0,), (1.0,))) == []


@pytest.mark.skipif(not REAL.exists(), reason="the shared real log is not here")
@pytest.mark.parametrize("records", [(0, 1460), (0, 1947)])
def test_parts_of_the_real_log_the_fit_determines_pass_the_gate(records: tuple[int, int]) -> None:
    # The first 60 % and the log without its last fifth: before, the start's misfit was taken for
    # noise and sensor_y came out ±2 m, "not determined"; fitted, it is known to about a centimetre.
    sc = scenario_from_mapping(
        {
            "dataset": str(REAL),
            "samples": {"start": records[0], "stop": records[1]},
            "model": "tricycle_reverse",
            "robust": {"kernel": "huber", "delta": 0.25},
            "residual": {"horizon": 25, "integration": "exact", "steering_sample": "mean"},
            "alignment": {"tracker_lag": "auto", "search": [-0.2, 0.2]},
            "solvers": ["gauss_newton"],
        },
        "part",
        REAL.parent,
    )
    report = preflight(sc)
    assert report.stop_words() == "", report.stop_words()
    sensor_y = next(p for p in report.parameters if p.name == "sensor_y")
    assert sensor_y.std < 0.03


@pytest.mark.parametrize("name", ["demo", "real_tricycle"])
def test_the_preflights_information_and_jackknife_are_its_fits_own(
    name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 41: the pre-flight's information at its fit is the fit's own normal equations there
    (determinacy.information evaluated again gives it to rounding), and its jackknife's folds
    (``validation.leave_out``: the first step from the fit's normal equations less the block's)
    land within σ/100 of full refits to rounding (σ: the pre-flight's own)."""
    seen: dict[str, object] = {}
    original = pf._propagated

    def spy(d, binder, x, windows, fitted):  # type: ignore[no-untyped-def]
        seen.update(binder=binder, windows=windows, whole=fitted[1])
        return original(d, binder, x, windows, fitted)

    monkeypatch.setattr(pf, "_propagated", spy)
    if name == "real_tricycle" and not REAL.exists():
        pytest.skip("the real log is not on this machine")
    a = pf.assess(load_scenario(SCENARIOS / f"{name}.yaml"))
    d = a.drive
    again = det.information(d.fns, pf._judged(d), a.x, d.start.x_fixed, a.omega, a.delta)
    np.testing.assert_allclose(a.info.H, again.H, rtol=1e-9, atol=1e-12 * np.abs(again.H).max())
    assert a.info.chi2 == pytest.approx(again.chi2, rel=1e-9)
    assert a.info.spread2 == pytest.approx(again.spread2, rel=1e-9)
    assert (a.info.n_windows, a.info.motion2) == (again.n_windows, again.motion2)
    binder, windows, whole = seen["binder"], seen["windows"], seen["whole"]
    assert isinstance(binder, Binder) and isinstance(windows, ResidualData)
    assert isinstance(whole, NormalEquations) and a.propagated is not None
    free = [d.fns.names.index(n) for n in d.fns.free]
    moved = []
    for block in pf._blocks(windows, 5):
        fold = pf._fold(binder, a.x, windows, whole, block)
        kept = binder.evaluate(windows.select(np.setdiff1d(np.arange(windows.n_residuals), block)))
        _, x_full, converged = binder.fit(kept, a.x)
        assert fold.converged and converged
        gap = np.abs(fold.params[free] - x_full) / a.propagated
        assert np.max(gap) < 0.01, gap
        moved.append(np.max(np.abs(x_full - a.x) / a.propagated))
    assert max(moved) > 0.1  # the folds do move: the bound above is not met by staying at x


def test_the_preflight_judges_every_window_the_budget_holds() -> None:
    # 1499 windows of one record were rounded down to 1280 (a whole number of buckets): the fit on
    # them stopped elsewhere along a direction the drive barely holds than the run's on all 1499.
    assert np.array_equal(det.spread(1499, det.MAX_WORK), np.arange(1499))
    more = det.spread(10 * det.MAX_WORK, det.MAX_WORK)
    assert more.size <= det.MAX_WORK and more.size % det.BUCKET == 0 and more[0] == 0


def test_the_preflight_calls_not_observable_what_the_runs_verdict_does() -> None:
    """One rule (observability.not_observable): the parameters of the directions beyond the limit
    or free, as weak_directions names them for the verdict; not a parameter's own σ."""
    names = ("a", "b", "c")
    c, s = np.cos(0.5), np.sin(0.5)  # b's share of the loose direction 0.23
    V = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    lam = np.array([1.0 / 150.0**2, 1.0 / 2.0**2, 1.0])  # 1σ 150, 2 and 1 reference units
    found = obs.Directions(lam, V, np.zeros(3, dtype=bool), np.zeros(3))
    said = {
        n
        for w in obs.weak_directions(names, lam, V, found.free)
        if w.std_reference > 100
        for n in w.components
    }
    flagged = {n for n, f in zip(names, obs.not_observable(found)) if f}
    assert flagged == said == {"a", "b"}
    free = obs.Directions(np.array([1e-30, 1.0, 1.0]), np.eye(3), np.array([True, False, False]), np.zeros(3))
    assert list(obs.not_observable(free)) == [True, False, False]


@pytest.mark.parametrize("model", ["car_like", "car_like_ackermann"])
def test_a_car_whose_rear_track_the_drive_barely_holds_is_never_handed_off(
    tmp_path: Path, model: str
) -> None:
    """The gate study's car draw 501 (s-curves, 1500 records, stamps 29.9 ms late, the lag fitted):
    its rear track fits about as well near zero as at its length. Its σ at the fit moves tenfold
    with how each interval is read (0.106, 0.773 and 0.082 m on three versions of the reading),
    so what is held is what must not move: the pre-flight and the run agree (refused by both, or
    both with caveats), they start and end at one fit with one σ, the truth lies within 3σ, and
    the rear track reaches the hand-off as not determined, named by the verdict or by the profile
    (zero within 3σ by the cost: a second valley or a plateau), never as calibrated (#43 item 5)."""
    report, calibration, run = _gate_study_car(tmp_path, model)
    rear = next(p for p in report.parameters if p.name == "rear_track")
    assert rear.status in (WEAKLY, NOT_DETERMINED), rear
    assert [p.name for p in report.missing() if p.name != "rear_track"] == []
    refused = {4: UNDETERMINED, 3: CAVEATS}
    assert refused[report.exit_code] == run.verdict.level, (report.exit_code, run.verdict)
    _same_fit_and_sigma(report, calibration, run)
    assert "rear_track" in run.doubts("gauss_newton"), run.doubts("gauss_newton")
    profile = next(r for r in run.checks.more if r.name == "profile")
    if run.verdict.level == UNDETERMINED:
        assert "rear_track" in run.verdict.line(), run.verdict
    else:
        assert profile.level == CAVEAT and set(profile.concerns) == {"rear_track"}, profile
    if profile.level == CAVEAT:  # zero within 3σ by the cost
        assert profile.table["sigmas_by_cost"]["rear_track"] < profile_check.WITHIN, profile.table


def _gate_study_car(tmp_path: Path, model: str) -> tuple[Preflight, Calibration, CalibrationRun]:
    """The gate study's car draw 501 (s-curves, 1500 records, stamps 29.9 ms late, the lag fitted)
    as ``model``: its pre-flight, its calibration and the run."""
    lag = float(np.random.default_rng(501).uniform(0.0, 0.03))  # as the study draws it
    log = write_sim(tmp_path, "car.txt", seed=501, model=model, latency_s=lag)
    sc = scenario_from_mapping(
        {
            "dataset": str(log),
            "model": model,
            "initial_guess": "from_file",
            "solvers": ["gauss_newton"],
            "alignment": {"tracker_lag": "auto"},
        },
        "car",
        tmp_path,
    )
    report = preflight(sc)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calibration = Calibration(sc)
        run = calibration.run()
    return report, calibration, run


def _same_fit_and_sigma(report: Preflight, calibration: Calibration, run: CalibrationRun) -> None:
    """The pre-flight's fit ends where the run's solver does (the same lag, the same start, the
    same windows): the run's estimate less the step that frees it of the counters' rounding bias;
    one σ before the fit and after it, within what the run adds (half the forward-reverse
    difference where larger), as test_vehicles' highway car holds it; the truth within 3σ."""
    fitted = pf.assess(calibration.scenario).fitted()
    assert fitted is not None
    fitting = calibration.fitting
    solver_stop = fitting.before_step(run.reports["gauss_newton"].result.x)
    full = np.asarray(fitting.fns.assemble(solver_stop, fitting.problem.start.x_fixed)).ravel()
    estimate = dict(zip(fitting.fns.names, full))
    for name, value in fitted.items():
        assert value == pytest.approx(estimate[name], rel=1e-6, abs=1e-9), name
    std = run.std("gauss_newton")
    ratios = {p.name: p.std / std[p.name] for p in report.parameters if std[p.name] > 0}
    assert all(0.5 < r < 2.0 for r in ratios.values()), ratios
    truth = run.checks.truth
    assert truth is not None
    assert np.nanmax(np.abs(truth.z)) < 3.0, dict(zip(truth.names, truth.z))


def test_a_parameter_the_drive_tells_from_zero_is_not_profiled_away(tmp_path: Path) -> None:
    """The reverse steering gain of a tricycle that reverses: held at a twentieth of it, the cost
    puts it as many σ away as its σ does (a quadratic valley), so the profile finds it determined
    (no caveat of its own)."""
    log = write_sim(tmp_path, "rev.txt", seed=12, model="tricycle_reverse", records=1500)
    sc = scenario_from_mapping(
        {
            "dataset": str(log),
            "model": "tricycle_reverse",
            "initial_guess": "from_file",
            "solvers": ["gauss_newton"],
        },
        "rev",
        tmp_path,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = Calibration(sc).run()
    profile = next(r for r in run.checks.more if r.name == "profile")
    assert profile.level != CAVEAT and not profile.concerns, profile
    by_cost, by_std = (profile.table[k]["k_steer_reverse"] for k in ("sigmas_by_cost", "sigmas_by_std"))
    assert by_cost > 5.0 and 0.5 < by_cost / by_std < 2.0, profile.table


def test_a_run_searches_its_lag_once_and_the_gate_judges_at_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Issue 41: inside ``run`` the lag is searched once, by the run on the log it fits, and the
    gate judges at that lag; on the demo its verdict is the stand-alone pre-flight's."""
    from nlp_calib.cli import gate as cli_gate
    from nlp_calib.cli import preflight as cli_preflight
    from nlp_calib.pipeline import align

    searched: list[LagEstimate] = []
    judged: list[LagEstimate | None] = []
    search, judge, gate = align.estimate_tracker_lag, cli_preflight.preflight, cli_gate.stops

    def counted(*args: object) -> LagEstimate:
        searched.append(search(*args))  # type: ignore[arg-type]
        return searched[-1]

    def spied(sc: object, logs: object, found: LagEstimate | None = None, run: object = None) -> object:
        judged.append(found)
        return gate(sc, logs, found, run)  # type: ignore[arg-type]

    monkeypatch.setattr(align, "estimate_tracker_lag", counted)
    monkeypatch.setattr(pf, "estimate_tracker_lag", counted)
    monkeypatch.setattr(cli_gate, "stops", spied)
    demo = SCENARIOS / "demo.yaml"
    proc = cli("run", str(demo), "--solver", "gauss_newton", "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    assert len(searched) == 1 and judged == [searched[0]]
    own = preflight(load_scenario(demo))
    assert len(searched) == 2  # the stand-alone pre-flight searches its own
    at_run = judge(load_scenario(demo), None, searched[0])
    assert at_run.verdict == own.verdict
    assert [(p.name, p.status) for p in at_run.parameters] == [(p.name, p.status) for p in own.parameters]


def test_inside_a_run_the_gate_prepares_and_builds_nothing_of_its_own(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Issue 41: inside ``run`` the pre-flight judges with the run's own prepared log and
    evaluation backend: it prepares no log and makes no backend of its own (a second one built
    its maps again and set the helpers' column map anew, over the run's), and its problem is the
    run's Functions."""
    from nlp_calib.pipeline import build, stages

    prepared: list[object] = []
    backends: list[object] = []
    columns: list[object] = []
    judged: list[pf.Assessment] = []
    own = stages.prepare, build.prepare_backend, build.compile_columns, pf.assess

    def counted_prepare(*args: object) -> object:
        prepared.append(args)
        return own[0](*args)  # type: ignore[arg-type]

    def counted_backend(*args: object) -> object:
        backends.append(own[1](*args))  # type: ignore[arg-type]
        return backends[-1]

    def counted_columns(column_map: object) -> None:
        columns.append(column_map)
        own[2](column_map)  # type: ignore[arg-type]

    def spied(*args: object, **kw: object) -> object:
        judged.append(own[3](*args, **kw))  # type: ignore[arg-type]
        return judged[-1]

    for module in (stages, pf):
        monkeypatch.setattr(module, "prepare", counted_prepare)
    for module in (build, pf):
        monkeypatch.setattr(module, "prepare_backend", counted_backend)
    monkeypatch.setattr(build, "compile_columns", counted_columns)
    monkeypatch.setattr(pf, "assess", spied)
    demo = SCENARIOS / "demo.yaml"
    proc = cli("run", str(demo), "--solver", "gauss_newton", "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr
    # The run's own: one log prepared, one backend got ready (its helpers' column map set once).
    assert len(judged) == 1 and len(prepared) == 1 and len(backends) == 1 and len(columns) == 1
    assert judged[0].drive.backend is backends[0]


def test_the_gate_judges_with_the_runs_stages_as_on_its_own(tmp_path: Path) -> None:
    """Issue 41: the pre-flight on a run's prepared log and backend judges bit for bit as it does
    preparing its own (the same start, fit, information and words)."""
    from nlp_calib.pipeline.stages import align_log

    sc = load_scenario(SCENARIOS / "demo.yaml")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = align_log(sc, None, ("gauss_newton",))
    found = run.alignment.estimate
    shared, own = pf.assess(sc, None, found, run=run), pf.assess(sc, None, found)
    assert shared.drive.backend is run.problem.binder.backend and own.drive.backend is None
    assert shared.drive.fns is own.drive.fns is run.problem.fns
    assert shared.converged and own.converged and shared.where == own.where
    assert np.array_equal(shared.x, own.x) and np.array_equal(shared.info.H, own.info.H)
    assert shared.info.chi2 == own.info.chi2 and shared.sigma2 == own.sigma2
    assert np.array_equal(shared.propagated, own.propagated, equal_nan=True)


def test_two_loose_combinations_of_the_same_parameters_are_one_caveat() -> None:
    """Two weak directions over the same three parameters read as one caveat (they read twice,
    their names in another order), the loosest kept; a weak one over other parameters stays."""
    names = ("a", "b", "c", "d")
    V = np.zeros((4, 4))
    V[:3, 0] = [0.8, 0.5, 0.33]  # the loosest
    V[:3, 1] = [0.4, -0.6, 0.69]  # the same three, another order by size
    V[3, 2] = 1.0  # d alone
    lam = np.array([4e-4, 1e-3, 1e-2, 1e4])  # 1σ 50, 31.6, 10 and 0.01 reference units
    weak = obs.weak_directions(names, lam, V, np.zeros(4, dtype=bool))
    assert [set(w.components) for w in weak] == [{"a", "b", "c"}, {"d"}]
    assert weak[0].std_reference == pytest.approx(50.0)


def test_the_gate_stops_where_the_preflight_does_and_says_what_it_says(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 41: inside a run the gate (``stops``) decides without the σ to believe, the needed
    precisions or the plan, which only its words need: it lets the demo go on without computing
    them, and where the stand-alone pre-flight stops a drive it stops it with the same report."""
    computed: list[object] = []
    sigma = pf._propagated

    def counted(*args: object) -> object:
        computed.append(args)
        return sigma(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(pf, "_propagated", counted)
    demo = load_scenario(SCENARIOS / "demo.yaml")
    assert pf.stops(demo) is None and not computed
    assert preflight(demo).stop_words() == "" and len(computed) == 1
    log = write_sim(tmp_path, "straight.txt", seed=5, records=800, trajectory="straight")
    sc = scenario_from_mapping(
        {"dataset": str(log), "model": "tricycle", "initial_guess": "from_file", "solvers": ["gauss_newton"]},
        "straight",
        tmp_path,
    )
    own, gated = preflight(sc), pf.stops(sc)
    assert own.stop_words() and gated is not None
    assert gated.stop_words() == own.stop_words() and gated.exit_code == own.exit_code
    assert gated.plan is not None and gated.plan.best is not None

    def stored(report: object) -> object:
        return {k: v for k, v in codec.to_data(report).items() if k != "time_s"}

    assert stored(gated) == stored(own)


def test_the_profiles_held_fit_on_the_runs_evaluator_is_the_held_problem_set_up_anew(tmp_path: Path) -> None:
    """Issue 41: the profile's fit held at a value, on the run's own evaluator (the held parameter
    and the time offset, at the run's lag, out of its normal equations), costs what the scenario
    set up anew with them known costs (prepared, screened, aligned at that lag, bound, fitted)."""
    import dataclasses

    from nlp_calib.pipeline import profile_check
    from nlp_calib.pipeline.fit import Fit
    from nlp_calib.pipeline.stages import setup_log

    log = write_sim(tmp_path, "rev.txt", seed=12, model="tricycle_reverse", records=1500)
    mapping = {"dataset": str(log), "model": "tricycle_reverse", "initial_guess": "from_file"}
    sc = scenario_from_mapping({**mapping, "solvers": ["gauss_newton"]}, "rev", tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calibration = Calibration(sc)
        run = calibration.run()
        name = "k_steer_reverse"
        value = run.reports["gauss_newton"].result.param_dict()[name] - 2.0 * run.std("gauss_newton")[name]
        ours = profile_check._held_cost(calibration.fitting, run, name, value)
        start = {
            n: v
            for n, v in run.reports["gauss_newton"].result.param_dict().items()
            if n in run.scenario.layout.robot()
        }
        held = dataclasses.replace(
            sc.parameters, initial_guess={**start, name: value}, known={**sc.parameters.known, name: value}
        )
        lag = dataclasses.replace(sc.log.alignment, tracker_lag=run.data.tracker_lag_s)
        part = setup_log(sc.with_options(parameters=held, alignment=lag), None, ("gauss_newton",))
        anew = Fit(part.problem, part.windows.data, ("gauss_newton",)).solve("gauss_newton")
    assert ours is not None and anew.converged
    assert ours == pytest.approx(anew.cost, rel=1e-9)
    assert ours > run.reports["gauss_newton"].result.cost  # held 2σ off, the cost rises
