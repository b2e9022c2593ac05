"""``python -m stereo`` replaces its own earlier results with --overwrite (never a user's file),
writes strict JSON, and reads what spreadsheets write."""

import csv
import importlib
import json
import subprocess
import sys
import tomllib

import pytest

from stereo.cli import main
from tests.badinput import REPO, assert_refused
from tests.stereo.conftest import SMALL_SIZE


def test_reconstruct_summary_is_strict_json_with_an_imported_calibration(small_stereo, tmp_path):
    """An OpenCV calibration carries no RMS error (NaN): the summary says null, never NaN."""
    s = small_stereo
    calib = tmp_path / "imported.json"
    assert main(["import-calib", str(s.yml), "--out", str(calib)]) == 0
    assert json.loads(calib.read_text())["rms_px"] is None
    out = tmp_path / "rec"
    argv = ["reconstruct", "--calib", calib, "--left", s.left, "--right", s.right,
            "--grid", "5x4", "--roi", "280,150,400,240", "--out", out, "-q"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    summary = json.loads((out / "summary.json").read_text(), parse_constant=pytest.fail)
    assert summary["calibration"]["rms_px"] is None
    assert summary["calibration"]["image_size"] == list(SMALL_SIZE)
    assert summary["points"] == {"n": 20, "grid": [5, 4], "roi": [280.0, 150.0, 400.0, 240.0]}
    assert summary["parameters"]["shape_function"] == "quadratic"
    assert summary["parameters"]["directions"] is None
    assert summary["command"] == ["stereo", *map(str, argv)]  # as every result records it


def _earlier_calibration(path, small_stereo):
    assert main(["import-calib", str(small_stereo.yml), "--out", str(path)]) == 0


@pytest.mark.parametrize("command", ["calibrate", "import-calib", "match"])
def test_an_earlier_result_is_replaced_with_overwrite_but_a_users_file_is_not(
    command, small_stereo, tmp_path, capsys
):
    s = small_stereo
    name = "matches.csv" if command == "match" else "calib.json"
    out = tmp_path / name
    if command == "calibrate":
        argv = ["calibrate", "--left", s.views_left, "--right", s.views_right,
                "--board", "checkerboard:9x6:10"]  # fmt: skip
    elif command == "import-calib":
        argv = ["import-calib", s.yml, "--unit", "cm"]
    else:
        argv = ["match", s.left0, s.right0, "--points", s.points, "--calib", s.calib]
    argv = [str(a) for a in [*argv, "--out", out, "-q"]]
    # an earlier result of the toolkit (recorded in the folder's ledger): replaced with --overwrite
    if command == "match":
        assert main(argv) == 0
    else:
        _earlier_calibration(out, s)
    assert main([*argv, "--overwrite"]) == 0
    if command == "match":
        rows = list(csv.DictReader(out.read_text().splitlines()))
        assert len(rows) == len(s.truth["left_px"][0])
    else:
        calib = json.loads(out.read_text())
        assert ("imported_from" in calib) == (command == "import-calib")
        assert calib["unit"] == ("cm" if command == "import-calib" else "mm")
    # a file of the user's with the same name: left as it is, with or without --overwrite
    out.write_text("x,y\n1,2\n" if command == "match" else '{"notes": "mine"}\n')
    for extra in ([], ["--overwrite"]):
        assert_refused(main, [*argv, *extra], capsys, prog="stereo", fragments=[name], out=out)


def test_points_written_by_a_spreadsheet_are_read(small_stereo, tmp_path):
    """A byte-order mark, spaces and capitals in the header, CRLF line ends."""
    s = small_stereo
    rows = [f"{x:.4f},{y:.4f}" for x, y in s.truth["left_px"][0][:5]]
    points = tmp_path / "points.csv"
    points.write_bytes(("\ufeff X , Y \r\n" + "\r\n".join(rows) + "\r\n").encode("utf-8"))
    out = tmp_path / "m.csv"
    argv = ["match", s.left0, s.right0, "--points", points, "--calib", s.calib, "--out", out]
    assert main([str(a) for a in [*argv, "-q"]]) == 0
    assert len(list(csv.DictReader(out.read_text().splitlines()))) == 5


def test_the_console_script_runs_like_python_m(small_stereo, tmp_path):
    scripts = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["scripts"]
    module, name = scripts["stereo"].split(":")
    assert callable(getattr(importlib.import_module(module), name))
    code = f"import sys; sys.argv[0] = 'stereo'; from {module} import {name}; {name}()"
    bad = tmp_path / "calib.json"
    bad.write_text("{")
    argv = [sys.executable, "-c", code, "import-calib", str(bad), "--out", str(tmp_path / "c")]
    proc = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.startswith("stereo import-calib: error: ") and "calib.json" in proc.stderr


def test_reconstruct_fills_a_tissue_mask_on_the_left_view(small_stereo, tmp_path):
    """--mask (a polygon CSV on the left view): the grid fills it, no point off the tissue,
    the strain's triangles on it; each point is the rectangle run's point at the same place."""
    import numpy as np

    from strain2d.tracks import read_tracks

    s = small_stereo
    angle = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    outline = np.c_[340 + 60 * np.cos(angle), 195 + 45 * np.sin(angle)]
    mask = tmp_path / "outline.csv"
    np.savetxt(mask, outline, delimiter=",", header="x,y", comments="")
    common = ["reconstruct", "--calib", s.calib, "--left", s.left, "--right", s.right,
              "--grid", "7x6", "--strain", "-q"]  # fmt: skip
    assert main([str(a) for a in [*common, "--mask", mask, "--out", tmp_path / "m"]]) == 0
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    info = summary["points"]["mask"]
    assert info["kind"] == "polygon-csv" and info["grid_points"] == 42
    n = summary["points"]["n"]
    assert n == 42 - info["points_off_tissue"] and 20 <= n < 42
    left = read_tracks(tmp_path / "m" / "tracks_left.csv").reference
    inside = ((left[:, 0] - 340) / 60) ** 2 + ((left[:, 1] - 195) / 45) ** 2 <= 1.0
    assert inside.all() and len(left) == n
    x0, y0, x1, y1 = summary["points"]["roi"]
    rect = ["--roi", f"{x0},{y0},{x1},{y1}", "--out", tmp_path / "r"]
    assert main([str(a) for a in [*common, *rect]]) == 0
    rec = read_tracks(tmp_path / "r" / "tracks_left.csv")
    index = {(round(x, 6), round(y, 6)): i for i, (x, y) in enumerate(rec.reference)}
    assert all((round(x, 6), round(y, 6)) in index for x, y in left)
    masked = json.loads((tmp_path / "m" / "strain" / "summary.json").read_text())
    whole = json.loads((tmp_path / "r" / "strain" / "summary.json").read_text())
    assert 0 < masked["mesh"]["n_triangles"] < whole["mesh"]["n_triangles"]
