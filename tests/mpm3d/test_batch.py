"""``mpm3d batch``: stacks analyzed as a batch, each run the one analyze makes, a table of their
metrics, a damaged stack reported in one line, a rerun that keeps what is complete (whatever
memory limit it was made under: the results do not depend on it)."""

import csv
import json
import shutil

from mpm3d.batch import METRIC_COLUMNS
from mpm3d.cli import main
from tissue_core.batch import differences


def test_a_batch_of_stacks_makes_analyze_runs_and_a_table_of_their_metrics(
    mpm_small, tmp_path, capsys
):
    stack = mpm_small[0]
    first = tmp_path / "first.tif"
    shutil.copy(stack, first)
    broken = tmp_path / "broken.tif"
    broken.write_bytes(stack.read_bytes()[:20000])
    manifest = tmp_path / "stacks.csv"
    manifest.write_text(f"stack,name,channel\n{first},A,\n{broken},B,\n{first},C,0\n")
    out = tmp_path / "batch"
    assert main(["batch", str(manifest), "--no-figures", "--workers", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    line = err.strip().splitlines()[-1]
    assert line.startswith("mpm3d batch: error: 1 of 3 runs failed") and "B: " in line, err
    assert "truncated or damaged" in line
    # each run is the one analyze makes
    alone = tmp_path / "alone"
    assert main(["analyze", str(first), "--no-figures", "--out", str(alone), "-q"]) == 0
    assert differences(alone, out / "runs" / "A") == []
    # the table: one row per stack made, the values of its metrics.json
    with open(out / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["name"] for r in rows] == ["A", "C"]
    metrics = json.loads((out / "runs" / "C" / "metrics.json").read_text())
    assert metrics["parameters"]["channel"] == 0
    for column in METRIC_COLUMNS:
        value = metrics[column]
        assert rows[1][column] == ("" if value is None else str(value)), column
    # a rerun under another memory limit keeps A and C, and tries B again
    before = (out / "runs" / "A" / ".tissue-strain-result.json").read_bytes()
    argv = ["batch", str(manifest), "--no-figures", "--memory-limit", "3GiB", "--workers", "1"]
    assert main([*argv, "--out", str(out)]) == 2
    log = (out / "batch.log").read_text()
    assert "batch of 3 runs: 2 complete already, 1 to run" in log
    assert (out / "runs" / "A" / ".tissue-strain-result.json").read_bytes() == before
    # stacks named on the command line, without a manifest
    capsys.readouterr()
    assert (
        main(["batch", str(first), "--no-figures", "--workers", "1", "--out", str(tmp_path / "b2")])
        == 0
    )
    assert (tmp_path / "b2" / "runs" / "first" / "metrics.json").is_file()


def test_bad_batches_of_stacks_end_in_one_line_before_anything_runs(mpm_small, tmp_path, capsys):
    stack = mpm_small[0]
    manifest = tmp_path / "stacks.csv"
    cases = [
        # a cell the option's own checker refuses (it raised argparse's error: a traceback)
        ("stack,name,spacing\n{s},A,abc\n", [], "line 2: column spacing: --spacing must be"),
        ("stack,name,threshold\n{s},A,abc\n", [], "line 2: column threshold"),
        ("stack,name\n{s},A\n", [str(stack)], "is a manifest: give stacks, or one manifest"),
        ("stack\n{s}\n{s}\n", [], "repeated: "),
    ]
    for text, extra, fragment in cases:
        manifest.write_text(text.format(s=stack))
        out = tmp_path / "batch"
        argv = ["batch", str(manifest), *extra, "--workers", "1", "--out", str(out)]
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and fragment in err[0], err
        assert not out.exists()


def test_a_metrics_table_the_user_edited_is_kept_until_overwrite(mpm_small, tmp_path, capsys):
    stack = tmp_path / "A.tif"
    shutil.copy(mpm_small[0], stack)
    out = tmp_path / "batch"
    argv = ["batch", str(stack), "--no-figures", "--workers", "1", "--out", str(out), "-q"]
    assert main(argv) == 0
    table = out / "metrics.csv"
    mine = table.read_text().replace("\n", ",checked\n", 1)  # a column of the user's
    table.write_text(mine)
    capsys.readouterr()
    assert main(argv) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("mpm3d batch: warning: "), err
    assert str(table) in err[0] and "kept as it is" in err[0] and "--overwrite" in err[0]
    assert table.read_text() == mine
    assert main([*argv, "--overwrite"]) == 0
    assert "checked" not in table.read_text()
