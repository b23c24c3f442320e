"""Pipeline layer: scenario configuration and the calibration as named stages.

The stages, in order: prepare (:mod:`.prepare`), build (:mod:`.build`), screen (:mod:`.screen`),
align (:mod:`.align`), bind (:mod:`.windows`), fit (:mod:`.fit`), analyse (:mod:`.analyse`) and
assemble (:mod:`.assemble`); :mod:`.calibration` chains them for one log or several. The only
layer that speaks scenario language: library errors from below are translated here into
messages that name the scenario key to fix (:mod:`.keys`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nlp_calib.core import lazy

if TYPE_CHECKING:
    from nlp_calib.pipeline.analyse import Wanted
    from nlp_calib.pipeline.calibration import Calibration
    from nlp_calib.pipeline.scenario import LogEntry, Scenario, load_scenario, scenario_from_mapping

# Each name's module is imported at the name's first use (core/lazy.py).
_EXPORTS: dict[str, str] = {
    "Wanted": "nlp_calib.pipeline.analyse",
    "Calibration": "nlp_calib.pipeline.calibration",
    "LogEntry": "nlp_calib.pipeline.scenario",
    "Scenario": "nlp_calib.pipeline.scenario",
    "load_scenario": "nlp_calib.pipeline.scenario",
    "scenario_from_mapping": "nlp_calib.pipeline.scenario",
}

__getattr__, __dir__ = lazy.exports(__name__, _EXPORTS)

__all__ = [
    "Calibration",
    "LogEntry",
    "Scenario",
    "Wanted",
    "load_scenario",
    "scenario_from_mapping",
]
