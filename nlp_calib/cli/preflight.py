"""``nlp-calib preflight`` and ``nlp-calib init``: a recording checked before any fit, and a first
scenario drafted from it; and the pre-flight every calibrating command runs first."""

from __future__ import annotations

import argparse
import json
import warnings
from collections.abc import Sequence
from pathlib import Path

from nlp_calib.core.errors import DatasetError, NlpCalibWarning, ScenarioError, UsageError
from nlp_calib.core.files import check_output_dir, note_input
from nlp_calib.core.text import escaped
from nlp_calib.logs import Log
from nlp_calib.outputs.outdir import refuse_collisions, write_file
from nlp_calib.outputs.preflight import preflight_lines
from nlp_calib.pipeline import Scenario, load_scenario
from nlp_calib.pipeline.draft import draft
from nlp_calib.pipeline.preflight import preflight, refuse, stops
from nlp_calib.pipeline.stages import Aligned, align_log
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
    drafted = draft(args.recording, out, args.model)
    note_input(args.recording)
    print("found:")
    print("\n".join(f"  {escaped(line)}" for line in drafted.found))
    write_file(out, drafted.text, force=args.force)
    print(f"wrote {out}: check it with 'nlp-calib preflight {out}', then 'nlp-calib run {out}'")
    return 0


def gate(
    scenarios: Sequence[Scenario],
    logs: Sequence[Sequence[Log]],
    skip: bool,
    runs: Sequence[Aligned | None] = (),
) -> None:
    """The pre-flight of each scenario on its logs (read already): a calibration that cannot succeed
    stops here with the pre-flight's words (``--skip-preflight``: it goes on). ``runs``: each
    scenario's run's stages before its windows are bound (None: none), whose lag estimate, prepared
    log and backend the pre-flight judges with (else it prepares and searches its own)."""
    if skip:
        return
    for sc, log_list, run in zip(scenarios, logs, [*runs, *[None] * (len(scenarios) - len(runs))]):
        lag = None if run is None else run.alignment.estimate
        try:
            report = stops(sc, log_list, lag, run)  # its σ, its plan: only where it stops
        except (DatasetError, ScenarioError, UsageError):  # the run refuses these inputs or settings
            raise  # so (its preparation, its backend): said once, now
        except Exception as exc:  # the pre-flight must never be what stops a run that could succeed
            warnings.warn(
                f"pre-flight of {sc.name} not done ({type(exc).__name__}: {exc}); the run goes on",
                NlpCalibWarning,
                stacklevel=2,
            )
            continue
        if report is None:
            continue
        print("\n".join(escaped(line) for line in preflight_lines(report)) + "\n")
        refuse(report, "; to calibrate anyway, give --skip-preflight")


def set_up_and_gate(
    scenarios: Sequence[Scenario],
    logs: Sequence[Sequence[Log]],
    skip: bool,
    solvers: Sequence[str] | None,
) -> list[Aligned | None]:
    """Each one-log scenario through the run's stages before its windows are bound (prepared,
    screened, its lag searched), then :func:`gate` with each run's own lag estimate: the lag is
    searched once, on the screened log the run fits, not again by the pre-flight on the log as
    read; the windows are bound after the gate (their memory not held while it judges). The
    warnings of those stages are said after the gate lets the run go on, as they were when the
    gate came first. None for a scenario of several logs or whose stages failed (the run goes
    through them again when its turn comes and says why there, as it did)."""
    aligned: list[Aligned | None] = []
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        for sc, log_list in zip(scenarios, logs):
            aligned.append(None if sc.data.joint else _aligned(sc, log_list[0], solvers))
    gate(scenarios, logs, skip, aligned)
    for w in {(str(w.message), w.category, w.filename, w.lineno): w for w in said}.values():
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, source=w.source)
    return aligned


def _aligned(sc: Scenario, log: Log, solvers: Sequence[str] | None) -> Aligned | None:
    try:
        return align_log(sc, log, tuple(solvers or sc.solvers))
    except Exception:  # said by the run, in its turn, which goes through these stages again
        return None
