"""Simulation options from a YAML file and command-line overrides."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nlp_calib.core.config import fail, from_mapping, read_yaml
from nlp_calib.core.ranges import Range
from nlp_calib.simulation import LIMITS, SimulationOptions

#: What a user may ask of ``nlp-calib simulate``: the simulator's own limits, with the size of one
#: run bounded (memory grows with records × substeps, about 200 MB at MAX_FINE_STEPS).
CLI_LIMITS: Mapping[str, Range] = {**LIMITS, "records": Range(3, 50_000, integer=True)}
MAX_FINE_STEPS = 1_000_000


def simulation_options(config: Path | None, overrides: Mapping[str, Any]) -> SimulationOptions:
    """Options from ``config`` (YAML mapping of :class:`SimulationOptions` fields), then overrides."""
    raw: dict[str, Any] = {}
    source = "simulate"
    if config is not None:
        loaded = read_yaml(config, "simulation config")
        if loaded is not None and not isinstance(loaded, Mapping):
            fail(str(config), "expected a mapping of simulation options")
        raw.update(loaded or {})
        source = str(config)
    raw.update(overrides)
    opts: SimulationOptions = from_mapping(SimulationOptions, raw, source)
    reason = CLI_LIMITS["records"].problem(opts.records)
    if reason is not None:
        fail(f"{source}: records", reason)
    if opts.records * opts.substeps > MAX_FINE_STEPS:
        fail(
            f"{source}: records × substeps",
            f"must be at most {MAX_FINE_STEPS:,} (memory), got {opts.records} × {opts.substeps}",
        )
    return opts
