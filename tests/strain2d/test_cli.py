import csv
import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest
import tifffile

from strain2d.cli import main


def _hash(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def test_analyze_writes_the_contracted_outputs(small_case, tmp_path):
    folder, video = small_case
    src = folder / "eq.avi"
    before = _hash(src)
    out = tmp_path / "run"
    x0, y0, x1, y1 = video.truth.roi
    rc = main(
        [
            "-q",
            "analyze",
            str(src),
            "--grid",
            "5x5",
            "--roi",
            f"{x0},{y0},{x1},{y1}",
            "--tracker",
            "klt",
            "--window",
            "21",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    for name in (
        "tracks.csv",
        "strain_nodes.csv",
        "strain_elements.csv",
        "summary.json",
        "strain.pvd",
        "figures/tracked_grid.png",
        "figures/strain_frame0005.png",
    ):
        assert (out / name).is_file(), name
    assert len(list((out / "strain").glob("strain_*.vtp"))) == 6
    rows = _read_csv(out / "strain_nodes.csv")
    assert list(rows[0])[:10] == [
        "frame",
        "point",
        "x",
        "y",
        "u",
        "v",
        "visible",
        "Exx",
        "Eyy",
        "Exy",
    ]
    assert {"E1", "E2", "J"} <= set(rows[0])
    assert len(rows) == 6 * 25
    last = [r for r in rows if r["frame"] == "5"]
    exx = np.array([float(r["Exx"]) for r in last])
    assert abs(exx.mean() - 0.625) < 0.02
    summary = json.loads((out / "summary.json").read_text())
    assert summary["software"]["version"]
    assert summary["inputs"] == [str(src)]
    assert summary["tracker"]["options"]["window"] == 21
    assert summary["points"]["grid"] == "5x5"
    assert summary["final_frame"]["nodal_strain"]["Exx"]["n"] == 25
    assert _hash(src) == before  # inputs are never modified
    assert not list(tmp_path.glob(".run.tmp-*"))


def test_existing_output_needs_overwrite(small_case, tmp_path, capsys):
    folder, _ = small_case
    out = tmp_path / "run"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    rc = main(["analyze", str(folder / "eq.tif"), "--out", str(out)])
    assert rc == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "mine"
    assert (
        main(
            [
                "-q",
                "analyze",
                str(folder / "eq.tif"),
                "--grid",
                "3x3",
                "--out",
                str(out),
                "--overwrite",
            ]
        )
        == 0
    )
    assert not (out / "keep.txt").exists()
    assert (out / "summary.json").is_file()


def test_interrupted_run_leaves_nothing_behind(small_case, tmp_path, monkeypatch, capsys):
    folder, _ = small_case
    import strain2d.export

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(strain2d.export, "write_pvd", boom)
    out = tmp_path / "run"
    assert (
        main(["-q", "analyze", str(folder / "eq.avi"), "--grid", "3x3", "--out", str(out)]) == 130
    )
    assert "interrupted" in capsys.readouterr().err
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_track_command_writes_tracks_csv(small_case, tmp_path):
    folder, video = small_case
    points = tmp_path / "points.csv"
    grid = video.truth.grid((3, 3))
    points.write_text("x,y\n" + "\n".join(f"{x},{y}" for x, y in grid))
    out = tmp_path / "tracks.csv"
    assert (
        main(
            [
                "-q",
                "track",
                str(folder / "eq.tif"),
                "--points",
                str(points),
                "--tracker",
                "klt",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = _read_csv(out)
    assert list(rows[0]) == ["frame", "point", "x", "y", "visible", "quality"]
    assert len(rows) == 6 * 9
    final = np.array([[float(r["x"]), float(r["y"])] for r in rows if r["frame"] == "5"])
    np.testing.assert_allclose(final, video.truth.positions(grid, 5), atol=0.5)
    # the written tracks come back through the imported tracker
    out2 = tmp_path / "run"
    assert (
        main(
            [
                "-q",
                "analyze",
                str(folder / "eq.tif"),
                "--tracker",
                "imported",
                "--tracks-file",
                str(out),
                "--out",
                str(out2),
            ]
        )
        == 0
    )
    assert len(_read_csv(out2 / "strain_nodes.csv")) == 6 * 9


def _bad_inputs(tmp_path, small_case):
    folder, _ = small_case
    garbage = tmp_path / "garbage.mp4"
    garbage.write_bytes(b"\x00not a video" * 50)
    one = tmp_path / "one.tif"
    tifffile.imwrite(one, np.zeros((1, 32, 32), np.uint8))
    two_pts = tmp_path / "two.csv"
    two_pts.write_text("x,y\n10,10\n20,20\n")
    line_pts = tmp_path / "line.csv"
    line_pts.write_text("x,y\n10,10\n20,20\n30,30\n")
    eq = str(folder / "eq.avi")
    out = str(tmp_path / "out")
    return {
        "missing file": (["analyze", str(tmp_path / "nope.avi"), "--out", out], "no such file"),
        "unreadable video": (["analyze", str(garbage), "--out", out], "cannot read"),
        "one-frame video": (["analyze", str(one), "--out", out], "1 frame"),
        "two points": (["analyze", eq, "--points", str(two_pts), "--out", out], "at least 3"),
        "collinear points": (["analyze", eq, "--points", str(line_pts), "--out", out], "collinear"),
        "roi outside": (["analyze", eq, "--roi", "0,0,500,500", "--out", out], "outside"),
        "bad grid": (["analyze", eq, "--grid", "seven", "--out", out], "--grid"),
        "unknown tracker": (["track", eq, "--tracker", "magic", "--out", out], "unknown tracker"),
        "option for another tracker": (
            ["analyze", eq, "--tracks-file", "x.csv", "--out", out],
            "does not apply",
        ),
        "missing output folder": (
            ["analyze", eq, "--out", str(tmp_path / "a" / "b")],
            "does not exist",
        ),
    }


CASES = [
    "missing file",
    "unreadable video",
    "one-frame video",
    "two points",
    "collinear points",
    "roi outside",
    "bad grid",
    "unknown tracker",
    "option for another tracker",
    "missing output folder",
]


@pytest.mark.parametrize("name", CASES)
def test_user_errors_exit_2_with_one_line(name, tmp_path, small_case, capsys):
    argv, expected = _bad_inputs(tmp_path, small_case)[name]
    rc = main(["-q", *argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert len(err.strip().splitlines()) == 1, err
    assert expected in err
    assert "Traceback" not in err
    assert not (tmp_path / "out").exists()


def test_module_entry_point_and_argparse_errors(tmp_path):
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "strain2d",
            "analyze",
            str(tmp_path / "x.avi"),
            "--out",
            str(tmp_path / "o"),
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 2
    assert res.stderr.count("\n") == 1 and "no such file" in res.stderr
    res = subprocess.run(
        [sys.executable, "-m", "strain2d", "analyze"], capture_output=True, text=True
    )
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    res = subprocess.run(
        [sys.executable, "-m", "strain2d", "--help"], capture_output=True, text=True
    )
    assert res.returncode == 0 and "analyze" in res.stdout


def test_benchmark_quick(tmp_path):
    out = tmp_path / "bench"
    assert (
        main(["-q", "benchmark", "--quick", "--cases", "rotation,tissue", "--out", str(out)]) == 0
    )
    results = json.loads((out / "benchmark.json").read_text())
    rows = {(r["case"], r["tracker"]): r for r in results["results"]}
    assert set(rows) == {("rotation", "klt"), ("tissue", "klt")}
    for row in rows.values():
        assert row["track_px"]["rmse"] < 0.5
        assert row["Exx"]["rmse"] < 0.005
    table = (out / "benchmark.md").read_text()
    assert "| rotation | klt |" in table and "paper (CoTracker3)" in table
    assert (
        main(["-q", "benchmark", "--quick", "--cases", "nope", "--out", str(tmp_path / "b2")]) == 2
    )
