"""``nlp-calib batch``: many logs at once, one folder each and a summary table (each calibrated,
or checked as ``nlp-calib check`` checks one)."""

from __future__ import annotations

import argparse
import sys
import time

from nlp_calib.core import threads
from nlp_calib.core.errors import UsageError
from nlp_calib.core.files import check_output_dir
from nlp_calib.fleet import (
    SUMMARY_FILES,
    BatchOptions,
    BatchRow,
    batch_jobs,
    job_outputs,
    local_workers,
    run_jobs,
    write_summary,
)
from nlp_calib.outputs.batch import summary_markdown
from nlp_calib.outputs.outdir import StagedOutput, refuse_collisions
from nlp_calib.outputs.progress import Progress
from nlp_calib.pipeline import load_scenario
from nlp_calib.pipeline.stored import read_calibration
from nlp_calib.results.check import CANNOT_TELL, DRIFTED, EXIT_CODES, STILL_GOOD


def _options(args: argparse.Namespace) -> BatchOptions:
    """The batch's shared options, each input checked before any work."""
    if args.scenario is not None and args.model is not None:
        raise UsageError("give --scenario or --model, not both (the scenario names its model)")
    if args.scenario is not None:
        load_scenario(args.scenario)
    if args.check is not None:
        read_calibration(args.check)
    return BatchOptions(args.out, args.scenario, args.model, args.check, args.solver, args.report, args.force)


def _batch_code(rows: list[BatchRow]) -> int:
    """0 every log ran (with --check: and is still good); 1 one failed; 3 or 4, a log drifted or
    could not tell."""
    if not all(r.ok for r in rows):
        return 1
    verdicts = {r.verdict for r in rows}
    for verdict in (DRIFTED, CANNOT_TELL):
        if verdict in verdicts:
            return EXIT_CODES[verdict]
    return EXIT_CODES[STILL_GOOD]


def cmd_batch(args: argparse.Namespace) -> int:
    options = _options(args)
    jobs = batch_jobs(args.inputs, options)
    out = check_output_dir(options.out)
    refuse_collisions(out, SUMMARY_FILES, force=options.force)
    for job in jobs:
        refuse_collisions(
            check_output_dir(job.folder), [o.name for o in job_outputs(job)], force=options.force
        )
    if args.dask is not None:
        if args.jobs is not None:
            raise UsageError("give --jobs or --dask, not both (the cluster's workers run the logs)")
        workers, where = 0, f"on the Dask cluster at {args.dask}"
    else:
        free = threads.free_cores()
        workers = local_workers(args.jobs, len(jobs), free)
        where = f"{workers} at a time ({free:.1f} of {threads.cores()} cores free)"
    rows: list[BatchRow | None] = [None] * len(jobs)
    t0 = time.perf_counter()
    with Progress(len(jobs), sys.stderr, label="logs") as progress:
        progress.update(0, where)

        def done(i: int, row: BatchRow) -> None:
            rows[i] = row
            n = sum(r is not None for r in rows)
            left = (time.perf_counter() - t0) / n * (len(jobs) - n)
            failed = sum(1 for r in rows if r is not None and not r.ok)
            progress.update(n, f"{row.name} {row.verdict}; {failed} failed; about {left:.0f} s left")

        if args.dask is not None:
            from nlp_calib.fleet.cluster import run_on_dask

            run_on_dask(jobs, args.dask, done)
        else:
            run_jobs(jobs, workers, done)
    finished = [r for r in rows if r is not None]
    with StagedOutput(out, "batch", force=options.force) as stage:
        write_summary(finished, stage.path)
        final = stage.commit()
    print(summary_markdown(finished))
    print("\n".join(f"wrote {p}" for p in final))
    print(f"wrote {len(jobs)} log folders into {out}/ ({time.perf_counter() - t0:.1f} s, {where})")
    return _batch_code(finished)
