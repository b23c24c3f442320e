"""``result.json``: the document a run writes into its output folder."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.analysis.metrics import TrajectoryMetrics
from nlp_calib.core.files import atomic_write_text
from nlp_calib.core.version import __version__
from nlp_calib.pipeline import CalibrationRun, SolverReport

RESULT_FILE = "result.json"


def _metrics_dict(full: TrajectoryMetrics, holdout: TrajectoryMetrics | None) -> dict[str, Any]:
    out: dict[str, Any] = full.as_dict()
    if holdout is not None:
        out.update({f"holdout_{k}": v for k, v in holdout.as_dict().items()})
    return out


def _faults_dict(run: CalibrationRun) -> dict[str, Any] | None:
    if run.findings is None:
        return None
    rep = run.findings.report
    return {
        "handling": run.findings.handling,
        "checked": not rep.unchecked,
        "unchecked_reason": rep.unchecked or None,
        "found": [f.as_dict() for f in rep.faults],
        "windows_left_out": run.dropped_faulty,
        "repairs": list(run.findings.repairs),
        "stale_readings": dict(rep.stale),
        "noise_ticks": dict(rep.noise_ticks),
    }


def _crossval_dict(run: CalibrationRun) -> dict[str, Any] | None:
    cv = run.crossval
    if cv is None:
        return None
    return {
        "blocks": len(cv.folds),
        "std_blocks": run.std_blocks(),
        "spread": dict(zip(cv.names, map(float, cv.spread()))),
        "heldout": {label: cv.heldout_mean(label) for label, _ in cv.folds[0].heldout.figures()[:4]}
        if cv.folds and cv.folds[0].heldout is not None
        else {},
        "folds": [
            {
                "records": [f.first, f.stop],
                "converged": f.converged,
                "params": dict(zip(cv.names, map(float, f.params))),
                "heldout": f.heldout.as_dict() if f.heldout is not None else None,
            }
            for f in cv.folds
        ],
    }


def _solver_dict(run: CalibrationRun, name: str, report: SolverReport) -> dict[str, Any]:
    r, u = report.result, report.uncertainty
    return {
        "params": r.param_dict(),
        "std": run.std(name),
        "std_white_noise": u.std_dict(),
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
            for h in r.history
        ],
    }


def result_dict(run: CalibrationRun) -> dict[str, Any]:
    """The ``result.json`` document of a run."""
    sc = run.scenario
    return {
        "scenario": sc.name,
        "tool": {"name": "nlp_calib", "version": __version__},
        "model": sc.model,
        "dataset": {
            "path": str(sc.dataset),
            "records": run.log.n_records,
            "used": list(run.used),
            "fit": list(run.fit),
            "residuals": run.n_residuals,
            "dropped_stationary": run.dropped_stationary,
            "dropped_records": [{"line": d.line, "reason": d.reason} for d in run.log.dropped],
        },
        "residual": dict(sc.residual.__dict__),
        "robust": dict(sc.robust.__dict__),
        "alignment": {
            "tracker_lag_s": run.tracker_lag_s,
            "estimate": run.lag_estimate.as_dict() if run.lag_estimate is not None else None,
        },
        "initial": dict(run.initial),
        "initial_guess": sc.initial_guess if isinstance(sc.initial_guess, str) else "mapping",
        "baseline": {"metrics": _metrics_dict(run.baseline, run.baseline_holdout)},
        "solvers": {name: _solver_dict(run, name, rep) for name, rep in run.reports.items()},
        "crossvalidation": _crossval_dict(run),
        "direction": run.direction.as_dict() if run.direction is not None else None,
        "faults": _faults_dict(run),
        "observability": run.observability.as_dict() if run.observability is not None else None,
        "warnings": list(run.warnings),
    }


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"cannot serialise {type(obj).__name__}")


def finite_or_null(obj: Any) -> Any:
    """The same structure with NaN and infinities as ``None`` (JSON has no such numbers)."""
    if isinstance(obj, float | np.floating):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [finite_or_null(v) for v in obj]
    return obj


def result_document(run: CalibrationRun) -> dict[str, Any]:
    """The ``result.json`` document as plain JSON types, exactly as the file stores it."""
    doc: dict[str, Any] = json.loads(json.dumps(finite_or_null(result_dict(run)), default=_json_default))
    return doc


VALIDATION_FILE = "validation.json"
ODOMETRY_CSV = "odometry.csv"
ODOMETRY_PNG = "odometry.png"


def write_validation(run: CalibrationRun, out_dir: Path) -> Path:
    """Write ``out_dir/validation.json``: the blocked cross-validation and the direction check."""
    solver = next(iter(run.reports))
    doc = {
        "scenario": run.scenario.name,
        "tool": {"name": "nlp_calib", "version": __version__},
        "solver": solver,
        "params": run.reports[solver].result.param_dict(),
        "std": run.std(solver),
        "std_white_noise": run.reports[solver].uncertainty.std_dict(),
        "crossvalidation": _crossval_dict(run),
        "direction": run.direction.as_dict() if run.direction is not None else None,
    }
    path = out_dir / VALIDATION_FILE
    text = json.dumps(
        json.loads(json.dumps(finite_or_null(doc), default=_json_default)), indent=2, allow_nan=False
    )
    atomic_write_text(path, text + "\n")
    return path


def write_result(run: CalibrationRun, out_dir: Path) -> Path:
    """Write ``out_dir/result.json`` atomically and return its path."""
    path = out_dir / RESULT_FILE
    text = json.dumps(result_document(run), indent=2, allow_nan=False)
    atomic_write_text(path, text + "\n")
    return path
