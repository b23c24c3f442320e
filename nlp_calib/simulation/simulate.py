"""Synthetic logs with known truth, in the log text format, for any registered model.

The robot is simulated in continuous time (exact arcs on a fine sub-step grid, with smoothly
varying speed and turning), then sampled at jittered ~25 Hz: quantised encoders (wheel counters
start near 2³² so they wrap), and a tracker that sees the sensor pose with noise, gross outliers
and latency. What differs between robots (how speed and turning move the wheels, and which
encoders read them) is each model's ``drive``. Independent of the symbolic model on purpose: it
is the yardstick the model is checked against. Deterministic for a given seed, and the same
whether made in memory (:func:`simulate`) or written block by block (:func:`simulate_to_file`,
:mod:`nlp_calib.simulation.blocks`).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from nlp_calib.core.files import atomic_write_text, atomic_writer, truth_path
from nlp_calib.logs import LogHeader, format_header, format_log, format_records
from nlp_calib.models import MODELS
from nlp_calib.simulation.blocks import Block, blocks, inject_faults, with_faults, with_odometry
from nlp_calib.simulation.faults import InjectedFault
from nlp_calib.simulation.options import (
    LIMITS,
    REVERSALS,
    TRAJECTORIES,
    ProfileSettings,
    SimulationOptions,
    drive_profiles,
)

__all__ = [
    "LIMITS",
    "REVERSALS",
    "TRAJECTORIES",
    "ProfileSettings",
    "SimulatedLog",
    "SimulationOptions",
    "drive_profiles",
    "inject_faults",
    "simulate",
    "simulate_to_file",
    "truth_document",
    "truth_path",
    "write_simulation",
]

#: The simulated log's first stamp (ns): a plausible epoch, so that stamps look like a robot's.
EPOCH_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class SimulatedLog:
    """A simulated log: record arrays plus the header that describes them."""

    header: LogHeader
    time_ns: np.ndarray
    ticks: np.ndarray
    model_pose: np.ndarray
    T_world_sensor: np.ndarray
    T_world_base_true: np.ndarray
    options: SimulationOptions
    faults: tuple[InjectedFault, ...] = ()
    #: Per record, whether its tracker pose took in a gross outlier (paired: either bracket).
    tracker_outliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def text(self) -> str:
        return format_log(self.header, self.time_ns, self.ticks, self.model_pose, self.T_world_sensor)

    def truth_dict(self) -> dict[str, Any]:
        outliers = np.flatnonzero(self.tracker_outliers).tolist()
        return truth_document(self.options, self.faults, outliers, int(self.time_ns.size))


def truth_document(
    opts: SimulationOptions, faults: Sequence[InjectedFault], outliers: Sequence[int], records: int
) -> dict[str, Any]:
    """The truth JSON of a simulated log: the true parameters, every option, the injected faults,
    the records whose tracker pose took in an outlier and how many records the log holds."""
    return {
        "params": dict(opts.truth),
        "options": opts.flat(),
        "faults": [f.as_dict() for f in faults],
        "tracker_outliers": list(outliers),
        "records": records,
    }


def _time_ns(t_s: np.ndarray) -> np.ndarray:
    return np.round(t_s * 1e9).astype(np.int64) + EPOCH_NS


def simulate(opts: SimulationOptions, block: int | None = None) -> SimulatedLog:
    """Simulate a drive and the log it would produce, in memory (``block``: records simulated at
    once; the log is the same whatever it is)."""
    header = MODELS[opts.model].drive.header(opts)
    parts, faults = with_faults(opts, header, blocks(opts, block))
    pieces = list(with_odometry(opts, header, parts))
    joined = {f.name: np.concatenate([getattr(b, f.name) for b, _ in pieces]) for f in fields(Block)}
    return SimulatedLog(
        header=header,
        time_ns=_time_ns(joined["time_s"]),
        ticks=joined["ticks"],
        model_pose=np.concatenate([odometry for _, odometry in pieces]),
        T_world_sensor=joined["T_world_sensor"],
        T_world_base_true=joined["T_world_base_true"],
        options=opts,
        faults=faults,
        tracker_outliers=joined["outliers"],
    )


def write_simulation(sim: SimulatedLog, out: str | Path) -> tuple[Path, Path]:
    """Write the log and its truth JSON (atomically); returns both paths."""
    log_path = Path(out)
    atomic_write_text(log_path, sim.text())
    return log_path, _write_truth(log_path, sim.truth_dict())


def _write_truth(log_path: Path, truth: dict[str, Any]) -> Path:
    tp = truth_path(log_path)
    atomic_write_text(tp, json.dumps(truth, indent=2) + "\n")
    return tp


def simulate_to_file(opts: SimulationOptions, out: str | Path, block: int | None = None) -> tuple[Path, Path]:
    """Simulate and write the log block by block, then its truth JSON (each atomically); returns
    both paths. The file holds the bytes ``simulate(opts).text()`` would; memory stays that of one
    block (``block`` records; default: :data:`~nlp_calib.simulation.blocks.BLOCK_SUBSTEPS` fine
    sub-steps), whatever the log's length, unless the log must be made whole (injected faults, a
    tracker on its own clock)."""
    log_path = Path(out)
    header = MODELS[opts.model].drive.header(opts)
    parts, faults = with_faults(opts, header, blocks(opts, block))
    records, outliers = 0, []
    with atomic_writer(log_path) as fh:
        fh.write(format_header(header).encode())
        for blk, odometry in with_odometry(opts, header, parts):
            fh.write(format_records(_time_ns(blk.time_s), blk.ticks, odometry, blk.T_world_sensor).encode())
            outliers += (records + np.flatnonzero(blk.outliers)).tolist()
            records += blk.time_s.size
    return log_path, _write_truth(log_path, truth_document(opts, faults, outliers, records))
