"""One row of a batch's summary: what one log's calibration (or check) found, or why it failed.

A plain, picklable record: a batch's per-log task returns it from whatever process or machine
ran the log, and the summary table is written from the rows alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from nlp_calib.results.run import CalibrationRun

#: The verdict of a log whose calibration or check did not run to the end.
FAILED = "failed"


@dataclass(frozen=True)
class BatchRow:
    """``name``: the log's folder name in the batch; ``source``: the log or scenario file;
    ``folder``: where its files are; ``verdict`` and ``detail``: the run's verdict (or the check's)
    and its reasons; ``parameters``: the model's headline parameters, each ``(value, σ to
    believe)``, with their ``units``; ``figures``: the fair figures by label; ``error``: why it
    failed ("" when it did not); ``seconds``: its wall time; ``notes``: warnings it raised."""

    name: str
    source: str
    folder: str
    model: str = ""
    verdict: str = FAILED
    detail: str = ""
    parameters: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    units: Mapping[str, str] = field(default_factory=dict)
    figures: Mapping[str, float] = field(default_factory=dict)
    error: str = ""
    seconds: float = 0.0
    notes: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        return not self.error

    @classmethod
    def of_run(
        cls, run: CalibrationRun, where: tuple[str, str, str], seconds: float, notes: tuple[str, ...]
    ) -> BatchRow:
        """The row of a finished ``run`` of the log ``where`` = (name, source, folder)."""
        drift = run.checks.drift
        solver = drift.solver if drift is not None else run.chosen_solver()
        if drift is not None:
            verdict, detail = (
                drift.verdict,
                "; ".join((*drift.reasons, *([drift.hint] if drift.hint else []))),
            )
        else:
            verdict, detail = run.verdict.level, "; ".join(run.verdict.reasons)
        params: dict[str, tuple[float, float]] = {}
        figures: dict[str, float] = {}
        if solver is not None:
            values, std = run.reports[solver].result.param_dict(), run.std(solver)
            params = {n: (values[n], std[n]) for n in run.scenario.headline}
            figures = run.reports[solver].metrics.fair_figures()
        units = {n: run.scenario.units[n] for n in params}
        return cls(*where, run.scenario.model, verdict, detail, params, units, figures, "", seconds, notes)

    @classmethod
    def failure(
        cls, where: tuple[str, str, str], error: str, seconds: float, notes: tuple[str, ...] = ()
    ) -> BatchRow:
        """The row of a log that failed with ``error`` (one line)."""
        line = " ".join(error.split()) or "failed without a message"
        return cls(*where, error=line, seconds=seconds, notes=notes)
