"""``nlp-calib check``: is a calibration still good on a new log? (Apart from ``batch``, whose
worker pool a check does not load.)"""

from __future__ import annotations

import argparse
from pathlib import Path

from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.outputs import registry
from nlp_calib.outputs.check import check_text, drift_of
from nlp_calib.outputs.outdir import refuse_collisions
from nlp_calib.pipeline.check import check, check_scenario
from nlp_calib.pipeline.prepare import read_all
from nlp_calib.pipeline.stored import read_calibration

#: The output groups ``check`` writes: check.json and the refit's result.json.
CHECK_GROUPS = ("check", "result")


def cmd_check(args: argparse.Namespace) -> int:
    stored = read_calibration(args.calibration)
    scenario = check_scenario(stored, args.target)
    # Several logs checked jointly are the scenario's, not its first log's.
    name = scenario.name if scenario.data.joint else scenario.dataset.stem
    out = check_output_dir(args.out if args.out is not None else Path("out") / f"check_{name}")
    if out.resolve() == stored.path.resolve().parent:
        raise UsageError(f"--out {out} holds the calibration being checked; choose another --out")
    outputs = registry.selected(CHECK_GROUPS, report=False)
    refuse_collisions(out, [o.name for o in outputs], force=args.force)
    run = check(stored, scenario, read_all(scenario))
    print(check_text(run))
    final = registry.write_staged(out, outputs, run, registry.OutputOptions(), "check", force=args.force)
    print("\n" + "\n".join(f"wrote {p}" for p in final))
    return drift_of(run).exit_code
