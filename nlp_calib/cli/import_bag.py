"""``nlp-calib import-bag``: a ROS bag's encoders and tracker written as a text log."""

from __future__ import annotations

import argparse

from nlp_calib.core import interrupts
from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import atomic_write_text, check_output_dir, refuse_input_alias
from nlp_calib.logs.bag_files import bag_root
from nlp_calib.logs.reader import parse_log
from nlp_calib.models import get_model
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.sources import BagSource


def cmd_import_bag(args: argparse.Namespace) -> int:
    model = get_model(args.model)
    source = BagSource(
        args.bag, args.joint_states, args.joints, args.tracker, args.tracker_frame, args.robot, args.max_gap
    )
    out = args.out
    if out.is_dir() or out.name in ("", ".", ".."):
        raise UsageError(f"--out {out} is a folder; give the path of the log file to write")
    folder = check_output_dir(out.parent)
    bag_root(args.bag)  # a bag, not a FIFO; noted as an input: the log is never written over it
    refuse_input_alias(out)
    refuse_collisions(folder, [out.name], tracked=False, force=args.force)  # it may be the user's log
    header, records = source.records(model)
    text = records.text(header, model.encoder_kinds)
    # Read back as a run will read it: records a strict read refuses are named now, as warnings.
    log = parse_log(text.splitlines(), model.encoder_kinds, str(out), strict=False)
    with StagedOutput(folder, None, force=args.force) as stage:
        atomic_write_text(stage.path / out.name, text)
        interrupts.hold()
        stage.commit()
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
