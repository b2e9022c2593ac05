"""Bad input for ``surface_strain compute``: exit 2, one line naming the file, nothing touched.

See tests/badinput.py for the contract and the families.
"""

from __future__ import annotations

import signal
from types import SimpleNamespace

import numpy as np
import pytest

from surface_strain.cli import main
from tests.badinput import (
    WRITING,
    assert_refused,
    interrupt,
    killed,
    message_lines,
    parse_case_id,
    scratch_left,
    snapshot,
)
from tests.filenames import assert_ran, assert_refused_process, latin1, shown, strict_json
from tests.surface_strain.test_cli import _tilted_sheet_tracks, _write

PROG = "surface_strain"


def _set_column(row: str, k: int, value: str) -> str:
    cells = row.split(",")
    cells[k] = value
    return ",".join(cells)


def _decimal_comma(row: str) -> str:
    """The row with its X written with a decimal comma (``12,5`` for ``12.5``)."""
    return _set_column(row, 2, row.split(",")[2].replace(".", ","))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("bad_points")
    c = SimpleNamespace(dir=d)
    points, *_ = _tilted_sheet_tracks(frames=3)
    c.points = d / "points3d.csv"
    _write(c.points, points)
    good = c.points.read_text()
    header, *rows = good.splitlines()
    broken = {
        "empty": "",
        "header_only": header + "\n",
        "no_xyz": "frame,point,X,Y\n0,0,1,2\n",
        "text": good.replace(rows[3], rows[3].replace(rows[3].split(",")[2], "left", 1), 1),
        "infinite": good.replace(rows[3], rows[3].replace(rows[3].split(",")[2], "inf", 1), 1),
        "missing_row": "\n".join([header, *rows[:-1]]) + "\n",
        "duplicate_row": "\n".join([header, *rows, rows[5]]) + "\n",
        "negative_index": "\n".join([header, "-1" + rows[0][1:], *rows[1:]]) + "\n",
        "bom_text": "\ufeff" + good.replace(rows[2], _set_column(rows[2], 3, "y"), 1),
        "truncated": good[: len(good) // 2].rsplit(",", 2)[0] + "\n",
        "all_lost": "\n".join([header] + [",".join([*r.split(",")[:-1], "0"]) for r in rows])
        + "\n",
        # indices that would size (T, N) arrays of 10^16 cells
        "huge_indices": good + "100000000,100000000," + rows[0].split(",", 2)[2] + "\n",
        # a decimal comma (1,5 for 1.5) makes one cell too many: on a later frame and on the
        # reference frame (where it read as a lost point); a cell missing
        "ragged_decimal_comma": good.replace(rows[40], _decimal_comma(rows[40]), 1),
        "ragged_reference_frame": good.replace(rows[3], _decimal_comma(rows[3]), 1),
        "ragged_short_row": good.replace(rows[40], rows[40].rsplit(",", 1)[0], 1),
        "visible_7": good.replace(rows[40], _set_column(rows[40], -1, "7"), 1),
        "visible_half": good.replace(rows[3], _set_column(rows[3], -1, "0.5"), 1),
        "visible_minus_1": good.replace(rows[40], _set_column(rows[40], -1, "-1"), 1),
    }
    for name, text in broken.items():
        (d / f"points_{name}.csv").write_text(text)
    (d / "points_binary.csv").write_bytes(b"\x00\xff\xfe\x01" * 64)
    (d / "points.xlsx").write_bytes(b"PK\x03\x04")
    tri = {"outside": "p0,p1,p2\n0,1,99\n", "repeat": "p0,p1,p2\n0,1,1\n",
           "text": "p0,p1,p2\n0,a,2\n", "empty": "", "two_columns": "p0,p1\n0,1\n",
           "ragged": "p0,p1,p2\n0,1,5\n1,6,5,2\n", "short": "p0,p1,p2\n0,1,5\n1,6\n",
           "ragged_no_header": "0,1,5\n1,6,5,2\n",
           "repeated": "p0,p1,p2\n0,1,5\n1,6,5\n0,1,5\n",
           "repeated_reordered": "p0,p1,p2\n0,1,5\n1,6,5\n5,0,1\n"}  # fmt: skip
    for name, text in tri.items():
        (d / f"tri_{name}.csv").write_text(text)
    (d / "tri_binary.csv").write_bytes(b"\x00\xff\xfe\x01" * 64)
    c.mine = d / "thesis"
    c.mine.mkdir()
    (c.mine / "notes.txt").write_text("mine")
    return c


def _compute(c, *extra, points=None):
    return ["compute", points or c.points, *extra]


# fmt: off
CASES = [
    ("compute-missing-points", lambda c, o: _compute(c, "--out", o, points=c.dir / "no.csv"),
     ["no.csv", "not found"]),
    ("compute-missing-triangles", lambda c, o: _compute(c, "--triangles", c.dir / "no.csv",
     "--out", o), ["no.csv"]),
    ("compute-empty-file", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_empty.csv"), ["points_empty.csv", "empty"]),
    ("compute-empty-header-only", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_header_only.csv"), ["points_header_only.csv", "no rows"]),
    ("compute-empty-triangles", lambda c, o: _compute(c, "--triangles", c.dir / "tri_empty.csv",
     "--out", o), ["tri_empty.csv", "no triangles"]),
    ("compute-empty-all-lost", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_all_lost.csv"), ["points_all_lost.csv", "reference frame"]),
    ("compute-truncated-rows", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_truncated.csv"), ["points_truncated.csv"]),
    ("compute-truncated-missing-row", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_missing_row.csv"), ["points_missing_row.csv", "one row for each"]),
    ("compute-wrong-type-binary", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_binary.csv"), ["points_binary.csv"]),
    ("compute-wrong-type-xlsx", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points.xlsx"), ["points.xlsx"]),
    ("compute-wrong-type-folder", lambda c, o: _compute(c, "--out", o, points=c.dir),
     ["is a folder, not a points file"]),
    ("compute-wrong-type-folder-as-triangles", lambda c, o: _compute(c, "--triangles", c.dir,
     "--out", o), ["is a folder, not a triangles file"]),
    ("compute-wrong-type-binary-triangles", lambda c, o: _compute(c, "--triangles",
     c.dir / "tri_binary.csv", "--out", o), ["tri_binary.csv"]),
    *[(f"compute-csv-{name}", (lambda n: lambda c, o: _compute(
        c, "--out", o, points=c.dir / f"points_{n}.csv"))(name), [f"points_{name}.csv", fragment])
      for name, fragment in [("no_xyz", "lacks the column"), ("text", "not a number"),
                             ("infinite", "infinite"), ("duplicate_row", "row"),
                             ("negative_index", "negative"), ("bom_text", "not a number")]],
    *[(f"compute-csv-triangles-{name}", (lambda n: lambda c, o: _compute(
        c, "--triangles", c.dir / f"tri_{n}.csv", "--out", o))(name), [f"tri_{name}.csv"])
      for name in ("outside", "repeat", "text", "two_columns")],
    ("compute-allocation-indices-beyond-the-rows", lambda c, o: _compute(c, "--out", o,
     points=c.dir / "points_huge_indices.csv"), ["points_huge_indices.csv", "is incomplete",
                                                 "frame indices up to 1e+08"]),
    *[(f"compute-csv-{name.replace('_', '-')}", (lambda n: lambda c, o: _compute(
        c, "--out", o, points=c.dir / f"points_{n}.csv"))(name),
        [f"points_{name}.csv, line {line}: {fragment}"]) for name, line, fragment in [
          ("ragged_decimal_comma", 42, "8 cells where the header has 7 (a decimal comma?)"),
          ("ragged_reference_frame", 5, "8 cells where the header has 7 (a decimal comma?)"),
          ("ragged_short_row", 42, "6 cells where the header has 7"),
          ("visible_7", 42, "visible must be 0 or 1, got 7"),
          ("visible_half", 5, "visible must be 0 or 1, got 0.5"),
          ("visible_minus_1", 42, "visible must be 0 or 1, got -1")]],
    *[(f"compute-csv-triangles-{name.replace('_', '-')}", (lambda n: lambda c, o: _compute(
        c, "--triangles", c.dir / f"tri_{n}.csv", "--out", o))(name), [f"tri_{name}.csv",
        fragment]) for name, fragment in [
          ("ragged", "line 3: 4 cells where the header has 3: 1,6,5,2"),
          ("short", "line 3: 2 cells where the header has 3"),
          ("ragged_no_header", "line 2: 4 cells where the first row (line 1) has 3"),
          ("repeated", "lines 2 and 4 give the same triangle: 0, 1, 5 and 0, 1, 5"),
          ("repeated_reordered", "lines 2 and 4 give the same triangle: 0, 1, 5 and 5, 0, 1")]],
    ("compute-option-fps-zero", lambda c, o: _compute(c, "--fps", "0", "--out", o), ["--fps"]),
    ("compute-option-fps-inf", lambda c, o: _compute(c, "--fps", "inf", "--out", o), ["--fps"]),
    ("compute-option-grid-1x25", lambda c, o: _compute(c, "--grid", "1x25", "--out", o),
     ["2 x 2"]),
    ("compute-option-grid-wrong-count", lambda c, o: _compute(c, "--grid", "4x4", "--out", o),
     ["4x4 grid has 16 points"]),
    ("compute-option-grid-text", lambda c, o: _compute(c, "--grid", "five", "--out", o),
     ["--grid"]),
    ("compute-option-directions-cone", lambda c, o: _compute(c, "--directions", "cone:1,2",
     "--out", o), ["--directions"]),
    ("compute-option-directions-nan", lambda c, o: _compute(c, "--directions",
     "vectors:nan,0,0:0,1,0", "--out", o), ["finite"]),
    ("compute-option-directions-parallel", lambda c, o: _compute(c, "--directions",
     "vectors:0,0,1:0,0,2", "--grid", "5x5", "--out", o),
     ["--directions vectors:0,0,1:0,0,2", "parallel"]),
    ("compute-option-directions-zero-vector", lambda c, o: _compute(c, "--directions",
     "vectors:1,0,0:0,0,0", "--out", o), ["--directions", "second vector has zero length"]),
    ("compute-option-directions-zero-axis", lambda c, o: _compute(c, "--directions",
     "cylinder:0,0,0:0,0,0", "--out", o), ["--directions", "axis A has zero length"]),
    ("compute-option-projection", lambda c, o: _compute(c, "--projection", "torus", "--out", o),
     ["--projection"]),
    ("compute-conflict-triangles-and-grid", lambda c, o: _compute(c, "--triangles",
     c.dir / "tri_outside.csv", "--grid", "5x5", "--out", o), ["--triangles and --grid"]),
    ("compute-conflict-grid-and-projection", lambda c, o: _compute(c, "--grid", "5x5",
     "--projection", "sphere", "--out", o), ["--grid and --projection"]),
    ("compute-output-is-the-input", lambda c, o: _compute(c, "--out", c.points, "--overwrite"),
     ["would replace the input"]),
    ("compute-output-inside-input-folder", lambda c, o: _compute(c, "--out", c.dir / "run",
     points=c.dir), ["inside the input folder"]),
    ("compute-output-users-folder", lambda c, o: _compute(c, "--out", c.mine), ["thesis"]),
    ("compute-output-users-folder-overwrite", lambda c, o: _compute(c, "--out", c.mine,
     "--overwrite"), ["thesis", "not a result"]),
    ("compute-output-missing-parent", lambda c, o: _compute(c, "--out", c.dir / "no" / "run"),
     ["does not exist"]),
    ("compute-output-working-directory", lambda c, o: _compute(c, "--out", ".", "--overwrite"),
     ["working directory"]),
]
# fmt: on


@pytest.mark.parametrize(("case", "build", "fragments"), CASES, ids=[c[0] for c in CASES])
def test_bad_input(inputs, tmp_path, capsys, monkeypatch, case, build, fragments):
    monkeypatch.chdir(inputs.dir)
    out = tmp_path / "out"
    argv = [str(a) for a in build(inputs, out)]
    argv.insert(1, "-q")
    assert_refused(main, argv, capsys, prog=PROG, fragments=fragments, inputs=[inputs.dir],
                   out=out)  # fmt: skip
    assert not out.exists()


def test_bad_input_cases_name_their_command_and_family():
    for case, *_ in CASES:
        command, _family, name = parse_case_id(case)
        assert command == "compute" and name, case
    assert len({c[0] for c in CASES}) == len(CASES)


def test_points_lost_on_the_reference_frame_are_named(inputs, tmp_path, capsys):
    points, *_ = _tilted_sheet_tracks(frames=3)
    visible = np.ones(points.shape[:2], bool)
    visible[0, [3, 7]] = False
    points[0, 12] = np.nan
    src = tmp_path / "p.csv"
    _write(src, points, visible)
    assert main(["compute", str(src), "--grid", "5x5", "--no-figures", "--out",
                 str(tmp_path / "o")]) == 0  # fmt: skip
    lines = message_lines(capsys.readouterr().err)
    assert lines == [
        "surface_strain compute: warning: 3 of 25 points are lost (not visible, or NaN) on the "
        "reference frame and are left out of the mesh: point(s) 3, 7, 12"
    ]


@pytest.mark.parametrize(
    ("when", "after", "signum"),
    [
        (None, 0.3, signal.SIGINT),
        ("points over 40 frames", 0.02, signal.SIGINT),
        ("points over 40 frames", 0.5, signal.SIGINT),
        ("points over 40 frames", 0.02, signal.SIGTERM),
        (WRITING, 0.0, signal.SIGTERM),
        ("points over 40 frames", 0.02, signal.SIGHUP),
        ("stale", None, None),
    ],
    ids=[
        "compute-interrupt-imports",
        "compute-interrupt-strain",
        "compute-interrupt-writing",
        "compute-terminate-strain",
        "compute-terminate-writing",
        "compute-terminate-sighup-strain",
        "compute-stale-killed-run",
    ],
)
def test_interrupt(tmp_path, when, after, signum):
    points, *_ = _tilted_sheet_tracks(n=40, frames=40)
    src = tmp_path / "p.csv"
    _write(src, points)
    out = tmp_path / "run"
    if when == "stale":  # a run killed (SIGKILL) while it wrote: the next one removes its scratch
        argv = ["compute", str(src), "--out", str(out)]  # the figures: seconds of writing
        assert killed(["-m", "surface_strain", *argv], out=out)
        assert main(["-q", *argv]) == 0
        assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv", "run"]
        return
    status, err = interrupt(["-m", "surface_strain", "compute", src, "--out", out], after=after,
                            when=when, out=out, inputs=[src], signum=signum)  # fmt: skip
    assert status == 128 + signum  # before the command is parsed the line names the program only
    assert message_lines(err)[-1].startswith("surface_strain")


# ---- names that are not UTF-8 (Windows-origin and shared drives) ---------------------------
# Read and written, in a real process given its names as bytes (VTK raised on them): exit 0,
# the tables of plainly named files, every text file valid UTF-8 (names shown as \xNN).


def _names_points_triangles_and_out(tmp):
    plain = tmp / "plain"
    plain.mkdir()
    points, *_ = _tilted_sheet_tracks(frames=3)
    _write(plain / "points3d.csv", points)
    (plain / "triangles.csv").write_text("p0,p1,p2\n0,1,5\n1,6,5\n1,2,6\n")
    folder = tmp / latin1("Messdatén")
    folder.mkdir()
    src, tri = folder / latin1("pöints3d.csv"), folder / latin1("triängles.csv")
    src.write_bytes((plain / "points3d.csv").read_bytes())
    tri.write_bytes((plain / "triangles.csv").read_bytes())
    before = snapshot(folder)
    # the figures (VTK's screenshots, titles) once; the given triangles without them
    for name, extra in (("grid", []), ("given", ["--triangles", tri, "--no-figures"])):
        ref = plain / name
        plain_extra = ["--triangles", str(plain / "triangles.csv")] if extra else []
        assert main(["compute", "-q", str(plain / "points3d.csv"), "--no-figures", "--out",
                     str(ref), *plain_extra]) == 0  # fmt: skip
        out = tmp / latin1(f"résultats_{name}")
        assert_ran(["-m", "surface_strain", "compute", src, *extra, "--out", out], out)
        for table in ("strain_nodes.csv", "strain_elements.csv"):
            assert (out / table).read_bytes() == (ref / table).read_bytes()
        assert len(list((out / "strain").glob("*.vtp"))) == 3
        assert (out / "figures").is_dir() == (not extra)
        summary = strict_json(out / "summary.json")
        assert summary["input_files"][0]["path"] == shown(src)
    assert snapshot(folder) == before
    assert scratch_left(tmp) == []


class TestNamesNotUtf8:
    """The bad-input matrix's ``filename`` family: names that are not UTF-8 are read and
    written (``test_bad_input[compute-filename-CASE]``, counted with the refusals)."""

    @pytest.mark.parametrize(
        "case", ["compute-filename-points-triangles-and-out", "compute-filename-missing-points"]
    )
    def test_bad_input(self, tmp_path, case):
        assert parse_case_id(case)[:2] == ("compute", "filename")
        if case.endswith("-missing-points"):
            missing = tmp_path / latin1("pöints_perdus.csv")
            assert_refused_process(["-m", "surface_strain", "compute", missing, "--out",
                                    tmp_path / "out"], fragments=[shown(missing)])  # fmt: skip
            assert list(tmp_path.iterdir()) == []
        else:
            _names_points_triangles_and_out(tmp_path)
