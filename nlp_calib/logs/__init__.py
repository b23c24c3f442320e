"""Input layer: the robot log text format (reading, checking, writing), ROS bags read into the same
records, and encoder resampling.

Knows no kinematic model: callers say which encoders are absolute and which are counters.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nlp_calib.core import lazy

if TYPE_CHECKING:
    from nlp_calib.logs.bag_reader import BagError, BagTopics
    from nlp_calib.logs.bag_records import read_bag
    from nlp_calib.logs.camera import CameraRecording, JointInput, camera_log, pair, planar_track
    from nlp_calib.logs.joint_log import JointTable, format_joint_csv, read_joint_csv
    from nlp_calib.logs.log import ENCODER_KINDS, DroppedRecord, EncoderKind, JointStream, Log, LogHeader
    from nlp_calib.logs.reader import parse_log, read_log, yaw_from_quaternion
    from nlp_calib.logs.resample import resample_encoders
    from nlp_calib.logs.tum import Trajectory3D, format_tum, read_tum
    from nlp_calib.logs.writer import format_header, format_log, format_records

# Each name's module is imported at the name's first use (core/lazy.py).
_EXPORTS: dict[str, str] = {
    "BagError": "nlp_calib.logs.bag_reader",
    "BagTopics": "nlp_calib.logs.bag_reader",
    "read_bag": "nlp_calib.logs.bag_records",
    "CameraRecording": "nlp_calib.logs.camera",
    "JointInput": "nlp_calib.logs.camera",
    "camera_log": "nlp_calib.logs.camera",
    "pair": "nlp_calib.logs.camera",
    "planar_track": "nlp_calib.logs.camera",
    "JointTable": "nlp_calib.logs.joint_log",
    "format_joint_csv": "nlp_calib.logs.joint_log",
    "read_joint_csv": "nlp_calib.logs.joint_log",
    "ENCODER_KINDS": "nlp_calib.logs.log",
    "DroppedRecord": "nlp_calib.logs.log",
    "EncoderKind": "nlp_calib.logs.log",
    "JointStream": "nlp_calib.logs.log",
    "Log": "nlp_calib.logs.log",
    "LogHeader": "nlp_calib.logs.log",
    "parse_log": "nlp_calib.logs.reader",
    "read_log": "nlp_calib.logs.reader",
    "yaw_from_quaternion": "nlp_calib.logs.reader",
    "resample_encoders": "nlp_calib.logs.resample",
    "Trajectory3D": "nlp_calib.logs.tum",
    "format_tum": "nlp_calib.logs.tum",
    "read_tum": "nlp_calib.logs.tum",
    "format_header": "nlp_calib.logs.writer",
    "format_log": "nlp_calib.logs.writer",
    "format_records": "nlp_calib.logs.writer",
}

__getattr__, __dir__ = lazy.exports(__name__, _EXPORTS)

__all__ = [
    "ENCODER_KINDS",
    "BagError",
    "BagTopics",
    "CameraRecording",
    "DroppedRecord",
    "EncoderKind",
    "JointInput",
    "JointStream",
    "JointTable",
    "Log",
    "LogHeader",
    "Trajectory3D",
    "camera_log",
    "format_header",
    "format_joint_csv",
    "format_log",
    "format_records",
    "format_tum",
    "pair",
    "parse_log",
    "planar_track",
    "read_bag",
    "read_joint_csv",
    "read_log",
    "read_tum",
    "resample_encoders",
    "yaw_from_quaternion",
]
