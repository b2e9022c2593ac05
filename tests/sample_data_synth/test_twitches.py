"""The repeated-twitch case: its truth, its stimulus and mask, and the command that writes it."""

import csv

import cv2
import numpy as np
import pytest

from sample_data_synth import load_ground_truth
from sample_data_synth.cli import main
from sample_data_synth.deformations import Twitches, time_profile_from_dict
from sample_data_synth.twitches import DEFAULT_TWITCHES, STIMULUS_LEAD


def test_twitches_rest_between_them_and_scale_the_strain_by_their_amplitude():
    profile = Twitches(DEFAULT_TWITCHES)
    assert time_profile_from_dict(profile.to_dict()) == profile
    values = np.array([profile(k) for k in range(48)])
    for onset, peak, end, amplitude in DEFAULT_TWITCHES:
        assert values[onset] == 0 and values[end] == 0 and values[peak] == pytest.approx(amplitude)
        assert values[onset + 1 : end].min() > 0
    assert values[15:18].max() == 0 and values[44:].max() == 0  # rest between and after
    with pytest.raises(ValueError, match="starts before"):
        Twitches([(0, 3, 8, 1.0), (6, 9, 12, 1.0)])
    with pytest.raises(ValueError, match="amplitude"):
        Twitches([(0, 3, 8, 1.5)])


def test_the_command_writes_video_truth_stimulus_and_mask(tmp_path):
    out = tmp_path / "tw"
    assert main(["-q", "twitches", "--out", str(out)]) == 0
    truth = load_ground_truth(out / "twitches_truth.json")
    assert truth.time_profile.cycles == [
        {"onset": o, "peak": p, "end": e, "amplitude": a} for o, p, e, a in DEFAULT_TWITCHES
    ]
    points = truth.grid((9, 7))
    peaks = [truth.strain(points, p)[:, 0, 0].mean() for _, p, _, _ in DEFAULT_TWITCHES]
    assert np.array(peaks) / peaks[0] == pytest.approx([1.0, 0.55, 0.8], rel=0.05)
    with open(out / "stimulus.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    pulses = [int(r["frame"]) for r in rows if r["stimulus"] == "1"]
    assert pulses == [o - STIMULUS_LEAD for o, *_ in DEFAULT_TWITCHES]
    assert float(rows[10]["time_s"]) == pytest.approx(1.0)
    mask = cv2.imread(str(out / "mask.png"), cv2.IMREAD_UNCHANGED)
    assert mask.shape == (300, 400) and 0.3 < (mask > 0).mean() < 0.7
    assert not mask[0, 0] and mask[150, 200]  # an ellipse, not a rectangle
    assert main(["-q", "twitches", "--frames", "20", "--out", str(tmp_path / "x")]) == 2
