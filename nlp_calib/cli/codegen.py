"""``nlp-calib codegen``: the residual and its Jacobian as C, with an example that checks them."""

from __future__ import annotations

import argparse

from nlp_calib.cli.calibrate import with_data
from nlp_calib.core import interrupts
from nlp_calib.core.files import check_output_dir
from nlp_calib.outputs.outdir import StagedOutput
from nlp_calib.pipeline import load_scenario
from nlp_calib.pipeline.export import write_c_export


def cmd_codegen(args: argparse.Namespace) -> int:
    scenario = with_data(load_scenario(args.scenario), args.data)
    with StagedOutput(check_output_dir(args.out), "codegen", force=args.force) as stage:
        files, example = write_c_export(scenario, stage.path)
        final = [stage.final(p) for p in files]
        interrupts.hold()
        stage.commit()
    for path in final:
        print(f"wrote {path}")
    print(
        f"\nexample.c evaluates the residual and its Jacobian at the parameters {example.params_from}, on "
        f"{example.window}, and prints its largest difference from Python's values for the same call.\n"
        f"build and run it: make -C {args.out} example && {args.out / 'example'}"
    )
    return 0
