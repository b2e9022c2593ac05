"""Scenes that judge a tracker beyond the tissue suite: exact truth of each."""

import numpy as np
import pytest

from sample_data_synth.cases import GroundTruth, load_ground_truth
from sample_data_synth.deformations import Field, Twitch, time_profile_from_dict


def test_bump_gradient_and_inverse_are_exact():
    bump = Field("bump", (50.0, 40.0), ax=6.0, ay=-4.0, s=20.0)
    X = np.random.default_rng(2).uniform(0, 100, (40, 2))
    h = 1e-5
    numeric = np.stack(
        [
            (bump.forward(X + h * e, 0.7) - bump.forward(X - h * e, 0.7)) / (2 * h)
            for e in np.eye(2)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(bump.gradient(X, 0.7), numeric, atol=1e-8)
    np.testing.assert_allclose(bump.inverse(bump.forward(X, 0.7), 0.7), X, atol=1e-9)
    np.testing.assert_allclose(bump.forward(np.array([50.0, 40.0]), 1.0), [56.0, 36.0])
    np.testing.assert_allclose(bump.forward(np.array([500.0, 40.0]), 1.0), [500.0, 40.0])


def test_twitch_rises_relaxes_and_round_trips(tmp_path):
    profile = Twitch(2, 6, 12)
    t = np.array([profile(k) for k in range(15)])
    assert t[:3].tolist() == [0.0, 0.0, 0.0] and t[6] == 1.0 and t[12:].tolist() == [0.0] * 3
    assert np.all(np.diff(t[2:7]) > 0) and np.all(np.diff(t[6:13]) < 0)
    assert time_profile_from_dict(profile.to_dict()) == profile
    for bad in [(3, 3, 5), (0, 4, 2), (-1, 2, 3), (0.5, 2, 3)]:
        with pytest.raises(ValueError, match="onset, peak and endpoint"):
            Twitch(*bad)
    truth = GroundTruth(
        "twitch", Field("gaussian", (20.0, 20.0), a=0.1, s=8.0), 15, (40, 40), (0, 0, 39, 39),
        time_profile=profile,
    )  # fmt: skip
    truth.save(tmp_path / "truth.json")
    back = load_ground_truth(tmp_path / "truth.json")
    assert back.time_profile == profile
    X = np.array([[25.0, 20.0]])
    np.testing.assert_allclose(back.positions(X, 6), truth.deformation.forward(X, 1.0))
    np.testing.assert_allclose(back.positions(X, 13), X)
    with pytest.raises(ValueError, match="past the last frame"):
        GroundTruth("twitch", truth.deformation, 10, (40, 40), (0, 0, 39, 39), time_profile=profile)


def test_a_fade_with_a_direction_is_deeper_on_one_side():
    from sample_data_synth.tissue import Light

    light = Light(fade=0.2, fade_gradient=(0.2, 0.0))
    flat = np.full((40, 40), 100.0)
    start, end = light.apply(flat, 0.0), light.apply(flat, 1.0)
    np.testing.assert_allclose(start, 100.0)
    assert end[20, 20] == pytest.approx(80.0)
    assert end[20, 0] == pytest.approx(100 * (1 - 0.2 - 0.2 * (0 - 20) / 40))  # shallower
    assert end[20, 39] == pytest.approx(100 * (1 - 0.2 - 0.2 * (39 - 20) / 40))  # deeper
    assert light.to_dict()["fade_gradient"] == [0.2, 0.0]


def test_rendered_frames_start_from_the_texture_and_follow_the_truth():
    from scipy import ndimage

    from sample_data_synth.tissue import render_frames, tissue_texture

    texture = tissue_texture("fibres", 96, rng=1)
    field = Field("bump", (48.0, 48.0), ax=3.0, ay=1.5, s=15.0)
    frames = render_frames(texture, field, [0.0, 1.0], read_noise=0, shot_gain=0)
    np.testing.assert_array_equal(frames[0], np.clip(np.rint(texture), 0, 255))
    yy, xx = np.mgrid[30:66, 30:66].astype(float)
    X = np.stack([xx.ravel(), yy.ravel()], axis=-1)
    x = field.forward(X, 1.0)
    moved = ndimage.map_coordinates(frames[1].astype(float), [x[:, 1], x[:, 0]], order=3)
    still = ndimage.map_coordinates(frames[1].astype(float), [X[:, 1], X[:, 0]], order=3)
    reference = texture[30:66, 30:66].ravel()
    assert np.sqrt(np.mean((moved - reference) ** 2)) < 3.0
    assert np.sqrt(np.mean((still - reference) ** 2)) > 10.0
    blurred = render_frames(texture, field, [0.0], blur=1.5, read_noise=0, shot_gain=0)[0]
    optics = np.clip(np.rint(ndimage.gaussian_filter(texture, 1.5, mode="mirror")), 0, 255)
    assert np.abs(blurred.astype(float) - optics).max() <= 1.0  # rounding of equal values
