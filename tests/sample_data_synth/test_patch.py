"""A microscope's patch of a stereo scene: its truth, its files, and bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest
import tifffile

from sample_data_synth.patch import microscope_patch, write_patch
from tests.scenes import SphereCap


def test_the_patch_lies_on_the_surface_with_its_folds_and_its_true_placement(tmp_path):
    scene = SphereCap()
    flat = microscope_patch(scene, center=(5.0, -4.0), fold_um=0.0, landmark_mm=0.0, rng=1)
    folded = microscope_patch(scene, center=(5.0, -4.0), fold_um=12.0, landmark_mm=0.0, rng=1)
    n = flat.height_um.shape[0]
    cols, rows = np.meshgrid(np.arange(n), np.arange(n))
    xy = np.column_stack([cols.ravel(), rows.ravel()]) * flat.pixel_um
    world = flat.to_world(np.column_stack([xy, -flat.height_um.ravel().astype(float)]))
    # every pixel of the map without folds lies on the sphere (float32 heights: 1e-5 um)
    off = np.linalg.norm(world - [0.0, 0.0, 390.0], axis=1) - scene.radius
    assert np.abs(off).max() < 1e-7  # mm
    folds = (folded.height_um - flat.height_um).astype(float)
    assert folds.max() == pytest.approx(6.0, abs=0.1)
    assert folds.min() == pytest.approx(-6.0, abs=0.1)
    # the microscope's depth points into the tissue, away from the cameras; a rotation
    assert np.dot(flat.rotation[:, 2], world.mean(axis=0)) > 0
    assert np.linalg.det(flat.rotation) == pytest.approx(1.0)
    # exact landmarks: the camera side is the smooth surface under each landmark's pixel
    camera, microscope = flat.landmarks[:, :3], flat.landmarks[:, 3:]
    mapped = flat.to_world(microscope * [1, 1, -1])
    np.testing.assert_allclose(mapped, camera, atol=1e-9)
    paths = write_patch(folded, tmp_path / "patch")
    with tifffile.TiffFile(paths["heightmap"]) as tif:
        np.testing.assert_array_equal(tif.asarray(), folded.height_um)
        numerator, denominator = tif.pages[0].tags["XResolution"].value
        assert denominator / numerator == pytest.approx(5.0)  # um per pixel
    truth = json.loads(paths["truth"].read_text())
    np.testing.assert_allclose(truth["rotation"], folded.rotation)
    header = paths["landmarks"].read_text().splitlines()[0]
    assert header == "camera_x,camera_y,camera_z,microscope_x,microscope_y,microscope_z"


def _patch_cli(*argv):
    return subprocess.run([sys.executable, "-m", "sample_data_synth", "patch", *argv],
                          capture_output=True, text=True, timeout=120)  # fmt: skip


def test_patch_bad_input_is_one_line(tmp_path):
    not_scene = tmp_path / "nothing"
    not_scene.mkdir()
    cases = [
        ([str(not_scene)], "not a stereo scene"),
        ([str(not_scene), "--center", "4"], "--center must be X,Y"),
        ([str(not_scene), "--size-um", "10", "--pixel-um", "5"], "16 to 2000 pixels"),
        ([str(not_scene), "--pixel-um", "nan"], "--pixel-um must be a positive number"),
        ([str(not_scene), "--fold-um", "1e12"], "--fold-um must be at most"),
        ([str(not_scene), "--landmark-mm", "1e300"], "--landmark-mm must be at most"),
        ([str(not_scene), "--angle", "inf"], "--angle must be a number"),
    ]
    for extra, message in cases:
        done = _patch_cli(*extra, "--out", str(tmp_path / "out"))
        assert done.returncode == 2 and message in done.stderr, (extra, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
