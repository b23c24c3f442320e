"""Simulation options from a YAML file and command-line overrides."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from nlp_calib.core.config import coerce, fail, key_name, read_yaml
from nlp_calib.core.errors import FieldError, NlpCalibError
from nlp_calib.core.ranges import Range
from nlp_calib.simulation import LIMITS, SimulationOptions
from nlp_calib.simulation.options import flat_hints

#: What a user may ask of ``nlp-calib simulate``: the simulator's own limits (it writes a log block
#: by block, so its memory does not grow with the log's length).
CLI_LIMITS: Mapping[str, Range] = LIMITS


def simulation_options(config: Path | None, overrides: Mapping[str, Any]) -> SimulationOptions:
    """Options from ``config`` (a YAML mapping of options by their flat names), then overrides."""
    raw: dict[str, Any] = {}
    source = "simulate"
    if config is not None:
        loaded = read_yaml(config, "simulation config")
        if loaded is not None and not isinstance(loaded, Mapping):
            fail(str(config), "expected a mapping of simulation options")
        raw.update(loaded or {})
        source = str(config)
    raw.update(overrides)
    hints = flat_hints()
    for key in raw:
        if key not in hints:
            fail(f"{source}.{key_name(key)}", f"unknown key; valid keys are {', '.join(hints)}")
    typed = {k: coerce(v, hints[k], f"{source}.{k}") for k, v in raw.items()}
    try:
        return SimulationOptions.of(**typed)
    except FieldError as exc:
        fail(f"{source}.{exc.field}", exc.reason)
    except (ValueError, TypeError, NlpCalibError) as exc:
        fail(source, str(exc))
