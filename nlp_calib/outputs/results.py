"""``result.json``: the document a run writes into its output folder."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.results import CalibrationRun, SolverReport
from nlp_calib.results.checks import CostComparison
from nlp_calib.results.codec import finite_or_null
from nlp_calib.results.figures import TrajectoryMetrics
from nlp_calib.results.run import GIVEN
from nlp_calib.results.uncertainty import Uncertainty


def not_estimated(run: CalibrationRun, solver: str | None = None) -> set[str]:
    """The parameters ``solver``'s fit held rather than estimated (given, or held at its guess;
    without ``solver``, any solver's): they have no σ."""
    out: set[str] = set()
    for name in run.reports if solver is None else (solver,):
        out |= set(run.reports[name].held)
        out |= {n for n, (level, _) in run.handoff_status(name).items() if level == GIVEN}
    return out


def sigmas(run: CalibrationRun, solver: str | None, std: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """``std`` with no σ (null) for each parameter the fit held rather than estimated (see
    :func:`not_estimated`): a 0 there would read as a value known exactly."""
    if std is None:
        return None
    held = not_estimated(run, solver)
    return {n: None if n in held else v for n, v in std.items()}


def _metrics_dict(full: TrajectoryMetrics, holdout: TrajectoryMetrics | None) -> dict[str, Any]:
    out: dict[str, Any] = full.as_dict()
    if holdout is not None:
        out.update({f"holdout_{k}": v for k, v in holdout.as_dict().items()})
    return out


def _crossval_dict(run: CalibrationRun) -> dict[str, Any] | None:
    cv = run.checks.crossval
    if cv is None:
        return None
    first = cv.folds[0].heldout if cv.folds else None
    labels = [label for label, _ in first.figures()[:4]] if first is not None else []
    return {
        "blocks": len(cv.folds),
        "std_blocks": sigmas(run, None, run.std_blocks()),
        "spread": dict(zip(cv.names, map(float, cv.spread()))),
        "heldout": {label: cv.heldout_mean(label) for label in labels},
        "insample": {label: cv.insample_mean(label) for label in labels},
        "folds": [
            {
                "records": [f.first, f.stop],
                "converged": f.converged,
                "params": dict(zip(cv.names, map(float, f.params))),
                "heldout": f.heldout.as_dict() if f.heldout is not None else None,
                "insample": f.insample.as_dict() if f.insample is not None else None,
            }
            for f in cv.folds
        ],
    }


def _pivots_dict(run: CalibrationRun) -> dict[str, Any]:
    """Each pivot fitted on its own: how many, the σ their scatter gives (null where held) and
    each pivot's records."""
    pivots = run.checks.pivots
    assert pivots is not None
    out = pivots.as_dict()
    out["std_pivots"] = sigmas(run, None, out["std_pivots"])
    return out


def _logs_dict(run: CalibrationRun) -> dict[str, Any] | None:
    """Several logs: each log's own fit against the other logs', and the jackknife over the logs."""
    check, logs = run.checks.consistency, run.checks.logs
    if check is None and logs is None:
        return None
    out: dict[str, Any] = {"consistency": check.as_dict() if check is not None else None}
    if logs is not None:
        out["std_logs"] = {n: (float(v) if np.isfinite(v) else None) for n, v in zip(logs.names, logs.std)}
        out["held_out_logs"] = [
            {"records": [f.first, f.stop], "converged": f.converged, "heldout": _or_none(f.heldout)}
            for f in logs.folds
        ]
    return out


def _or_none(metrics: TrajectoryMetrics | None) -> dict[str, Any] | None:
    return metrics.as_dict() if metrics is not None else None


def _cost_dict(cost: CostComparison | None) -> dict[str, Any] | None:
    if cost is None:
        return None
    t = cost.gain_sigmas
    return {
        "against": cost.against,
        "outcome": cost.outcome,
        "heldout_gain_in_standard_errors": float(t) if np.isfinite(t) else None,
        "heldout_folds": int(cost.heldout.shape[0]),
        "insample_data_cost": {"other": cost.insample[0], "fit": cost.insample[1]},
    }


def _nominal_dict(run: CalibrationRun) -> dict[str, Any] | None:
    nominal = run.checks.nominal
    if nominal is None:
        return None
    return {
        "values": dict(nominal.values),
        "source": nominal.source,
        "scored": dict(zip(next(iter(run.reports.values())).result.names, map(float, nominal.params))),
        "metrics": nominal.metrics.as_dict(),
        "cost": _cost_dict(nominal.cost),
    }


def _block_chi2(u: Uncertainty) -> dict[str, Any] | None:
    """Each parameter's blocks' χ² about their weighted mean and its degrees of freedom (None: not
    judged)."""
    if u.block_chi2 is None:
        return None
    return {
        n: {"chi2": float(c), "dof": int(d)} if d > 0 else None for n, (c, d) in zip(u.names, u.block_chi2.T)
    }


def _solver_dict(run: CalibrationRun, name: str, report: SolverReport) -> dict[str, Any]:
    r, u = report.result, report.uncertainty
    return {
        "params": r.param_dict(),
        "std": sigmas(run, name, run.std(name)),
        "std_white_noise": sigmas(run, name, u.std_dict()),
        "std_residuals": sigmas(run, name, dict(zip(u.names, map(float, u.residual_spread())))),
        "std_block_scatter": sigmas(run, name, dict(zip(u.names, map(float, u.block_spread())))),
        "block_chi2": sigmas(run, name, _block_chi2(u)),
        "correlation": {"names": list(u.names), "matrix": np.round(u.correlation, 6).tolist()},
        "cost": r.cost,
        "chi2": r.chi2,
        "inliers": r.inliers,
        "residuals": r.n_residuals,
        "iterations": r.iterations,
        "converged": r.converged,
        "reason": r.reason,
        "time_s": r.time_s,
        "noise": u.noise,
        "metrics": _metrics_dict(report.metrics, report.holdout),
        "history": [
            {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in h.__dict__.items()}
            for h in r.trace.history
        ],
    }


def result_dict(run: CalibrationRun) -> dict[str, Any]:
    """The ``result.json`` document of a run."""
    sc, data, checks = run.scenario, run.data, run.checks
    return {
        "scenario": sc.name,
        "tool": {"name": "nlp_calib", "version": __version__},
        "model": sc.model,
        "dataset": {
            "path": run.log.path,
            "records": run.log.records,
            "used": list(data.used),
            "fit": list(data.fit),
            "residuals": data.n_residuals,
            "dropped_stationary": data.dropped_stationary,
            "dropped_records": [{"line": d.line, "reason": d.reason} for d in run.log.dropped],
        },
        "residual": dict(sc.residual),
        "robust": dict(sc.robust),
        "sensor": _sensor_dict(run),
        "alignment": {
            "tracker_lag_s": data.tracker_lag_s,
            "estimate": data.lag_estimate.as_dict() if data.lag_estimate is not None else None,
        },
        "initial": dict(run.initial),
        "initial_guess": sc.initial_guess,
        "baseline": {"metrics": _metrics_dict(run.baseline, run.baseline_holdout)},
        "solvers": {name: _solver_dict(run, name, rep) for name, rep in run.reports.items()},
        "crossvalidation": _crossval_dict(run),
        # Only where the drive pivots (each pivot fitted on its own): no field otherwise.
        **({"pivots": _pivots_dict(run)} if run.checks.pivots is not None else {}),
        **_check_records(run),
        "logs": _logs_dict(run),
        "start": _cost_dict(checks.start),
        "nominal": _nominal_dict(run),
        "warnings": list(run.every_warning()),
        "verdict": {
            "level": run.verdict.level,
            "reasons": list(run.verdict.reasons),
            "gain": run.verdict.gain,
            # Each parameter a caveat concerns, with it: no hand-off file writes it as calibrated.
            "concerns": dict(run.verdict.concerns),
        },
    }


def _sensor_dict(run: CalibrationRun) -> dict[str, Any]:
    """The sensor as its plug-in describes itself: its kind, pose group and scale, the parameters it
    holds (and why), its closed-form start alone and the windows the start and the fit left out,
    by reason."""
    data, info = run.data, run.scenario.sensor
    return {
        "kind": info.kind,
        "mount": info.kind,
        "group": info.group,
        "scale": info.scale,
        "held": {n: run.initial.get(n, 0.0) for n in info.held},
        "held_why": info.held_why,
        "start": dict(run.initial) if data.start_dropped is not None else None,
        "start_dropped": None if data.start_dropped is None else dict(data.start_dropped),
        "fit_dropped": None if data.fit_dropped is None else dict(data.fit_dropped),
    }


#: Keys of the plug-in checks' records that result.json has always held, null when the check did not
#: run (readers in the wild look them up).
STORED_CHECKS = ("direction", "truth", "faults", "observability")


def _check_records(run: CalibrationRun) -> dict[str, Any]:
    """What each plug-in check stores in result.json, under its name."""
    found = {r.name: r.record for r in run.checks.more if r.record is not None}
    return {**dict.fromkeys(STORED_CHECKS), **found}


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def result_document(run: CalibrationRun) -> dict[str, Any]:
    """The ``result.json`` document as plain JSON types, exactly as the file stores it."""
    doc: dict[str, Any] = json.loads(json.dumps(finite_or_null(result_dict(run)), default=_json_default))
    return doc


def write_validation(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Write ``validation.json``: the blocked cross-validation and the direction check."""
    solver = next(iter(run.reports))
    doc = {
        "scenario": run.scenario.name,
        "tool": {"name": "nlp_calib", "version": __version__},
        "solver": solver,
        "params": run.reports[solver].result.param_dict(),
        "std": sigmas(run, solver, run.std(solver)),
        "std_white_noise": sigmas(run, solver, run.reports[solver].uncertainty.std_dict()),
        "crossvalidation": _crossval_dict(run),
        "direction": _check_records(run)["direction"],
    }
    path = folder / name
    text = json.dumps(
        json.loads(json.dumps(finite_or_null(doc), default=_json_default)), indent=2, allow_nan=False
    )
    atomic_write_text(path, text + "\n")
    return [path]


def write_result(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Write ``result.json`` atomically."""
    path = folder / name
    text = json.dumps(result_document(run), indent=2, allow_nan=False)
    atomic_write_text(path, text + "\n")
    return [path]


def write_odometry(run: CalibrationRun, folder: Path, name: str) -> list[Path]:
    """Write the calibrated odometry with its covariance as CSV, one row per record."""
    if run.odometry is None:
        return []
    atomic_write_text(folder / name, run.odometry.csv())
    return [folder / name]
