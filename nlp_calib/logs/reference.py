"""What a log's reference measures, and what that means for its windows.

A reference either gives the sensor's **poses** (a tracker, a camera, a GNSS/vision device: any two
of them give the motion between them, so a window may span any records) or its own **motions**
between two of its stamps (a scan matcher, visual odometry, a vendor's increments: each increment
is compared with the wheels over exactly its two stamps, and intervals no one-interval increment
measures have no reference). Each kind is one class here and one line of :data:`REFERENCES`; a
log's reference names its kind (``log.reference.kind``) and the stages ask the kind, never the
log's fields.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar, Protocol

import numpy as np

from nlp_calib.logs.relative import RelativeMotions


class ReferenceKind(Protocol):
    """What the stages ask of a reference's kind."""

    name: ClassVar[str]
    #: Whether each window's measurement is one the reference made itself (its noise its own,
    #: not the difference of two poses').
    own_increments: ClassVar[bool]
    #: What one of its windows is called in messages.
    window_words: ClassVar[str]

    def uncovered(self, n_records: int) -> np.ndarray: ...  # the intervals no measurement covers
    def own_windows(self, z: np.ndarray) -> np.ndarray: ...  # per window (z's columns): its own noise?
    def window_count(self, span: tuple[int, int], horizon: int, stride: int) -> int: ...
    def horizon(self, horizon: int) -> int | None: ...  # its own, or None: the scenario's


@dataclass(frozen=True)
class Poses:
    """Poses of the sensor: windows of ``horizon`` records every ``stride``."""

    name: ClassVar[str] = "poses"
    own_increments: ClassVar[bool] = False
    window_words: ClassVar[str] = "residual window(s)"

    def uncovered(self, n_records: int) -> np.ndarray:
        return np.zeros(max(n_records - 1, 0), dtype=bool)

    def window_count(self, span: tuple[int, int], horizon: int, stride: int) -> int:
        intervals = span[1] - span[0] - 1
        return 0 if intervals < horizon else (intervals - horizon) // stride + 1

    def horizon(self, horizon: int) -> int | None:
        return None

    def own_windows(self, z: np.ndarray) -> np.ndarray:
        """None: each window's noise is its two poses'."""
        return np.zeros(np.shape(z)[1], dtype=bool)


@dataclass(frozen=True)
class Motions:
    """The sensor's own ``motions`` between pairs of its stamps: each increment is a window."""

    name: ClassVar[str] = "motions"
    own_increments: ClassVar[bool] = True
    window_words: ClassVar[str] = "increment(s)"

    motions: RelativeMotions

    def uncovered(self, n_records: int) -> np.ndarray:
        return ~self.motions.covered(n_records)

    def window_count(self, span: tuple[int, int], horizon: int, stride: int) -> int:
        return -(-self.motions.select(*span).n // stride)

    def horizon(self, horizon: int) -> int:
        """1 when every increment spans one interval (the fastest form), else at least 2 (an
        increment may span several records)."""
        spans = self.motions.last - self.motions.first
        return 1 if spans.size and np.all(spans == 1) else max(horizon, 2)

    def own_windows(self, z: np.ndarray) -> np.ndarray:
        """Every window's noise is its own."""
        return np.ones(np.shape(z)[1], dtype=bool)


@dataclass(frozen=True)
class PoseMotions(Motions):
    """A tracker's poses as the motions between each two consecutive ones, beside a second sensor's
    own increments (a gyro's, :mod:`nlp_calib.logs.beside`): the windows are the increments, as
    :class:`Motions`' are, but a tracker's window's noise is its two poses' (two consecutive
    windows share one). Each window's ``z`` ends in a row saying whose it is (1: the second
    sensor's)."""

    name: ClassVar[str] = "pose_motions"

    def own_windows(self, z: np.ndarray) -> np.ndarray:
        """The second sensor's windows (its noise its own), not the tracker's."""
        return np.asarray(np.asarray(z)[-1] > 0.5)


class Measured(Protocol):
    """What a reference holds that its kind may read (``nlp_calib.logs.log.ReferenceData``)."""

    @property
    def motions(self) -> RelativeMotions | None: ...


def _own_motions(reference: Measured) -> Motions:
    if reference.motions is None:
        raise ValueError("a reference said to measure its own motions holds none")
    return Motions(reference.motions)


#: The reference kinds, by the name a log's reader gives its reference (``ReferenceData.measures``):
#: each built from what the reference holds.
REFERENCES: dict[str, Callable[[Measured], ReferenceKind]] = {
    Poses.name: lambda reference: Poses(),
    Motions.name: _own_motions,
    PoseMotions.name: lambda reference: PoseMotions(_own_motions(reference).motions),
}
