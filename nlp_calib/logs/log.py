"""A robot log in memory: :class:`LogHeader` (what the ``#`` lines say) and :class:`Log` (records)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from nlp_calib.core.errors import DatasetError
from nlp_calib.core.numeric import wrapped_difference

#: How an encoder reports: ``absolute`` readings lie in ``[0, max)`` (a steering angle);
#: ``counter`` readings are a uint32 count that wraps at 2³² (a wheel).
EncoderKind = Literal["absolute", "counter"]
ENCODER_KINDS: tuple[EncoderKind, ...] = ("absolute", "counter")


@dataclass(frozen=True)
class DroppedRecord:
    """A record left out by a non-strict read, with the line it came from and why."""

    line: int
    reason: str


@dataclass(frozen=True)
class LogHeader:
    """What the ``#`` lines say: model, initial guess, encoders, nominal ``T_base_sensor``.

    ``parameters`` keeps the header's own names (the model maps them onto its parameter names);
    ``T_base_sensor`` is ordered ``(x, y, theta)``.
    """

    kinematic_model: str
    parameters: Mapping[str, float]
    encoder_names: tuple[str, ...]
    encoder_max: tuple[int, ...]
    sensor_frame: str
    T_base_sensor: tuple[float, float, float]

    def encoder_index(self, name: str) -> int:
        """Column of the encoder called ``name`` in :attr:`Log.ticks`."""
        if name not in self.encoder_names:
            raise DatasetError(
                "<header>",
                None,
                f"the log has no encoder called {name!r} (it lists {list(self.encoder_names)})",
            )
        return self.encoder_names.index(name)

    def encoder_range(self, name: str) -> int:
        """The ``#joints_max_enc_values`` entry of encoder ``name``."""
        return self.encoder_max[self.encoder_index(name)]


@dataclass(frozen=True)
class Log:
    """An immutable robot log: per-record arrays of equal length ``n_records``.

    ``ticks`` holds the raw encoder readings (columns in ``header.encoder_names`` order),
    ``T_world_sensor`` the tracker poses and ``model_pose`` the vendor odometry, both
    ``(x, y, theta)`` per row. ``time_s`` is relative to the first record of the file, whose own
    stamp on the log's clock is ``start_ns`` (ns).
    ``(x, y, theta)`` per row. ``time_s`` is relative to the first record of the file.

    A 3-D tracker (a camera's own trajectory) fills ``T_world_sensor_3d`` too, ``(x, y, z, qx, qy,
    qz, qw)`` per row in its own world frame and units; ``T_world_sensor`` then holds its levelled
    planar track (see :func:`nlp_calib.logs.camera.planar_track`), so every planar consumer keeps
    working. ``None`` for a planar log.
    """

    path: str
    header: LogHeader
    time_s: np.ndarray
    ticks: np.ndarray
    model_pose: np.ndarray
    T_world_sensor: np.ndarray
    line_numbers: np.ndarray
    dropped: tuple[DroppedRecord, ...] = field(default=())
    start_ns: int = 0
    T_world_sensor_3d: np.ndarray | None = None

    @property
    def n_records(self) -> int:
        return int(self.time_s.shape[0])

    def encoder(self, name: str) -> np.ndarray:
        """Raw readings of one encoder, ``(n_records,)`` int64."""
        return self.ticks[:, self.header.encoder_index(name)]

    def increments(self, name: str) -> np.ndarray:
        """Signed increments of a counter (wrapping uint32), ``(n_records - 1,)``."""
        return wrapped_difference(self.encoder(name))

    def select(self, start: int, stop: int) -> Log:
        """The records ``start:stop`` (time stays relative to the file's first record)."""
        sl = slice(start, stop)
        return replace(
            self,
            time_s=frozen(self.time_s[sl]),
            ticks=frozen(self.ticks[sl]),
            model_pose=frozen(self.model_pose[sl]),
            T_world_sensor=frozen(self.T_world_sensor[sl]),
            line_numbers=frozen(self.line_numbers[sl]),
            T_world_sensor_3d=None if self.T_world_sensor_3d is None else frozen(self.T_world_sensor_3d[sl]),
        )


def frozen(a: np.ndarray) -> np.ndarray:
    """A contiguous, read-only copy (or view) of ``a``."""
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a
