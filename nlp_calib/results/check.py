"""What a check of a stored calibration on a new log found: each parameter's change in its σ, and
the verdict (still good, drifted, cannot tell).

Computed by :mod:`nlp_calib.analysis.drift` (the statistics) and the pipeline's check stage; the
record carries what it compared (the stored values and σ, the refit's) so that it reads alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The check's verdicts, and the exit code of ``nlp-calib check`` for each.
STILL_GOOD = "still good"
DRIFTED = "drifted"
CANNOT_TELL = "cannot tell"
EXIT_CODES = {STILL_GOOD: 0, DRIFTED: 3, CANNOT_TELL: 4}


@dataclass(frozen=True)
class ParameterChange:
    """One parameter: the stored value and its σ to believe, the refit's on the new log, the
    change in units of the combined σ ``z`` (each σ without the part from values both fits hold,
    which moves them alike: :func:`~nlp_calib.analysis.drift.common_held`), the degrees of freedom
    of that σ and the threshold ``|z|`` must pass to count as a drift; ``untested`` says why the new
    log cannot test it ("" when it can)."""

    name: str
    unit: str
    stored: float
    refit: float
    std_stored: float
    std_refit: float
    dof: float
    z: float
    threshold: float
    untested: str = ""
    #: Whether the parameter is a gain or a length whose change reads as a percentage.
    relative: bool = False
    #: The change in units of the combined σ widened as if errors that vary along the drive were
    #: shared by all of a log's blocks (:func:`~nlp_calib.analysis.drift.between_logs_std`).
    z_shared: float = math.nan

    @property
    def change(self) -> float:
        return self.refit - self.stored

    @property
    def drifted(self) -> bool:
        return not self.untested and math.isfinite(self.z) and abs(self.z) > self.threshold

    @property
    def confirmed(self) -> bool:
        """Whether the change passes the threshold also with errors shared by a log's blocks
        (NaN ``z_shared``: nothing to widen, confirmed as it is)."""
        return not math.isfinite(self.z_shared) or abs(self.z_shared) > self.threshold


@dataclass(frozen=True)
class DriftCheck:
    """A stored calibration (``calibration``: its file; ``solver``: the refit's solver) checked on
    a new log: per parameter the change (:class:`ParameterChange`), the family-wise false-alarm
    rate the thresholds hold (``false_alarm``), the verdict, its reasons, and what to drive
    (``hint``) when the log cannot tell."""

    calibration: str
    solver: str
    changes: tuple[ParameterChange, ...]
    false_alarm: float
    verdict: str
    reasons: tuple[str, ...]
    hint: str = ""

    @property
    def exit_code(self) -> int:
        return EXIT_CODES[self.verdict]

    @property
    def drifted(self) -> tuple[ParameterChange, ...]:
        return tuple(c for c in self.changes if c.drifted)

    @property
    def untested(self) -> tuple[ParameterChange, ...]:
        return tuple(c for c in self.changes if c.untested)

    def line(self) -> str:
        """The verdict in one line: the verdict, then its reasons."""
        head = {DRIFTED: "DRIFTED: recalibrate", STILL_GOOD: "STILL GOOD", CANNOT_TELL: "CANNOT TELL"}
        text = head[self.verdict] + (": " + "; ".join(self.reasons) if self.reasons else "")
        return text + (f"; {self.hint}" if self.hint else "")
