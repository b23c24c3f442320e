"""A first scenario drafted from a recording: ``nlp-calib init``.

From a bag's survey (:mod:`nlp_calib.logs.bag_survey`), a joint log's header row or a text log's
header: the joints topic and its joints in the model's encoder order, the tracker topic (and
frame), the model the joint names suggest, and the keys a first run needs. Each encoder takes the
joint whose name carries a word of the encoder's name (``left`` for an encoder named ``left_…``),
an angle encoder (``absolute``) a joint named ``steer…``, a wheel (``counter``) left over any joint named
``…wheel…``, ``…traction…`` or ``…drive…``; a model is a candidate when every one of its encoders
takes a joint of its own; of those, a steered one where a joint is named steer…, the one reading
the most joints, the first registered, is drafted; where a three-wheeler driven by its steered
wheel and a car read the same joints, a joint log's drive that corners as a car does
(:data:`CAR_CORNERING`) drafts the car. A joint log's wheel columns that look like speeds to the
pre-flight's detector are drafted with ``form: speeds``. The tracker is the pose topic
whose name says most clearly that it is a reference (a motion-capture system's, a ground truth),
never the robot's own odometry. The text says what was found and why each choice was made, as
comments, and is read back as a scenario before it is written: ``run`` accepts it as it is.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nlp_calib.analysis.lag_screen import REACH_S, coarse_lag, shown_lag, unshown
from nlp_calib.analysis.turning import TURN_STEP_S, Turning, turning
from nlp_calib.analysis.units import findings
from nlp_calib.core import poses3d
from nlp_calib.core.config import parse_yaml
from nlp_calib.core.errors import DatasetError, FieldError, UsageError
from nlp_calib.core.ranges import check_ros_name
from nlp_calib.core.text import escaped, unprintable
from nlp_calib.logs import Log
from nlp_calib.logs.bag_reader import ODOMETRY_TYPE, POSE_TYPE, TF_TYPE, TRANSFORM_TYPE, is_bag
from nlp_calib.logs.bag_survey import BagSurvey, Topic, survey
from nlp_calib.logs.imu import IMU_TYPE
from nlp_calib.logs.joint_log import read_joint_csv
from nlp_calib.logs.reader import read_header
from nlp_calib.logs.scans import SCAN_TYPE
from nlp_calib.logs.tum import read_tum
from nlp_calib.models import MODELS, encoders, model_for_log
from nlp_calib.models.base import QUARTER_TURN, KinematicModel
from nlp_calib.models.radians import in_units
from nlp_calib.pipeline import prepare
from nlp_calib.pipeline.options import AlignmentOptions
from nlp_calib.pipeline.scenario import Scenario, scenario_from_mapping
from nlp_calib.pipeline.slip_check import lateral
from nlp_calib.results.preflight import UnitFinding
from nlp_calib.sensors import BESIDE, sensor_for
from nlp_calib.sensors.mount import length_params
from nlp_calib.sources.joints import paired_files
from nlp_calib.sources.motions import MOTIONS_SUFFIX, motions_pair
from nlp_calib.sources.robot import load_robot

#: Words in a topic's name that say it carries a reference, and those that say it does not.
REFERENCE_WORDS = (
    "mocap",
    "vicon",
    "optitrack",
    "vrpn",
    "qualisys",
    "tracker",
    "ground_truth",
    "groundtruth",
    "gt",
)
NOT_REFERENCE_WORDS = ("odom", "cmd", "goal", "plan", "amcl", "estimate", "filtered")
#: Words of a wheel joint's name when the encoder's own words are not in it.
WHEEL_WORDS = ("wheel", "traction", "drive")
#: A gyro's CSV beside a recording's poses ``NAME.tum`` (``t, wx, wy, wz``), as ``simulate --imu`` names it.
GYRO_SUFFIX = ".gyro.csv"
#: Poses whose motions turn about an axis this far (rad, about 30°) from their frame's z or more are
#: a camera's (its optical frame: about 90°), not a planar tracker's, whose world is level.
TILTED_RAD = 0.52
#: ...judged on motions over about this long (s) that turn by at least this much (rad).
TURN_SPAN_S, TURN_MIN_RAD = 1.0, 0.05
#: The lateral acceleration (m/s²) a drive's bends reach (:func:`cornering`) from which the draft
#: reads a steering and a wheel joint as a car's rather than a front-wheel-driven tricycle's: the
#: F1/10 car's drives reach 1.0-1.4 m/s², a road car's 1-4; OptiOdom's tricycle, its differential
#: drive and the camera demo 0.02 at most (an industrial base turns slowly).
CAR_CORNERING = 0.25
#: What the draft asks of a first run.
DEFAULTS: Mapping[str, Any] = {
    "initial_guess": "auto",
    "residual": {"horizon_s": 0.5},
    "alignment": {"tracker_lag": "auto", "search": list(AlignmentOptions().search)},
    "solvers": ["gauss_newton"],
}


def defaults(model: str) -> dict[str, Any]:
    """:data:`DEFAULTS` for ``model``: a steer angle taken as the mean of its readings at an
    interval's two ends (the joints interpolated there on their own clock): held from the start,
    it would lag by half an interval, and the fitted clock offset with it."""
    if not MODELS[model].level_inputs:
        return dict(DEFAULTS)
    return {**DEFAULTS, "residual": {**DEFAULTS["residual"], "steering_sample": "mean"}}


@dataclass(frozen=True)
class Draft:
    """A drafted scenario: its mapping, its commented text, and what was found, line by line."""

    raw: Mapping[str, Any]
    text: str
    found: tuple[str, ...]

    def scenario(self, where: Path) -> Scenario:
        """The drafted scenario as ``run`` reads it from a file at ``where``."""
        return scenario_from_mapping(parse_yaml(self.text, str(where)), str(where), where.parent, where)


def _words(name: str) -> set[str]:
    return {w for w in re.split(r"[^a-z0-9]+", name.lower()) if w}


def assign(model_name: str, joints: Sequence[str], eliminate: bool = False) -> dict[str, str] | None:
    """Each of the model's encoders' joint by name (see the module docstring); None when some
    encoder finds none of its own. ``eliminate`` (the model given): an encoder no name gives a joint
    takes the one joint of its kind left (:func:`_eliminated`)."""
    model = MODELS[model_name]
    named = by_name(model, joints)
    if len(named) == len(encoders(model)):
        return named
    return _eliminated(model, joints, named) if eliminate else None


def by_name(model: KinematicModel, joints: Sequence[str]) -> dict[str, str]:
    """The model's encoders whose joint a name gives (see the module docstring), each with it."""
    # A steering encoder reads a steering joint (where any is named so), a wheel one never does.
    steer = [j for j in joints if "steer" in j.lower()]
    out: dict[str, str] = {}
    for encoder in encoders(model):
        kind = model.encoder_kinds[encoder]
        own = _words(encoder) - {"wheel"}
        free = [j for j in joints if j not in out.values()]
        if kind == "absolute" and steer:
            free = [j for j in free if j in steer]
        elif kind == "counter":
            free = [j for j in free if j not in steer]
        # The joint sharing most of the encoder's words (rear_left_wheel: rear_left, not front_left).
        shared = sorted((-len(own & _words(j)), i) for i, j in enumerate(free) if own & _words(j))
        match = [free[i] for _, i in shared]
        if not match and kind == "absolute":
            match = free if steer else []
        if not match and kind == "counter":
            match = [j for j in free if any(w in j.lower() for w in WHEEL_WORDS)]
        if match:
            out[encoder] = match[0]
    return out


def _eliminated(model: KinematicModel, joints: Sequence[str], named: dict[str, str]) -> dict[str, str] | None:
    """``named`` with each encoder it lacks given the one joint of its kind left: an angle encoder
    (``absolute``) a joint named steer… (the joint left, where it is the only encoder left), a
    wheel one a joint not so named; None where the joints left are not one per encoder lacking
    one, one of each kind (two unnamed wheels: which is the left one?). A converter's columns
    (``speed``) need not carry a wheel's words, but a given model leaves no choice there."""
    missing = [e for e in encoders(model) if e not in named]
    left = [j for j in joints if j not in named.values()]
    if len(left) != len(missing):
        return None
    out = dict(named)
    for encoder in missing:
        kind = model.encoder_kinds[encoder]
        same = [e for e in missing if model.encoder_kinds[e] == kind]
        steer = [j for j in left if "steer" in j.lower()]
        ours = (
            (steer or left[: len(missing) == 1])
            if kind == "absolute"
            else [j for j in left if j not in steer]
        )
        if len(same) != 1 or len(ours) != 1:
            return None
        out[encoder] = ours[0]
    return {e: out[e] for e in encoders(model)}


def guess_model(
    joints: Sequence[str], model: str | None, cornering: float | None = None
) -> tuple[str, dict[str, str], str]:
    """The model (``model`` when given), its encoders' joints and why, in words: of the models
    whose every encoder finds a joint, the one that reads the most joints (a steer joint beside
    four wheels is a car's, not a three-wheeler's nor a two-wheeled base's), of those the one the
    drive's motion says (``cornering``: see :func:`_by_motion`), else the first registered; a steer
    joint is read by a steered model where one fits."""
    names = [model] if model is not None else list(MODELS)
    fits = {m: a for m in names if (a := assign(m, joints, model is not None)) is not None}
    if not fits:
        given = f"model {model}'s encoders ({', '.join(encoders(MODELS[model]))})" if model else "any model"
        way = (
            "give the encoders' joints in the scenario"
            if model
            else "give --model (a joint no name gives is read by the one encoder of its kind left), or give "
            "the encoders' joints in the scenario"
        )
        raise UsageError(
            f"the joints {', '.join(joints) or '(none)'} do not name the joints of {given}; {way} "
            "(docs/bags.md)"
        )
    # A steering joint is read by a steered model where one fits (never a differential drive's).
    if any("steer" in j.lower() for j in joints) and not model:
        steered = {m: a for m, a in fits.items() if "absolute" in MODELS[m].encoder_kinds.values()}
        fits = steered or fits
    most = max(len(a) for a in fits.values())
    chosen, motion = _by_motion([m for m, a in fits.items() if len(a) == most], model, cornering)
    pairs = ", ".join(f"{e}: {j}" for e, j in fits[chosen].items())
    others = [m for m in fits if m != chosen]
    why = f"{'given' if model else 'the joint names fit it'} ({pairs})"
    named = by_name(MODELS[chosen], joints)
    if guessed := [f"{j} ({e})" for e, j in fits[chosen].items() if named.get(e) != j]:
        why += f"; no name says so of {', '.join(guessed)}: the one joint of its kind left, check it"
    if not model and len(fits[chosen]) < len(joints):
        unread = [j for j in joints if j not in fits[chosen].values()]
        why += f"; it reads the most of them ({', '.join(unread)} left unread)"
    if others:
        why += f"; {', '.join(others)} read(s) {'fewer or ' if not model else ''}the same joints"
    return chosen, fits[chosen], why + motion + _held(chosen)


def is_car(model: str) -> bool:
    """Whether ``model`` is a car's: a steered wheel that turns less than a quarter turn (a
    three-wheeler's driven steered wheel turns a quarter turn, about the rear axle)."""
    steer_max = MODELS[model].steer_max
    return steer_max is not None and steer_max < QUARTER_TURN


def _by_motion(tied: Sequence[str], model: str | None, cornering: float | None) -> tuple[str, str]:
    """Of the models reading the same joints (``tied``, in registry order), the one the drive's
    motion says, and why in words: a car's where one ties with a three-wheeler and the drive's bends
    reach :data:`CAR_CORNERING` (``cornering``, m/s²); else the first registered. A front-wheel-
    driven three-wheeler and a car read one steer joint and one wheel joint alike; on a drive's bends
    their kinematics differ only by the wheel's speed over 1/cos of the steer angle, which a
    wheel radius and a steer gain take up: how the robot corners tells them apart."""
    cars = [m for m in tied if is_car(m)]
    if model or not cars or len(cars) == len(tied):
        return tied[0], ""
    other = next(m for m in tied if not is_car(m))
    if cornering is None:
        return tied[0], f"; {cars[0]} reads the same joints: for a car, give --model {cars[0]}"
    bends = f"the drive's bends reach {cornering:.2g} m/s² of lateral acceleration (90th percentile"
    if cornering >= CAR_CORNERING:
        car = f"; {other} reads the same joints, but {bends}; a car's from {CAR_CORNERING:g}): a car"
        return cars[0], car
    return tied[0], (
        f"; {cars[0]} reads the same joints, but {bends}; a car's from {CAR_CORNERING:g}): for a car, give "
        f"--model {cars[0]}"
    )


def _held(model: str) -> str:
    """What the model holds at its start where a drive does not tell it (an Ackermann pair's
    track between its steer pivots whatever the drive), in the joints' names, said before any run."""
    form = in_units(MODELS[model], "radians")
    held = form.undetermined(np.zeros((len(form.input_names), 0)))
    if not held:
        return ""
    return (
        f"; it holds {', '.join(held)} at the start where the drive does not tell them (the pre-flight "
        "says which): give measured values under known:"
    )


def _score(topic: Topic) -> int:
    words = _words(topic.name) | {w for f in topic.frames for w in _words(f)}
    score = 2 * len(words & set(REFERENCE_WORDS)) - 3 * any(
        w in topic.name.lower() for w in NOT_REFERENCE_WORDS
    )
    return score + (topic.msgtype in (POSE_TYPE, TRANSFORM_TYPE)) - (topic.msgtype == TF_TYPE)


def tracker(found: BagSurvey) -> tuple[Topic, str | None, list[Topic]]:
    """The tracker topic, its frame (where the type names one to pick) and the other candidates."""
    poses = sorted(
        found.of_type(POSE_TYPE, TRANSFORM_TYPE, ODOMETRY_TYPE, TF_TYPE), key=lambda t: (-_score(t), -t.count)
    )
    poses = [t for t in poses if t.name != "/tf_static"]
    if not poses:
        raise UsageError(
            f"{found.path}: no topic holds poses (PoseStamped, TransformStamped, Odometry or TF), a "
            f"lidar's scans ({SCAN_TYPE}) or a gyro's rates ({IMU_TYPE}); a calibration needs one of "
            "them as its reference"
        )
    best = poses[0]
    frame = None
    if best.msgtype == TF_TYPE or len(best.frames) > 1:
        frames = sorted(best.frames, key=lambda f: -len(_words(f) & set(REFERENCE_WORDS)))
        frame = frames[0] if frames else None
    return best, frame, poses[1:]


def sensor_frame(found: BagSurvey, base: str = "base_link") -> str | None:
    """The frame on ``/tf_static`` the tracker most likely follows: a leaf of the fixed transforms
    that leads to ``base`` (the only one, or the one whose name says it is a marker or a
    reference); None when there is none to tell."""
    parents = set(found.static.values())

    def reaches(frame: str) -> bool:
        seen: set[str] = set()
        while frame in found.static and frame not in seen:
            seen.add(frame)
            frame = found.static[frame]
        return frame == base

    leaves = [f for f in found.static if f not in parents and reaches(f)]
    marked = [f for f in leaves if _words(f) & {*REFERENCE_WORDS, "marker", "body", "rigid"}]
    chosen = marked or leaves
    return chosen[0] if len(chosen) == 1 else None


def _listing(found: BagSurvey) -> list[str]:
    lines = []
    for t in found.topics:
        what = (
            f"joints: {', '.join(t.joints)}"
            if t.joints
            else (f"frames: {', '.join(t.frames)}" if t.frames else "")
        )
        lines.append(f"{t.name}  {t.msgtype}  {t.count} messages, {t.rate_hz:.0f} Hz  {what}".rstrip())
    if found.static:
        lines.append("static transforms: " + ", ".join(f"{p} -> {c}" for c, p in found.static.items()))
    return lines


def _one_line_names(path: Path, dataset: Mapping[str, Any]) -> None:
    """Refuse a drafted name (topic, joint, frame) that is not one line of printable text: a run
    reads a scenario's names as such (a frame id holding a line break is no frame a robot has)."""
    for key, value in dataset.items():
        names = (
            value.values() if isinstance(value, Mapping) else value if isinstance(value, list) else [value]
        )
        for name in names:
            if isinstance(name, str) and (bad := unprintable(name)) is not None:
                raise UsageError(
                    f"{path}: the {key} {escaped(name)!r} holds {bad}, a line break or control character; "
                    "a topic, joint or frame name is one line of printable text: re-record it (or remap "
                    "it) under a plain name"
                )


def _relative(path: Path, where: Path) -> str:
    """``path`` relative to the scenario's folder when it lies inside it (the two move together),
    else absolute."""
    target, folder = path.resolve(), where.parent.resolve()
    return str(target.relative_to(folder)) if target.is_relative_to(folder) else str(target)


def _text(header: Sequence[str], raw: Mapping[str, Any], notes: Mapping[str, str]) -> str:
    """The scenario as YAML with ``header`` comments on top and each key's note after it: one line a
    key, a mapping of several keys (the dataset's) as a block."""
    # A comment holds only text that cannot end it: names from the recording are escaped.
    lines = [f"# {escaped(h)}" if h else "#" for h in header]
    for key, value in raw.items():
        if isinstance(value, Mapping) and len(value) > 2:
            lines += yaml.safe_dump(
                {key: dict(value)}, sort_keys=False, default_flow_style=None, width=200
            ).splitlines()
            continue
        shown = yaml.safe_dump(value, sort_keys=False, default_flow_style=True, width=200).strip()
        shown = shown.removesuffix("...").strip()
        note = notes.get(key)
        lines.append(f"{key}: {shown}" + (f"   # {escaped(note)}" if note else ""))
    return "\n".join(lines) + "\n"


NOTES: Mapping[str, str] = {
    "initial_guess": "the closed-form start from the data: no guess needed",
    "residual": "windows of half a second whatever the rates; a steer angle: its two readings' mean",
    "alignment": "the tracker's lag behind the joints, fitted within search (why this search: above)",
    "solvers": "add ipopt to compare the two",
}


#: The topics a ros2_control drive controller publishes or takes, under its own name.
_CONTROLLER_TOPICS = ("odom", "cmd_vel", "cmd_vel_unstamped", "reference", "reference_unstamped")


def controller_name(found: BagSurvey) -> str | None:
    """The drive controller's name where the recording shows it (``/NAME/odom``, ``/NAME/cmd_vel``
    ...: ros2_control's controllers publish under their own names), if exactly one such name, a ROS 2
    node name, appears; else None."""
    names = set()
    for t in found.topics:
        parts = t.name.strip("/").split("/")
        if len(parts) == 2 and parts[1] in _CONTROLLER_TOPICS and "controller" in parts[0]:
            names.add(parts[0])
    if len(names) != 1:
        return None
    (name,) = names
    try:
        check_ros_name("controller_name", name)
    except FieldError:
        return None
    return name


def _tracker_keys(
    found: BagSurvey, dataset: dict[str, Any]
) -> tuple[Topic, str | None, list[Topic], str | None]:
    """The tracker, its frame, the other pose topics and the sensor's frame, put in ``dataset``."""
    best, frame, others = tracker(found)
    dataset["tracker"] = best.name
    if frame is not None:
        dataset["tracker_frame"] = frame
    mount = sensor_frame(found) if frame is None else None
    if mount is not None:
        dataset["sensor_frame"] = mount
    return best, frame, others, mount


#: What a draft's sensor_frame gives.
MOUNT_WORDS = (
    "its fixed transforms from base_link on /tf_static give the nominal mount (the hand-off's height, "
    "roll and pitch)."
)


def _draft_bag(path: Path, where: Path, model: str | None) -> Draft:
    found = survey(path)
    joint_topics = [t for t in found.of_type("sensor_msgs/msg/JointState") if t.joints]
    if not joint_topics:
        raise UsageError(f"{path}: no sensor_msgs/msg/JointState topic names any joint")
    js = max(joint_topics, key=lambda t: (t.positions, len(t.joints), t.count))
    name, joints, why = guess_model(js.joints, model)
    dataset: dict[str, Any] = {
        "bag": _relative(path, where),
        "joint_states": js.name,
        "joints": list(joints.values()),
    }
    scans = sorted(found.of_type(SCAN_TYPE), key=lambda t: -t.count)
    rates = sorted(found.of_type(IMU_TYPE), key=lambda t: -t.count)
    poses = [
        t for t in found.of_type(POSE_TYPE, TRANSFORM_TYPE, ODOMETRY_TYPE, TF_TYPE) if t.name != "/tf_static"
    ]
    if not poses and (scans or rates):
        # A lidar measures distance, a gyro none: the scans are the reference, the gyro beside them.
        alone = _lidar(scans, rates, dataset) if scans else _gyro(rates, name)
        return _draft_alone(path, where, (found, js), (name, joints, why), (dataset, alone))
    best, frame, others, mount = _tracker_keys(found, dataset)
    _one_line_names(path, dataset)
    controller = controller_name(found)
    handoff = {"handoff": {"controller_name": controller}} if controller else {}
    sensor = _beside(rates, dataset)
    raw = {"name": where.stem, "model": name, **sensor, "dataset": dataset, **defaults(name), **handoff}
    searched = _searched(raw, where)
    header = [
        f"Drafted by nlp-calib init from {path}: {found.duration_s:.1f} s, {len(found.topics)} topics.",
        *(
            [f"handoff.controller_name {controller}: the controller whose topics the recording holds."]
            if controller
            else []
        ),
        *(f"  {line}" for line in _listing(found)),
        f"model: {name}, because {why}.",
        f"joints {', '.join(joints.values())} are the model's encoders {', '.join(joints)}, in that order.",
        f"tracker: {best.name} ({best.msgtype}){f', frame {frame}' if frame else ''}"
        + (f"; other pose topics: {', '.join(t.name for t in others)}" if others else "")
        + " (the robot's own odometry is never a reference)"
        + _too(("a lidar's scans", scans, "lidar"))
        + ".",
        *([_beside_words(rates)] if rates else []),
        *([f"sensor_frame {mount}: {MOUNT_WORDS}"] if mount else []),
        searched,
        f"Check it before a run: nlp-calib preflight {where}",
    ]
    text = _text(header, raw, NOTES)
    lines = (
        *_listing(found),
        f"model {name}: {why}",
        f"tracker {best.name}" + (f" (frame {frame})" if frame else ""),
        *([f"gyro beside it {rates[0].name}"] if rates else []),
        searched,
    )
    return Draft(raw, text, lines)


@dataclass(frozen=True)
class _Alone:
    """A reference other than poses a bag holds: the dataset's key for its topic, the topic, what
    else the scenario needs (``sensor: gyro``), what the draft says of it, and lines it writes
    commented out (for the user to complete)."""

    key: str
    topic: Topic
    more: Mapping[str, Any]
    words: str
    short: str
    todo: tuple[str, ...] = ()


def _too(*others: tuple[str, Sequence[Topic], str]) -> str:
    """The other references a bag holds, each as (what, its topics, its page in docs/), in words."""
    return "".join(
        f"; {what} too: {', '.join(t.name for t in topics)} (docs/{page}.md)"
        for what, topics, page in others
        if topics
    )


def _also(kind: str, topics: Sequence[Topic]) -> str:
    return f"; other {kind} topics: {', '.join(t.name for t in topics)}" if topics else ""


def _beside(rates: Sequence[Topic], dataset: dict[str, Any]) -> dict[str, Any]:
    """A gyro beside the reference when the bag holds an Imu topic: its topic in ``dataset``, and
    the scenario's sensor that fits both (docs/imu.md)."""
    if not rates:
        return {}
    dataset["imu"] = rates[0].name
    return {"sensor": {"mount": "planar", "beside": "gyro"}}


def _beside_words(rates: Sequence[Topic]) -> str:
    return (
        f"beside it, the gyro's rates on {rates[0].name} ({IMU_TYPE}), fitted in one objective with "
        f"sensor: {{mount: planar, beside: gyro}}: its bias, tilt and clock offset (gyro_lag) beside the "
        f"reference's (docs/imu.md){_also('Imu', rates[1:])}."
    )


def _lidar(scans: Sequence[Topic], rates: Sequence[Topic], dataset: dict[str, Any]) -> _Alone:
    """A lidar's scans as the reference (docs/lidar.md), a gyro beside them if the bag has one."""
    frames = f", frame {', '.join(scans[0].frames)}" if scans[0].frames else ""
    words = (
        f"reference: the lidar's scans on {scans[0].name} ({SCAN_TYPE}{frames}), each matched to the one "
        f"before (docs/lidar.md); no topic holds poses{_also('scan', scans[1:])}."
    )
    more = _beside(rates, dataset)
    words += f" {_beside_words(rates)}" if rates else ""
    short = f"reference: the scans on {scans[0].name}" + (
        f"; gyro beside it {rates[0].name}" if rates else ""
    )
    return _Alone("scan", scans[0], more, words, short)


def _gyro(rates: Sequence[Topic], model: str) -> _Alone:
    """A gyro's rates as the reference (docs/imu.md): it measures no length, so the draft leaves a
    line for one measured length, commented out (a guessed length would be a wrong scale)."""
    length = length_params(in_units(MODELS[model], "radians"))[-1]
    words = (
        f"reference: the gyro's rates on {rates[0].name} ({IMU_TYPE}), integrated over intervals and "
        f"compared with the wheels' turning (docs/imu.md); no topic holds poses{_also('Imu', rates[1:])}. "
        f"A gyro measures no length: the wheels' lengths are NOT DETERMINED until one is known; measure "
        f"{length} and give it in the commented line below."
    )
    todo = (f"known: {{{length}: <metres>}}   # measured; a gyro alone fixes only the ratios of the lengths",)
    return _Alone(
        "imu", rates[0], {"sensor": "gyro"}, words, f"reference: the gyro's rates on {rates[0].name}", todo
    )


def _draft_alone(
    path: Path,
    where: Path,
    bag: tuple[BagSurvey, Topic],
    chosen: tuple[str, Mapping[str, str], str],
    block: tuple[dict[str, Any], _Alone],
) -> Draft:
    """A bag whose only reference is not a pose topic (a lidar's scans, a gyro's rates)."""
    (found, _), (name, joints, why), (dataset, alone) = bag, chosen, block
    dataset[alone.key] = alone.topic.name
    _one_line_names(path, dataset)
    raw = {"name": where.stem, "model": name, **alone.more, "dataset": dataset, **defaults(name)}
    # A lidar's scans are matched as they are read (seconds a thousand scans): the run's own search.
    searched = _searched(raw, where) if alone.key != "scan" else ""
    header = [
        f"Drafted by nlp-calib init from {path}: {found.duration_s:.1f} s, {len(found.topics)} topics.",
        *(f"  {line}" for line in _listing(found)),
        f"model: {name}, because {why}.",
        f"joints {', '.join(joints.values())} are the model's encoders {', '.join(joints)}, in that order.",
        alone.words,
        *([searched] if searched else []),
        f"Check it before a run: nlp-calib preflight {where}",
    ]
    text = _text(header, raw, NOTES) + "".join(f"# {line}\n" for line in alone.todo)
    return Draft(
        raw, text, (*_listing(found), f"model {name}: {why}", alone.short, *([searched] if searched else []))
    )


def _motions(poses_path: Path) -> tuple[np.ndarray, np.ndarray] | None:
    """A TUM file's motions over about :data:`TURN_SPAN_S`, each in the frame it starts from
    ``(n, 7)``, and their durations (s); None where the poses span less."""
    trajectory = read_tum(poses_path)
    t = trajectory.time_s
    dt = np.diff(t)
    step = max(1, round(TURN_SPAN_S / max(float(np.median(dt)), 1e-9))) if dt.size else 1
    P = trajectory.poses
    if P.shape[0] <= step:
        return None
    return poses3d.between(P[:-step], P[step:]), t[step:] - t[:-step]


def cornering(poses_path: Path) -> float | None:
    """The lateral acceleration (m/s²) a tracker's bends reach, as the slip check measures
    it (:func:`~nlp_calib.pipeline.slip_check.lateral`: speed × turn rate, the moving motions'
    90th percentile), over motions of about :data:`TURN_SPAN_S`; None where the poses span less."""
    found = _motions(poses_path)
    if found is None:
        return None
    motions, span = found
    # The turn's angle whatever its axis: a camera's optical frame turns about its y.
    rate = np.linalg.norm(poses3d.quat_to_rotvec(motions[:, 3:7]), axis=1) / span
    return lateral(np.hypot(motions[:, 0], motions[:, 1]) / span, rate)


def turn_axis_tilt(poses_path: Path) -> float | None:
    """How far (rad) the axis a TUM file's poses turn about lies from their frame's z: about 0 for a
    planar tracker's, about π/2 for a camera's optical frame; None where they turn too little."""
    found = _motions(poses_path)
    if found is None:
        return None
    phi = poses3d.quat_to_rotvec(found[0][:, 3:7])
    phi = phi[np.linalg.norm(phi, axis=1) >= TURN_MIN_RAD]
    if phi.shape[0] < 3:
        return None
    axis = np.linalg.eigh(phi.T @ phi)[1][:, -1]
    return float(np.arccos(min(1.0, abs(float(axis[2])))))


def _pose_sensor(poses_path: Path, gyro: bool) -> tuple[dict[str, Any], list[str], tuple[str, ...]]:
    """The scenario's sensor for a TUM file's poses (a camera's where they turn about a tilted axis)
    and a gyro's CSV beside them, what the draft says of it and the lines it leaves for the user."""
    tilt = turn_axis_tilt(poses_path)
    spatial = tilt is not None and tilt >= TILTED_RAD
    # The registered mounts a gyro fits beside: the one whose poses are 3-D, or the planar one.
    mount = next(m for m, _ in BESIDE if sensor_for(m).group == ("SE(3)" if spatial else "SE(2)"))
    reference = sensor_for(mount)
    words = []
    if spatial:
        words.append(
            f"the poses in {poses_path.name} turn about an axis {np.degrees(tilt or 0.0):.0f}° from their z: "
            f"a camera's (sensor: {mount}, its pose on the base in 3-D; docs/camera.md)."
        )
    todo = tuple(f"known: {{{n}: <metres>}}   # measured: {reference.held_why}" for n in reference.held)
    if not gyro:
        return ({"sensor": mount} if spatial else {}), words, todo
    sensor = sensor_for(BESIDE[(mount, "gyro")])
    words.append(
        f"beside them the gyro's rates in {poses_path.with_suffix(GYRO_SUFFIX).name}: {sensor.roles}."
    )
    return {"sensor": {"mount": mount, "beside": "gyro"}}, words, todo


def speeds_finding(sc: Scenario, read: tuple[KinematicModel, Log] | None = None) -> UnitFinding | None:
    """The pre-flight's finding (:func:`nlp_calib.analysis.units.findings`) that the wheel columns
    of ``sc``'s log (``read``: as already read), read as positions, look like speeds; None where it
    finds none."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the log's own warnings are the run's to say
        model, log = read if read is not None else prepare.read(sc)
    track = sc.objective.sensor.sensor.floor_track(log)
    found = findings(log, model, (track[:, :2], track[:, 2]), None, False)
    return next((f for f in found if f.kind == "speeds"), None)


#: The draft's search holds the lag the data show (:func:`lag_search`) at least this far (s) from
#: its edges: the coarse lag is good to about its speeds' span, and a fit needs room about a lag.
LAG_MARGIN_S = 0.25


def _wheel_positions(model: KinematicModel, log: Log) -> np.ndarray:
    """The counters' positions at the records ``(n, k)`` (radians, or counts unwrapped)."""
    names = [n for n, kind in model.encoder_kinds.items() if kind == "counter"]
    return np.column_stack([log.running_position(n) for n in names]) if names else np.zeros((0, 0))


def lag_search(sc: Scenario, read: tuple[KinematicModel, Log] | None = None) -> tuple[list[float], str]:
    """The draft's ``alignment.search`` and why, in words: the search a run makes by default,
    widened to hold the coarse lag the data show (:mod:`~nlp_calib.analysis.lag_screen`, over
    ±:data:`~nlp_calib.analysis.lag_screen.REACH_S`) :data:`LAG_MARGIN_S` inside its edges."""
    lo, hi = AlignmentOptions().search
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the log's own warnings are the run's to say
        model, log = read if read is not None else prepare.read(sc)
        wheels = _wheel_positions(model, log)
        track = sc.objective.sensor.sensor.floor_track(log)
    found = coarse_lag(log.time_s, wheels, track) if wheels.size else None
    lag = shown_lag(found)
    default = f"the search a run makes by default, [{lo:g}, {hi:g}] s"
    speeds = "the wheels' and the reference's speeds"
    if found is None:
        return [lo, hi], f"{default}: {speeds} show no lag (one of them never moves)"
    if lag is None:
        return [lo, hi], (
            f"{default}: {speeds} show no lag within ±{REACH_S:g} s (best {1e3 * found[0]:.0f} ms apart): "
            f"{unshown(found)}"
        )
    shown = f"{speeds} agree best {1e3 * lag:.0f} ms apart (within ±{REACH_S:g} s)"
    if lo + LAG_MARGIN_S <= lag <= hi - LAG_MARGIN_S:
        return [lo, hi], f"{default}: {shown}"
    lo, hi = (
        min(lo, np.floor(10 * (lag - LAG_MARGIN_S)) / 10),
        max(hi, np.ceil(10 * (lag + LAG_MARGIN_S)) / 10),
    )
    return [float(lo), float(hi)], f"[{lo:g}, {hi:g}] s, wider than {default}, because {shown}"


def _drafted(raw: Mapping[str, Any], where: Path) -> Scenario:
    """``raw`` read back as ``run`` reads a scenario at ``where``."""
    return scenario_from_mapping(
        parse_yaml(yaml.safe_dump(dict(raw)), str(where)), str(where), where.parent, where
    )


def _searched(raw: dict[str, Any], where: Path, read: tuple[KinematicModel, Log] | None = None) -> str:
    """``alignment.search`` put in ``raw`` (:func:`lag_search`), and the words that say why."""
    search, why = lag_search(_drafted(raw, where), read)
    raw["alignment"] = {**raw["alignment"], "search": search}
    return f"alignment.search: {why}."


def _wheel_form(raw: Mapping[str, Any], where: Path) -> tuple[list[str], tuple[KinematicModel, Log] | None]:
    """``form: speeds`` put in ``raw``'s dataset where its wheel columns look like speeds (the
    pre-flight's one detector, on the draft as ``run`` would read it), the words that say why, and
    the log as the draft reads it (None: read as positions, it is not the one ``run`` reads)."""
    sc = _drafted(raw, where)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the log's own warnings are the run's to say
        read = prepare.read(sc)
    found = speeds_finding(sc, read)
    if found is None:
        return [], read
    raw["dataset"]["form"] = "speeds"
    return [f"dataset.form: speeds, because {found.words.removesuffix('; say so (form: speeds)')}."], None


#: A two-wheeled base whose wheels' difference turns it as if they were this many times farther
#: apart than the geometric track (ROBOT.yaml's) says, on most of its turns, skids: a differential
#: drive turns as its track says (OptiOdom's: 1.0 times), a skid-steer 1.5 to 2 times (a Husky's
#: ros2_control multiplier is 1.875; the Scout's drive 1.76).
SKID_RATIO = 1.4


def skidding(name: str) -> str | None:
    """The registered model that reads the same wheels as ``name`` and turns them as it does with
    a slip more (a skid-steer beside a differential drive); None where there is none."""
    chosen = MODELS[name]
    for other in MODELS.values():
        if (
            other.name != name
            and dict(other.encoder_kinds) == dict(chosen.encoder_kinds)
            and set(chosen.kinematic_params) < set(other.kinematic_params)
            and set(chosen.turning_params) < set(other.turning_params)
        ):
            return other.name
    return None


def nominal_turning(robot: Path, name: str) -> tuple[float, float | None] | None:
    """ROBOT.yaml's track (m) for the model ``name`` in radians, and its wheels' mean radius (None
    where it gives none); None where it gives no track."""
    form = in_units(MODELS[name], "radians")
    given = load_robot(robot, form).initial_guess
    tracks = [n for n in form.turning_params if n in length_params(form) and n in given]
    radii = [given[n] for n in length_params(form) if n not in form.turning_params and n in given]
    if not tracks:
        return None
    return float(given[tracks[0]]), (float(np.mean(radii)) if radii else None)


def _turning_words(found: Turning) -> str:
    return (
        f"the wheels' difference turns the base as wheels {found.track:.3g} m apart would (the median over "
        f"{found.steps} turning steps of {TURN_STEP_S:g} s, wheels of {1e3 * found.radius:.0f} mm radius by "
        "the travel)"
    )


def _skid_verdict(found: Turning, nominal: tuple[float, float | None], robot: Path) -> tuple[bool, str]:
    """Whether the effective track is :data:`SKID_RATIO` times the geometric one (``nominal``:
    ROBOT.yaml's track and radius) or more on the median turn and no less on most turns (the
    lower quartile), and the words for it."""
    track, radius = nominal
    # In the wheels' own radians where ROBOT.yaml gives their radius: no travel's bias then.
    per_heading = track / radius if radius else track / found.radius
    ratio, most = found.per_heading / per_heading, found.quartiles[0] / per_heading
    said = f"{ratio:.2f} times the {track:.3g} m between the wheels {robot.name} gives"
    if ratio >= SKID_RATIO and most >= 1.0:
        return True, (
            f"{_turning_words(found)}, {said} (on three turns of four, {most:.2f} times or more): its "
            "sides skid as it turns (a differential drive's wheels turn it as their track says; from "
            f"{SKID_RATIO:g} times it, a skid-steer's). This rests on {robot.name}'s track: if it is "
            "not the robot's, give --model"
        )
    if ratio <= 1.0 / SKID_RATIO:
        return False, (
            f"{_turning_words(found)}, {said}: the base turns more than its wheels would, which no skid "
            f"does: check the track and the wheels' radii in {robot.name}"
        )
    return False, f"{_turning_words(found)}, {said}: no skid"


def _skid_sign(
    raw: dict[str, Any], where: Path, read: tuple[KinematicModel, Log] | None, robot: Path | None
) -> tuple[list[str], tuple[KinematicModel, Log] | None]:
    """For a guessed two-wheeled model with a skidding sibling (:func:`skidding`): the words on the
    track the drive turns with, the sibling put in ``raw`` where ``robot``'s geometric track says
    the base skids (:data:`SKID_RATIO`), and the log as read for ``raw`` (None once changed)."""
    name = raw["model"]
    skid = skidding(name)
    if skid is None:
        return [], read
    sc = _drafted(raw, where)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the log's own warnings are the run's to say
        model, log = read if read is not None else prepare.read(sc)
        track = sc.objective.sensor.sensor.floor_track(log)
    found = turning(log, model, (track[:, :2], track[:, 2]))
    nominal = nominal_turning(robot, name) if robot is not None else None
    if found is None:
        return [], (model, log)
    if nominal is None:
        return [
            f"{_turning_words(found)}: a skid-steer's sides drag as it turns, so that it turns as if its "
            f"wheels were farther apart than they are: if yours are nearer, give --model {skid} (or the "
            "track in a ROBOT.yaml: init --robot)."
        ], (model, log)
    skids, words = _skid_verdict(found, nominal, robot or Path())
    if not skids:
        return [f"{words}."], (model, log)
    raw["model"] = skid
    raw.update(defaults(skid))
    return [f"model: {skid}, not {name}, because {words} {name}."], None


@dataclass(frozen=True)
class _Reference:
    """What a joint log's recording is fitted against, as a draft writes it: the joints' CSV, the
    reference's files by their dataset key (a TUM file's poses and a gyro's rates beside them, or
    the sensor's own motions), how the draft names them and how hard the drive corners (None:
    not measured)."""

    joints: Path
    files: Mapping[str, Path]
    named: str
    cornering: float | None = None


def _reference(path: Path) -> _Reference:
    """The recording ``path`` names: a joint log with a TUM file, or (its motions file beside it,
    no TUM file) with a motions file (docs/motions.md)."""
    joints_path, motions_path = motions_pair(path)
    tum = (
        path.suffix.lower() == ".tum" or path.with_name(f"{path.stem.removesuffix('.joints')}.tum").is_file()
    )
    if path.name.endswith(MOTIONS_SUFFIX) or (motions_path.is_file() and not tum):
        if not joints_path.is_file():
            raise DatasetError(str(path), None, f"no {joints_path.name} beside it (its joints' CSV)")
        return _Reference(
            joints_path, {"motions": motions_path}, f"{motions_path.name} (the sensor's motions)"
        )
    joints_path, poses_path = paired_files(path)
    gyro_path = poses_path.with_suffix(GYRO_SUFFIX)
    files = {"poses": poses_path, **({"gyro": gyro_path} if gyro_path.is_file() else {})}
    named = poses_path.name + (f" (a gyro's rates beside them: {gyro_path.name})" if "gyro" in files else "")
    return _Reference(joints_path, files, named, cornering(poses_path))


def _draft_joint_log(path: Path, where: Path, model: str | None, robot: Path | None = None) -> Draft:
    ref = _reference(path)
    table = read_joint_csv(ref.joints)
    name, joints, why = guess_model(list(table.names), model, ref.cornering)
    dataset = {
        "joints": _relative(ref.joints, where),
        **{key: _relative(p, where) for key, p in ref.files.items()},
        "encoders": dict(joints),
        **({"robot": _relative(robot, where)} if robot is not None else {}),
    }
    _one_line_names(ref.joints, dataset)
    gyro = "gyro" in ref.files
    if "poses" in ref.files:
        sensor, words, todo = _pose_sensor(ref.files["poses"], gyro)
    else:
        sensor, words, todo = {}, ["the reference: the sensor's own motions, each over its two stamps."], ()
    raw = {"name": where.stem, "model": name, **sensor, "dataset": dataset, **defaults(name)}
    form, read = _wheel_form(raw, where)
    skid, read = _skid_sign(raw, where, read, robot) if model is None else ([], read)
    searched = _searched(raw, where, read)
    header = [
        f"Drafted by nlp-calib init from {ref.joints.name} (joints: {', '.join(table.names)}) and "
        f"{ref.named}.",
        f"model: {name}, because {why}." if raw["model"] == name else f"first {name}, because {why}.",
        *form,
        *skid,
        searched,
        *words,
        f"Check it before a run: nlp-calib preflight {where}",
    ]
    found = (f"joints: {', '.join(table.names)}", f"model {name}: {why}", *form, *skid, searched)
    text = _text(header, raw, NOTES) + "".join(f"# {line}\n" for line in todo)
    return Draft(raw, text, (*found, *((f"gyro beside the poses {ref.files['gyro'].name}",) if gyro else ())))


def _draft_text_log(path: Path, where: Path, model: str | None) -> Draft:
    kind = read_header(path).kinematic_model
    name = model or model_for_log(kind).name
    raw = {"name": where.stem, "model": name, "dataset": _relative(path, where), "initial_guess": "from_file"}
    header = [
        f"Drafted by nlp-calib init from {path} (#kinematic_model: {kind}).",
        f"Check it: nlp-calib preflight {where}",
    ]
    return Draft(raw, _text(header, raw, {}), (f"a text log of kind {kind}: model {name}",))


def draft(path: Path, where: Path, model: str | None = None, robot: Path | None = None) -> Draft:
    """The scenario drafted from the recording at ``path``, to be written at ``where`` (paths in it
    are relative to that file), read back as ``run`` reads it; ``robot``: a ROBOT.yaml of the
    robot's nominal values (a joint log's)."""
    if robot is not None and path.suffix.lower() not in (".csv", ".tum"):
        raise UsageError(f"--robot {robot}: init reads a ROBOT.yaml beside a joint log (CSV and TUM) only")
    if is_bag(path):
        d = _draft_bag(path, where, model)
    elif path.suffix.lower() in (".csv", ".tum"):
        d = _draft_joint_log(path, where, model, robot)
    else:
        d = _draft_text_log(path, where, model)
    d.scenario(where)  # the draft is one run accepts, or this says why not
    return d
