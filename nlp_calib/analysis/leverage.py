"""Which stretch of the drive alone determines a direction of the parameters.

A direction is determined when the information the drive gives along it clears a floor
(:mod:`nlp_calib.analysis.degeneracy`). Where one stretch gives nearly all of it, the rest of the
drive leaves that direction free: a start from standstill that no sinusoid of the rest imitates,
the one turn of a log that otherwise drives straight. The estimate along it then rests on that
stretch alone, and neither σ shows it: the white-noise σ counts the stretch's information as the
whole drive's, and a blocked cross-validation's fold without the stretch has no information along
the direction, so its refit stays where it starts, at the estimate. The uncertainty already sums
each contiguous batch of windows' information (:class:`~nlp_calib.analysis.residual_floor.ScoreRows`):
each batch's is taken out of the whole in turn, and what is left judged by the same floor; then
each two neighbouring batches together where neither alone is found, for a stretch across their
boundary (each alone leaves the other half). A stretch across three is not found.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.analysis.degeneracy import FIDELITY, free_directions, motion_terms
from nlp_calib.problem import ProblemFunctions, ResidualData
from nlp_calib.results.uncertainty import Stretch

#: A parameter moves along a direction when its squared share of it exceeds this (as the
#: uncertainty names the parameters of a direction the drive leaves free).
SHARE = 1e-3


def _moved(V: np.ndarray, free: np.ndarray) -> np.ndarray:
    """Which parameters the directions ``V[:, free]`` move."""
    return np.asarray((V[:, free] ** 2).sum(axis=1) > SHARE)


def _own_log(fns: ProblemFunctions, data: ResidualData) -> list[np.ndarray | None]:
    """Per free parameter, the windows of the log it belongs to (None: the logs share it)."""
    of = data.log_of(data.starts)
    logs = [fns.layout.param(n).log if n in fns.layout else None for n in fns.free]
    return [None if i is None else of == i for i in logs]


def _gone(own: list[np.ndarray | None], rest: np.ndarray) -> np.ndarray:
    """Which free parameters' own log has no window in ``rest``."""
    return np.array([w is not None and not (w & rest).any() for w in own], dtype=bool)


def stretches(
    fns: ProblemFunctions,
    data: ResidualData,
    omega: np.ndarray,
    scale: np.ndarray,
    batches: tuple[np.ndarray, np.ndarray],
) -> tuple[Stretch, ...]:
    """The batches of windows (``batches``: each one's data information ``(B, n, n)``, free
    parameters' coordinates, and the window indices that bound them, ``B + 1``) without whose
    windows the rest leaves a direction free that all of them determine, one batch at a time and
    then two neighbours together where neither alone is found (a turn across their boundary);
    ``scale``: each free parameter's reference precision, the units the floor is judged in."""
    information, edges = batches
    if information.shape[0] < 2:
        return ()
    RR = np.outer(scale, scale)
    H = information.sum(axis=0)
    lam, V = np.linalg.eigh(H * RR)
    # Each window's motion term once: every stretch's scale is the mean of the rest's.
    motion = motion_terms(fns, data.z, omega)
    whole = _moved(V, free_directions(lam, data.n_residuals, float(np.mean(motion)) if motion.size else 0.0))
    own = _own_log(fns, data)

    def without(lo: int, hi: int) -> Stretch | None:
        """The stretch of batches ``lo … hi − 1``, where the rest leaves a direction free."""
        rest = np.ones(data.n_residuals, dtype=bool)
        rest[edges[lo] : edges[hi]] = False
        if not rest.any() or rest.all():
            return None
        n, m2 = int(rest.sum()), float(np.mean(motion[rest]))
        lam_r, V_r = np.linalg.eigh((H - information[lo:hi].sum(axis=0)) * RR)
        # A log's own parameter (its clock, its mount) with none of its log's windows left is free
        # by construction: its log is the stretch, which is no finding.
        moved = _moved(V_r, free_directions(lam_r, n, m2)) & ~whole & ~_gone(own, rest)
        if not moved.any():
            return None
        floor = FIDELITY**2 * n * m2
        names = tuple(f for f, m in zip(fns.free, moved) if m)
        first, stop = int(data.starts[edges[lo]]), int(data.stops[edges[hi] - 1]) + 1
        shortfall = max(float(lam_r[0]), 0.0) / floor if floor > 0 else 0.0
        return Stretch(first, stop, names, shortfall, information.shape[0], data.n_records, hi - lo)

    B = information.shape[0]
    single = [without(b, b + 1) for b in range(B)]
    pairs = [without(b, b + 2) for b in range(B - 1) if single[b] is None and single[b + 1] is None]
    return tuple(s for s in (*single, *pairs) if s is not None)
