"""Textured pieces turning on a blank background: which points are on texture, exact motion."""

import numpy as np
import pytest
from scipy import ndimage

from sample_data_synth import load_ground_truth
from sample_data_synth.pieces import PIECES_GRID, make_rotation_pieces, texture_depth


@pytest.fixture(scope="module")
def quiet():
    return make_rotation_pieces(size=300, n_frames=3, read_noise=0.0, shot_gain=0.0, rng=1)


def test_most_points_lie_on_the_blank_background_well_away_from_any_edge(quiet):
    truth = quiet.truth
    points = truth.grid(PIECES_GRID)
    on = np.array(truth.params["on_texture"])
    assert on.shape == (81,) and on.sum() == 21
    depth = texture_depth(truth.params["pieces"], points)
    step = (truth.roi[2] - truth.roi[0]) / 8
    assert np.all(np.abs(depth) >= 0.49 * step) and np.array_equal(depth > 0, on)
    assert on.reshape(9, 9)[4, 4] and not on.reshape(9, 9)[0, 8]  # row-major: [row, column]


def test_depth_is_the_signed_distance_to_a_rounded_box():
    piece = {"box": [10.0, 20.0, 50.0, 40.0], "corner_radius": 4.0}
    points = np.array([[30.0, 30.0], [30.0, 45.0], [0.0, 30.0], [50.0 + 3.0, 40.0 + 4.0]])
    depth = texture_depth([piece], points)
    np.testing.assert_allclose(depth[:3], [10.0, -5.0, -10.0])
    corner = np.array([46.0, 36.0])  # the rounding's centre
    np.testing.assert_allclose(depth[3], 4.0 - np.linalg.norm(points[3] - corner))


def test_the_background_is_blank_where_the_truth_says_and_texture_moves_rigidly(quiet):
    truth = quiet.truth
    pieces = truth.params["pieces"]
    yy, xx = np.mgrid[0:300, 0:300].astype(float)
    here = np.stack([xx, yy], axis=-1)
    for k in range(truth.n_frames):
        reference = truth.deformation.inverse(here, truth.time(k))
        depth = texture_depth(pieces, reference)
        assert np.all(quiet.frames[k][depth < -4] == 0)  # black: nothing but noise there
        assert quiet.frames[k][depth > 4].mean() > 60
    inside = texture_depth(pieces, here) > 4
    X = here[inside]
    x = truth.positions(X, 2)
    moved = ndimage.map_coordinates(quiet.frames[2].astype(float), [x[:, 1], x[:, 0]], order=3)
    assert np.sqrt(np.mean((moved - quiet.frames[0][inside]) ** 2)) < 6.0
    step = np.degrees(np.arctan2(*(x[0] - truth.deformation.center)[::-1]))
    start = np.degrees(np.arctan2(*(X[0] - truth.deformation.center)[::-1]))
    assert (step - start) % 360 == pytest.approx(40.0)  # 20 degrees per frame


def test_sensor_noise_of_the_stated_level_on_a_grey_background(tmp_path):
    video = make_rotation_pieces(size=240, n_frames=2, background=30.0, read_noise=2.0, rng=2)
    truth = video.truth
    yy, xx = np.mgrid[0:240, 0:240].astype(float)
    far = texture_depth(truth.params["pieces"], np.stack([xx, yy], axis=-1)) < -4
    values = video.frames[0][far].astype(float)
    assert values.mean() == pytest.approx(30.0, abs=0.1)
    assert values.std() == pytest.approx(np.sqrt(4.0 + 0.02 * 30 + 1 / 12), rel=0.05)
    truth.save(tmp_path / "truth.json")
    back = load_ground_truth(tmp_path / "truth.json")
    assert back.params["on_texture"] == truth.params["on_texture"]
    np.testing.assert_allclose(
        texture_depth(back.params["pieces"], truth.grid(PIECES_GRID)),
        texture_depth(truth.params["pieces"], truth.grid(PIECES_GRID)),
    )
    with pytest.raises(ValueError, match="size"):
        make_rotation_pieces(size=100)
