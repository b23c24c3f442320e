"""What a recording holds, as the pre-flight lists it: its streams, their rates and gaps, the clocks.

A text log is one stream of records; a joint log and a bag in radians keep the joints on their
own clock (their stream) beside the tracker's poses the records are made at; a bag also lists
its topics with their types and message counts.
"""

from __future__ import annotations

import numpy as np

from nlp_calib.analysis.streams import GAP_FACTOR, gap_threshold
from nlp_calib.core.errors import NlpCalibError
from nlp_calib.logs import Log
from nlp_calib.logs.bag_survey import topic_counts
from nlp_calib.pipeline.scenario import Scenario
from nlp_calib.results.preflight import Recording, Stream
from nlp_calib.sources import BagSource


def stream(name: str, kind: str, time_s: np.ndarray, note: str = "", windows: bool = False) -> Stream:
    """A stream of messages at ``time_s`` (s); ``windows``: its gaps counted as the ones no residual
    window crosses (:func:`~nlp_calib.analysis.streams.gap_threshold`: the records the windows run
    over), else as intervals over :data:`~nlp_calib.analysis.streams.GAP_FACTOR` median ones."""
    t = np.asarray(time_s, dtype=float)
    if t.size < 2:
        return Stream(name, kind, int(t.size), 0.0, (float(t[0]) if t.size else 0.0,) * 2, 0, 0.0, note)
    dt = np.diff(t)
    median = float(np.median(dt))
    # The records' count must be the run's: a tracker that delivers its poses in bursts has a
    # median interval of milliseconds, and intervals over 5 of them that no window skips.
    gaps = dt > (gap_threshold(t) if windows else GAP_FACTOR * max(median, 1e-9))
    return Stream(
        name,
        kind,
        int(t.size),
        1.0 / median if median > 0 else 0.0,
        (float(t[0]), float(t[-1])),
        int(gaps.sum()),
        float(dt.max()),
        note,
    )


def _bag_streams(source: BagSource) -> list[Stream]:
    """The bag's topics with their types and message counts (no time: only its metadata is read)."""
    try:
        topics = topic_counts(source.bag)
    except NlpCalibError:
        return []
    used = {source.joint_states: "joints", source.tracker: "tracker"}
    return [
        Stream(name, msgtype, count, 0.0, (0.0, 0.0), 0, 0.0, used.get(name, ""))
        for name, (msgtype, count) in sorted(topics.items())
    ]


def recording(sc: Scenario, log: Log) -> Recording:
    """The recording of ``sc``'s (single) log as it was read (``log``)."""
    source = sc.log.source
    encoders = ", ".join(log.header.encoder_names)
    streams = [
        stream("records", f"one per {source.record_word}", log.time_s, f"encoders {encoders}", windows=True)
    ]
    overlap = None
    joints = log.joint_stream
    if joints is not None:
        js = stream("joints", "joint positions (rad) on their own clock", joints.time_s, encoders)
        streams.append(js)
        overlap = max(0.0, min(js.span_s[1], float(log.time_s[-1])) - max(js.span_s[0], float(log.time_s[0])))
    if isinstance(source, BagSource):
        streams += _bag_streams(source)
    notes = [f"times: {source.clock()}"]
    roles = sc.objective.sensor.sensor.roles
    if roles:
        notes.append(f"sensors: {roles}")
    if log.dropped:
        notes.append(f"{len(log.dropped)} record(s) left out while reading (first: {log.dropped[0].reason})")
    if joints is not None and joints.integrated:
        notes.append(f"integrated from velocities: {', '.join(joints.integrated)} (known up to its start)")
    t = log.time_s
    return Recording(
        path=str(source.path),
        source=source.kind,
        streams=tuple(streams),
        records=log.n_records,
        duration_s=float(t[-1] - t[0]) if t.size else 0.0,
        overlap_s=overlap,
        notes=tuple(notes),
    )
