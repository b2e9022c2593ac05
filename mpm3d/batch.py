"""``mpm3d batch``: many stacks analyzed as a batch, and one table of their metrics.

The stacks are named on the command line (``mpm3d batch stacks/*.tif``) or in a
manifest CSV with one row per stack:

* ``stack``: the TIFF, relative to the manifest's folder or absolute (required);
* ``name``: the run's name (default: the stack's name without suffix);
* any option of ``mpm3d analyze`` by its long name (``channel``, ``spacing``,
  ``threshold``, ``smooth``...): that row's value, which wins over the one
  given to the batch.

Each stack is analyzed into ``OUT/runs/NAME`` as ``mpm3d analyze`` would, as one
task of the batch (:mod:`tissue_core.batch`); ``OUT/metrics.csv`` then lists the
headline metrics of every run, one row per stack, with units in the column
names.  The table is the batch's while it holds what the batch wrote (the
folder's ledger, ``.tissue-strain-files.json``, records it); one the user
edited is kept as it is, with a warning, unless ``--overwrite``.  Its names
are written inert for spreadsheets (:mod:`tissue_core.csvtext`).
"""

from __future__ import annotations

import io
import json
import warnings
from pathlib import Path

from tissue_core.batch import Outcome, update_batch_file
from tissue_core.csvtext import csv_writer
from tissue_core.errors import InputError
from tissue_core.filenames import readable

__all__ = ["METRIC_COLUMNS", "stack_rows", "write_metrics_table"]

#: the columns of metrics.csv after name and stack: metrics.json's headline values
METRIC_COLUMNS = (
    "n_folds",
    "fold_height_um",
    "max_fold_height_um",
    "fold_wavelength_um",
    "fold_orientation_deg",
    "fold_coherency",
    "Sa_um",
    "Sq_um",
    "Ssk",
    "Sku",
    "Sz_um",
    "Sdr_percent",
    "surface_coverage",
)


def stack_rows(inputs: list[str]) -> list[dict[str, str]] | str:
    """The batch's rows: a manifest's path (one ``.csv`` given), or one row per stack."""
    if len(inputs) == 1 and inputs[0].lower().endswith(".csv"):
        return inputs[0]
    manifests = [path for path in inputs if path.lower().endswith(".csv")]
    if manifests:
        raise InputError(
            f"{manifests[0]} is a manifest: give stacks, or one manifest alone "
            f"({len(inputs)} inputs given)"
        )
    return [{"stack": path, "_line": f"stack {path}"} for path in inputs]


def write_metrics_table(
    path: Path, outcomes: list[Outcome], *, overwrite: bool = False
) -> int | None:
    """``metrics.csv`` of the runs that exist (made now or before); how many rows it has.

    A table the user edited, or one the batch did not write, is kept as it is
    unless ``overwrite``, with a warning; None then.
    """
    buffer = io.StringIO()
    writer = csv_writer(buffer, lineterminator="\n")
    writer.writerow(["name", "stack", *METRIC_COLUMNS])
    rows = 0
    for outcome in outcomes:
        if outcome.status == "failed":
            continue
        metrics = json.loads((Path(outcome.out) / "metrics.json").read_text(encoding="utf-8"))
        values = ["" if metrics.get(c) is None else metrics[c] for c in METRIC_COLUMNS]
        # a stack's name as text (bytes that are not UTF-8 as \xNN), as metrics.json has it
        writer.writerow([readable(outcome.name), metrics.get("input_path", ""), *values])
        rows += 1
    if update_batch_file(path, buffer.getvalue(), overwrite=overwrite) == "kept":
        warnings.warn(
            f"{path} was edited since the batch wrote it (or not written by a batch): kept as "
            f"it is, without the metrics of this batch's {rows} runs (--overwrite replaces it)",
            UserWarning,
            stacklevel=2,
        )
        return None
    return rows
