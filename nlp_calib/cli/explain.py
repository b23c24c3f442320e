"""One-line explanations of outcomes that are not errors of the input but still fail a command."""

from __future__ import annotations

from pathlib import Path

from nlp_calib.analysis.crossval import blocks as cut_blocks
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import MIN_FOLDS


def no_crossvalidation(run: CalibrationRun, blocks: int) -> str:
    """Why ``validate`` has no cross-validation of ``run`` (asked for ``blocks`` blocks), and what to do."""
    sc = run.scenario
    where = f"{sc.path or sc.name}: {Path(sc.dataset).name}"
    first, stop = run.data.fit
    made = len(cut_blocks(first, stop, blocks))
    if made < MIN_FOLDS:
        return (
            f"{where}: the log is too short to cross-validate: its {stop - first} fitted records make "
            f"{made} block(s) of at least 2 records where validation.blocks asks for {blocks}, and "
            f"{MIN_FOLDS} fits are needed; use a longer log (or wider samples)"
        )
    cv = run.checks.crossval
    if cv is None:
        solver, report = next(iter(run.reports.items()))
        return (
            f"{where}: {solver} did not converge on the fitted records ({report.result.reason}), so "
            "there is nothing to cross-validate; see the run's warnings, or use a longer log"
        )
    folds = cv.folds
    converged = sum(f.converged for f in folds)
    return (
        f"{where}: only {converged} of {len(folds)} cross-validation fits converged ({MIN_FOLDS} are "
        "needed): each fit leaves out one block, and the rest does not determine every parameter; use "
        "fewer blocks (--blocks, validation.blocks) or a longer log"
    )
