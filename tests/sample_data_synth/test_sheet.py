"""The twitching muscle sheet: strong texture, small strain, a twitch that returns to rest."""

import numpy as np
import pytest
from scipy import ndimage

from sample_data_synth.sheet import SHEET_GRID, make_muscle_sheet, muscle_texture


@pytest.fixture(scope="module")
def sheet():
    return make_muscle_sheet(shape=(96, 160), n_frames=8, read_noise=0, shot_gain=0, rng=4)


def test_the_twitch_rises_to_its_peak_strain_and_returns_to_rest(sheet):
    truth = sheet.truth
    points = truth.grid(SHEET_GRID)
    assert points.shape == (435, 2) and truth.image_size == (96, 160)
    peak = truth.time_profile.peak
    assert [truth.time(k) for k in (0, 1, 2, peak, 7)] == [0, 0, 0, 1, 0]
    E = truth.strain(points, peak)
    assert E[:, 0, 0].min() == pytest.approx(-0.01, rel=0.02)
    assert -0.005 < E[:, 0, 0].max() < -0.003
    assert -0.0021 < E[:, 1, 1].min() and E[:, 1, 1].max() < 0.0045
    for k in (0, 1, 2, 7):  # at rest: the reference, pixel for pixel
        np.testing.assert_array_equal(sheet.frames[k], sheet.frames[0])
        np.testing.assert_allclose(truth.positions(points, k), points, atol=1e-9)


def test_the_peak_frame_is_the_texture_moved_by_the_truth(sheet):
    truth = sheet.truth
    peak = truth.time_profile.peak
    yy, xx = np.mgrid[20:76, 20:140].astype(float)
    X = np.stack([xx.ravel(), yy.ravel()], axis=-1)
    x = truth.positions(X, peak)
    assert np.abs(x - X).max() > 0.3
    frame = sheet.frames[peak].astype(float)
    moved = ndimage.map_coordinates(frame, [x[:, 1], x[:, 0]], order=3)
    still = ndimage.map_coordinates(frame, [X[:, 1], X[:, 0]], order=3)
    reference = sheet.frames[0][20:76, 20:140].astype(float).ravel()
    assert np.sqrt(np.mean((moved - reference) ** 2)) < 0.5 * np.sqrt(
        np.mean((still - reference) ** 2)
    )


def test_muscle_texture_is_strong_repeatable_and_refuses_bad_shapes():
    from sample_data_synth.variants import texture_strength

    a = muscle_texture((120, 200), rng=2)
    np.testing.assert_array_equal(a, muscle_texture((120, 200), rng=2))
    assert 24 <= a.min() < a.max() <= 226
    assert np.median(texture_strength(a)[20:-20, 20:-20]) > 100  # the suite's textures: 10-170
    with pytest.raises(ValueError, match="n_frames"):
        make_muscle_sheet(n_frames=3)
    with pytest.raises(ValueError, match="peak"):
        make_muscle_sheet(peak=0.5)
