"""The measures the tests and the bench judge trackers by, on arrays with known answers."""

import numpy as np
import pytest

from sample_data_synth.measures import (
    Score,
    compare_to_dic,
    in_view,
    rigid_score,
    score_tracks,
    sigma_against_scatter,
)


def test_score_counts_kept_points_in_view_and_the_final_error():
    true = np.zeros((3, 4, 2))
    true[:, :, 0] = [10.0, 20.0, 30.0, 40.0]
    true[:, :, 1] = 10.0
    true[2, 3, 0] = 60.0  # leaves a 50 px wide frame on the last frame
    positions = true.copy()
    positions[2, 0] += [0.3, 0.4]  # 0.5 px on the last frame
    positions[1, 0] += [0.0, 0.1]
    visible = np.ones((3, 4), bool)
    visible[1, 2] = False  # lost on a middle frame: not kept
    score = score_tracks(positions, visible, true, shape=(20, 50))
    assert (score.in_view, score.kept, score.lost) == (3, 2, 1)
    assert score.rmse == pytest.approx(np.sqrt(0.25 / 2)) and score.worst == pytest.approx(0.5)
    assert score.rmse_all == pytest.approx(np.sqrt((0.01 + 0.25) / 4))
    assert in_view(true, (20, 50)).sum() == 11
    everything = score_tracks(positions, visible, true)
    assert (everything.in_view, everything.kept) == (4, 3)
    np.testing.assert_array_equal(score.kept_points, [True, True, False, False])
    first = score_tracks(positions, visible, true, among=np.array([False, True, True, True]))
    assert (first.in_view, first.kept, first.rmse) == (3, 2, 0.0)
    positions[1, 1] = np.nan  # a point without a position is not kept
    assert score_tracks(positions, visible, true, shape=(20, 50)).kept == 1


@pytest.mark.parametrize(
    ("mine", "dic", "verdict", "passed"),
    [
        (Score(9, 9, 0.105, 0.2, 0.1), Score(9, 9, 0.1, 0.2, 0.1), "within", True),
        (Score(9, 9, 0.05, 0.2, 0.1), Score(9, 9, 0.1, 0.2, 0.1), "within", True),
        (Score(9, 9, 0.111, 0.2, 0.1), Score(9, 9, 0.1, 0.2, 0.1), "worse", False),
        (Score(9, 9, 0.5, 0.9, 0.4), Score(9, 7, 0.1, 0.2, 0.1), "keeps where dic loses", True),
        (Score(9, 8, 0.05, 0.1, 0.1), Score(9, 9, 0.1, 0.2, 0.1), "loses points", False),
        (Score(9, 8, 0.05, 0.1, 0.1), Score(9, 7, 0.1, 0.2, 0.1), "loses points", False),
    ],
)
def test_compare_to_dic_follows_the_variants_rule(mine, dic, verdict, passed):
    result = compare_to_dic(mine, dic)
    assert (result.verdict, result.passed) == (verdict, passed)
    assert result.ratio == pytest.approx(mine.rmse / dic.rmse)


def test_an_allowance_in_pixels_adds_to_the_relative_one():
    mine, dic = Score(9, 9, 0.02, 0.1, 0.1), Score(9, 9, 0.01, 0.1, 0.1)
    assert not compare_to_dic(mine, dic).passed
    assert compare_to_dic(mine, dic, atol_px=0.01).passed


def test_sigma_against_scatter_recovers_a_known_calibration():
    rng = np.random.default_rng(0)
    T, N = 401, 30
    s = rng.uniform(0.02, 0.2, N)
    grid = rng.uniform(0, 100, (N, 2))
    positions = grid + s[:, None] * rng.standard_normal((T, N, 2))
    positions[0] = grid
    visible = np.ones((T, N), bool)
    calibrated = sigma_against_scatter(positions, visible, np.broadcast_to(s, (T, N)), grid)
    assert calibrated.median_ratio == pytest.approx(1.0, abs=0.06)
    assert calibrated.pooled_ratio == pytest.approx(1.0, abs=0.06)
    assert calibrated.within(1.5) == 1.0
    np.testing.assert_allclose(calibrated.scatter, s, rtol=0.15)
    twice = sigma_against_scatter(positions, visible, np.broadcast_to(2 * s, (T, N)), grid)
    assert twice.median_ratio == pytest.approx(2.0, abs=0.12) and twice.within(1.5) == 0.0
    visible[:, 0] = False
    visible[5:, 1] = False  # 4 frames after the reference: enough; 2 would not be
    visible[3:, 2] = False
    partial = sigma_against_scatter(positions, visible, np.broadcast_to(s, (T, N)), grid)
    assert np.isnan(partial.ratio[0]) and np.isfinite(partial.ratio[1])
    assert np.isnan(partial.ratio[2]) and partial.samples[1] == 4


def test_a_calibrated_sigma_on_a_still_video_shares_the_reference_noise():
    """Every frame is matched against one noisy reference: the numbers in SigmaCheck's notes."""
    rng = np.random.default_rng(0)
    T, N, s = 21, 20000, 0.01
    noise = s * rng.standard_normal((T, N, 2))
    positions = noise - noise[0]  # the reference's own noise, shared by every frame
    sigma = np.full((T, N), s * np.sqrt(2))
    check = sigma_against_scatter(positions, np.ones((T, N), bool), sigma, np.zeros((N, 2)))
    assert check.pooled_ratio == pytest.approx(1.0, abs=0.01)
    assert check.median_ratio == pytest.approx(1.08, abs=0.01)
    assert check.within(1.5) == pytest.approx(0.92, abs=0.01)


def test_disagreement_with_another_tracker_counts_both_sigmas():
    rng = np.random.default_rng(1)
    T, N, s = 301, 40, 0.1
    truth = rng.uniform(0, 50, (T, N, 2))
    a = truth + s * rng.standard_normal((T, N, 2))
    b = truth + s * rng.standard_normal((T, N, 2))
    sigma = np.full((T, N), s)
    visible = np.ones((T, N), bool)
    alone = sigma_against_scatter(a, visible, sigma, b)
    assert alone.median_ratio == pytest.approx(1 / np.sqrt(2), abs=0.05)
    both = sigma_against_scatter(
        a, visible, sigma, b, reference_visible=visible, reference_uncertainty=sigma
    )
    assert both.median_ratio == pytest.approx(1.0, abs=0.07)


def test_rigid_score_splits_textured_from_blank_points():
    true = np.zeros((3, 4, 2))
    positions = true.copy()
    positions[1:, 0, 0] = 0.03  # textured
    positions[1:, 1, 0] = 0.04  # textured
    visible = np.ones((3, 4), bool)
    visible[1:, 3] = False  # blank and said so
    visible[2, 1] = False
    score = rigid_score(positions, visible, true, np.array([True, True, False, False]))
    assert score.textured_rms == pytest.approx(np.sqrt((0.03**2 * 2 + 0.04**2) / 3))
    assert (score.textured_kept, score.textured) == (1, 2)
    assert (score.blank_measured, score.blank, score.blank_point_frames) == (1, 2, 2)
