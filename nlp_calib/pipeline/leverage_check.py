"""The ``leverage`` plug-in check: does the drive determine what it determines throughout, or in one
stretch of it only?

A direction of the parameters is determined when the information the drive gives along it clears
a floor (:mod:`nlp_calib.analysis.degeneracy`). Where one stretch gives nearly all of it, the rest
of the drive leaves that direction free: a start from standstill that no sinusoid of the rest
imitates, the one turn of a log that otherwise drives straight. The estimate along it then rests on
that stretch alone, and neither σ shows it: the white-noise σ counts the stretch's information as
the drive's, and the blocked cross-validation's fold without the stretch has no information along
the direction, so its refit stays where it starts, at the estimate. A check of the calibration on a
drive without such a stretch cannot test it. For each block of the cross-validation (its records,
``validation.blocks`` of them) the check takes the information of the windows that touch it out
of the whole fit's (data terms alone, at the estimate) and asks whether the rest still determines
every direction the whole did, by the same floor. A direction one block alone holds is a caveat
concerning every parameter it moves (so no hand-off file writes them as calibrated), naming the
block's records and how far the rest falls short.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from nlp_calib.analysis.crossval import blocks
from nlp_calib.analysis.degeneracy import FIDELITY, free_directions, motion_scale, scales
from nlp_calib.pipeline.analyse import RELEASE_FROM
from nlp_calib.pipeline.build import no_priors
from nlp_calib.pipeline.fit import Fit
from nlp_calib.results import CalibrationRun
from nlp_calib.results.checks import CAVEAT, CheckResult
from nlp_calib.solvers import ProblemEvaluator

NAME = "leverage"
#: A parameter moves along a direction when its squared share of it exceeds this (as the
#: uncertainty names the parameters of a direction the drive leaves free).
SHARE = 1e-3


@dataclasses.dataclass(frozen=True)
class Stretch:
    """A block of records ``[first, stop)`` without whose windows the drive leaves the parameters
    ``names`` free; ``shortfall``: the information the rest gives along the weakest direction over
    the floor that determines it (below 1)."""

    first: int
    stop: int
    names: tuple[str, ...]
    shortfall: float

    def as_dict(self) -> dict[str, object]:
        return {
            "records": [self.first, self.stop],
            "parameters": list(self.names),
            "shortfall": self.shortfall,
        }


def information(ev: ProblemEvaluator, x: np.ndarray) -> np.ndarray:
    """The data's information at ``x`` (the normal matrix without the priors' part)."""
    H = np.asarray(ev.normal_equations(x).H, dtype=float)
    return H - ev.prior_information(x) if ev.priors.active else H


def _moved(V: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Which parameters the directions ``V[:, free]`` move."""
    return np.asarray((V[:, free] ** 2).sum(axis=1) > SHARE)


def stretches(fit: Fit, x: np.ndarray, ranges: Sequence[tuple[int, int]], first: int) -> list[Stretch]:
    """Each block of ``ranges`` (records numbered from ``first``) without whose windows the fit's
    data at ``x`` (free values) leaves a direction free that all of them determine."""
    fns, data, binder = fit.fns, fit.data, fit.problem.binder
    values = np.asarray(fns.assemble(x, binder.x_fixed), dtype=float).ravel()
    scale = scales(fns, values[[fns.names.index(f) for f in fns.free]])
    RR = np.outer(scale, scale)
    H, omega = information(fit.evaluator, x), fit.evaluator.omega
    lam, V = np.linalg.eigh(H * RR)
    whole = _moved(V, free_directions(lam, data.n_residuals, motion_scale(fns, data.z, omega)))
    data_only = dataclasses.replace(binder, priors=no_priors(fns.n_free))
    found = []
    for a, b in ranges:
        bad = np.zeros(data.n_records - 1, dtype=bool)
        bad[a - first : b - first - 1] = True
        crossing = data.interval_counts(bad) > 0
        if not crossing.any() or crossing.all():
            continue
        left = data_only.evaluate(data.select(crossing))
        H_rest = H - np.asarray(left.normal_equations(x).H, dtype=float)
        left.release()
        n, m2 = int((~crossing).sum()), motion_scale(fns, data.z[:, ~crossing], omega)
        lam_r, V_r = np.linalg.eigh(H_rest * RR)
        moved = _moved(V_r, free_directions(lam_r, n, m2)) & ~whole
        if moved.any():
            floor = FIDELITY**2 * n * m2
            names = tuple(f for f, m in zip(fns.free, moved) if m)
            found.append(Stretch(a, b, names, max(float(lam_r[0]), 0.0) / floor if floor > 0 else 0.0))
    return found


def _share(shortfall: float) -> str:
    """How much of the information that determines a direction the rest gives, in words."""
    return "none of" if shortfall < 1e-6 else f"{shortfall:.2g}×"


def _words(s: Stretch, k: int) -> str:
    many = len(s.names) > 1
    they, their, weakest = ("them", "their", "their weakest combination") if many else ("it", "its", "it")
    return (
        f"{', '.join(s.names)} {'are' if many else 'is'} determined only through records "
        f"{s.first}–{s.stop - 1} (one of the drive's {k} blocks): the rest of the drive leaves {they} "
        f"free (it gives {_share(s.shortfall)} the information that determines {weakest}), so {their} "
        f"estimates and σ rest on those records alone, and a check on a drive without such a "
        f"stretch cannot test {they}"
    )


def check(run: CalibrationRun, fit: Fit | None) -> CheckResult | None:
    """The blocks one of which alone determines a direction of the run's estimate (None: there
    are none, no fit at hand, no converged estimate, or no blocks asked for)."""
    solver = run.chosen_solver()
    k = fit.problem.binder.scenario.validation.blocks if fit is not None else 0
    if fit is None or solver is None or not k or not run.reports[solver].result.converged:
        return None
    x = np.asarray(run.reports[solver].result.x, dtype=float)
    first, stop = run.data.fit
    if stop - first != fit.data.n_records:  # several logs end to end: the joint records
        first, stop = 0, fit.data.n_records
    found = stretches(fit, x, blocks(first, stop, k), first)
    if fit.evaluator.n_residuals >= RELEASE_FROM:
        fit.evaluator.release()  # a later use binds it again
    if not found:
        return None
    concerns: dict[str, str] = {}
    for s in found:
        for name in s.names:
            concerns.setdefault(name, _words(s, k))
    said = list(dict.fromkeys(_words(s, k) for s in found))
    return CheckResult(
        NAME,
        CAVEAT,
        said[0],
        tuple(said[1:]),
        caveat=said[0],
        caveats=tuple(said[1:]),
        concerns=concerns,
        record={"stretches": [s.as_dict() for s in found]},
        how=(
            "Each block's windows are taken out of the fit's information at the estimate, and what is "
            "left judged by the floor that decides what a drive determines."
        ),
    )
