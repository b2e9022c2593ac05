"""``python -m stereo`` end to end on rendered scenes with exact truth: calibration from
checkerboard views (with a realistic bad view), matching across views, and 3D tracks of a
stretching sheet; and every error a user can cause (exit 2, one line)."""

import contextlib
import csv
import io
import json

import numpy as np
import pytest

from sample_data_synth.stereo import (
    default_rig,
    render_calibration_views,
    render_surface_scene,
    save_calibration_views,
    save_stereo_scene,
)
from stereo.cli import main
from tests.tolerances import (
    STEREO_BASELINE_RELATIVE,
    STEREO_CALIB_RMS_PX,
    STEREO_MATCH_PX,
    STEREO_POINT_RMSE_MM,
    STEREO_REPROJ_RMS_PX,
    STEREO_STRAIN_RMSE,
)


def cli(*argv) -> int:
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "error" in err[0], err
    return err[0]


#: the module's tests share its rendered scenes, its calibration and its reconstruction: one
#: xdist worker runs them all (make test: loadgroup), so that each is made once
pytestmark = pytest.mark.xdist_group("stereo_pipeline")


@pytest.fixture(scope="module")
def calibration_views(tmp_path_factory):
    folder = tmp_path_factory.mktemp("calib") / "views"
    views = render_calibration_views(
        default_rig(), "checkerboard:9x6:10", n_views=9, supersample=2, partial_views=1, rng=3
    )
    save_calibration_views(folder, views)
    return folder, views


@pytest.fixture(scope="module")
def stretch(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stretch") / "scene"
    scene = render_surface_scene(default_rig(), "stretch", n_frames=3, supersample=2, rng=1)
    save_stereo_scene(folder, scene)
    truth = np.load(folder / "truth.npz")
    points = folder.parent / "points.csv"
    np.savetxt(points, truth["left_px"][0], delimiter=",", header="x,y", comments="")
    return folder, truth, points


@pytest.fixture(scope="module")
def calibrated(calibration_views, tmp_path_factory):
    """``stereo calibrate`` of the rendered views, once: (exit status, calib.json, stderr)."""
    folder, _ = calibration_views
    out = tmp_path_factory.mktemp("calibrated") / "calib.json"
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = cli(
            "calibrate",
            "--left", f"{folder}/left/*.png",
            "--right", f"{folder}/right/*.png",
            "--board", "checkerboard:9x6:10",
            "--out", out,
        )  # fmt: skip
    return code, out, err.getvalue()


@pytest.fixture(scope="module")
def reconstructed(stretch, tmp_path_factory):
    """``stereo reconstruct --strain`` of the stretching sheet, once: (exit status, folder)."""
    folder, _, points = stretch
    out = tmp_path_factory.mktemp("reconstructed") / "rec"
    code = cli("reconstruct", "--calib", folder / "rig.json", "--left", folder / "left",
               "--right", folder / "right", "--points", points, "--strain",
               "--out", out, "-q")  # fmt: skip
    return code, out


def test_calibration_meets_the_bars_and_names_the_bad_view(calibration_views, calibrated):
    _, views = calibration_views
    code, out, err = calibrated
    assert code == 0
    calib = json.loads(out.read_text())
    true = views.rig
    assert calib["rms_px"] <= STEREO_CALIB_RMS_PX
    baseline = np.linalg.norm(calib["T"])
    assert abs(baseline - true.baseline) / true.baseline <= STEREO_BASELINE_RELATIVE
    np.testing.assert_allclose(calib["K_left"], true.K_left, atol=5.0)
    # the view with the board partly out of frame is rejected, and the report says why
    partial = np.flatnonzero(~views.fully_visible)
    assert len(partial) == 1
    rejected = {r["image"].split(" / ")[0]: r["reason"] for r in calib["rejected"]}
    assert f"view_{partial[0]:02d}.png" in rejected
    assert "no target found" in rejected[f"view_{partial[0]:02d}.png"]
    assert "rejected view_" in err
    for key in ("image_size", "K_left", "dist_left", "K_right", "dist_right", "R", "T", "unit"):
        assert key in calib
    assert calib["flags"] == []  # a good calibration is not flagged


def test_reconstruction_of_a_stretching_sheet(stretch, tmp_path):
    folder, truth, points = stretch
    out = tmp_path / "rec"
    code = cli(
        "reconstruct",
        "--calib", folder / "rig.json",
        "--left", folder / "left",
        "--right", folder / "right",
        "--points", points,
        "--out", out, "-q",
    )  # fmt: skip
    assert code == 0
    rows = list(csv.DictReader((out / "points3d.csv").read_text().splitlines()))
    assert list(rows[0]) == ["frame", "point", "X", "Y", "Z", "reproj_error", "visible"]
    T, N = truth["positions"].shape[:2]
    X = np.array([[float(r[k]) for k in "XYZ"] for r in rows]).reshape(T, N, 3)
    assert all(r["visible"] == "1" for r in rows)
    rmse = np.sqrt(np.mean(np.sum((X - truth["positions"]) ** 2, axis=2)))
    assert rmse < STEREO_POINT_RMSE_MM
    summary = json.loads((out / "summary.json").read_text())
    assert summary["reprojection_rms_px"] <= STEREO_REPROJ_RMS_PX
    assert summary["unit"] == "mm" and summary["frames"] == T


def test_match_finds_the_true_right_positions(stretch, tmp_path):
    folder, truth, points = stretch
    out = tmp_path / "matches.csv"
    code = cli(
        "match",
        folder / "left" / "frame_000.png",
        folder / "right" / "frame_000.png",
        "--points", points,
        "--calib", folder / "rig.json",
        "--out", out, "-q",
    )  # fmt: skip
    assert code == 0
    rows = list(csv.DictReader(out.read_text().splitlines()))
    assert list(rows[0])[:6] == ["point", "x_left", "y_left", "x_right", "y_right", "quality"]
    right = np.array([[float(r["x_right"]), float(r["y_right"])] for r in rows])
    err = np.hypot(*(right - truth["right_px"][0]).T)
    assert np.sqrt(np.mean(err**2)) < STEREO_MATCH_PX
    assert all(float(r["epipolar_px"]) < 0.1 for r in rows)


def test_calibration_errors(calibration_views, tmp_path, capsys):
    folder, _ = calibration_views
    out = tmp_path / "c.json"
    left, right = f"{folder}/left/*.png", f"{folder}/right/*.png"
    board = "checkerboard:9x6:10"
    assert cli("calibrate", "--left", left, "--right", f"{folder}/right/view_0[0-3].png",
               "--board", board, "--out", out) == 2  # fmt: skip
    assert "unequal image counts" in one_error_line(capsys)
    # a part of the board is found as readily as the whole: refused, naming the board's size
    assert cli("calibrate", "--left", left, "--right", right, "--board", "checkerboard:7x4:10",
               "--out", out, "-q") == 2  # fmt: skip
    assert "the images hold 9x6 inner corners" in one_error_line(capsys)
    assert cli("calibrate", "--left", left, "--right", right, "--board", "square:9x6",
               "--out", out) == 2  # fmt: skip
    assert "--board must be" in one_error_line(capsys)
    assert cli("calibrate", "--left", f"{tmp_path}/none*.png", "--right", right,
               "--board", board, "--out", out) == 2  # fmt: skip
    assert "matches no image files" in one_error_line(capsys)
    assert not out.exists()


def test_images_of_different_sizes_are_refused(tmp_path, capsys):
    import cv2

    for side, size in (("left", (64, 48)), ("right", (60, 48))):
        (tmp_path / side).mkdir()
        cv2.imwrite(str(tmp_path / side / "a.png"), np.zeros(size[::-1], np.uint8))
    code = cli("calibrate", "--left", tmp_path / "left", "--right", tmp_path / "right",
               "--board", "checkerboard:9x6:10", "--out", tmp_path / "c.json")  # fmt: skip
    assert code == 2
    assert "differ in size" in one_error_line(capsys)


def test_reconstruct_errors(stretch, tmp_path, capsys):
    folder, _, points = stretch
    bad = tmp_path / "bad.json"
    bad.write_text("{ not json")
    args = ["--left", folder / "left", "--right", folder / "right", "--points", points]
    assert cli("reconstruct", "--calib", bad, *args, "--out", tmp_path / "r") == 2
    assert "not a valid calibration JSON" in one_error_line(capsys)
    wrong = json.loads((folder / "rig.json").read_text())
    wrong["image_size"] = [640, 480]
    (tmp_path / "wrong.json").write_text(json.dumps(wrong))
    assert cli("reconstruct", "--calib", tmp_path / "wrong.json", *args,
               "--out", tmp_path / "r") == 2  # fmt: skip
    assert "wrong.json is for 640x480 images" in one_error_line(capsys)
    assert not (tmp_path / "r").exists()


def test_import_calib_from_opencv_yaml(stretch, tmp_path):
    import cv2

    folder, _, _ = stretch
    true = json.loads((folder / "rig.json").read_text())
    path = tmp_path / "stereo.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, name in (("K_left", "M1"), ("dist_left", "D1"), ("K_right", "M2"),
                      ("dist_right", "D2"), ("R", "R"), ("T", "T")):  # fmt: skip
        fs.write(name, np.asarray(true[key], np.float64))
    fs.write("image_size", np.asarray(true["image_size"], np.float64))
    fs.release()
    out = tmp_path / "calib.json"
    assert cli("import-calib", path, "--out", out) == 0
    got = json.loads(out.read_text())
    np.testing.assert_allclose(got["T"], true["T"])
    assert got["image_size"] == true["image_size"]


def test_calibration_survives_jpeg_uneven_light_and_blur():
    from stereo.calibration import calibrate_stereo, parse_board

    views = render_calibration_views(
        default_rig(),
        "checkerboard:9x6:10",
        n_views=6,
        supersample=2,
        jpeg_quality=75,
        lighting=0.5,
        blur_sigma=1.2,
        rng=5,
    )
    calib = calibrate_stereo(
        list(views.left), list(views.right), parse_board("checkerboard:9x6:10")
    )
    assert calib.rms_px <= STEREO_CALIB_RMS_PX
    assert abs(calib.baseline - views.rig.baseline) / views.rig.baseline <= STEREO_BASELINE_RELATIVE


def test_charuco_calibration():
    from stereo.calibration import calibrate_stereo, parse_board

    spec = "charuco:11x8:8:6:DICT_4X4_50"
    views = render_calibration_views(
        default_rig(), spec, n_views=7, supersample=2, max_tilt_deg=20.0, rng=2
    )
    calib = calibrate_stereo(list(views.left), list(views.right), parse_board(spec))
    assert calib.rms_px <= STEREO_CALIB_RMS_PX
    assert abs(calib.baseline - views.rig.baseline) / views.rig.baseline <= STEREO_BASELINE_RELATIVE
    assert calib.extra["board"] == spec


def test_reconstruction_after_calibration_matches_the_truth_up_to_the_frame(
    calibration_views, calibrated, stretch, tmp_path
):
    """Calibrate, then reconstruct: the shape is right; the estimated world frame (the left
    camera, set by the estimated principal point) differs from the true one by a small
    rigid motion only."""
    _, views = calibration_views
    scene, truth, points = stretch
    code, calib, _ = calibrated  # the calibration of the views, as calibrate writes it
    assert code == 0
    got = json.loads(calib.read_text())
    # the right convention: x_right = R x_left + T, as in the true rig
    np.testing.assert_allclose(got["R"], views.rig.R, atol=2e-3)
    np.testing.assert_allclose(got["T"], views.rig.T, atol=0.5)
    out = tmp_path / "rec"
    assert cli("reconstruct", "--calib", calib, "--left", scene / "left", "--right",
               scene / "right", "--points", points, "--out", out, "-q") == 0  # fmt: skip
    rows = list(csv.DictReader((out / "points3d.csv").read_text().splitlines()))
    A = np.array([[float(r[k]) for k in "XYZ"] for r in rows])
    B = truth["positions"].reshape(-1, 3)
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    aligned = (A - ca) @ (Vt.T @ D @ U.T).T + cb
    assert np.sqrt(np.mean(np.sum((aligned - B) ** 2, axis=1))) < STEREO_POINT_RMSE_MM


def test_points_the_right_view_does_not_see_are_lost_not_fatal(stretch, tmp_path):
    folder, truth, points = stretch
    pts = np.loadtxt(points, delimiter=",", skiprows=1)
    extra = np.array([[5.0, 5.0], [8.0, 700.0], [30.0, 400.0]])  # far outside the sheet
    path = tmp_path / "points.csv"
    np.savetxt(path, np.vstack([pts, extra]), delimiter=",", header="x,y", comments="")
    out = tmp_path / "rec"
    assert cli("reconstruct", "--calib", folder / "rig.json", "--left", folder / "left",
               "--right", folder / "right", "--points", path, "--out", out, "-q") == 0  # fmt: skip
    rows = list(csv.DictReader((out / "points3d.csv").read_text().splitlines()))
    vis = np.array([r["visible"] == "1" for r in rows]).reshape(truth["positions"].shape[0], -1)
    assert vis[:, : len(pts)].all() and not vis[:, len(pts) :].any()


@pytest.mark.parametrize("n", [1, 2])
def test_match_takes_any_number_of_points(stretch, tmp_path, n):
    folder, truth, points = stretch
    pts = np.loadtxt(points, delimiter=",", skiprows=1)[:n]
    path = tmp_path / "p.csv"
    np.savetxt(path, pts.reshape(-1, 2), delimiter=",", header="x,y", comments="")
    out = tmp_path / "m.csv"
    assert cli("match", folder / "left" / "frame_000.png", folder / "right" / "frame_000.png",
               "--points", path, "--out", out, "-q") == 0  # fmt: skip
    rows = list(csv.DictReader(out.read_text().splitlines()))
    right = np.array([[float(r["x_right"]), float(r["y_right"])] for r in rows])
    assert np.abs(right - truth["right_px"][0][:n]).max() < 0.1


def test_reconstruct_with_strain_gives_the_analytic_strain(stretch, reconstructed):
    _, truth, _ = stretch
    code, out = reconstructed
    assert code == 0
    rows = list(csv.DictReader((out / "strain" / "strain_nodes.csv").read_text().splitlines()))
    T, N = truth["positions"].shape[:2]
    w = np.linalg.eigvalsh(truth["strain"])  # (T, N, 2), ascending
    for key, true in (("E1", w[..., 1]), ("E2", w[..., 0])):
        got = np.array([float(r[key]) for r in rows]).reshape(T, N)
        assert np.sqrt(np.nanmean((got - true) ** 2)) <= STEREO_STRAIN_RMSE
    assert (out / "strain" / "strain.pvd").is_file()


def test_a_study_combines_stereo_runs_with_2d_runs(reconstructed, tmp_path):
    """strain2d study over a stereo reconstruction, a surface_strain run and two 2D runs."""
    from sample_data_synth import make_case, write_video
    from strain2d import load_run
    from strain2d.cli import main as strain2d
    from surface_strain.cli import main as surface_strain

    code, rec = reconstructed  # read here, never written: the reconstruction test reads it too
    assert code == 0
    assert surface_strain(["compute", str(rec / "points3d.csv"), "--no-figures",
                           "--out", str(tmp_path / "s3d"), "-q"]) == 0  # fmt: skip
    # a 3D run with a point lost from the reference frame on (stereo loses points so)
    rows = (rec / "points3d.csv").read_text().splitlines()
    lost = [rows[0]] + [
        r if r.split(",")[1] != "0" else ",".join([*r.split(",")[:2], "", "", "", "nan", "0"])
        for r in rows[1:]
    ]
    (tmp_path / "lost.csv").write_text("\n".join(lost) + "\n")
    assert surface_strain(["compute", str(tmp_path / "lost.csv"), "--grid", "7x7",
                           "--no-figures", "--out", str(tmp_path / "lost"), "-q"]) == 0  # fmt: skip
    runs = [rec, tmp_path / "s3d", tmp_path / "lost"]
    for k in range(2):
        video = tmp_path / f"v{k}.tif"
        write_video(make_case("equibiaxial", size=160, n_frames=4, rng=k).frames, video)
        runs.append(tmp_path / f"2d{k}")
        assert strain2d(["analyze", str(video), "--grid", "4x4", "--tracker", "klt",
                         "--animation", "none", "--out", str(runs[-1]), "-q"]) == 0  # fmt: skip

    three_d = load_run(rec)
    assert three_d.positions.shape[-1] == 3 and three_d.unit == "mm"
    assert load_run(runs[3]).positions.shape[-1] == 2
    out = tmp_path / "study"
    assert strain2d(["study", *map(str, runs), "--out", str(out), "-q"]) == 0
    rows = {r["run"]: r for r in csv.DictReader((out / "specimens.csv").read_text().splitlines())}
    assert sorted(rows) == sorted(map(str, runs))
    # the stereo specimen's means are its nodal strains at its last frame, from its own table
    nodes = list(csv.DictReader((rec / "strain" / "strain_nodes.csv").read_text().splitlines()))
    last = max(int(r["frame"]) for r in nodes)
    for key in ("Exx", "Eyy"):
        values = [float(r[key]) for r in nodes if int(r["frame"]) == last]
        assert float(rows[str(rec)][f"mean_{key}"]) == pytest.approx(np.nanmean(values), abs=1e-9)
    # the same tracks meshed the same way: surface_strain compute reproduces the stereo run
    # (to the digits points3d.csv keeps)
    assert float(rows[str(tmp_path / "s3d")]["mean_Exx"]) == pytest.approx(
        float(rows[str(rec)]["mean_Exx"]), abs=1e-7
    )
    # and the 2D specimens measure their equibiaxial stretch
    for run in runs[3:]:
        assert float(rows[str(run)]["mean_Exx"]) > 0.1
    assert int(rows[str(tmp_path / "lost")]["n_nodes"]) == int(rows[str(rec)]["n_nodes"]) - 1
