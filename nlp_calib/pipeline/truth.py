"""A simulated log's known truth beside it: the estimate against it, in the σ to believe.

``nlp-calib simulate`` writes ``<log>.truth.json`` beside every log it makes; a run on such a log
says how far its estimate is from the truth, in σ, so that the demo shows what the σ mean.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from nlp_calib.core.errors import NlpCalibWarning
from nlp_calib.core.files import truth_path
from nlp_calib.models.clock import LAG_PARAM
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import FINE, CheckResult, TruthCheck
from nlp_calib.results.codec import finite_or_null

#: Parameter values in one form's names and units into another's.
Converter = Callable[[Mapping[str, float]], dict[str, float]]


def read_truth(log_path: Path) -> dict[str, float] | None:
    """The true parameters in the truth file beside ``log_path``; None when there is none (a
    file that is not one the simulator wrote is said in a warning and left alone)."""
    path = truth_path(log_path)
    if not path.is_file():
        return None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
        out = {str(k): float(v) for k, v in doc["params"].items()}
        options = doc.get("options") if isinstance(doc.get("options"), dict) else {}
        lag = doc.get("lag_s", options.get("latency_s"))  # the stamps' offset the simulator applied
        if isinstance(lag, (int, float)) and not isinstance(lag, bool):
            out[LAG_PARAM] = float(lag)
        return out
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError):
        warnings.warn(
            f"{path}: not a truth file nlp-calib simulate wrote (no 'params' mapping of numbers); "
            "the estimate is not compared with it",
            NlpCalibWarning,
            stacklevel=2,
        )
        return None


def check(run: CalibrationRun, files: Sequence[Path] = (), convert: Converter = dict) -> CheckResult | None:
    """:func:`against_truth` as the ``truth`` plug-in check's result (its one wording: how far the
    estimate is from the truth, in σ, and each parameter's error in its σ)."""
    t = against_truth(run, files, convert)
    if t is None:
        return None
    cells = ", ".join(f"{n} {z:+.1f}σ" for n, z in zip(t.names, t.z) if np.isfinite(z))
    columns = {"truth": t.truth, "error": t.error, "error_in_sigma": t.z}
    about = {"file": t.path, "solver": t.solver}
    table = {key: dict(zip(t.names, map(float, v))) for key, v in columns.items()}
    return CheckResult(
        "truth",
        FINE,
        f"against the simulator's truth ({t.path}), {t.solver}: {t.words()}",
        (cells,),
        about,
        table,
        record=finite_or_null({**about, **table}),
    )


def against_truth(
    run: CalibrationRun, files: Sequence[Path] = (), convert: Converter = dict
) -> TruthCheck | None:
    """The chosen solver's estimate against the truth beside the run's log (or beside the first of
    its source's ``files`` that has one: a camera's TUM file), in the run's names and units by
    ``convert`` (a camera simulation's truth is in the model's counts form's names and units)."""
    solver = run.chosen_solver()
    if solver is None:
        return None
    path = next((p for p in (Path(run.log.path), *files) if truth_path(p).is_file()), None)
    found = read_truth(path) if path is not None else None
    if path is None or found is None:
        return None
    truth = convert(found)
    result = run.reports[solver].result
    std = run.std(solver)
    true = np.array([truth.get(n, np.nan) for n in result.names])
    sigma = np.array([std.get(n, 0.0) for n in result.names])
    error = result.params - true
    z = np.where(sigma > 0, error / np.where(sigma > 0, sigma, 1.0), np.nan)
    return TruthCheck(str(truth_path(path)), solver, result.names, true, error, z)
