"""Sources layer: where a log's records come from (a text log, a ROS bag...), read as a ``Log``.

A scenario's ``dataset`` entry is parsed by the first registered source that claims it; adding a
source is one module (a class following :class:`~nlp_calib.sources.base.DatasetSource`) and one
entry in :data:`SOURCES`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from nlp_calib.core.config import fail
from nlp_calib.sources.bag import BagSource
from nlp_calib.sources.base import DatasetSource
from nlp_calib.sources.beside import BesideSource
from nlp_calib.sources.imu import GyroCsvSource, ImuSource
from nlp_calib.sources.joints import JointLogSource
from nlp_calib.sources.lidar import LidarSource
from nlp_calib.sources.motions import MotionsSource
from nlp_calib.sources.text import TextSource, load_log
from nlp_calib.sources.vendor import VendorSource

#: The dataset sources, in the order they are asked whether they read a scenario's entry.
SOURCES: dict[str, type[DatasetSource]] = {
    s.kind: s
    for s in (
        BesideSource,
        LidarSource,
        ImuSource,
        VendorSource,
        BagSource,
        MotionsSource,
        GyroCsvSource,
        JointLogSource,
        TextSource,
    )
}


def parse_source(raw: Any, where: str, base_dir: Path, also: tuple[str, ...] = ()) -> DatasetSource:
    """The source a scenario's ``dataset`` entry ``raw`` describes (paths relative to ``base_dir``;
    ``also``: the entry's own keys the caller took out, named among the valid ones)."""
    for kind in SOURCES.values():
        if kind.claims(raw):
            return kind.parse(raw, where, base_dir, also)
    fail(where, f"not a dataset entry of any known source ({', '.join(SOURCES)}): a log's path or a block")


def moved(source: DatasetSource, path: Path) -> DatasetSource:
    """``source``'s reading of another file (``--data PATH``): another bag is read with the same
    topics, either file of a joint-log pair with its partner beside it; any other path is a text
    log (reading a bag that way says how to name its topics)."""
    return source.moved(path) if type(source).accepts(path) else TextSource(path)


__all__ = [
    "SOURCES",
    "BagSource",
    "BesideSource",
    "DatasetSource",
    "GyroCsvSource",
    "ImuSource",
    "JointLogSource",
    "LidarSource",
    "MotionsSource",
    "TextSource",
    "VendorSource",
    "load_log",
    "moved",
    "parse_source",
]
