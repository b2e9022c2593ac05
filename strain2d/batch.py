"""``strain2d batch``: a manifest of videos analyzed as a batch, then combined in a study.

The manifest is a CSV with one row per specimen:

* ``video`` (or ``source``): the video, TIFF, or image folder, relative to the
  manifest's folder or absolute (required);
* ``specimen``: the run's name (default: the video's name without suffix);
* ``group``: the specimen's group in the study (optional);
* any option of ``strain2d analyze`` by its long name (``grid``, ``roi``,
  ``tracker``, ``fps``, ``scale``, ``endpoint``, ``min_triangle_quality``...):
  that row's value, which wins over the one given to the batch.

Other columns (notes, ground truth) are kept in the manifest and not used; the
log names them.  Each specimen is analyzed into ``OUT/runs/SPECIMEN`` as
``strain2d analyze`` would, as one task of the batch (see
:mod:`tissue_core.batch`); the runs that succeeded are then combined into
``OUT/study`` (``strain2d study``).  Its manifest, ``OUT/study_manifest.csv``
(``run,specimen,group``), is the batch's while it holds what the batch wrote
(the folder's ledger, ``.tissue-strain-files.json``, records it), and is
written again when the runs change.  Once edited (groups changed, an
``endpoint`` column added, a run left out) it is the user's: later batches
keep it as it is, build the study from it, and say so in a warning that names
the finished runs it does not list; ``--overwrite`` replaces it with the
batch's own.  Its names are written inert for spreadsheets
(:mod:`tissue_core.csvtext`).
"""

from __future__ import annotations

import argparse
import io
import os
import warnings
from pathlib import Path

from tissue_core.batch import (
    Job,
    RunOptions,
    job_state,
    manifest_jobs,
    run_job,
    update_batch_file,
)
from tissue_core.csvtext import csv_writer
from tissue_core.errors import InputError
from tissue_core.outputs import remove_stale_scratch

__all__ = ["analyze_jobs", "study_job", "write_study_manifest"]


def analyze_jobs(
    manifest: str, out: Path, options: RunOptions, args: argparse.Namespace
) -> tuple[list[Job], list[dict], list[str]]:
    """The batch's runs, one per manifest row: ``(jobs, rows, unused_columns)``."""
    return manifest_jobs(
        manifest,
        out,
        options,
        args,
        module="strain2d.cli",
        command="analyze",
        sources=[("video", None)],
        aliases={"source": "video"},
        own_columns=("group", "run"),
    )


def write_study_manifest(
    path: Path, jobs: list[Job], rows: list[dict], done: set[str], *, overwrite: bool = False
) -> bool:
    """The study's manifest (runs relative to it): the runs in ``done``; whether it changed.

    A manifest the user edited, or one the batch did not write, is kept as it
    is unless ``overwrite``, with a warning naming the runs of ``done`` it does
    not list (see the module docstring).
    """
    buffer = io.StringIO()
    writer = csv_writer(buffer, lineterminator="\n")
    writer.writerow(["run", "specimen", "group"])
    for job, row in zip(jobs, rows, strict=True):
        if job.name in done:
            writer.writerow([Path(job.out).relative_to(path.parent).as_posix(), job.name,
                             row.get("group", "")])  # fmt: skip
    remove_stale_scratch(path)  # left by a batch killed while it wrote the manifest
    what = update_batch_file(path, buffer.getvalue(), overwrite=overwrite)
    if what == "kept":
        unlisted = _not_listed(path, [job for job in jobs if job.name in done])
        warnings.warn(
            f"{path} was edited since the batch wrote it (or not written by a batch): kept as "
            "it is, and the study is built from it"
            + (f"; it does not list the finished runs {', '.join(unlisted)}" if unlisted else "")
            + " (--overwrite replaces it with the list of the runs)",
            UserWarning,
            stacklevel=2,
        )
    return what == "written"


def _not_listed(path: Path, jobs: list[Job]) -> list[str]:
    """The names of ``jobs`` whose run folders the study manifest ``path`` does not list."""
    from strain2d.study import read_manifest

    try:
        listed = {os.path.abspath(entry["run"]) for entry in read_manifest(path)}
    except InputError:  # the study says what is wrong with it
        return []
    return [job.name for job in jobs if os.path.abspath(job.out) not in listed]


def study_job(out: Path, args: argparse.Namespace) -> Job:
    """``strain2d study`` on the batch's study manifest, into ``OUT/study``."""
    argv = ["study", "--manifest", str(out / "study_manifest.csv")]
    argv += ["--compare", args.compare, "--alpha", str(args.alpha)]
    if getattr(args, "figure_format", None):
        argv += ["--figure-format", args.figure_format]
    argv += ["--out", str(out / "study")]
    # the manifest is an input: edited since the study was made, the study is made again
    return Job("study", "strain2d.cli", tuple(argv), str(out / "study"), (argv[2],))


def run_study(job: Job, changed: bool, run=run_job):
    """Build the study when a run changed or it is not complete; None when it was kept.

    ``run(job, overwrite, remake)`` makes it: here by default, on the batch's workers
    when :func:`tissue_core.batch.run_batch` passes its own (``then``).
    """
    remove_stale_scratch(job.out)  # left by a killed batch: its earlier study put back
    state = job_state(job)
    if state == "complete" and not changed:
        return None
    return run(job, overwrite=state != "missing", remake=changed)
