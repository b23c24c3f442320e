"""Dead-reckoned sensor tracks and their figures per fault-free segment, for figures and TUM files.

The same steps, segments and statistics as :mod:`nlp_calib.analysis.metrics`: a track restarted
from the tracker at the start of each segment is what the segment ATE scores, and each segment's
figures are what ``evo`` computes on the segment's exported files.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from nlp_calib.analysis.metrics import (
    PLANAR,
    Geometry,
    aligned_errors,
    geometry,
    restarted,
    rpe_of,
    rpe_pairs,
    steps,
)
from nlp_calib.problem import ProblemFunctions
from nlp_calib.results.figures import RPE_DISTANCES, ErrorStats
from nlp_calib.results.series import SegmentFigures


def dead_reckoned(
    fns: ProblemFunctions,
    params: np.ndarray,
    inputs: np.ndarray,
    T_ref: np.ndarray,
    parts: Sequence[tuple[int, int]],
) -> tuple[np.ndarray, np.ndarray]:
    """The track of ``params`` from the reference's first pose (full run), and the same restarted
    from the reference at the start of each of ``parts`` (NaN outside them)."""
    step, g = steps(fns, params, inputs), geometry(fns)
    return restarted(step, T_ref, [(0, T_ref.shape[0])], g), restarted(step, T_ref, list(parts), g)


def segment_figures(
    solver: str,
    track: np.ndarray,
    T_ref: np.ndarray,
    parts: Sequence[tuple[int, int]],
    good: np.ndarray,
    g: Geometry = PLANAR,
) -> list[SegmentFigures]:
    """Each part's ATE, aligned ATE and RPE over :data:`RPE_DISTANCES` of a restarted ``track``,
    over the reference poses marked ``good`` (positions in ``g``'s dimensions)."""
    out = []
    for k, (p, q) in enumerate(parts, start=1):
        idx = p + np.flatnonzero(good[p:q])
        ate = ErrorStats.of(np.linalg.norm(track[idx, : g.dims] - T_ref[idx, : g.dims], axis=1))
        aligned = ErrorStats.of(aligned_errors(track[idx], T_ref[idx], g))
        pairs = rpe_pairs(T_ref, [idx], RPE_DISTANCES, g)
        rpe = tuple(rpe_of(track, pairs[d], g) for d in RPE_DISTANCES)
        out.append(SegmentFigures(solver, k, len(idx), ate, aligned, rpe))
    return out
