"""Repair of counter faults on joints read in radians: the tracker-implied amount, no counter width.

A joint's angle has no counter width to wrap: a fault's deficit is corrected by what the tracker
implies, added to the position that shows it and every later one, in the positions at the records
and in the joints' own stream (from the first message after the record before the fault), so that
a later re-sampling at a tracker lag keeps the correction.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nlp_calib.logs import Log
from nlp_calib.logs.log import frozen
from nlp_calib.results.faults import FaultReport


def repair_joints(log: Log, report: FaultReport) -> tuple[Log, tuple[str, ...]]:
    """``log`` (joints in radians) with its counter faults corrected, and one line per change."""
    assert log.joint_positions is not None and log.joint_stream is not None
    positions = np.array(log.joint_positions, dtype=float)
    stream = np.array(log.joint_stream.positions, dtype=float)
    changes = []
    for f in report.counter_faults:
        assert f.encoder is not None
        col = log.header.encoder_index(f.encoder)
        correction = f.implied - f.logged
        positions[f.record :, col] += correction
        stream[log.joint_stream.time_s > log.time_s[f.record - 1], col] += correction
        changes.append(
            f"joint {f.encoder!r} at record {f.record} ({log.where(f.line)}): {correction:+.4g} rad added "
            f"from there on (the tracker's motion implied it, ± {f.noise:.2g}, over records "
            f"{f.first}-{f.record})"
        )
    repaired = replace(log.joint_stream, positions=frozen(stream))
    return replace(log, joint_positions=frozen(positions), joint_stream=repaired), tuple(changes)
