"""Simulation options from a YAML file and command-line overrides."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nlp_calib.core.config import fail, from_mapping, read_yaml
from nlp_calib.core.ranges import Range
from nlp_calib.simulation import LIMITS, SimulationOptions

#: What a user may ask of ``nlp-calib simulate``: the simulator's own limits (it writes a log block
#: by block, so its memory does not grow with the log's length).
CLI_LIMITS: Mapping[str, Range] = LIMITS


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
    return opts
