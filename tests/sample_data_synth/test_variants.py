"""Randomised variants of the tissue suite: seeded, held out, in view, exact truth."""

from dataclasses import replace

import numpy as np
import pytest

from sample_data_synth.tissue import TISSUE_CASES, Light
from sample_data_synth.variants import (
    MIN_TEXTURE_TO_NOISE,
    PHOTOGRAPHS,
    make_variant,
    texture_strength,
    tissue_variants,
    variant_reference,
    variant_truth,
    weakest_texture_to_noise,
)


@pytest.fixture(scope="module")
def variants():
    return tissue_variants(3, rng=7)


def test_variants_are_seeded_and_the_first_ones_do_not_depend_on_how_many(variants):
    again = tissue_variants(2, rng=7)
    assert [v.to_dict() for v in again] == [v.to_dict() for v in variants[:2]]
    other = tissue_variants(1, rng=8)[0]
    assert other.to_dict() != variants[0].to_dict()
    with pytest.raises(ValueError, match="n must be"):
        tissue_variants(0)


def test_variants_are_held_out_from_the_suite_and_in_their_ranges(variants):
    suite_crops = {(0.2, 0.2, 0.8, 0.8), (0.05, 0.0, 0.65, 1.0), (0.30, 0.42, 0.45, 0.57)}
    assert len({v.texture for v in variants}) == 3  # every texture once before any twice
    assert len({v.field for v in variants}) == 3
    for v in variants:
        assert v.name not in TISSUE_CASES and v.name.startswith("variant-")
        assert v.texture in (*PHOTOGRAPHS, "vessels", "fibres")
        assert tuple(round(c, 2) for c in v.crop) not in suite_crops
        assert 400 <= v.size <= 600 and 11 <= v.n_frames <= 21
        assert 0 <= v.blur <= 2 and 0.5 <= v.read_noise <= 3 and 0.005 <= v.shot_gain <= 0.06
        assert -0.25 <= v.light.fade <= 0.4 and all(7 <= g <= 15 for g in v.grid)
        assert v.describe().startswith(v.texture)


def test_every_grid_point_stays_in_view_on_texture_enough(variants):
    for v in variants:
        truth = variant_truth(v)
        points = truth.grid(v.grid)
        path = truth.positions(points)
        assert path.min() >= 45 and path.max() <= v.size - 1 - 45
        ratio = weakest_texture_to_noise(v, variant_reference(v))
        assert ratio >= MIN_TEXTURE_TO_NOISE


def test_texture_strength_is_the_weakest_direction_of_the_gradients():
    ramp = 2.0 * np.mgrid[0:64, 0:64][1].astype(
        float
    )  # texture along x only: nothing to lock onto along y
    assert np.allclose(texture_strength(ramp)[16:48, 16:48], 0, atol=1e-6)
    rng = np.random.default_rng(0)
    from scipy import ndimage

    speckle = ndimage.gaussian_filter(rng.standard_normal((64, 64)), 1.5) * 100
    strong = texture_strength(speckle)[32, 32]
    assert strong > 10 and texture_strength(0.5 * speckle)[32, 32] == pytest.approx(strong / 2)


def test_a_variant_is_its_texture_moved_by_the_truth_plus_the_stated_noise(variants):
    from scipy import ndimage

    v = variants[0]
    quiet = replace(v, n_frames=3, blur=0.0, read_noise=0.0, shot_gain=0.0, light=Light())
    video = make_variant(quiet)
    reference = variant_reference(quiet)
    np.testing.assert_array_equal(video.frames[0], np.clip(np.rint(reference), 0, 255))
    x0, y0, x1, y1 = (int(c) for c in quiet.roi)
    yy, xx = np.mgrid[y0:y1:3, x0:x1:3].astype(float)
    X = np.stack([xx.ravel(), yy.ravel()], axis=-1)
    x = video.truth.positions(X, 2)
    moved = ndimage.map_coordinates(video.frames[2].astype(float), [x[:, 1], x[:, 0]], order=3)
    assert np.sqrt(np.mean((moved - reference[yy.astype(int), xx.astype(int)].ravel()) ** 2)) < 3

    noisy = make_variant(replace(v, n_frames=2, light=Light()))
    frame0 = variant_reference(replace(v, light=Light()))
    expected = np.sqrt(v.read_noise**2 + v.shot_gain * frame0 + 1 / 12)  # and 8-bit rounding
    z = (noisy.frames[0] - frame0) / expected
    assert abs(z.std() - 1) < 0.05 and abs(z.mean()) < 0.05
