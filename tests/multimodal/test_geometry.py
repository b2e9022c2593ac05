"""Lengths along a folding surface, and the strain they give, against exact answers."""

import math

import numpy as np
import pytest
from scipy.special import ellipe

from multimodal import (
    Similarity,
    SurfaceMap,
    directional_tortuosity,
    fold_aware_strain,
    surface_lengths,
    tortuosity_correction,
)
from sample_data_synth.folds import FOLD_CASES, make_folding_wall
from surface_strain import deformation_gradient, green_lagrange
from tissue_core.errors import InputError


def grid_mesh(x0: float, x1: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    xs = np.linspace(x0, x1, n)
    points = np.stack(np.meshgrid(xs, xs), -1).reshape(-1, 2)
    triangles = []
    for r in range(n - 1):
        for c in range(n - 1):
            a = r * n + c
            triangles += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    return points, np.array(triangles)


def wave_map(amplitude: float, wavelength: float, pixel: float, size: int) -> SurfaceMap:
    """z = A sin(k x) on a ``size`` square map."""
    x = np.arange(size) * pixel
    z = amplitude * np.sin(2 * np.pi * x / wavelength)
    return SurfaceMap(np.tile(z, (size, 1)), (pixel, pixel))


def test_a_path_across_a_sine_has_the_elliptic_arc_length():
    A, lam, pixel = 10.0, 60.0, 0.5
    surface = wave_map(A, lam, pixel, 600)
    # four whole wavelengths along x: 4 * 4 sqrt(1 + (A k)^2) E(m), m = (A k)^2 / (1 + (A k)^2)
    ak = A * 2 * np.pi / lam
    exact = 4 * lam / (2 * np.pi) * 4 * math.sqrt(1 + ak**2) * ellipe(ak**2 / (1 + ak**2))
    start, end = np.array([[10.0, 100.0]]), np.array([[10.0 + 4 * lam, 100.0]])
    for path in ("chord", "geodesic"):
        got = surface_lengths(surface, start, end, path=path)[0]
        assert got == pytest.approx(exact, rel=2e-4)
    # across the folds' crests nothing is hidden
    across = surface_lengths(surface, np.array([[30.0, 10.0]]), np.array([[30.0, 200.0]]))
    assert across[0] == pytest.approx(190.0, rel=1e-12)


@pytest.mark.parametrize("slope", [0.8, 1.2, 1.6, 2.0])
def test_a_chord_across_oblique_folds_is_longer_than_the_shortest_path(slope):
    """The documented excess of the chord: 0.2-0.9 % at 30-60 degrees to folds of slope
    1.2-2 (less on gentler folds), none along or across the folds."""
    lam = 60.0
    surface = wave_map(slope * lam / (2 * np.pi), lam, 0.5, 1400)
    start = np.array([350.0, 350.0])
    for angle in (0, 30, 45, 60, 90):
        a = np.radians(angle)
        end = start + 240.0 * np.array([np.cos(a), np.sin(a)])
        chord = surface_lengths(surface, start[None], end[None], path="chord")[0]
        shortest = surface_lengths(surface, start[None], end[None])[0]
        excess = chord / shortest - 1
        if angle in (0, 90):
            assert abs(excess) < 1e-4, (slope, angle, excess)
        elif slope >= 1.2:
            assert 0.0015 < excess < 0.0095, (slope, angle, excess)
        else:
            assert 0.0003 < excess < 0.0015, (slope, angle, excess)


def test_an_edge_beside_a_gap_leaves_the_others_their_shortest_paths():
    """The edges are one optimisation: one whose shortest path would step into a gap must
    not hold the others back to their chords (folds of slope 1.1, edges at every angle)."""
    pixel, lam = 3.0, 110.0
    x = np.arange(480) * pixel
    z = np.tile(20.0 * np.sin(2 * np.pi * x / lam), (480, 1))
    rng = np.random.default_rng(1)
    starts = rng.uniform(300, 1100, (100, 2))
    angle, length = rng.uniform(0, np.pi, 100), rng.uniform(60, 150, 100)
    ends = starts + length[:, None] * np.column_stack([np.cos(angle), np.sin(angle)])
    clean = surface_lengths(SurfaceMap(z, (pixel, pixel)), starts, ends)
    # a strip 2.5-6.5 um beside one more edge's chord, at 45 degrees across the folds
    yy, xx = np.mgrid[0:480, 0:480] * pixel
    beside = np.abs(xx - yy) / np.sqrt(2)
    gapped = z.copy()
    gapped[(beside > 2.5) & (beside < 6.5) & (xx > 1150) & (xx < 1350)] = np.nan
    with_gap = surface_lengths(
        SurfaceMap(gapped, (pixel, pixel)),
        np.vstack([starts, [[1200.0, 1200.0]]]),
        np.vstack([ends, [[1300.0, 1300.0]]]),
    )
    assert np.isfinite(with_gap).all()
    np.testing.assert_allclose(with_gap[:100], clean, rtol=1e-4)


def test_paths_off_the_map_or_over_a_gap_have_no_length():
    heights = np.zeros((50, 50))
    heights[20:25, 20:25] = np.nan
    surface = SurfaceMap(heights, (1.0, 1.0))
    starts = np.array([[1.0, 1.0], [1.0, 22.0], [1.0, 1.0], [np.nan, 3.0]])
    ends = np.array([[40.0, 30.0], [40.0, 22.0], [60.0, 1.0], [3.0, 3.0]])
    got = surface_lengths(surface, starts, ends)
    assert got[0] == pytest.approx(math.hypot(39, 29), rel=1e-12)
    assert np.isnan(got[1:]).all()


@pytest.mark.parametrize("mirrored", [False, True])
def test_on_a_flat_map_the_strain_is_the_2d_strain(mirrored):
    rng = np.random.default_rng(3)
    X, triangles = grid_mesh(50.0, 150.0, 6)
    F = np.array([[0.83, 0.12], [-0.07, 1.09]])
    x = (X - 100) @ F.T + 100 + rng.normal(0, 0.4, X.shape)  # not homogeneous either
    transform = Similarity(3.7, 21.0, (400.0, -120.0), mirrored)
    corners = transform.apply(np.array([[0, 0], [250, 0], [0, 250], [250, 250]]))
    origin = corners.min(axis=0) - 5
    shape = np.ceil((corners.max(axis=0) - origin) / 2.5).astype(int) + 3
    flat = SurfaceMap.flat((shape[1], shape[0]), 2.5, origin_um=tuple(origin))
    for path in ("geodesic", "chord"):
        result = fold_aware_strain(X, x, triangles, flat, flat, transform, path=path)
        expected = green_lagrange(deformation_gradient(X, x, triangles))
        assert np.isfinite(result["E"]).all()
        np.testing.assert_allclose(result["E"], expected, rtol=0, atol=1e-9)
        np.testing.assert_allclose(result["E_projected"], expected, rtol=0, atol=1e-15)


def _case(name: str):
    case = make_folding_wall(name, size=480, n_frames=2)
    transform = Similarity(
        case.transform["scale_um_per_px"], case.transform["angle_deg"],
        tuple(case.transform["shift_um"]),
    )  # fmt: skip
    X, triangles = grid_mesh(170.0, 310.0, 5)  # inside the microscope's field
    x = case.true_positions(X, 1.0)
    pixel = (case.microscope_um, case.microscope_um)
    maps = SurfaceMap(case.before, pixel), SurfaceMap(case.after, pixel)
    return case, transform, X, x, triangles, maps


@pytest.mark.parametrize("name", list(FOLD_CASES))
def test_the_fold_aware_strain_recovers_the_true_stretch(name):
    case, transform, X, x, triangles, (before, after) = _case(name)
    result = fold_aware_strain(X, x, triangles, before, after, transform)
    true = case.wall.true_strain()
    projected = result["E_projected"]
    # the camera sees the folds as a contraction of the folding direction
    n = case.wall.axes[:, 0]
    assert np.einsum("i,mij,j->m", n, projected, n).max() < true @ n @ n - 0.1
    assert np.isfinite(result["E"]).all()
    # the issue asks for 0.01; every triangle is within 0.002 (chords would be 0.005-0.012 off)
    assert np.abs(result["E"] - true).max() < 0.003


@pytest.mark.parametrize("name", list(FOLD_CASES))
def test_the_chord_over_oblique_folds_is_too_long_and_the_shortest_path_is_not(name):
    case, transform, X, x, triangles, (before, after) = _case(name)
    true = case.wall.true_strain()
    chord = fold_aware_strain(X, x, triangles, before, after, transform, path="chord")
    geodesic = fold_aware_strain(X, x, triangles, before, after, transform)
    # edges that cross the folds obliquely: their chords climb more than the wall's material
    # lines, which the strain takes up
    assert np.abs(chord["E"] - true).max() > 0.004  # 0.0055-0.012 here
    assert np.abs(geodesic["E"] - true).max() < 0.003  # 0.0008-0.0019 here
    if name == "folding":  # the 45-degree diagonals, all one way: a shear
        assert np.abs(chord["E"][:, 0, 1]).min() > 0.005


@pytest.mark.parametrize("name", list(FOLD_CASES))
def test_the_statistics_only_correction_recovers_the_mean_strain(name):
    case, transform, X, x, triangles, (before, after) = _case(name)
    F = deformation_gradient(X, x, triangles)
    segment = float(np.median(np.hypot(*np.diff(transform.apply(X[triangles[:, :2]]), axis=1).T)))
    tb = directional_tortuosity(before, segment)
    ta = directional_tortuosity(after, segment)
    result = tortuosity_correction(F, tb, ta, transform)
    true = case.wall.true_strain()
    # the issue asks for 0.02; the means are within 0.004
    assert np.abs(result["E"].mean(axis=0) - true).max() < 0.006
    # each triangle is off by what the spread of the tortuosity over the field allows
    V = np.linalg.eigh(np.swapaxes(F, 1, 2) @ F)[1][:, :, ::-1]
    true_principal = np.einsum("mik,ij,mjk->mk", V, true, V)
    error = np.abs(result["E_principal"] - true_principal)
    assert (error <= 3 * result["E_principal_sd"] + 0.001).all()


def test_tortuosity_of_a_sine_along_and_across_its_folds():
    A, lam = 10.0, 60.0
    surface = wave_map(A, lam, 0.5, 400)
    tort = directional_tortuosity(surface, 2 * lam, angles_deg=[0, 90])
    ak = A * 2 * np.pi / lam
    exact = 4 * math.sqrt(1 + ak**2) * ellipe(ak**2 / (1 + ak**2)) / (2 * np.pi)
    assert tort.mean[0] == pytest.approx(exact, rel=1e-3)
    assert tort.mean[1] == pytest.approx(1.0, abs=1e-12)
    assert tort.at(np.array([180.0, 270.0]))[0] == pytest.approx(tort.mean, rel=1e-12)
    # periodic on both sides of the directions measured: 5 and 185 degrees lie between
    # 100 and 10 + 180
    shifted = directional_tortuosity(surface, 2 * lam, angles_deg=[10, 100])
    below = shifted.at(np.array([5.0, 185.0]))[0]
    assert below[0] == pytest.approx(below[1]) and below[0] > shifted.mean[1]
    with pytest.raises(InputError, match="do not fit"):
        directional_tortuosity(surface, 1000.0)


def test_landmarks_give_the_similarity_and_its_residual():
    truth = Similarity(2.5, -17.0, (300.0, 80.0))
    rng = np.random.default_rng(1)
    camera = rng.uniform(0, 400, (8, 2))
    fit, residual = Similarity.from_landmarks(camera, truth.apply(camera))
    assert fit.scale == pytest.approx(2.5, rel=1e-12)
    assert fit.angle_deg == pytest.approx(-17.0, abs=1e-9)
    np.testing.assert_allclose(fit.shift_um, truth.shift_um, atol=1e-9)
    assert residual.max() < 1e-9
    noisy = truth.apply(camera) + rng.normal(0, 1.0, camera.shape)
    fit, residual = Similarity.from_landmarks(camera, noisy)
    assert 0.5 < np.sqrt(np.mean(residual**2)) < 2.5  # 2D noise of 1 um per axis
    assert abs(fit.scale / 2.5 - 1) < 0.005
    mirror = Similarity(2.5, 40.0, (10.0, 20.0), mirrored=True)
    fit, residual = Similarity.from_landmarks(camera, mirror.apply(camera), mirrored=True)
    assert fit.angle_deg == pytest.approx(40.0, abs=1e-9) and residual.max() < 1e-9
    np.testing.assert_allclose(fit.inverse(fit.apply(camera)), camera, atol=1e-9)


@pytest.mark.parametrize(
    "camera, microscope, message",
    [
        (np.zeros((1, 2)), np.zeros((1, 2)), "at least 2"),
        (np.ones((3, 2)), np.arange(6.0).reshape(3, 2), "one place"),
        (np.arange(6.0).reshape(3, 2), np.array([[0, 0], [1, np.nan], [2, 2]]), "finite"),
        (np.zeros((3, 2)), np.zeros((4, 2)), "same shape"),
    ],
)
def test_landmarks_that_cannot_give_a_transform_are_refused(camera, microscope, message):
    with pytest.raises(InputError, match=message):
        Similarity.from_landmarks(camera, microscope)


def test_the_synthetic_wall_maps_material_to_projection_and_back():
    for wall in FOLD_CASES.values():
        rng = np.random.default_rng(0)
        P = rng.uniform(-1500, 1500, (200, 2))
        for t in (0.0, 0.4, 1.0):
            back = wall.material(wall.project(P, t), t)
            np.testing.assert_allclose(back, P, atol=1e-6)
    folding = FOLD_CASES["folding"]
    assert folding.tortuosity(0.0) == pytest.approx(1.0, abs=1e-9)
    # the projected length of a material segment along the folds is its length over the
    # tortuosity
    ends = folding.project(np.array([[-600.0, 0.0], [600.0, 0.0]]), 1.0)
    assert (ends[1, 0] - ends[0, 0]) * folding.tortuosity(1.0) == pytest.approx(1200.0, rel=1e-6)


def test_tiles_at_their_stage_positions_measure_what_the_stitched_map_does(tmp_path):
    from multimodal import SurfaceMosaic, read_surface_map

    case, transform, X, x, triangles, (before, after) = _case("oblique")
    whole = fold_aware_strain(X, x, triangles, before, after, transform)

    def tiles(surface, step=200, size=300):
        """Overlapping tiles of the map, cut on its pixel grid, at their stage positions."""
        out = []
        dy, dx = surface.pixel_um
        for r in range(0, surface.shape[0] - 1, step):
            for c in range(0, surface.shape[1] - 1, step):
                part = surface.height_um[r : r + size, c : c + size]
                out.append(SurfaceMap(part, surface.pixel_um, (c * dx, r * dy)))
        return out

    mosaic_before, mosaic_after = SurfaceMosaic(tiles(before)), SurfaceMosaic(tiles(after))
    assert len(mosaic_before.tiles) == 9
    tiled = fold_aware_strain(X, x, triangles, mosaic_before, mosaic_after, transform)
    np.testing.assert_allclose(tiled["L0"], whole["L0"], rtol=1e-9)
    np.testing.assert_allclose(tiled["E"], whole["E"], atol=1e-7)
    assert np.abs(tiled["E"] - case.wall.true_strain()).max() < 0.01
    # the same tiles from files and a CSV of their stage positions
    import tifffile

    rows = ["file,x_um,y_um"]
    for k, tile in enumerate(mosaic_after.tiles):
        tifffile.imwrite(tmp_path / f"t{k}.tif", tile.height_um.astype(np.float32), imagej=True,
                         resolution=(1 / 3.0, 1 / 3.0), metadata={"unit": "um"})  # fmt: skip
        rows.append(f"t{k}.tif,{tile.origin_um[0]},{tile.origin_um[1]}")
    (tmp_path / "tiles.csv").write_text("\n".join(rows) + "\n")
    read = read_surface_map(tmp_path / "tiles.csv")
    probe = np.random.default_rng(0).uniform(0, 1400, (500, 2))
    np.testing.assert_allclose(read.heights(probe), after.heights(probe), atol=1e-4)
    (tmp_path / "bad.csv").write_text("file,x_um\nt0.tif,0\n")
    with pytest.raises(InputError, match="file,x_um,y_um"):
        read_surface_map(tmp_path / "bad.csv")
