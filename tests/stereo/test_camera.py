import json

import cv2
import numpy as np
import pytest

from stereo.calibration import Calibration, load_calibration, parse_board
from stereo.camera import distort, project, reprojection_errors, triangulate, undistort
from stereo.match import epipolar_distance
from strain2d.errors import InputError, SourceError
from tests.tolerances import EXACT


@pytest.fixture
def rig():
    K1 = np.array([[1400.0, 0, 520], [0, 1405, 380], [0, 0, 1]])
    K2 = np.array([[1390.0, 0.5, 505], [0, 1392, 390], [0, 0, 1]])
    R, _ = cv2.Rodrigues(np.array([0.01, -0.16, 0.005]))
    return Calibration(
        image_size=(1024, 768),
        K_left=K1,
        dist_left=[-0.08, 0.05, 0.001, -0.0005, 0.0],
        K_right=K2,
        dist_right=[-0.07, 0.04, -0.0008, 0.0006, 0.01],
        R=R,
        T=[-120.0, 1.0, 8.0],
    )


def _points(n=300, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [rng.uniform(-60, 60, n), rng.uniform(-45, 45, n), rng.uniform(400, 500, n)]
    )


def test_projection_is_opencvs(rig):
    X = _points()
    rvec, _ = cv2.Rodrigues(rig.R)
    left = project(X, rig.K_left, rig.dist_left)
    right = project(X, rig.K_right, rig.dist_right, rig.R, rig.T)
    zero = np.zeros(3)
    cv_left = cv2.projectPoints(X, zero, zero, rig.K_left, rig.dist_left)[0][:, 0]
    # OpenCV's projection ignores the skew K[0, 1]; the toolkit keeps it: u += s * yd
    K = rig.K_right.copy()
    skew, K[0, 1] = K[0, 1], 0.0
    cv_right = cv2.projectPoints(X, rvec, rig.T, K, rig.dist_right)[0][:, 0]
    cv_right[:, 0] += skew * (cv_right[:, 1] - K[1, 2]) / K[1, 1]
    assert skew != 0  # the rig has one: the check covers it
    assert np.abs(left - cv_left).max() < 1e-9
    assert np.abs(right - cv_right).max() < 1e-9


def test_undistort_inverts_distort_exactly(rig):
    px = np.column_stack([np.linspace(0, 1023, 50), np.linspace(767, 0, 50)])
    back = distort(undistort(px, rig.K_left, rig.dist_left), rig.K_left, rig.dist_left)
    assert np.abs(back - px).max() < 1e-8


def test_triangulation_is_exact_for_exact_projections_and_reports_errors(rig):
    X = _points()
    pl = project(X, rig.K_left, rig.dist_left)
    pr = project(X, rig.K_right, rig.dist_right, rig.R, rig.T)
    Y, err = triangulate(pl, pr, rig)
    assert np.abs(Y - X).max() < 1e-8
    assert err.max() < 1e-8
    # a point moved off its epipolar line shows its reprojection error
    pr_bad = pr.copy()
    pr_bad[0, 1] += 2.0
    _, err_bad = triangulate(pl, pr_bad, rig)
    assert err_bad[0] == pytest.approx(np.sqrt(2.0**2 / 4), rel=0.05)  # split over both views
    assert reprojection_errors(Y, pl, pr, rig).max() < 1e-8


def test_triangulation_noise_and_missing_points(rig):
    rng = np.random.default_rng(1)
    X = _points(2000)
    pl = project(X, rig.K_left, rig.dist_left) + rng.normal(0, 0.05, (2000, 2))
    pr = project(X, rig.K_right, rig.dist_right, rig.R, rig.T) + rng.normal(0, 0.05, (2000, 2))
    pl[5] = np.nan
    Y, err = triangulate(pl, pr, rig)
    assert np.isnan(Y[5]).all() and np.isnan(err[5])
    ok = np.arange(2000) != 5
    rmse = np.sqrt(np.mean(np.sum((Y[ok] - X[ok]) ** 2, axis=1)))
    # 0.05 px at ~1400 px focal, 450 mm depth, 120 mm baseline: depth error ~ 0.1 mm
    assert rmse < 0.2
    # the refined points reproject closer than the noise (least squares)
    assert np.sqrt(np.mean(err[ok] ** 2)) < 0.05


def test_epipolar_distance_vanishes_for_true_pairs(rig):
    X = _points()
    pl = project(X, rig.K_left, rig.dist_left)
    pr = project(X, rig.K_right, rig.dist_right, rig.R, rig.T)
    assert np.nanmax(epipolar_distance(pl, pr, rig)) < 1e-6
    shifted = pr + np.array([0.0, 3.0])
    d = epipolar_distance(pl, shifted, rig)
    assert np.all((d > 1.0) & (d < 3.5))  # a 3 px shift, partly along the line


def test_calibration_json_round_trip(tmp_path, rig):
    rig.rms_px = 0.05
    path = tmp_path / "calib.json"
    rig.save(path)
    back = load_calibration(path)
    for name in ("K_left", "dist_left", "K_right", "dist_right", "R", "T"):
        np.testing.assert_allclose(getattr(back, name), getattr(rig, name), atol=EXACT)
    assert back.image_size == (1024, 768) and back.rms_px == 0.05 and back.unit == "mm"
    assert back.baseline == pytest.approx(np.linalg.norm([-120.0, 1.0, 8.0]))


def test_opencv_yaml_import(tmp_path, rig):
    intr, extr = tmp_path / "intrinsics.yml", tmp_path / "extrinsics.yml"
    fs = cv2.FileStorage(str(intr), cv2.FILE_STORAGE_WRITE)
    fs.write("M1", rig.K_left)
    fs.write("D1", rig.dist_left.reshape(1, -1))
    fs.write("M2", rig.K_right)
    fs.write("D2", rig.dist_right.reshape(1, -1))
    fs.write("image_width", 1024)
    fs.write("image_height", 768)
    fs.release()
    fs = cv2.FileStorage(str(extr), cv2.FILE_STORAGE_WRITE)
    fs.write("R", rig.R)
    fs.write("T", rig.T.reshape(3, 1))
    fs.release()
    back = load_calibration(intr, extr)
    np.testing.assert_allclose(back.K_right, rig.K_right)
    np.testing.assert_allclose(back.T, rig.T)
    assert back.image_size == (1024, 768)
    with pytest.raises(InputError, match="no R"):
        load_calibration(intr)


def test_bad_calibration_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="not a valid calibration JSON"):
        load_calibration(bad)
    bad.write_text('{"image_size": [10, 10]}')
    with pytest.raises(InputError, match="missing"):
        load_calibration(bad)
    with pytest.raises(SourceError, match="not found"):
        load_calibration(tmp_path / "nope.json")


@pytest.mark.parametrize(
    "spec",
    [
        "checkerboard:9x6",
        "checkerboard:9-6:10",
        "checkerboard:2x6:10",
        "charuco:11x8:8:9:DICT_4X4_50",
        "charuco:11x8:8:6:DICT_NOPE",
        "hexagon:3x3:1",
        "checkerboard:9x6:-1",
    ],
)
def test_bad_board_specs_are_refused(spec):
    with pytest.raises(InputError):
        parse_board(spec)


@pytest.mark.parametrize("n", [8, 12])
def test_rational_and_thin_prism_models_are_opencvs(rig, n):
    d = np.array(
        [-0.08, 0.05, 0.001, -0.0005, 0.01, 0.02, -0.01, 0.005, 0.001, -0.002, 0.0015, 0.0005]
    )
    d = d[:n]
    X = _points()
    ours = project(X, rig.K_left, d)
    theirs = cv2.projectPoints(X, np.zeros(3), np.zeros(3), rig.K_left, d)[0][:, 0]
    assert np.abs(ours - theirs).max() < 1e-9
    assert np.abs(distort(undistort(ours, rig.K_left, d), rig.K_left, d) - ours).max() < 1e-8
    calib = Calibration(
        image_size=(1024, 768), K_left=rig.K_left, dist_left=d, K_right=rig.K_right,
        dist_right=d, R=rig.R, T=rig.T,
    )  # fmt: skip
    pr = project(X, rig.K_right, d, rig.R, rig.T)
    Y, _ = triangulate(ours, pr, calib)
    assert np.abs(Y - X).max() < 1e-7


def test_tilted_sensor_terms_are_refused(rig):
    with pytest.raises(InputError, match="tilted"):
        Calibration(
            image_size=(1024, 768), K_left=rig.K_left, dist_left=[0.0] * 12 + [0.01, 0.0],
            K_right=rig.K_right, dist_right=rig.dist_right, R=rig.R, T=rig.T,
        )  # fmt: skip


def test_calibration_values_are_checked(tmp_path, rig):
    good = rig.to_dict()
    for key, value, message in (
        ("K_left", "abc", "K_left"),
        ("image_size", [1], "image_size"),
        ("dist_right", [0.1, 0.2, 0.3], "dist_right"),
        ("T", [1, 2], "T"),
    ):
        bad = dict(good, **{key: value})
        path = tmp_path / f"{key}.json"
        path.write_text(json.dumps(bad))
        with pytest.raises(InputError, match=message):
            load_calibration(path)


def test_opencv_yaml_nested_sequences_and_garbage(tmp_path, rig):
    path = tmp_path / "nested.yml"
    lines = ["%YAML:1.0", "---", "image_size: [1024, 768]"]
    for key, name in (("K_left", "M1"), ("dist_left", "D1"), ("K_right", "M2"),
                      ("dist_right", "D2"), ("R", "R")):  # fmt: skip
        lines.append(f"{name}: {np.asarray(getattr(rig, key)).tolist()}")
    lines.append("T: [[-120.0], [1.0], [8.0]]")
    path.write_text("\n".join(lines) + "\n")
    back = load_calibration(path)
    np.testing.assert_allclose(back.T, [-120.0, 1.0, 8.0])
    np.testing.assert_allclose(back.K_left, rig.K_left)
    junk = tmp_path / "junk.yml"
    junk.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError):
        load_calibration(junk)
