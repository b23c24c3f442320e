"""The pre-flight every calibrating command runs first: each scenario through the run's stages up
to its windows, then judged; a calibration that cannot succeed stops here."""

from __future__ import annotations

import warnings
from collections.abc import Sequence

from nlp_calib.core.errors import DatasetError, NlpCalibWarning, ScenarioError, UsageError
from nlp_calib.core.text import escaped
from nlp_calib.logs import Log
from nlp_calib.outputs.preflight import preflight_lines
from nlp_calib.pipeline import Scenario
from nlp_calib.pipeline.preflight import refuse, stops
from nlp_calib.pipeline.stages import Aligned, align_log


def gate(
    scenarios: Sequence[Scenario],
    logs: Sequence[Sequence[Log]],
    skip: bool,
    runs: Sequence[Aligned | None] = (),
) -> None:
    """The pre-flight of each scenario on its logs (read already): a calibration that cannot succeed
    stops here with the pre-flight's words (``--skip-preflight``: it goes on). ``runs``: each
    scenario's run's stages before its windows are bound (None: none), whose lag estimate, prepared
    log and backend the pre-flight judges with (else it prepares and searches its own)."""
    if skip:
        return
    for sc, log_list, run in zip(scenarios, logs, [*runs, *[None] * (len(scenarios) - len(runs))]):
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
        refuse(report, "; to calibrate anyway, give --skip-preflight")


def set_up_and_gate(
    scenarios: Sequence[Scenario],
    logs: Sequence[Sequence[Log]],
    skip: bool,
    solvers: Sequence[str] | None,
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
    gate(scenarios, logs, skip, aligned)
    for w in {(str(w.message), w.category, w.filename, w.lineno): w for w in said}.values():
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    return aligned


def _aligned(sc: Scenario, log: Log, solvers: Sequence[str] | None) -> Aligned | None:
    try:
        return align_log(sc, log, tuple(solvers or sc.solvers))
    except Exception:  # said by the run, in its turn, which goes through these stages again
        return None
