"""Still videos of real texture: the frames differ only by noise of the stated level."""

import numpy as np
import pytest

from sample_data_synth.still import NOISE_LEVELS, STILL_PHOTOGRAPHS, make_still_video, still_texture


@pytest.mark.parametrize("noise", list(NOISE_LEVELS))
def test_frames_are_the_photograph_plus_fresh_noise_of_the_stated_level(noise):
    video = make_still_video("immunohistochemistry", noise=noise, size=128, n_frames=6, rng=3)
    texture = still_texture("immunohistochemistry", 128)
    read_noise, shot_gain = NOISE_LEVELS[noise]
    level = np.sqrt(read_noise**2 + shot_gain * texture + 1 / 12)  # and 8-bit rounding
    z = (video.frames - texture) / level
    assert abs(z.mean()) < 0.03 and z.std() == pytest.approx(1.0, rel=0.05)
    first, second = (video.frames[k].astype(float) - texture for k in (1, 2))
    assert abs(np.corrcoef(first.ravel(), second.ravel())[0, 1]) < 0.05  # fresh on each frame
    points = video.truth.grid(tuple(video.truth.params["grid"]))
    assert points.shape == (121, 2)
    np.testing.assert_allclose(video.truth.positions(points, 5), points, atol=1e-12)


def test_every_photograph_renders_and_bad_choices_are_refused():
    for name in STILL_PHOTOGRAPHS:
        t = still_texture(name, 64)
        assert t.shape == (64, 64) and 24 <= t.min() < t.max() <= 226
    with pytest.raises(ValueError, match="unknown photograph"):
        still_texture("nope")
    with pytest.raises(ValueError, match="unknown noise level"):
        make_still_video(noise="loud")
