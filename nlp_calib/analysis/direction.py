"""Whether forward and reverse driving tell the same story: separate fits compared in their σ.

A calibration fitted to forward-only windows and one fitted to reverse-only windows should agree
within their uncertainty. Each part's σ is the jackknife σ of blocks of that part alone (the whole
fit's σ would not do: its blocks mix both directions, so it contains the very disagreement under
test); the difference is judged against ``√(σ_forward² + σ_reverse²)``. A disagreement beyond
:data:`SIGNIFICANT` of that and beyond the precision the calibration needs (see
:attr:`~nlp_calib.results.checks.DirectionCheck.flagged`) means the model misses something that
depends on the direction of travel.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.results.checks import DirectionCheck


def compare(
    names: tuple[str, ...],
    forward: np.ndarray,
    reverse: np.ndarray,
    windows: tuple[int, int],
    std_forward: np.ndarray,
    std_reverse: np.ndarray,
    held: set[str],
    apart: np.ndarray | None = None,
    needed: np.ndarray | None = None,
) -> DirectionCheck:
    """The check of two part fits and their σ; parameters held in a part are not compared.
    ``apart``: per parameter, the difference beyond which the two parts cannot both describe one
    robot (then a part's fit, not a model limit, is in question: the σ is not widened by it).
    ``needed``: per parameter, the precision a useful calibration needs (a smaller difference is
    no finding, however many σ)."""
    sigma = np.sqrt(std_forward**2 + std_reverse**2)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sigma > 0, (forward - reverse) / sigma, np.nan)
    z = np.where([n in held for n in names], np.nan, z)
    return DirectionCheck(
        names=names, forward=forward, reverse=reverse, windows=windows, z=z, apart=apart, needed=needed
    )
