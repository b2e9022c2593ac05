import json

import numpy as np
import pytest

from sample_data_synth import (
    CASES,
    Field,
    Homogeneous,
    add_sensor_noise,
    load_ground_truth,
    make_case,
    render_speckle,
    speckle_pattern,
)
from sample_data_synth.cli import main
from tests.tolerances import EXACT, RENDER_GRAY_LEVELS
from tissue_core.outputs import MARKER


def brute_force(pattern, deformation, t, shape):
    """Evaluate the deformed pattern exactly: every dot at every pixel, no PSF."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    X = deformation.inverse(np.stack([xx, yy], -1), t)
    S = np.zeros(shape)
    for c, s in zip(pattern.centers, pattern.sigmas, strict=True):
        S += np.exp(-np.sum((X - c) ** 2, -1) / (2 * s**2))
    return pattern.background - (pattern.background - pattern.ink) * (1 - np.exp(-S))


@pytest.mark.parametrize(
    "deformation",
    [
        Homogeneous("stretch", (20, 25), lx=1.5, ly=0.7),
        Homogeneous("rotation", (30, 20), angle_deg=40),
        Homogeneous("shear", (10, 10), gamma=0.5),
    ],
    ids=["stretch", "rotation", "shear"],
)
def test_speckle_render_is_the_exact_deformed_pattern(deformation):
    pattern = speckle_pattern((-40, -40, 90, 90), radius=2.0, density=0.6, rng=1)
    shape = (48, 56)
    fast = render_speckle(pattern, deformation, 0.8, shape, psf_sigma=0.0)
    exact = brute_force(pattern, deformation, 0.8, shape)
    assert np.abs(fast - exact).max() < RENDER_GRAY_LEVELS


def test_psf_is_the_analytic_gaussian_convolution():
    """One dot, stretched and blurred: its ink density is the exact convolved Gaussian."""
    from sample_data_synth import SpecklePattern

    center, sigma, psf = np.array([31.3, 30.7]), 2.0, 1.0
    pattern = SpecklePattern(center[None], np.array([sigma]))
    d = Homogeneous("stretch", (32, 32), lx=1.4, ly=0.8)
    image = render_speckle(pattern, d, 1.0, (64, 64), psf_sigma=psf)
    ink = -np.log(1 - (pattern.background - image) / (pattern.background - pattern.ink))
    F = d.matrix(1.0)
    cov = sigma**2 * F @ F.T + psf**2 * np.eye(2)
    amplitude = sigma**2 * np.linalg.det(F) / np.sqrt(np.linalg.det(cov))
    yy, xx = np.mgrid[0:64, 0:64]
    r = np.stack([xx, yy], -1) - d.forward(center, 1.0)
    expected = amplitude * np.exp(-0.5 * np.einsum("...i,ij,...j->...", r, np.linalg.inv(cov), r))
    np.testing.assert_allclose(ink, expected, atol=1e-4)


def test_deformation_inverse_and_strain():
    d = Homogeneous("shear", (5, 7), gamma=0.5)
    X = np.random.default_rng(0).uniform(0, 100, (10, 2))
    np.testing.assert_allclose(d.inverse(d.forward(X, 0.6), 0.6), X, atol=EXACT)
    np.testing.assert_allclose(d.strain(X, 1.0)[0], [[0, 0.25], [0.25, 0.125]], atol=EXACT)
    np.testing.assert_allclose(d.forward(X, 0.0), X)


def test_noise_statistics_and_quantization():
    img = np.full((400, 400), 200.0)
    noisy = add_sensor_noise(img, read_noise=1.0, shot_gain=0.02, rng=0)
    assert noisy.dtype == np.uint8
    assert noisy.astype(float).std() == pytest.approx(np.sqrt(1 + 0.02 * 200), rel=0.05)
    assert noisy.astype(float).mean() == pytest.approx(200, abs=0.05)


@pytest.mark.parametrize(
    ("case", "paper_px"), [("equibiaxial", 140), ("rotation", 105), ("shear", 200)]
)
def test_paper_geometry_matches_the_papers_displacements(case, paper_px):
    video = make_case(case, size=800, n_frames=2, rng=0)
    grid = video.truth.grid((7, 7))
    disp = np.linalg.norm(video.truth.positions(grid, 1) - grid, axis=1).max()
    assert disp == pytest.approx(paper_px, rel=0.02)
    assert video.frames.shape == (2, 800, 800)


def test_ground_truth_round_trip(tmp_path):
    video = make_case("tissue", size=128, n_frames=3, rng=0)
    video.truth.save(tmp_path / "t.json")
    back = load_ground_truth(tmp_path / "t.json")
    pts = np.array([[10.0, 20.0], [100.0, 50.0]])
    for k in range(3):
        np.testing.assert_allclose(back.positions(pts, k), video.truth.positions(pts, k))
        np.testing.assert_allclose(back.strain(pts, k), video.truth.strain(pts, k))
    d = json.loads((tmp_path / "t.json").read_text())
    assert d["final_E"]["Exx"] == pytest.approx(-0.32)


def test_tissue_frames_are_the_photograph_warped_by_the_map():
    """Frame k equals the photograph resampled by an independent affine transform.

    ``scipy.ndimage.affine_transform`` works in (row, col) order; the matrix is
    built here by hand, which checks the renderer's x/y convention and centre.
    """
    from scipy.ndimage import affine_transform

    from sample_data_synth.texture import tissue_photograph

    video = make_case("tissue", size=128, n_frames=3, read_noise=0, shot_gain=0, rng=0)
    photo = tissue_photograph(128)
    np.testing.assert_allclose(video.frames[0], np.rint(photo), atol=0.51)
    A = video.truth.deformation.matrix(0.5)
    c = video.truth.deformation.center
    Ainv = np.linalg.inv(A)[::-1, ::-1]  # (row, col) order
    crc = c[::-1]
    expected = affine_transform(photo, Ainv, offset=crc - Ainv @ crc, order=3, mode="mirror")
    inner = (slice(20, 108), slice(20, 108))
    np.testing.assert_allclose(video.frames[1][inner], expected[inner], atol=0.51)


def test_cli_writes_videos_and_truth(tmp_path, capsys):
    out = tmp_path / "syn"
    assert (
        main(
            [
                "video",
                "--case",
                "rotation",
                "--size",
                "96",
                "--frames",
                "3",
                "-q",
                "--formats",
                "avi,tif,mp4",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        MARKER,
        "rotation.avi",
        "rotation.mp4",
        "rotation.tif",
        "rotation_truth.json",
        "rotation_truth.npz",
    ]
    npz = np.load(out / "rotation_truth.npz")
    assert npz["positions"].shape == (3, 49, 2) and npz["E"].shape == (3, 49, 2, 2)
    np.testing.assert_allclose(npz["E"], 0, atol=EXACT)
    assert main(["video", "--case", "rotation", "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(["video", "--case", "bogus", "--out", str(tmp_path / "x")]) == 2
    assert main(["video", "--shot-gain", "-1", "--out", str(tmp_path / "x")]) == 2
    assert main(["video", "--read-noise", "nan", "--out", str(tmp_path / "x")]) == 2
    assert "--read-noise" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    assert main(["list"]) == 0
    assert set(CASES) <= set(capsys.readouterr().out.split())


FIELDS = [  # the benchmark's fields at its quick (400 px) scale
    Field("gaussian", (50, 40), a=0.3, s=32.0),
    Field("sinusoid", (50, 40), amplitude=4.0, wavelength=160.0),
    Field("fold", (50, 40), a=0.4, width=16.0),
]


@pytest.mark.parametrize("field", FIELDS, ids=lambda f: f.kind)
def test_field_gradient_and_inverse_are_exact(field):
    X = np.random.default_rng(1).uniform(0, 100, (40, 2))
    h = 1e-5
    numeric = np.stack(
        [
            (field.forward(X + h * e, 0.7) - field.forward(X - h * e, 0.7)) / (2 * h)
            for e in np.eye(2)
        ],
        axis=-1,
    )
    np.testing.assert_allclose(field.gradient(X, 0.7), numeric, atol=1e-8)
    np.testing.assert_allclose(field.inverse(field.forward(X, 0.7), 0.7), X, atol=1e-9)
    from sample_data_synth.deformations import deformation_from_dict

    back = deformation_from_dict(field.to_dict())
    np.testing.assert_allclose(back.forward(X, 0.4), field.forward(X, 0.4))


@pytest.mark.parametrize("field", FIELDS, ids=lambda f: f.kind)
def test_speckle_render_of_a_heterogeneous_field(field):
    """Dots are mapped by their local F (first order): dot centres are exact, dot shapes
    differ from the exact deformed pattern where the field bends over a dot's width.
    The bounds are the measured ones (gray levels of a 160-level contrast)."""
    pattern = speckle_pattern((-20, -20, 120, 100), radius=2.0, density=1.0, rng=3)
    shape = (80, 100)
    fast = render_speckle(pattern, field, 1.0, shape, psf_sigma=0.0)
    exact = brute_force(pattern, field, 1.0, shape)
    assert np.abs(fast - exact).max() < 10.0
    assert np.abs(fast - exact).mean() < 1.0


def test_heterogeneous_case_truth():
    video = make_case("gaussian", size=200, n_frames=3, rng=0)
    c = video.truth.deformation.center
    np.testing.assert_allclose(
        video.truth.strain(c[None], 2)[0], np.eye(2) * (0.7**2 - 1) / 2, atol=1e-12
    )
    far = c + np.array([90.0, 0.0])
    assert np.abs(video.truth.strain(far[None], 2)).max() < 0.01
