"""Input layer: the robot log text format (reading, checking, writing), ROS bags read into the same
records, and encoder resampling.

Knows no kinematic model: callers say which encoders are absolute and which are counters.
"""

from nlp_calib.logs.bag_reader import BagError, BagTopics
from nlp_calib.logs.bag_records import read_bag
from nlp_calib.logs.camera import CameraRecording, JointInput, camera_log, pair, planar_track
from nlp_calib.logs.joint_log import JointTable, format_joint_csv, read_joint_csv
from nlp_calib.logs.log import ENCODER_KINDS, DroppedRecord, EncoderKind, JointStream, Log, LogHeader
from nlp_calib.logs.reader import parse_log, read_log, yaw_from_quaternion
from nlp_calib.logs.resample import resample_encoders
from nlp_calib.logs.tum import Trajectory3D, format_tum, read_tum
from nlp_calib.logs.writer import format_header, format_log, format_records

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
