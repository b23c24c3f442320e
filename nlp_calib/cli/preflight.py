"""``nlp-calib preflight`` and ``nlp-calib init``: a recording checked before any fit, and a first
scenario drafted from it (the pre-flight every calibrating command runs first: :mod:`.gate`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import check_output_dir, note_input
from nlp_calib.core.text import escaped
from nlp_calib.outputs.outdir import refuse_collisions, write_file
from nlp_calib.outputs.preflight import preflight_lines
from nlp_calib.pipeline import Scenario, load_scenario
from nlp_calib.pipeline.draft import draft
from nlp_calib.pipeline.preflight import preflight
from nlp_calib.results import codec
from nlp_calib.results.preflight import Preflight

#: A scenario file, by its name.
SCENARIO_SUFFIXES = (".yaml", ".yml")


def _scenario_of(target: Path, model: str | None) -> Scenario:
    """The scenario to check: the file itself, or one drafted from a recording (not written)."""
    if target.suffix.lower() in SCENARIO_SUFFIXES:
        if model is not None:
            raise UsageError("--model drafts a scenario for a recording; a scenario names its own model")
        return load_scenario(target)
    where = target.parent / f"{target.stem}.scenario.yaml"
    return draft(target, where, model).scenario(where)


def cmd_preflight(args: argparse.Namespace) -> int:
    """Check a recording (or a scenario's) before any fit; the exit code says the verdict."""
    if args.json is not None:  # refused before the work, not after it
        refuse_collisions(
            check_output_dir(args.json.parent), [args.json.name], tracked=False, force=args.force
        )
    sc = _scenario_of(args.target, args.model)
    report = preflight(sc)
    print("\n".join(escaped(line) for line in preflight_lines(report)))
    if args.json is not None:
        data = json.dumps(_document(report), indent=2, allow_nan=False) + "\n"
        write_file(args.json, data, force=args.force)  # never over an input, a link or a device
        print(f"wrote {args.json}")
    return report.exit_code


def _document(report: Preflight) -> object:
    """The report as JSON data, with its verdict and exit code; the unit and sign findings also
    under ``units``, the key readers have always found them under."""
    doc = {"verdict": report.verdict, "exit_code": report.exit_code, **codec.to_data(report)}
    return {**doc, "units": codec.to_data(report.units)}


def cmd_init(args: argparse.Namespace) -> int:
    """Draft a scenario from a recording and write it (never over a file without --force)."""
    out: Path = args.out if args.out is not None else Path(f"{args.recording.stem or 'recording'}.yaml")
    if out.suffix.lower() not in SCENARIO_SUFFIXES:
        raise UsageError(f"--out {out}: a scenario file ends in .yaml")
    check_output_dir(out.parent)
    refuse_collisions(out.parent, [out.name], tracked=False, force=args.force)
    drafted = draft(args.recording, out, args.model, args.robot)
    note_input(args.recording)
    print("found:")
    print("\n".join(f"  {escaped(line)}" for line in drafted.found))
    write_file(out, drafted.text, force=args.force)
    print(f"wrote {out}: check it with 'nlp-calib preflight {out}', then 'nlp-calib run {out}'")
    return 0
