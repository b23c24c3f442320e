"""``nlp-calib import-bag``: a ROS bag's joints and tracker written as files a scenario reads.

Joints in radians (the default) are written as they were published, each stream on its own clock:
the joints as a CSV joint log at ``--out`` and the tracker's poses as a TUM file beside it (same
name, ``.tum``), which a scenario reads as ``dataset: {joints: …, poses: …, encoders: …}`` exactly
as it reads the bag. Raw counts (``--joint-units counts``) are paired into a text log.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path

from nlp_calib.core import interrupts
from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import atomic_write_text, check_output_dir, refuse_input_alias
from nlp_calib.logs.bag_files import bag_root
from nlp_calib.logs.bag_joints import joint_files
from nlp_calib.logs.bag_reader import ENCODER_TYPE, TRACKER_TYPES, bag_inventory
from nlp_calib.logs.reader import parse_log
from nlp_calib.models import KinematicModel, encoders, get_model
from nlp_calib.models.radians import in_units
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.sources import BagSource
from nlp_calib.sources.robot import load_robot


def _stamps(given: list[str] | None) -> str | Mapping[str, str]:
    """``--stamps``: ``header``/``receive`` for every topic, or ``TOPIC=how`` for one."""
    if not given:
        return "header"
    if len(given) == 1 and "=" not in given[0]:
        return given[0]
    out = {}
    for item in given:
        topic, sep, how = item.rpartition("=")
        if not sep:
            raise UsageError(
                f"--stamps {item}: give header or receive once, or TOPIC=header|receive per topic"
            )
        out[topic] = how
    return out or "header"


def _write(folder: Path, texts: Mapping[str, str], force: bool) -> StagedOutput:
    with StagedOutput(folder, None, force=force) as stage:
        for name, text in texts.items():
            atomic_write_text(stage.path / name, text)
        interrupts.hold()
        stage.commit()
    return stage


def _joints_named(names: tuple[str, ...], model: KinematicModel) -> tuple[str, ...] | None:
    """The joints among ``names`` whose names say which of the model's encoders each is (its
    encoder's first word in the joint's name, one joint each); None when they do not."""
    out = []
    for encoder in encoders(model):
        word = encoder.split("_")[0]
        found = [n for n in names if word in n.lower()]
        if len(found) != 1:
            return None
        out.append(found[0])
    return tuple(out) if len(set(out)) == len(out) else None


def chosen_topics(args: argparse.Namespace, model: KinematicModel) -> tuple[str, tuple[str, ...], str]:
    """The JointState topic, its joints in the model's encoder order and the tracker's topic: as
    given, else the bag's only candidates; when the bag leaves a choice open, an error listing
    what it holds (topics, types, joint names and frames)."""
    if args.joint_states and args.joints and args.tracker:
        return args.joint_states, args.joints, args.tracker
    found = bag_inventory(args.bag)
    states = [args.joint_states] if args.joint_states else found.of_type(ENCODER_TYPE)
    # Fixed transforms are the robot's description, never a tracker.
    trackers = (
        [args.tracker] if args.tracker else [t for t in found.of_type(*TRACKER_TYPES) if t != "/tf_static"]
    )
    joints = args.joints or (
        _joints_named(found.joints.get(states[0], ()), model) if len(states) == 1 else None
    )
    if len(states) == 1 and len(trackers) == 1 and joints is not None:
        return states[0], joints, trackers[0]
    open_ = [
        w
        for w, ok in (
            ("--joint-states", len(states) == 1),
            ("--joints", joints is not None),
            ("--tracker", len(trackers) == 1),
        )
        if not ok
    ]
    listing = "\n  ".join(found.lines())
    raise UsageError(
        f"{args.bag}: cannot choose {', '.join(open_)} from the bag; it holds:\n  {listing}\ngive "
        f"{' '.join(open_)} (the joints in {model.name}'s encoder order: {', '.join(encoders(model))}); a "
        "lidar's scans (sensor_msgs/msg/LaserScan) are read by a scenario's dataset block with scan: TOPIC "
        "(docs/lidar.md), a gyro's rates (sensor_msgs/msg/Imu) with imu: TOPIC (docs/imu.md); "
        f"nlp-calib init {args.bag} drafts that scenario"
    )


def cmd_import_bag(args: argparse.Namespace) -> int:
    model = get_model(args.model)
    joint_states, joints, tracker = chosen_topics(args, model)
    source = BagSource(
        args.bag,
        joint_states,
        joints,
        tracker,
        args.tracker_frame,
        args.robot,
        args.max_gap,
        args.joint_units,
        _stamps(args.stamps),
        args.clock_offset,
    )
    out = args.out
    if out.is_dir() or out.name in ("", ".", ".."):
        raise UsageError(f"--out {out} is a folder; give the path of the log file to write")
    folder = check_output_dir(out.parent)
    bag_root(args.bag)  # a bag, not a FIFO; noted as an input: the log is never written over it
    names = [out.name] if args.joint_units == "counts" else [out.name, out.with_suffix(".tum").name]
    for name in names:
        refuse_input_alias(folder / name)
    refuse_collisions(folder, names, tracked=False, force=args.force)  # it may be the user's log
    if args.joint_units == "radians":
        return _import_radians(args, source, folder, names)
    header, records = source.records(model)
    text = records.text(header, model.encoder_kinds)
    # Read back as a run will read it: records a strict read refuses are named now, as warnings.
    log = parse_log(text.splitlines(), model.encoder_kinds, str(out), strict=False)
    stage = _write(folder, {out.name: text}, args.force)
    print(f"read {args.bag}: {records.pairing.describe()}")
    print(f"wrote {stage.final(stage.path / out.name)} ({log.n_records} records over {log.time_s[-1]:.1f} s)")
    if args.robot is None:
        guess = ", ".join(f"{n} {v:g}" for n, v in header.parameters.items())
        ranges = ", ".join(f"{n} {v}" for n, v in zip(header.encoder_names, header.encoder_max))
        print(
            f"note: no --robot: the header holds {model.name}'s defaults (initial guess {guess}; encoder "
            f"ranges {ranges}); give your robot's in ROBOT.yaml, or use 'initial_guess: auto'"
        )
    return 0


def _import_radians(args: argparse.Namespace, source: BagSource, folder: Path, names: list[str]) -> int:
    model = get_model(args.model)
    if args.robot is not None:  # read and checked now: the scenario line below names it
        load_robot(args.robot, in_units(model, "radians"))
    csv_text, tum_text, summary = joint_files(args.bag, source.topics())
    stage = _write(folder, dict(zip(names, (csv_text, tum_text))), args.force)
    joints, poses = (stage.final(stage.path / n) for n in names)
    print(f"read {args.bag}: {summary}")
    print(f"wrote {joints} (the joints in radians) and {poses} (the tracker's poses)")
    pairs = ", ".join(f"{e}: {j}" for e, j in zip(encoders(model), source.joints))
    robot = "" if args.robot is None else f", robot: {args.robot}"
    block = f"{{joints: {joints}, poses: {poses}, encoders: {{{pairs}}}{robot}}}"
    print(f"a scenario reads them as: dataset: {block}")
    return 0
