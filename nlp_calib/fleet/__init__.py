"""Fleet layer: many logs at once, one folder each and a summary table.

A batch is a list of picklable jobs (:func:`batch_jobs`: folders, globs, YAML lists), a per-log
task (:func:`run_job`: calibrate or check one log, write its folder, return its summary row) and
a table of the rows (:func:`write_summary`). :func:`run_jobs` runs the jobs on this machine's
processes (:func:`local_workers` of them at once), :func:`~nlp_calib.fleet.cluster.run_on_dask` on
a Dask cluster; any engine that maps a function over arguments runs them elsewhere (docs/fleet.md).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from nlp_calib.core import lazy

if TYPE_CHECKING:
    from nlp_calib.fleet.jobs import BatchOptions, Job, batch_jobs
    from nlp_calib.fleet.pool import local_workers, run_jobs
    from nlp_calib.fleet.task import job_outputs, run_job
    from nlp_calib.outputs.batch import SUMMARY_FILES, write_summary
    from nlp_calib.results.batch import BatchRow

# Each name's module is imported at the name's first use (core/lazy.py).
_EXPORTS: dict[str, str] = {
    "BatchOptions": "nlp_calib.fleet.jobs",
    "Job": "nlp_calib.fleet.jobs",
    "batch_jobs": "nlp_calib.fleet.jobs",
    "local_workers": "nlp_calib.fleet.pool",
    "run_jobs": "nlp_calib.fleet.pool",
    "job_outputs": "nlp_calib.fleet.task",
    "run_job": "nlp_calib.fleet.task",
    "SUMMARY_FILES": "nlp_calib.outputs.batch",
    "write_summary": "nlp_calib.outputs.batch",
    "BatchRow": "nlp_calib.results.batch",
}

__getattr__, __dir__ = lazy.exports(__name__, _EXPORTS)

__all__ = [
    "SUMMARY_FILES",
    "BatchOptions",
    "BatchRow",
    "Job",
    "batch_jobs",
    "job_outputs",
    "local_workers",
    "run_job",
    "run_jobs",
    "write_summary",
]
