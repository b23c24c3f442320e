"""The pre-flight every calibrating command runs first: each scenario through the run's stages up
to its windows, then judged; a calibration that cannot succeed stops here."""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from nlp_calib.core.errors import DatasetError, NlpCalibWarning, ScenarioError, UsageError
from nlp_calib.core.text import escaped
from nlp_calib.logs import Log
from nlp_calib.outputs.outdir import StagedOutput
from nlp_calib.outputs.plan import write_plan_of
from nlp_calib.outputs.preflight import preflight_lines
from nlp_calib.pipeline import Scenario
from nlp_calib.pipeline.preflight import refuse, stops
from nlp_calib.pipeline.stages import Aligned, align_log
from nlp_calib.results.preflight import Preflight


def gate(
    scenarios: Sequence[Scenario],
    logs: Sequence[Sequence[Log]],
    skip: bool,
    runs: Sequence[Aligned | None] = (),
    outs: tuple[Sequence[Path], bool] = ((), False),
) -> None:
    """The pre-flight of each scenario on its logs (read already): a calibration that cannot succeed
    stops here with the pre-flight's words (``--skip-preflight``: it goes on), its plan written into
    its output folder (``outs``: each scenario's, and whether files nlp_calib did not write may be
    replaced). ``runs``: each scenario's run's stages before its windows are bound (None: none),
    whose lag estimate, prepared log and backend the pre-flight judges with (else it prepares and
    searches its own)."""
    if skip:
        return
    folders = [*outs[0], *[None] * (len(scenarios) - len(outs[0]))]
    for sc, log_list, run, out in zip(
        scenarios, logs, [*runs, *[None] * (len(scenarios) - len(runs))], folders
    ):
        lag = None if run is None else run.alignment.estimate
        try:
            report = stops(sc, log_list, lag, run)  # its σ, its plan: only where it stops
        except (DatasetError, ScenarioError, UsageError):  # the run refuses these inputs or settings
            raise  # so (its preparation, its backend): said once, now
        except Exception as exc:  # the pre-flight must never be what stops a run that could succeed
            warnings.warn(
                f"pre-flight of {sc.name} not done ({type(exc).__name__}: {exc}); the run goes on",
                NlpCalibWarning,
                stacklevel=2,
            )
            continue
        if report is None:
            continue
        print("\n".join(escaped(line) for line in preflight_lines(report)) + "\n")
        if out is not None:
            _stopped_plan(report, out, outs[1])
        refuse(report, "; to calibrate anyway, give --skip-preflight")


def _stopped_plan(report: Preflight, out: Path, force: bool) -> None:
    """``plan.md`` and ``plan.png`` of a run the pre-flight stops, in the run's output folder, as
    the run's own files: what to drive next, ranked in full (the terminal shows the first four).
    The previous run's files there go, as the run's own would have replaced them."""
    if report.plan is None:
        return
    with StagedOutput(out, "run", force=force) as stage:
        written = write_plan_of(report.plan, report.scenario, stage.path, "plan.md")
        if report.plan.ranked:  # matplotlib imported only for a sketch to draw
            figures: Any = importlib.import_module("nlp_calib.outputs.figures")
            written += figures.plan_sketch(report.plan, report.scenario, stage.path, "plan.png")
        stage.commit()
    print("\n".join(f"wrote {stage.final(p)}" for p in written) + "\n")


def set_up_and_gate(
    scenarios: Sequence[Scenario],
    logs: Sequence[Sequence[Log]],
    skip: bool,
    solvers: Sequence[str] | None,
    outs: tuple[Sequence[Path], bool] = ((), False),
) -> list[Aligned | None]:
    """Each one-log scenario through the run's stages before its windows are bound (prepared,
    screened, its lag searched), then :func:`gate` with each run's own lag estimate: the lag is
    searched once, on the screened log the run fits, not again by the pre-flight on the log as
    read; the windows are bound after the gate (their memory not held while it judges). The
    warnings of those stages are said after the gate lets the run go on, as they were when the
    gate came first. None for a scenario of several logs or whose stages failed (the run goes
    through them again when its turn comes and says why there, as it did)."""
    aligned: list[Aligned | None] = []
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for sc, log_list in zip(scenarios, logs):
            aligned.append(None if sc.data.joint else _aligned(sc, log_list[0], solvers))
    gate(scenarios, logs, skip, aligned, outs)
    for w in {(str(w.message), w.category, w.filename, w.lineno): w for w in said}.values():
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    return aligned


def _aligned(sc: Scenario, log: Log, solvers: Sequence[str] | None) -> Aligned | None:
    try:
        return align_log(sc, log, tuple(solvers or sc.solvers))
    except Exception:  # said by the run, in its turn, which goes through these stages again
        return None
