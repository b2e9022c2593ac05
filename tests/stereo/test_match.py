"""The epipolar tolerance of ``match_views`` governs the feature matches that relate the views
as well as the final matches."""

import cv2
import numpy as np
import pytest

from stereo.calibration import Calibration, load_calibration
from stereo.match import FEATURE_EPIPOLAR_FACTOR, match_views
from tissue_core.errors import InputError
from tissue_core.images import read_gray


@pytest.fixture(scope="module")
def views(small_stereo):
    s = small_stereo
    points = np.loadtxt(s.points, delimiter=",", skiprows=1)
    return read_gray(s.left0), read_gray(s.right0), points, load_calibration(s.calib)


def _rotated(calib: Calibration, angle: float) -> Calibration:
    """The calibration with the right camera turned by ``angle`` rad about x (a rig knocked
    after it was calibrated): true matches lie a few pixels off their epipolar lines."""
    d = calib.to_dict()
    d["R"] = (cv2.Rodrigues(np.array([angle, 0.0, 0.0]))[0] @ np.asarray(d["R"])).tolist()
    return Calibration.from_dict(d)


def test_a_tighter_tolerance_keeps_fewer_feature_matches(views):
    left, right, points, calib = views
    tight = match_views(left, right, points, calib=calib, max_epipolar_px=0.05)
    usual = match_views(left, right, points, calib=calib, max_epipolar_px=1.0)
    assert tight.meta["matches"] < usual.meta["matches"]
    assert usual.meta["feature_max_epipolar_px"] == FEATURE_EPIPOLAR_FACTOR * 1.0
    assert tight.visible.all() and usual.visible.all()  # the true rig: every point matches


def test_a_looser_tolerance_accepts_a_calibration_a_little_off(views):
    left, right, points, calib = views
    off = _rotated(calib, 0.006)  # about 4 px off the epipolar lines
    with pytest.raises(InputError, match=r"epipolar lines: check that the calibration"):
        match_views(left, right, points, calib=off, max_epipolar_px=1.0)
    loose = match_views(left, right, points, calib=off, max_epipolar_px=5.0)
    assert loose.visible.all()
    assert np.all((loose.epipolar_px > 1.0) & (loose.epipolar_px <= 5.0))


def test_a_calibration_for_other_images_is_named(views):
    left, right, points, calib = views
    d = calib.to_dict()
    d["image_size"] = [1024, 768]
    with pytest.raises(InputError, match=r"calibration is for 1024x768 images, the views are"):
        match_views(left, right, points, calib=Calibration.from_dict(d))
