"""The ``leverage`` plug-in check: does the drive determine what it determines throughout, or in one
stretch of it only?

Where one stretch of the drive gives nearly all the information along a direction of the
parameters, the rest leaves that direction free, and the estimate along it rests on that stretch
alone: neither σ shows it, and a check of the calibration on a drive without such a stretch cannot
test it (:mod:`nlp_calib.analysis.leverage`, which the uncertainty runs on the information it sums
batch by batch). Such a direction is a caveat concerning every parameter it moves, so no hand-off
file writes them as calibrated, naming the stretch's records and how far the rest falls short.
"""

from __future__ import annotations

from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, CheckResult
from nlp_calib.results.uncertainty import Stretch

NAME = "leverage"


def _share(shortfall: float) -> str:
    """How much of the information that determines a direction the rest gives, in words."""
    return "none of" if shortfall < 1e-6 else f"{shortfall:.2g}×"


def _which(s: Stretch) -> str:
    """Which of the drive's stretches it is, in words."""
    many = {1: "one", 2: "two neighbouring"}.get(s.span, f"{s.span} neighbouring")
    return f"{many} of {s.of} stretches of the drive"


def _words(s: Stretch, first: int) -> str:
    many = len(s.names) > 1
    they, their, weakest = ("them", "their", "their weakest combination") if many else ("it", "its", "it")
    return (
        f"{', '.join(s.names)} {'are' if many else 'is'} determined only through records "
        f"{first + s.first}–{first + s.stop - 1} ({_which(s)}): the rest leaves "
        f"{they} free (it gives {_share(s.shortfall)} the information that determines {weakest}), so "
        f"{their} estimates and σ rest on those records alone, and a check on a drive without such a "
        f"stretch cannot test {they}"
    )


def check(run: CalibrationRun) -> CheckResult | None:
    """The stretches one of which alone determines a direction of the chosen estimate (None: there
    are none, or no estimate converged)."""
    solver = run.chosen_solver()
    if solver is None or not run.reports[solver].uncertainty.stretches:
        return None
    found = run.reports[solver].uncertainty.stretches
    a, b = run.data.fit
    # One log: its records as the log numbers them; several: the joint fit's (the logs end to end).
    first = a if found[0].n_records == b - a else 0
    said = [_words(s, first) for s in found]
    concerns: dict[str, str] = {}
    for s, words in zip(found, said):
        for name in s.names:
            concerns.setdefault(name, words)
    return CheckResult(
        NAME,
        CAVEAT,
        said[0],
        tuple(said[1:]),
        caveat=said[0],
        caveats=tuple(said[1:]),
        concerns=concerns,
        record={"stretches": [s.as_dict(first) for s in found]},
        how=(
            "Each stretch's windows are taken out of the fit's information at the estimate, and what is "
            "left judged by the floor that decides what a drive determines."
        ),
    )
