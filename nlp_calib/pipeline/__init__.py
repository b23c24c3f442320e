"""Pipeline layer: scenario configuration and the calibration as named stages.

The stages, in order: prepare (:mod:`.prepare`), build (:mod:`.build`), screen (:mod:`.screen`),
align (:mod:`.align`), bind (:mod:`.windows`), fit (:mod:`.fit`), analyse (:mod:`.analyse`) and
assemble (:mod:`.assemble`); :mod:`.calibration` chains them for one log or several. The only
layer that speaks scenario language: library errors from below are translated here into
messages that name the scenario key to fix (:mod:`.keys`).
"""

from nlp_calib.pipeline.analyse import Wanted
from nlp_calib.pipeline.calibration import Calibration
from nlp_calib.pipeline.scenario import LogEntry, Scenario, load_scenario, scenario_from_mapping

__all__ = [
    "Calibration",
    "LogEntry",
    "Scenario",
    "Wanted",
    "load_scenario",
    "scenario_from_mapping",
]
