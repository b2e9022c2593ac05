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
