"""Input layer: the robot log text format (reading, checking, writing), ROS bags read into the same
records, and encoder resampling.

Knows no kinematic model: callers say which encoders are absolute and which are counters.
"""

from nlp_calib.logs.bag_reader import BagError, BagTopics
from nlp_calib.logs.bag_records import read_bag
from nlp_calib.logs.log import ENCODER_KINDS, DroppedRecord, EncoderKind, Log, LogHeader
from nlp_calib.logs.reader import parse_log, read_log, yaw_from_quaternion
from nlp_calib.logs.resample import resample_encoders, resample_tracker
from nlp_calib.logs.writer import format_header, format_log, format_records

__all__ = [
    "ENCODER_KINDS",
    "BagError",
    "BagTopics",
    "DroppedRecord",
    "EncoderKind",
    "Log",
    "LogHeader",
    "format_header",
    "format_log",
    "format_records",
    "parse_log",
    "read_bag",
    "read_log",
    "resample_encoders",
    "resample_tracker",
    "yaw_from_quaternion",
]
