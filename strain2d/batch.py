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
``OUT/study`` (``strain2d study``).  Its manifest, ``OUT/study_manifest.csv``,
is written again by every batch; copy it to edit it (groups, endpoints) and give
the copy to ``strain2d study``.
"""

from __future__ import annotations

import argparse
import csv
import io
from pathlib import Path

from tissue_core.batch import Job, RunOptions, job_state, manifest_jobs, run_job
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


def write_study_manifest(path: Path, jobs: list[Job], rows: list[dict], done: set[str]) -> bool:
    """The study's manifest (runs relative to it): the runs in ``done``; whether it changed."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["run", "specimen", "group"])
    for job, row in zip(jobs, rows, strict=True):
        if job.name in done:
            writer.writerow([Path(job.out).relative_to(path.parent).as_posix(), job.name,
                             row.get("group", "")])  # fmt: skip
    text = buffer.getvalue()
    remove_stale_scratch(path)  # left by a batch killed while it wrote the manifest
    try:
        if path.read_text(encoding="utf-8") == text:
            return False
    except OSError:
        pass
    from tissue_core.outputs import replaced_on_success

    with replaced_on_success(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return True


def study_job(out: Path, args: argparse.Namespace) -> Job:
    """``strain2d study`` on the batch's study manifest, into ``OUT/study``."""
    argv = ["study", "--manifest", str(out / "study_manifest.csv")]
    argv += ["--compare", args.compare, "--alpha", str(args.alpha)]
    if getattr(args, "figure_format", None):
        argv += ["--figure-format", args.figure_format]
    argv += ["--out", str(out / "study")]
    return Job("study", "strain2d.cli", tuple(argv), str(out / "study"))


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
