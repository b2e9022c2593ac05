import csv
import hashlib
import json
import subprocess
import sys

import numpy as np
import pytest
import tifffile

from strain2d.cli import main
from strain2d.tracks import read_tracks


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
    assert summary["tracker"]["name"] == "klt"
    assert summary["points"]["grid"] == "5x5"
    assert summary["final_frame"]["nodal_strain"]["Exx"]["n"] == 25
    assert _hash(src) == before  # inputs are never modified
    assert not list(tmp_path.glob(".run.tmp-*"))


def test_existing_output_needs_overwrite(small_case, tmp_path, capsys):
    folder, _ = small_case
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "keep.txt").write_text("mine")
    run = ["-q", "analyze", str(folder / "eq.tif"), "--grid", "3x3", "--animation", "none"]
    for flags in ([], ["--overwrite"]):  # a folder of the user's is never replaced
        assert main([*run, "--out", str(mine), *flags]) == 2
        assert "is not a result of this toolkit" in capsys.readouterr().err
        assert [p.name for p in mine.iterdir()] == ["keep.txt"]
    out = tmp_path / "run"
    assert main([*run, "--out", str(out)]) == 0
    assert main([*run, "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    first = json.loads((out / "summary.json").read_text())
    again = [*run[:3], "--grid", "4x4", "--animation", "none", "--out", str(out), "--overwrite"]
    assert main(again) == 0
    second = json.loads((out / "summary.json").read_text())
    assert (first["points"]["n"], second["points"]["n"]) == (9, 16)


def test_interrupted_run_leaves_nothing_behind(small_case, tmp_path, monkeypatch, capsys):
    """Ctrl-C while the animation is written here, the figures and tables by the workers."""
    folder, _ = small_case
    import strain2d.figures

    def boom(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(strain2d.figures, "write_strain_animation", boom)
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
    trackers = ("dic", "dic (quadratic)", "gdic", "klt", "exact positions")
    assert set(rows) == {(c, t) for c in ("rotation", "tissue") for t in trackers}
    limits = {
        "dic": (0.05, 0.001),
        "dic (quadratic)": (0.1, 0.002),
        "gdic": (0.05, 0.001),
        "klt": (0.5, 0.005),
    }
    for (_, tracker), row in rows.items():
        if tracker == "exact positions":  # homogeneous fields: no discretization error
            assert row["Exx"]["rmse"] < 1e-9
            continue
        assert row["track_px"]["rmse"] < limits[tracker][0]
        assert row["Exx"]["rmse"] < limits[tracker][1]
    figures = sorted(p.name for p in (out / "figures").glob("*.png"))
    assert "rotation_dic_quadratic.png" in figures and len(figures) == 8
    table = (out / "benchmark.md").read_text()
    assert "| rotation | klt |" in table and "| rotation | dic |" in table
    assert "paper (CoTracker3)" in table
    assert (
        main(["-q", "benchmark", "--quick", "--cases", "nope", "--out", str(tmp_path / "b2")]) == 2
    )


def test_output_columns_hold_the_exact_values(small_case, tmp_path):
    """Exact simple-shear tracks through the CLI: every column has its analytic value."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    from sample_data_synth import make_case, write_video
    from strain2d.tracks import Tracks, write_tracks_csv

    video = make_case("shear", size=128, n_frames=3, rng=0)
    write_video(video.frames, tmp_path / "shear.tif")
    grid = video.truth.grid((4, 4))
    true = video.truth.positions(grid)
    write_tracks_csv(tmp_path / "t.csv", Tracks(true, np.ones((3, 16), bool), np.ones((3, 16))))
    out = tmp_path / "run"
    assert (
        main(
            [
                "-q",
                "analyze",
                str(tmp_path / "shear.tif"),
                "--tracker",
                "imported",
                "--tracks-file",
                str(tmp_path / "t.csv"),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    last = [r for r in _read_csv(out / "strain_nodes.csv") if r["frame"] == "2"]
    col = {k: np.array([float(r[k]) for r in last]) for k in last[0]}
    np.testing.assert_allclose(col["u"], true[2, :, 0] - grid[:, 0], atol=1e-5)
    np.testing.assert_allclose(col["v"], true[2, :, 1] - grid[:, 1], atol=1e-5)
    E = np.array([[0.0, 0.25], [0.25, 0.125]])
    e1, e2 = 0.0625 + np.hypot(0.0625, 0.25), 0.0625 - np.hypot(0.0625, 0.25)
    theta = 0.5 * np.degrees(np.arctan2(0.5, -0.125))  # 52.02 degrees
    expected = {
        "Exx": E[0, 0],
        "Eyy": E[1, 1],
        "Exy": E[0, 1],
        "E1": e1,
        "E2": e2,
        "max_shear": 0.5 * (e1 - e2),
        "theta1_deg": theta,
        "J": 1.0,
    }
    for key, value in expected.items():
        np.testing.assert_allclose(col[key], value, atol=1e-6, err_msg=key)
    elements = [r for r in _read_csv(out / "strain_elements.csv") if r["frame"] == "2"]
    for key, value in expected.items():
        got = np.array([float(r[key]) for r in elements])
        np.testing.assert_allclose(got, value, atol=1e-6, err_msg=f"element {key}")
    # reference frame: zero strain, no principal direction
    first = [r for r in _read_csv(out / "strain_nodes.csv") if r["frame"] == "0"]
    assert all(r["theta1_deg"] == "nan" and abs(float(r["Exx"])) < 1e-12 for r in first)
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(out / "strain" / "strain_0002.vtp"))
    reader.Update()
    direction = vtk_to_numpy(reader.GetOutput().GetPointData().GetArray("principal_direction_1"))
    np.testing.assert_allclose(
        direction[:, :2], [[np.cos(np.radians(theta)), np.sin(np.radians(theta))]] * 16, atol=1e-6
    )


def test_outputs_never_replace_inputs_or_the_working_directory(
    small_case, tmp_path, monkeypatch, capsys
):
    folder, _ = small_case
    frames = tmp_path / "frames"
    frames.mkdir()
    import shutil

    src = tmp_path / "eq.avi"
    shutil.copy(folder / "eq.avi", src)
    monkeypatch.chdir(tmp_path)
    cases = [
        ["analyze", str(src), "--out", str(tmp_path), "--overwrite"],
        ["analyze", str(src), "--out", ".", "--overwrite"],
        ["track", str(src), "--out", str(src), "--overwrite"],
        ["track", str(src), "--out", str(frames), "--overwrite"],
    ]
    for argv in cases:
        assert main(["-q", *argv]) == 2, argv
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert src.is_file() and frames.is_dir()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["eq.avi", "frames"]


def test_outputs_get_normal_permissions(small_case, tmp_path):
    import os
    import stat

    folder, _ = small_case
    old = os.umask(0o022)
    try:
        assert (
            main(
                [
                    "-q",
                    "analyze",
                    str(folder / "eq.tif"),
                    "--grid",
                    "3x3",
                    "--out",
                    str(tmp_path / "run"),
                ]
            )
            == 0
        )
        assert (
            main(
                [
                    "-q",
                    "track",
                    str(folder / "eq.tif"),
                    "--grid",
                    "3x3",
                    "--out",
                    str(tmp_path / "t.csv"),
                ]
            )
            == 0
        )
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "run").stat().st_mode) == 0o755
    assert stat.S_IMODE((tmp_path / "t.csv").stat().st_mode) == 0o644


def _bad_files(tmp_path):
    """Malformed points and tracks files, each with the words its error must contain."""
    files = {}
    (tmp_path / "adir").mkdir()
    files["points folder"] = ("--points", tmp_path / "adir", "folder")
    p = tmp_path / "bin.csv"
    p.write_bytes(b"\xff\xfe\x00\x81garbage")
    files["binary points"] = ("--points", p, "not a text")
    p = tmp_path / "dup.csv"
    p.write_text("x,y\n50,50\n80,50\n50,80\n50,50\n")
    files["duplicate points"] = ("--points", p, "twice")
    p = tmp_path / "inf.csv"
    p.write_text("frame,point,x,y,visible\n0,0,1,1,inf\n")
    files["infinite flag"] = ("--tracks-file", p, "visible must be 0 or 1")
    p = tmp_path / "vis.npz"
    np.savez(p, positions=np.zeros((6, 3, 2)), visible=np.ones((6, 4), bool))
    files["misshaped visible"] = ("--tracks-file", p, "visible must have shape")
    p = tmp_path / "obj.npz"
    np.savez(p, positions=np.array([None, 1], dtype=object))
    files["object array"] = ("--tracks-file", p, "cannot read")
    p = tmp_path / "nan0.npy"
    pos = np.random.default_rng(0).uniform(20, 100, (6, 4, 2))
    pos[0, 1] = np.nan
    np.save(p, pos)
    files["lost on frame 0"] = ("--tracks-file", p, "visible on the reference")
    return files


@pytest.mark.parametrize(
    "name",
    [
        "points folder",
        "binary points",
        "duplicate points",
        "infinite flag",
        "misshaped visible",
        "object array",
        "lost on frame 0",
    ],
)
def test_malformed_files_exit_2_with_one_line(name, small_case, tmp_path, capsys):
    folder, _ = small_case
    flag, path, expected = _bad_files(tmp_path)[name]
    argv = [
        "-q",
        "analyze",
        str(folder / "eq.avi"),
        flag,
        str(path),
        "--out",
        str(tmp_path / "out"),
    ]
    if flag == "--tracks-file":
        argv += ["--tracker", "imported"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert expected in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("options", "expected"),
    [
        (["--tracker", "klt", "--window", "301"], "smaller than"),
        (["--tracker", "klt", "--fb-threshold", "nan"], "fb-threshold"),
        (["--tracker", "klt", "--window", "-3"], "--window"),
        (["--subset", "301"], "smaller than"),
        (["--subset", "30"], "odd"),
        (["--zncc-min", "1.5"], "between"),
        (["--fps", "-5"], "--fps"),
    ],
)
def test_bad_numbers_exit_2(options, expected, small_case, tmp_path, capsys):
    folder, _ = small_case
    assert (
        main(["-q", "analyze", str(folder / "eq.avi"), *options, "--out", str(tmp_path / "out")])
        == 2
    )
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1


def test_benchmark_heterogeneous_case_separates_grid_and_tracking_error(tmp_path):
    out = tmp_path / "bench"
    assert (
        main(
            [
                "-q",
                "benchmark",
                "--quick",
                "--cases",
                "gaussian",
                "--trackers",
                "dic",
                "--grid",
                "9x9",
                "--no-figures",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = {r["tracker"]: r for r in json.loads((out / "benchmark.json").read_text())["results"]}
    floor, dic = rows["exact positions"], rows["dic"]
    assert floor["Exx"]["rmse"] > 0.01  # a 9x9 grid cannot resolve the local contraction
    assert dic["Exx"]["rmse"] < floor["Exx"]["rmse"] + 0.005  # tracking adds little
    assert dic["track_px"]["rmse"] < 0.3
    assert not (out / "figures").exists()


def test_sweeps_write_tables_and_show_the_expected_trends(tmp_path):
    from strain2d.benchmark import run_sweep, sweep_markdown

    sweep = run_sweep("contrast", quick=True, trackers=["dic"])
    dic = {r["value"]: r for r in sweep["results"] if r["tracker"] == "dic"}
    assert {r["tracker"] for r in sweep["results"]} == {"exact positions", "dic", "dic (quadratic)"}
    assert set(dic) == {0.1, 0.2, 0.4, 0.8}
    assert dic[0.1]["track_px"]["rmse"] > dic[0.8]["track_px"]["rmse"]  # faint pattern: worse
    assert "| equibiaxial | 0.8 | dic |" in sweep_markdown(sweep)
    out = tmp_path / "b"
    assert (
        main(
            [
                "-q",
                "benchmark",
                "--quick",
                "--cases",
                "rotation",
                "--trackers",
                "dic",
                "--no-figures",
                "--sweep",
                "bogus",
                "--out",
                str(out),
            ]
        )
        == 2
    )


def test_dic_summary_records_reference_updates(small_case, tmp_path):
    folder, _ = small_case
    out = tmp_path / "run"
    argv = ["-q", "analyze", str(folder / "eq.tif"), "--grid", "3x3", "--tracker", "dic"]
    assert main([*argv, "--out", str(out)]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["tracker"]["name"] == "dic"
    assert summary["tracker"]["options"]["shape_function"] == "affine"
    assert len(summary["tracker"]["reference_updates"]) == 9


# ---- what a user sees when stderr is a log file, and a few answers that must be honest


def _run_logged(args, cwd):
    """Run ``python -m strain2d ARGS`` with stderr in a pipe (a log file, not a terminal)."""
    return subprocess.run(
        [sys.executable, "-m", "strain2d", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_progress_is_timestamped_lines_when_stderr_is_a_log(small_case, tmp_path):
    folder, _ = small_case
    out = tmp_path / "run"
    res = _run_logged(["analyze", folder / "eq.avi", "--grid", "3x3", "--animation", "none",
                       "--out", out], tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    lines = res.stderr.splitlines()
    steps = [line for line in lines if line.startswith("[")]
    assert any("6 frames of 200x200 px" in line for line in steps), lines
    assert any("tracking 9 points (gdic): 6/6 frames in" in line for line in steps), lines
    assert lines[-1].endswith(f"] results in {out}")
    assert all(line.startswith(("[", "strain2d analyze: warning:")) for line in lines), lines
    res = _run_logged(["track", folder / "eq.avi", "--grid", "3x3", "--out", tmp_path / "t.csv"],
                      tmp_path)  # fmt: skip
    assert res.returncode == 0 and res.stderr.splitlines()[-1].endswith("] tracks in " + str(
        tmp_path / "t.csv"))  # fmt: skip
    res = _run_logged(["-q", "track", folder / "eq.avi", "--grid", "3x3", "--out",
                       tmp_path / "t2.csv"], tmp_path)  # fmt: skip
    assert res.returncode == 0 and res.stderr == ""


def test_a_truncated_video_is_named_and_ffmpeg_keeps_quiet(small_case, tmp_path):
    folder, _ = small_case
    data = (folder / "eq.avi").read_bytes()
    cut = tmp_path / "cut.avi"
    cut.write_bytes(data[: len(data) // 2])
    res = _run_logged(["analyze", cut, "--grid", "3x3", "--out", tmp_path / "run"], tmp_path)
    assert res.returncode == 2
    lines = [line for line in res.stderr.splitlines() if not line.startswith("[")]
    assert len(lines) == 1, res.stderr  # no line of FFmpeg's own
    assert "cut.avi: frame 2 of the 6" in lines[0] and "truncated or damaged" in lines[0]
    assert "--stop 2" in lines[0]
    assert not (tmp_path / "run").exists()


def test_points_the_tracker_cannot_use_on_the_reference_frame_are_named(small_case, tmp_path,
                                                                        capsys):  # fmt: skip
    folder, video = small_case
    points = tmp_path / "p.csv"
    points.write_text("x,y\n0,0\n100,100\n199,10\n50,150\n150,150\n12,100\n")
    out = tmp_path / "run"
    argv = ["analyze", str(folder / "eq.avi"), "--points", str(points), "--animation", "none"]
    # gdic falls back to a smaller subset near the edge (21 or 15 px): a point 12 px from it
    # is measured while one fits, the corners (where none does) never, nor anything out of view
    assert main([*argv, "--out", str(tmp_path / "gdic")]) == 0
    warning = [line for line in capsys.readouterr().err.splitlines() if ": warning: " in line]
    assert len(warning) == 1 and "2 of 6 points cannot be used on the reference frame" in (
        warning[0])  # fmt: skip
    assert "point 0 at (0, 0), point 2 at (199, 10)" in warning[0]
    tracks = read_tracks(tmp_path / "gdic" / "tracks.csv")
    truth = video.truth.positions(tracks.positions[0])
    in_view = np.all((truth >= 0) & (truth <= 199), axis=2)
    assert in_view[0].all() and not in_view[1:, [0, 2]].any()  # the stretch takes them out
    assert tracks.visible[0, 5] and tracks.visible[:, [1, 3, 4]].all()
    assert not (tracks.visible & ~in_view).any()
    argv += ["--tracker", "dic"]  # dic's 31 px subset must fit on the reference frame
    assert main([*argv, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    warning = [line for line in err.splitlines() if ": warning: " in line]
    assert len(warning) == 1 and "3 of 6 points cannot be used on the reference frame" in (
        warning[0])  # fmt: skip
    assert "point 0 at (0, 0), point 2 at (199, 10), point 5 at (12, 100)" in warning[0]
    assert "image edge" in warning[0]
    points.write_text("x,y\n0,0\n100,100\n199,10\n199,199\n")  # only one point left
    assert main([*argv, "--out", str(tmp_path / "run2")]) == 2
    err = capsys.readouterr().err
    assert "only 1 of 4 points can be used on the reference frame" in err
    assert not (tmp_path / "run2").exists()


def test_a_video_that_fades_in_is_told_which_frame_to_start_at(small_case, tmp_path, capsys):
    """A recording that starts dark (a real one fades in over its first frames): most points
    cannot be used on the blank reference, and the warning says to start where the texture
    is, counted in the video's own frames whatever --start was given."""
    from sample_data_synth import write_video

    _, video = small_case
    gain = np.array([0.0, 0.0, 0.01, 0.3, 0.85, 1.0, 1.0, 1.0])[:, None, None]
    frames = np.concatenate([video.frames[:1]] * 3 + [video.frames[:5]])  # 8 frames
    write_video(np.round(frames * gain).astype(np.uint8), tmp_path / "fade.avi")
    argv = ["-q", "track", str(tmp_path / "fade.avi"), "--grid", "3x3"]
    # gdic uses no point on the blank reference: too few left, one line
    assert main([*argv, "--out", str(tmp_path / "a.csv")]) == 2
    err = capsys.readouterr().err
    assert "only 0 of 9 points can be used on the reference frame" in err
    assert "the reference frame is almost blank" in err and "e.g. --start 4" in err
    assert len(err.strip().splitlines()) == 1 and not (tmp_path / "a.csv").exists()
    assert main([*argv, "--start", "1", "--out", str(tmp_path / "b.csv")]) == 2
    assert "e.g. --start 4" in capsys.readouterr().err
    # dic takes every point on the reference and loses them after it: a warning
    argv += ["--tracker", "dic"]
    assert main([*argv, "--out", str(tmp_path / "b.csv")]) == 0
    err = capsys.readouterr().err
    assert "9 of 9 points are lost on most frames" in err and "e.g. --start 4" in err
    argv = argv[:-2]  # gdic from the textured frame on: every point
    assert main([*argv, "--start", "4", "--out", str(tmp_path / "c.csv")]) == 0
    assert read_tracks(tmp_path / "c.csv").visible.all()
    assert capsys.readouterr().err == ""
    # the same from Python, on frames in memory; a one-pass iterator cannot be read again
    from strain2d.pipeline import blank_start

    faded = np.round(frames * gain)
    points = np.array([[60.0, 60.0], [140.0, 140.0]])
    first, spread, largest = blank_start(faded, points)
    box = faded[:, 60:141, 60:141].reshape(8, -1)
    assert first == 4 and spread == 0 and largest == pytest.approx(box.std(axis=1).max())
    assert blank_start(iter(faded), points) is None and blank_start(faded[4:], points) is None
    # a textured reference where points fail for another reason: no such hint
    points = tmp_path / "p.csv"
    points.write_text("x,y\n0,0\n100,100\n199,10\n199,199\n")
    good = ["-q", "track", str(tmp_path / "fade.avi"), "--start", "4", "--tracker", "dic"]
    assert main([*good, "--points", str(points), "--out", str(tmp_path / "d.csv")]) == 2
    assert "blank" not in capsys.readouterr().err


def test_a_video_without_deformation_has_no_contraction_endpoint(tmp_path, capsys):
    from scipy import ndimage

    rng = np.random.default_rng(0)
    texture = ndimage.gaussian_filter(rng.uniform(0, 255, (160, 160)), 2)
    texture = np.clip((texture - texture.mean()) * 8 + 128, 0, 255)
    noisy = [np.clip(texture + rng.normal(0, 1, texture.shape), 0, 255) for _ in range(8)]
    for name, frames in (("still.tif", [texture] * 8), ("noisy.tif", noisy)):
        tifffile.imwrite(tmp_path / name, np.stack(frames).astype(np.uint8))
        for tracker in ("dic", "klt"):
            out = tmp_path / f"{name}-{tracker}"
            assert main(["-q", "analyze", str(tmp_path / name), "--grid", "4x4", "--tracker",
                         tracker, "--animation", "none", "--out", str(out)]) == 0  # fmt: skip
            assert capsys.readouterr().err == ""  # no warning of NumPy's either
            ep = json.loads((out / "summary.json").read_text())["contraction_endpoint"]
            assert ep["source"].startswith("none: no deformation"), (name, tracker, ep)
            assert ep["frame"] == 7 and ep["detected_frame"] is None
            assert "no deformation" in (out / "report.html").read_text()


# ------------------------------------------------------------------ tissue masks


def _elements(run) -> dict:
    """``{(frame, three reference points): (valid, Exx, Eyy, Exy)}`` of a run's triangles."""
    import pandas as pd

    nodes = pd.read_csv(run / "strain_nodes.csv")
    first = nodes[nodes.frame == 0].set_index("point")
    where = {p: (round(r.x, 6), round(r.y, 6)) for p, r in first.iterrows()}
    table = pd.read_csv(run / "strain_elements.csv")
    return {
        (int(r.frame), frozenset(where[int(p)] for p in (r.p0, r.p1, r.p2))): (
            int(r.valid),
            r.Exx,
            r.Eyy,
            r.Exy,
        )
        for r in table.itertuples()
    }


def test_a_masked_run_is_the_rectangle_run_on_the_tissue(small_case, tmp_path, capsys):
    """A grid in a tissue mask (a disc with a notch, from an image as Fiji saves it): no
    point off the tissue; with dic (a local tracker), every triangle on the tissue has the
    strain of the same triangle in the run over the mask's bounding rectangle, to dic's
    convergence tolerance (1e-3 px: each point starts from its neighbours' motion, and the
    masked grid has fewer neighbours)."""
    import cv2

    folder, _ = small_case
    yy, xx = np.mgrid[:200, :200]
    tissue = (xx - 100) ** 2 + (yy - 95) ** 2 <= 70**2
    tissue &= ~((xx > 85) & (xx < 115) & (yy > 100))  # a notch from below: concave
    cv2.imwrite(str(tmp_path / "mask.png"), tissue.astype(np.uint8) * 255)
    rows, cols = np.flatnonzero(tissue.any(axis=1)), np.flatnonzero(tissue.any(axis=0))
    bounds = f"{cols[0]},{rows[0]},{cols[-1]},{rows[-1]}"
    common = ["-q", "analyze", str(folder / "eq.avi"), "--grid", "9x9", "--tracker", "dic",
              "--animation", "none"]  # fmt: skip
    assert main([*common, "--mask", str(tmp_path / "mask.png"), "--out", str(tmp_path / "m")]) == 0
    assert main([*common, "--roi", bounds, "--out", str(tmp_path / "r")]) == 0
    assert capsys.readouterr().err == ""
    masked = read_tracks(tmp_path / "m" / "tracks.csv")
    rect = read_tracks(tmp_path / "r" / "tracks.csv")
    ref = masked.reference
    inside = tissue[np.round(ref[:, 1]).astype(int), np.round(ref[:, 0]).astype(int)]
    assert inside.all() and 20 < len(ref) < 81
    # the same points as the rectangle's, tracked alike
    index = {(round(x, 6), round(y, 6)): i for i, (x, y) in enumerate(rect.reference)}
    same = [index[(round(x, 6), round(y, 6))] for x, y in ref]
    assert np.array_equal(masked.visible, rect.visible[:, same])
    gap = np.abs(masked.positions - rect.positions[:, same])[masked.visible]
    assert gap.max() < 1e-3
    mine, theirs = _elements(tmp_path / "m"), _elements(tmp_path / "r")
    assert set(mine) < set(theirs)  # every masked triangle is one of the rectangle's
    spacing = np.diff(np.unique(rect.reference[:, 0])).min()
    for key, values in mine.items():  # 1e-3 px over a side of a triangle
        assert values == pytest.approx(theirs[key], abs=2e-3 / spacing, nan_ok=True), key
    # the triangles across the notch or the disc's edge are left out, and said so
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    mask = summary["points"]["mask"]
    n_tri = summary["mesh"]["n_triangles"]
    assert mask["grid_points"] == 81 and mask["points_off_tissue"] == 81 - len(ref)
    assert mask["grid_triangles"] - mask["triangles_off_tissue"] == n_tri == len(mine) // 6
    notch = [k for k in theirs if k[0] == 0 and np.mean([p[0] for p in k[1]]) > 88
             and np.mean([p[0] for p in k[1]]) < 112 and min(p[1] for p in k[1]) > 110]  # fmt: skip
    assert notch and not set(notch) & set(mine)
    report = (tmp_path / "m" / "report.html").read_text()
    assert "tissue mask" in report and "mask.png" in report


def test_a_run_keeps_its_own_log_quiet_or_not(small_case, tmp_path, capsys):
    """run.log in the run folder: the steps with their times, the warnings, even with -q."""
    folder, _ = small_case
    points = tmp_path / "p.csv"
    points.write_text("x,y\n0,0\n60,60\n140,60\n100,140\n")  # the corner cannot be tracked
    argv = ["-q", "analyze", str(folder / "eq.avi"), "--points", str(points), "--tracker", "dic",
            "--out", str(tmp_path / "run")]  # fmt: skip
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "warning: 1 of 4 points cannot be used" in err
    log = (tmp_path / "run" / "run.log").read_text().splitlines()
    assert log[0].endswith("eq.avi: 6 frames of 200x200 px (video)")
    assert any("tracking 4 points (dic): 6/6 frames in" in line for line in log)
    assert any("warning: 1 of 4 points cannot be used" in line for line in log)
    assert "figures and animation: 6/6 frames" in log[-1]
    for line in log:  # ISO time, then the time since the start
        stamp, rest = line.split(" ", 1)
        assert stamp[:4] == "2" + stamp[1:4] and "T" in stamp and rest.startswith("[")
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert "run.log" in summary["outputs"]


def test_a_grid_at_a_spacing_fills_a_mask_or_a_region(small_case, tmp_path, capsys):
    """--spacing PX: points PX apart over the mask's bounds (or --roi), centred; with --grid
    or --points it is one line."""
    import cv2

    folder, _ = small_case
    yy, xx = np.mgrid[:200, :200]
    disc = (xx - 100) ** 2 + (yy - 100) ** 2 <= 60**2
    cv2.imwrite(str(tmp_path / "disc.png"), disc.astype(np.uint8) * 255)
    argv = ["-q", "track", str(folder / "eq.avi"), "--tracker", "klt", "--spacing", "20"]
    assert (
        main([*argv, "--mask", str(tmp_path / "disc.png"), "--out", str(tmp_path / "m.csv")]) == 0
    )
    ref = read_tracks(tmp_path / "m.csv").reference
    assert disc[np.round(ref[:, 1]).astype(int), np.round(ref[:, 0]).astype(int)].all()
    steps = np.diff(np.unique(np.round(ref[:, 0], 6)))
    assert np.allclose(steps, 20.0) and np.isclose(ref[:, 0].min() + ref[:, 0].max(), 200.0)
    assert main([*argv, "--roi", "20,30,125,95", "--out", str(tmp_path / "r.csv")]) == 0
    ref = read_tracks(tmp_path / "r.csv").reference
    assert sorted(set(ref[:, 0])) == [22.5, 42.5, 62.5, 82.5, 102.5, 122.5]
    assert sorted(set(ref[:, 1])) == [32.5, 52.5, 72.5, 92.5]
    capsys.readouterr()
    for extra, fragment in ((["--grid", "5x5"], "not both"), (["--spacing", "1"], "closer than"),
                            (["--roi", "20,30,35,95"], "fewer than 2 points")):  # fmt: skip
        assert main([*argv, *extra, "--out", str(tmp_path / "x.csv")]) == 2
        assert fragment in capsys.readouterr().err
