"""Dot-grid (circle-grid) calibration targets: the board, its texture, its rendered views.

The texture must hold exactly the dots' area, and the rendered dots must be
found by ``cv2.findCirclesGrid`` where the rig projects their centres.
"""

import json

import cv2
import numpy as np
import pytest

from sample_data_synth.boards import CircleGrid, parse_board
from sample_data_synth.cli import main
from sample_data_synth.stereo import default_rig, render_calibration_views

# --- this module's tolerances ---
#: dark texture area against the dots' analytic area, relative (texel coverage is exact to
#: second order in the texel; measured 1e-5 to 2.2e-4 with the float32 raster)
AREA_RELATIVE = 1e-3
#: dot centres found by the blob detector against the projected centres, RMS px (measured
#: 0.014-0.032 px at 512 x 384, the centroid of a dot's image is not the image of its centre)
DOT_RMS_PX = 0.05


def dot_centres(image, true):
    """The blob detector's dot centres nearest to the true ones (N, 2), and their count.

    No dot is larger than the image shared among them: a larger area limit lets the
    bright board, thresholded near its own gray level, pass as a blob (as stereo's
    detector sets it)."""
    params = cv2.SimpleBlobDetector_Params()
    params.minArea, params.maxArea = 4.0, image.size / len(true)
    keypoints = cv2.SimpleBlobDetector_create(params).detect(image)
    blobs = np.array([k.pt for k in keypoints])
    nearest = np.linalg.norm(true[:, None] - blobs[None], axis=2).argmin(axis=1)
    return blobs[nearest], len(blobs)


@pytest.mark.parametrize(
    ("text", "board"),
    [
        ("circles:9x6:10:5", CircleGrid(9, 6, 10.0, 5.0)),
        ("acircles:4x11:10:7", CircleGrid(4, 11, 10.0, 7.0, asymmetric=True)),
    ],
)
def test_dot_grid_specs_parse_and_print(text, board):
    assert parse_board(text) == board and board.spec() == text
    assert board.to_dict()["kind"] == text.split(":")[0]


@pytest.mark.parametrize(
    "text", ["circles:9x6:10", "circles:9x6:10:10", "acircles:4x11:10:14.2", "circles:1x6:10:5"]
)
def test_bad_dot_grid_specs_are_refused(text):
    with pytest.raises(ValueError, match="board"):
        parse_board(text)


def test_object_points_are_opencvs_order():
    sym = CircleGrid(4, 3, 10.0, 5.0).object_points()
    assert sym[:5, :2].tolist() == [[0, 0], [10, 0], [20, 0], [30, 0], [0, 10]]
    asym = CircleGrid(4, 11, 10.0, 7.0, asymmetric=True).object_points()
    # OpenCV's calibration sample: ((2 j + i % 2) s, i s, 0)
    assert asym[:6, :2].tolist() == [[0, 0], [20, 0], [40, 0], [60, 0], [10, 10], [30, 10]]


@pytest.mark.parametrize(
    "board", [CircleGrid(5, 4, 10.0, 6.0), CircleGrid(4, 5, 8.0, 9.0, asymmetric=True)]
)
def test_texture_holds_exactly_the_dots_area(board):
    from sample_data_synth._raytrace import _DARK, _LIGHT

    raster = board._texture(100)
    dark = (_LIGHT - raster.values.astype(float)) / (_LIGHT - _DARK)
    area = dark.sum() * raster.texel**2
    expected = len(board.object_points()) * np.pi * board.diameter**2 / 4
    assert abs(area / expected - 1) < AREA_RELATIVE
    # the raster's texel centres: the first dot's centre is the darkest texel near it
    x0, y0 = raster.origin
    j, i = round(-x0 / raster.texel), round(-y0 / raster.texel)
    assert dark[i, j] == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("spec", ["circles:9x6:10:5", "acircles:4x11:10:7"])
def test_rendered_dots_land_on_the_projection(spec):
    rig = default_rig(image_size=(512, 384))
    views = render_calibration_views(rig, spec, n_views=2, rng=4)
    n = len(views.object_points())
    for k in range(views.n_views):
        for camera in ("left", "right"):
            true = views.image_points(k, camera)
            found, count = dot_centres(getattr(views, camera)[k], true)
            assert count == n, (k, camera, count)
            error = np.sqrt(np.mean(np.sum((found - true) ** 2, axis=1)))
            assert error < DOT_RMS_PX, (k, camera, error)


def test_cli_renders_a_dot_grid_calibration(tmp_path, capsys):
    out = tmp_path / "stereo"
    args = ["stereo", "--case", "calibration", "--board", "circles:7x5:10:5", "--size", "256x192",
            "--views", "1", "--out", str(out), "-q"]  # fmt: skip
    assert main(args) == 0
    poses = json.loads((out / "calibration" / "poses.json").read_text())
    assert poses["board"]["kind"] == "circles" and poses["board"]["diameter_mm"] == 5
    assert len(poses["object_points"]) == 35 and len(poses["views"][0]["left_px"]) == 35
    assert (out / "calibration" / "left" / "view_00.png").is_file()
    assert main([*args[:4], "circles:7x5:10", *args[5:], "--overwrite"]) == 2
    assert "DIAMETER" in capsys.readouterr().err
