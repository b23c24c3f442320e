"""Results layer: what a calibration found, as plain records (numbers, arrays, words).

The records are computed by the layers below the pipeline and assembled by its stages; the
outputs only format them. Every record stores as JSON types and reads back (:mod:`.codec`).
Depends on numpy alone.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nlp_calib.core import lazy

if TYPE_CHECKING:
    from nlp_calib.results.run import (
        CalibrationRun,
        Checks,
        DataInfo,
        DroppedLine,
        Encoder,
        LogInfo,
        ScenarioInfo,
        SensorInfo,
        SolverReport,
        Verdict,
    )
    from nlp_calib.results.solver import IterationRecord, SolverResult

# Each name's module is imported at the name's first use (core/lazy.py).
_EXPORTS: dict[str, str] = {
    "CalibrationRun": "nlp_calib.results.run",
    "Checks": "nlp_calib.results.run",
    "DataInfo": "nlp_calib.results.run",
    "DroppedLine": "nlp_calib.results.run",
    "Encoder": "nlp_calib.results.run",
    "LogInfo": "nlp_calib.results.run",
    "ScenarioInfo": "nlp_calib.results.run",
    "SensorInfo": "nlp_calib.results.run",
    "SolverReport": "nlp_calib.results.run",
    "Verdict": "nlp_calib.results.run",
    "IterationRecord": "nlp_calib.results.solver",
    "SolverResult": "nlp_calib.results.solver",
}

__getattr__, __dir__ = lazy.exports(__name__, _EXPORTS)

__all__ = [
    "CalibrationRun",
    "Checks",
    "DataInfo",
    "DroppedLine",
    "Encoder",
    "IterationRecord",
    "LogInfo",
    "ScenarioInfo",
    "SensorInfo",
    "SolverReport",
    "SolverResult",
    "Verdict",
]
