"""Results layer: what a calibration found, as plain records (numbers, arrays, words).

The records are computed by the layers below the pipeline and assembled by its stages; the
outputs only format them. Every record stores as JSON types and reads back (:mod:`.codec`).
Depends on numpy alone.
"""

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
