"""Plain-text tables of a run for the terminal (the CLI prints them; nothing here prints)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import believed_std
from nlp_calib.results.figures import TrajectoryMetrics


def _fmt(v: float, width: int = 12) -> str:
    if not np.isfinite(v):
        return f"{'-':>{width}}"
    a = abs(v)
    if a != 0 and (a < 1e-3 or a >= 1e5):
        return f"{v:>{width}.4e}"
    return f"{v:>{width}.6f}"


def _figure(v: float, width: int = 0) -> str:
    """A figure in 4 significant digits, "-" where there is none (NaN: nothing to measure it on)."""
    return f"{v:>{width}.4g}" if np.isfinite(v) else f"{'-':>{width}}"


def _row(label: str, cells: list[str], label_width: int = 26) -> str:
    return f"{label:<{label_width}}" + "".join(cells)


def uncertainty_lines(run: CalibrationRun) -> list[str]:
    """Which σ the table shows, and how the two estimates of it compare."""
    blocked = run.std_blocks()
    first = next(iter(run.reports), None)
    if blocked is None or first is None:
        return [
            "1σ: white-noise σ only (no block cross-validation): a lower bound where timing, slip or "
            "model errors are present"
        ]
    white = run.reports[first].uncertainty.std_dict()
    ratio = {n: blocked[n] / white[n] for n in blocked if white[n] > 0 and np.isfinite(blocked[n])}
    lo, hi = (min(ratio.values()), max(ratio.values())) if ratio else (float("nan"), float("nan"))
    # A jackknife over ~10 blocks scatters by ~25 %: only a factor beyond 2 says something.
    larger = [n for n, r in ratio.items() if r > 2.0]
    cv = run.checks.crossval
    assert cv is not None
    if len(larger) == len(ratio):
        verdict = (
            ": errors that vary along the drive (timing, slip, model error) outweigh white noise, so the "
            "block σ is the one to believe"
        )
    elif larger:
        verdict = (
            f"; beyond 2× for {', '.join(larger)}: errors that vary along the drive (timing, slip, model "
            "error) matter there"
        )
    else:
        verdict = ": white noise explains the scatter, the two agree"
    lines = [
        f"1σ: the white-noise σ, or the σ of {len(cv.converged)} fits each without one block of records "
        f"(jackknife) where it exceeds it beyond its own noise; the block σ is {lo:.1f}–{hi:.1f}× the "
        "white-noise σ" + verdict
    ]
    lines += widened_lines(run)
    if not run.scenario.sensor.positions:
        return lines
    ate, rpe = "segment ATE mean [m]", "RPE over 1 m [m]"
    held, inside = cv.heldout_mean(rpe), cv.insample_mean(rpe)
    rpe_words = (
        f"RPE over 1 m {held:.3f} m (in-sample {inside:.3f} m)"
        if np.isfinite(held) and np.isfinite(inside)
        else "no RPE over 1 m (no block holds a stretch of 1 m between gaps or faults)"
    )
    lines.append(
        f"cross-validation over {len(cv.folds)} blocks: held-out segment ATE {cv.heldout_mean(ate):.3f} m "
        f"(in-sample {cv.insample_mean(ate):.3f} m), {rpe_words}: each block scored by the fit without it, "
        "and by the full fit"
    )
    return lines


def widened_lines(run: CalibrationRun) -> list[str]:
    """The parameters whose σ takes in how they move with the driving, and from which check."""
    first = next(iter(run.reports), None)
    checks = run.checks
    if first is None:
        return []
    u = run.reports[first].uncertainty
    names, white = u.names, u.std
    blocks = checks.crossval.beyond(white) if checks.crossval is not None else np.full(len(names), np.nan)
    base = believed_std(white, u.residual_spread(), blocks)
    out = []
    scatter, (chi2, dof) = u.block_spread(), u.block_chi2 if u.block_chi2 is not None else ((), ())
    wider = [
        f"{n} (χ² {c:.0f} on {d:.0f})" for n, b, v, c, d in zip(names, base, scatter, chi2, dof) if v > b
    ]
    if wider:
        out.append(
            f"   σ of {', '.join(wider)}: scaled by √(χ²/dof), the blocks of the drive, each fitting "
            "it alone, disagree beyond their own σ (errors that vary along the drive)"
        )
    base = believed_std(base, scatter)
    if checks.pivots is not None:
        spread = checks.pivots.beyond(white)
        wider = [n for n, b, v in zip(names, base, spread) if np.isfinite(v) and v > b]
        if wider:
            out.append(
                f"   σ of {', '.join(wider)}: the scatter of the drive's {len(checks.pivots.pivots)} pivots, "
                "each fitted on its own (a pivot's windows share one slip of the ground)"
            )
    for label, spread in checks.moving():
        wider = [n for n, b, v in zip(names, base, spread) if np.isfinite(v) and v > b]
        if wider:
            out.append(f"   σ of {', '.join(wider)}: {label} (they move with the driving: a model limit)")
    slip = checks.slip(names)
    wider = [n for n, b, v in zip(names, base, slip) if np.isfinite(v) and v > b]
    if wider:
        out.append(
            f"   σ of {', '.join(wider)}: with the tyres' slip the drive's speeds leave open, in "
            "quadrature (the slip check's lines over the speed squared)"
        )
    held = checks.held(names)
    wider = [n for n, b, v in zip(names, base, held) if np.isfinite(v) and 3.0 * v > b]
    if wider:
        out.append(
            f"   σ of {', '.join(wider)}: with what the held values' plausible errors move them by, in "
            "quadrature (the held check)"
        )
    return out


def check_lines(run: CalibrationRun) -> list[str]:
    """What each plug-in check found, in its one wording (one with a section of its own in the
    report set apart by a blank line)."""
    return [line for r in run.checks.more for line in (["", *r.lines()] if r.section else r.lines())]


def error_stats_lines(run: CalibrationRun, solver: str) -> list[str]:
    """``solver``'s trajectory errors with the statistics evo prints, beside the uncalibrated ones
    (none for a reference without positions, with why)."""
    if reason := run.scenario.sensor.no_position:
        return [
            f"trajectory errors: none in metres ({reason}: ATE and RPE would compare positions it does "
            "not have); the fit is judged by its residuals, the heading changes, and the checks below"
        ]
    m, b = run.reports[solver].metrics, run.baseline
    rows = [
        ("segment ATE [m]", m.segment_ate, b.segment_ate),
        ("segment ATE aligned [m]", m.segment_ate_aligned, b.segment_ate_aligned),
        *((f"RPE over {d:g} m [m]", s, b.rpe_distance[d]) for d, s in m.rpe_distance.items()),
        ("full-run ATE [m]", m.ate, b.ate),
    ]
    head = f"{'':<26}" + "".join(f"{h:>10}" for h in ("rmse", "mean", "median", "std", "min", "max", "n"))
    lines = [
        f"trajectory errors of {solver} (statistics as evo reports them; bad tracker poses left out):",
        head,
    ]
    for label, stats, base in rows:
        cells = "".join(
            _figure(v, 10) for v in (stats.rmse, stats.mean, stats.median, stats.std, stats.min, stats.max)
        )
        lines.append(f"{label:<26}{cells}{stats.n:>10d}   (uncalibrated rmse {_figure(base.rmse)})")
    # A distance no stretch between gaps and faults reaches has no figure: said, never "nan %".
    per_m = [
        f"RPE over {d:g} m: {100 * s.mean / d:.2g} % of the distance"
        if s.n and np.isfinite(s.mean)
        else f"RPE over {d:g} m: none (no stretch of {d:g} m between gaps or faults)"
        for d, s in m.rpe_distance.items()
    ]
    if m.distance_m > 0 and np.isfinite(m.ate_final):
        per_m.append(f"full-run final error {100 * m.ate_final / m.distance_m:.2g} % of {m.distance_m:.1f} m")
    elif m.distance_m > 0:
        per_m.append(
            f"full-run figures: none (the records do not connect: a gap, a reference's missing or left-out "
            f"increments or a log's end; the segment figures restart at each of the {m.segments} parts)"
        )
    lines.append("per metre driven: " + "; ".join(per_m))
    return lines


def lag_lines(run: CalibrationRun) -> list[str]:
    """The fitted tracker lag with its σ and what moves with it, in words."""
    data, solver = run.data, run.chosen_solver() or run.solver_order()[0]
    est = data.lag_estimate
    assert est is not None
    if not est.converged:
        early = 1e3 * data.tracker_lag_s
        return [f"tracker lag not fitted: no fit converged (the encoders are read {early:.1f} ms early)"]
    std = run.std(solver)
    params = run.reports[solver].result.param_dict()
    out = []
    for effect in run.checks.lag_effects or ():
        lag = params.get(effect.lag, data.tracker_lag_s)
        moves = ", ".join(
            _per_10ms(n, v, params.get(n, 0.0), run.scenario.units.get(n, ""))
            for n, v in effect.per_second.items()
        )
        sd = 1e3 * std.get(effect.lag, float("nan"))
        pinned = effect.lag in run.pinned()
        own = run.lag_estimates().get(effect.lag, est)  # a joint fit's view: that lag's own log's
        where = own.held_reason or "pinned on the edge of alignment.search"
        spread = f" ms, {where} (no σ)" if pinned else f" ± {sd:.2g} ms"
        out.append(
            f"{effect.lag} {1e3 * lag:.1f}{spread}, a parameter of the fit "
            f"(encoders re-sampled at {len(est.path_s)} lags on the way)"
            + (f"; per 10 ms of it, {moves}" if moves else "; no other parameter moves with it")
        )
    return out or [f"tracker lag fitted with the other parameters: {1e3 * data.tracker_lag_s:.1f} ms"]


def _per_10ms(name: str, per_second: float, value: float, unit: str) -> str:
    """``name``'s change over 10 ms of lag: relative for gains and lengths of the model, absolute
    for the mount's and angles."""
    change = 0.01 * per_second
    if name.startswith("sensor_") or unit in ("rad", "s") or value == 0.0:
        return f"{name} {change:+.2g} {unit}".rstrip()
    return f"{name} {100.0 * change / abs(value):+.2g} %"


def _dropped_line(run: CalibrationRun) -> str:
    """One line on the records a non-strict read dropped: how many, where, and the first reason."""
    dropped = run.log.dropped
    shown = ", ".join(str(d.line) for d in dropped[:5]) + (", ..." if len(dropped) > 5 else "")
    return (
        f"log: dropped {len(dropped)} of {run.log.records + len(dropped)} records (strict: false) at "
        f"line(s) {shown}; line {dropped[0].line}: {dropped[0].reason} "
        "(all listed in result.json under dataset.dropped_records)"
    )


def _header_lines(run: CalibrationRun) -> list[str]:
    sc, data = run.scenario, run.data
    r, robust = sc.residual, sc.robust
    lines = [
        f"scenario {sc.name}: model {sc.model}, "
        f"records [{data.used[0]}, {data.used[1]}) of {run.log.records}, "
        f"fit on [{data.fit[0]}, {data.fit[1]}), {data.n_residuals} residuals "
        f"(horizon {r['horizon']}, stride {r['stride']}, {r['integration']}), "
        f"kernel {robust['kernel']} δ={robust['delta']:g}"
    ]
    if data.lag_estimate is not None:
        lines += lag_lines(run)
    elif data.tracker_lag_s:
        lines.append(f"tracker lag (from the scenario): {1e3 * data.tracker_lag_s:.1f} ms")
    if run.log.dropped:
        lines.append(_dropped_line(run))
    if data.dropped_stationary:
        lines.append(f"dropped {data.dropped_stationary} windows without motion")
    return [*lines, *camera_lines(run), ""]


def _by_reason(counts: Mapping[str, int]) -> str:
    given = [f"{n} {reason}" for reason, n in counts.items() if n]
    return ", ".join(given) if given else "none"


def camera_lines(run: CalibrationRun) -> list[str]:
    """A sensor's own start and selection of windows, in words (nothing where it has none)."""
    data, kind = run.data, run.scenario.sensor.kind
    lines = []
    if data.start_dropped is not None:
        lines.append(
            f"sensor {kind}: the 'initial' column is its closed-form start alone; its windows left out: "
            f"{_by_reason(data.start_dropped)}"
        )
    if data.fit_dropped is not None:
        lines.append(f"sensor {kind}: fitted windows left out: {_by_reason(data.fit_dropped)}")
    return lines


def _parameter_lines(run: CalibrationRun, solvers: list[str], w: int) -> list[str]:
    names = list(next(iter(run.reports.values())).result.names) if run.reports else list(run.initial)
    units = run.scenario.units
    lines = [_row("parameter", [f"{'initial':>12}"] + [f"{s:>{w}}" for s in solvers] + ["  unit"])]
    for n in names:
        cells = [_fmt(run.initial[n])]
        for s in solvers:
            v = run.reports[s].result.param_dict()[n]
            sd = "pinned" if n in run.pinned() else f"{run.std(s)[n]:<9.2g}"
            cells.append(f"{_fmt(v, 12)} ± {sd:<9}")
        lines.append(_row(n, [*cells, f"  {units[n]}"]))
    lines += uncertainty_lines(run)
    if len(solvers) == 2:
        a, b = (run.reports[s].result for s in solvers)
        lines.append(
            f"max relative parameter difference {solvers[0]} vs {solvers[1]}: "
            f"{run.relative_difference(*solvers):.2e}; "
            f"cost difference {abs(a.cost - b.cost) / max(abs(a.cost), 1e-300):.2e} (relative)"
        )
    return [*lines, ""]


def _solver_lines(run: CalibrationRun, solvers: list[str], w: int) -> list[str]:
    res = {s: run.reports[s].result for s in solvers}
    figures = [
        ("cost", lambda s: _fmt(res[s].cost, w)),
        ("chi2", lambda s: _fmt(res[s].chi2, w)),
        ("inliers", lambda s: f"{res[s].inliers:>{w - 6}d}/{res[s].n_residuals:<5d}"),
        ("iterations", lambda s: f"{res[s].iterations:>{w}d}"),
        ("time [ms]", lambda s: f"{1e3 * res[s].time_s:>{w}.1f}"),
        ("converged", lambda s: f"{'yes' if res[s].converged else 'NO':>{w}}"),
    ]
    lines = [_row(label, [f"{'':>12}"] + [cell(s) for s in solvers]) for label, cell in figures]
    if not run.scenario.sensor.positions:
        return lines  # figures in metres of a track without positions: said once, below
    metric_sets: list[tuple[bool, TrajectoryMetrics]] = [(False, run.baseline)]
    if run.baseline_holdout is not None:
        metric_sets.append((True, run.baseline_holdout))
    for holdout, base in metric_sets:
        per_solver = [run.reports[s].holdout if holdout else run.reports[s].metrics for s in solvers]
        for i, (label, value) in enumerate(base.figures()):
            cells = [_fmt(value)]
            cells += [_fmt(m.figures()[i][1] if m is not None else float("nan"), w) for m in per_solver]
            lines.append(_row(("hold-out " if holdout else "") + label, cells))
    return lines


def _check_lines(run: CalibrationRun, solvers: list[str]) -> list[str]:
    lines: list[str] = []
    chosen = next((s for s in solvers if run.reports[s].result.converged), None)
    if chosen is not None:
        lines += ["", *error_stats_lines(run, chosen)]
    lines += check_lines(run)
    # What a check said in its lines is not said again.
    said = [line for r in run.checks.more for line in (r.words, *r.details)]
    # Every other warning result.json holds (a solver's failure is said below, in its own words).
    failed = {f"{s}: {run.reports[s].result.reason}" for s in solvers}
    lines.extend(
        f"WARNING: {w}" for w in run.warnings if w not in failed and not any(w in line for line in said)
    )
    for s in solvers:
        res = run.reports[s].result
        if not res.converged:
            lines.append(f"WARNING: {s} did not converge: {res.reason}. Do not use its parameters.")
    return lines


def run_table(run: CalibrationRun) -> str:
    """Parameters side by side (initial, each solver ± 1σ), solver figures and metrics."""
    solvers, w = list(run.reports), 24
    lines = _header_lines(run) + _parameter_lines(run, solvers, w) + _solver_lines(run, solvers, w)
    return "\n".join(lines + _check_lines(run, solvers))


def validation_table(run: CalibrationRun) -> str:
    """The folds of the blocked cross-validation, the two σ side by side, and the direction check."""
    cv, solver = run.checks.crossval, next(iter(run.reports))
    if cv is None:
        return "no cross-validation: too few converged fits"
    names = list(cv.names)
    short = [n.replace("sensor_", "s_")[:11] for n in names]
    head = f"{'held-out records':<18}{'conv':>5}" + "".join(f"{s:>12}" for s in short)
    head += f"{'segATE [m]':>12}{'RPE 1 m [m]':>12}"
    lines = [f"cross-validation of {run.scenario.name} ({solver}), {len(cv.folds)} contiguous blocks:", head]
    for f in cv.folds:
        cells = "".join(f"{v:>12.6g}" for v in f.params)
        m = f.heldout
        scores = f"{m.segment_ate.mean:>12.4f}{m.rpe_distance[1.0].mean:>12.4f}" if m is not None else ""
        lines.append(f"{f'[{f.first}, {f.stop})':<18}{'yes' if f.converged else 'NO':>5}{cells}{scores}")
    full = run.reports[solver].result.params
    lines.append(f"{'all records':<18}{'':>5}" + "".join(f"{v:>12.6g}" for v in full))
    white = run.reports[solver].uncertainty.std
    lines += ["", f"{'parameter':<18}{'white-noise σ':>14}{'block σ':>12}{'ratio':>8}{'spread':>12}"]
    for n, w, b, sp in zip(names, white, cv.std, cv.spread()):
        ratio = b / w if w > 0 else float("nan")
        lines.append(f"{n:<18}{w:>14.3g}{b:>12.3g}{ratio:>8.1f}{sp:>12.3g}")
    direction = run.checks.plugin("direction")
    lines += ["", *uncertainty_lines(run), *(direction.lines() if direction is not None else ())]
    return "\n".join(lines)


def correlation_table(run: CalibrationRun, solver: str) -> str:
    """The parameter correlation matrix of one solver's estimate."""
    u = run.reports[solver].uncertainty
    short = [n.replace("sensor_", "s_")[:9] for n in u.names]
    lines = [f"correlation ({solver}):", _row("", [f"{s:>10}" for s in short], 14)]
    for n, row in zip(u.names, u.correlation):
        lines.append(_row(n[:13], [f"{v:>10.3f}" for v in row], 14))
    return "\n".join(lines)


def summary_table(runs: list[CalibrationRun]) -> str:
    """One line per scenario and solver: residual form, each model's headline parameters, the
    fault-robust trajectory errors and the scenario's verdict."""
    headline: list[str] = []
    for run in runs:
        headline += [n for n in run.scenario.headline if n not in headline]
    head = (
        f"{'scenario':<22}{'solver':<14}{'H':>4}{'integr.':>8}"
        + "".join(f"{n[:11]:>12}" for n in headline)
        + f"{'segATE [m]':>11}{'RPE 5 m':>9}{'hold-out':>10}{'conv':>6}  verdict"
    )
    lines = ["summary", head, "-" * len(head)]
    for run in runs:
        r = run.scenario.residual
        level = run.verdict.level
        for name, rep in run.reports.items():
            p = rep.result.param_dict()
            m = rep.metrics
            ho = f"{rep.holdout.segment_ate.mean:>10.3f}" if rep.holdout is not None else f"{'-':>10}"
            values = "".join(f"{p[n]:>12.6g}" if n in p else f"{'-':>12}" for n in headline)
            lines.append(
                f"{run.scenario.name[:21]:<22}{name:<14}{r['horizon']:>4}{r['integration']:>8}{values}"
                f"{m.segment_ate.mean:>11.3f}{m.rpe_distance[5.0].mean:>9.3f}{ho}"
                f"{'yes' if rep.result.converged else 'NO':>6}  {level}"
            )
    return "\n".join(lines)
