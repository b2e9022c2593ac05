"""The speckle-free tissue suite: exact truth, light in the image frame, files."""

import numpy as np
import pytest

from sample_data_synth import load_ground_truth
from sample_data_synth.cli import main
from sample_data_synth.deformations import Homogeneous, deformation_from_dict
from sample_data_synth.tissue import TISSUE_CASES, Light, make_tissue_case, tissue_texture


def test_turn_is_a_contraction_while_turning_and_round_trips():
    turn = Homogeneous("turn", (50.0, 40.0), stretch=0.75, angle_deg=10.0)
    X = np.array([[60.0, 40.0], [50.0, 70.0]])
    x = turn.forward(X, 1.0)
    np.testing.assert_allclose(np.linalg.norm(x - [50, 40], axis=1), 0.75 * np.array([10, 30]))
    np.testing.assert_allclose(turn.inverse(x, 1.0), X, atol=1e-12)
    back = deformation_from_dict(turn.to_dict())
    np.testing.assert_allclose(back.forward(X, 0.5), turn.forward(X, 0.5))
    E = turn.strain(X, 1.0)[0]
    np.testing.assert_allclose(E, 0.5 * (0.75**2 - 1) * np.eye(2), atol=1e-12)


@pytest.mark.parametrize("kind", ["retina", "fur", "closeup", "vessels", "fibres"])
def test_textures_span_the_gray_range_and_are_repeatable(kind):
    a = tissue_texture(kind, 96, rng=4)
    assert a.shape == (96, 96) and 20 <= a.min() < a.max() <= 230
    np.testing.assert_array_equal(a, tissue_texture(kind, 96, rng=4))


def test_light_fades_and_has_a_gradient_in_the_image_frame():
    light = Light(fade=0.3, gradient=(0.2, 0.0), spots=((10.0, 10.0, 2.0, 50.0),))
    flat = np.full((40, 40), 100.0)
    start, end = light.apply(flat, 0.0), light.apply(flat, 1.0)
    assert end[20, 30] == pytest.approx(0.7 * start[20, 30])
    assert start[20, 39] > start[20, 0]
    assert start[10, 10] == pytest.approx(100 * (1 + 0.2 * (10 - 20) / 40) + 50)


def test_frames_are_the_texture_moved_by_the_truth():
    """Frame k sampled at the true positions of reference pixels equals frame 0 there,
    up to noise, light and interpolation (no light change in this case)."""
    from scipy import ndimage

    video = make_tissue_case("retina-contraction", size=160, n_frames=3, read_noise=0,
                             shot_gain=0, rng=1)  # fmt: skip
    truth = video.truth
    yy, xx = np.mgrid[50:110, 50:110].astype(float)
    X = np.stack([xx.ravel(), yy.ravel()], axis=-1)
    x = truth.positions(X, 2)
    warped = ndimage.map_coordinates(video.frames[2].astype(float), [x[:, 1], x[:, 0]], order=3)
    same = video.frames[0][50:110, 50:110].astype(float).ravel()
    assert np.sqrt(np.mean((warped - same) ** 2)) < 4.0
    wrong = ndimage.map_coordinates(video.frames[2].astype(float), [X[:, 1], X[:, 0]], order=3)
    assert np.sqrt(np.mean((wrong - same) ** 2)) > 3 * np.sqrt(np.mean((warped - same) ** 2))


def test_every_case_renders_with_its_grid_and_class():
    for name, spec in TISSUE_CASES.items():
        video = make_tissue_case(name, size=96, n_frames=2, rng=0)
        assert video.frames.shape == (2, 96, 96) and video.frames.dtype == np.uint8
        assert tuple(video.truth.params["grid"]) == spec.grid
        assert video.truth.params["kind"] in ("textured", "smooth")
    with pytest.raises(ValueError, match="unknown tissue case"):
        make_tissue_case("nope")


def test_cli_writes_a_tissue_case_with_truth(tmp_path):
    out = tmp_path / "suite"
    assert main(["video", "-q", "--case", "rotation-20", "--size", "96", "--out", str(out)]) == 0
    truth = load_ground_truth(out / "rotation-20_truth.json")
    assert truth.n_frames == 5 and truth.params["grid"] == [9, 9]
    data = np.load(out / "rotation-20_truth.npz")
    assert data["grid"].shape == (81, 2) and data["positions"].shape == (5, 81, 2)
    np.testing.assert_allclose(data["positions"][4], truth.positions(data["grid"], 4))
    assert main(["video", "-q", "--case", "tissue", "--size", "64", "--frames", "2",
                 "--formats", "tif", "--out", str(tmp_path / "paper")]) == 0  # fmt: skip
    assert (tmp_path / "paper" / "tissue.tif").exists()  # the paper's case keeps its name
