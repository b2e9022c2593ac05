import numpy as np
import pytest

from mpm3d.errors import InputError
from mpm3d.heightmap import fill_gaps, height_map
from mpm3d.io import read_stack, select_channel
from mpm3d.surface import heightmap_mesh, isosurface, largest_component, vertical_error
from tests.tolerances import MPM_SURFACE_RMS_ZSTEPS


def _rms(a):
    return float(np.sqrt(np.mean(np.square(a))))


@pytest.mark.parametrize("name", ["before", "after"])
@pytest.mark.parametrize("channel", [None, "urothelium"])
def test_height_map_finds_the_true_surface(mpm_pair, name, channel):
    path, case = mpm_pair[name]
    stack = read_stack(path)
    volume, _ = select_channel(stack, channel)
    hm = height_map(volume, spacing=stack.spacing)
    dz = stack.spacing[0]
    assert hm.coverage > 0.99
    err = hm.depth_um - case.depth_um
    assert _rms(err) < MPM_SURFACE_RMS_ZSTEPS * dz
    # sub-voxel, not just under one step: a quarter of a step in practice
    assert _rms(err) < 0.25 * dz
    np.testing.assert_allclose(hm.height_um, (stack.shape[0] - 1) * dz - hm.depth_um)


def test_height_map_is_exact_on_a_noise_free_tilted_edge():
    z = np.arange(60.0)[:, None, None]
    y, x = np.mgrid[0:24, 0:40]
    true = 20.0 + 0.1 * x + 0.05 * y  # slices
    vol = 100 + 1000 / (1 + np.exp(-(z - true[None]) / 0.7))
    hm = height_map(vol, spacing=(3.0, 1.0, 1.0), smooth_um=0)
    inner = (slice(2, -2), slice(2, -2))
    assert np.abs(hm.depth_um - 3.0 * true)[inner].max() < 0.05 * 3.0


def test_a_threshold_above_everything_finds_no_surface(mpm_pair):
    path, _ = mpm_pair["before"]
    volume, _ = select_channel(read_stack(path), "urothelium")
    with pytest.raises(InputError, match="no surface found"):
        height_map(volume, spacing=(4.0, 5.0, 5.0), threshold=60000)


def test_uniform_volume_has_no_surface():
    with pytest.raises(InputError, match="uniform"):
        height_map(np.full((5, 8, 8), 7, np.uint16), spacing=(1, 1, 1))


def test_drop_outs_are_masked_and_filled():
    z = np.arange(30.0)[:, None, None]
    vol = np.where(z >= 12, 1000.0, 100.0) * np.ones((1, 20, 20))
    vol[:, 8:11, 8:11] = 100.0  # a dark hole: no surface in these columns
    hm = height_map(vol, spacing=(1.0, 1.0, 1.0), smooth_um=0)
    assert not hm.valid[9, 9] and hm.valid[0, 0]
    assert hm.depth_um[9, 9] == pytest.approx(11.5, abs=1e-6)  # filled from the flat surroundings


def test_fill_gaps_keeps_valid_values_and_blends_across_gaps():
    ramp = np.tile(np.arange(10.0), (6, 1))
    valid = np.ones(ramp.shape, bool)
    valid[:, 4:6] = False
    out = fill_gaps(np.where(valid, ramp, np.nan), valid)
    np.testing.assert_array_equal(out[valid], ramp[valid])
    gap = out[:, 4:6]
    assert np.all((gap > 3) & (gap < 6)) and np.all(gap[:, 0] < gap[:, 1])
    with pytest.raises(InputError):
        fill_gaps(ramp, np.zeros_like(valid))


@pytest.mark.parametrize("iso_bin", [None, 1])
def test_isosurface_lies_on_the_true_surface(mpm_pair, iso_bin):
    path, case = mpm_pair["after"]
    stack = read_stack(path)
    volume, _ = select_channel(stack)
    hm = height_map(volume, spacing=stack.spacing)
    mesh = isosurface(
        volume, spacing=stack.spacing, level=hm.level, depth_um=hm.depth_um, bin=iso_bin
    )
    truth = heightmap_mesh(case.depth_um, spacing=stack.spacing)
    dist = np.asarray(mesh.compute_implicit_distance(truth)["implicit_distance"])
    p = mesh.points
    span = (np.array(case.depth_um.shape[::-1]) - 1) * stack.spacing[1:][::-1]
    inner = np.all((p[:, :2] > 10) & (p[:, :2] < span - 10), axis=1)
    assert _rms(dist[inner]) < MPM_SURFACE_RMS_ZSTEPS * stack.spacing[0]
    # normals into the lumen (towards the objective: -z)
    assert np.mean(mesh.point_normals[:, 2]) < -0.2
    # it spans the field and reaches crests and troughs
    assert vertical_error(mesh, case.depth_um, spacing=stack.spacing).size > 0.9 * mesh.n_points
    assert mesh.points[:, 2].min() < case.depth_um.min() + 10
    assert mesh.points[:, 2].max() > case.depth_um.max() - 10


def test_heightmap_mesh_of_a_plane_has_upward_normals_and_exact_points():
    depth = np.full((4, 5), 7.0)
    mesh = heightmap_mesh(depth, spacing=(2.0, 3.0, 0.5))
    assert mesh.n_points == 20 and mesh.n_cells == 24
    np.testing.assert_allclose(mesh.points[-1], [4 * 0.5, 3 * 3.0, 7.0])
    np.testing.assert_allclose(mesh.point_normals, np.tile([0, 0, -1.0], (20, 1)), atol=1e-12)
    assert heightmap_mesh(depth, spacing=(3.0, 0.5), mask=depth < 0).n_cells == 0


def test_largest_component_keeps_the_bigger_piece():
    big = heightmap_mesh(np.full((6, 6), 5.0), spacing=(1.0, 1.0))
    small = heightmap_mesh(np.full((3, 3), 9.0), spacing=(1.0, 1.0)).translate((20, 0, 0))
    both = big.merge(small)
    kept = largest_component(both)
    assert both.n_cells == big.n_cells + small.n_cells
    assert kept.n_cells == big.n_cells and kept.n_points == big.n_points
    assert np.allclose(kept.points[:, 2], 5.0)


def test_the_surface_intensity_is_the_layer_just_below_the_surface():
    """A bright layer 6 um thick under a tilted surface, dim tissue deeper and nothing
    above: the projection reads the layer's own brightness, which varies across x."""
    from mpm3d.heightmap import surface_intensity

    dz, ny, nx, nz = 1.0, 20, 30, 60
    depth = 10.3 + 0.45 * np.arange(nx)[None, :] + np.zeros((ny, 1))  # between slices
    brightness = 100.0 + 10.0 * np.arange(nx)[None, :] + np.zeros((ny, 1))
    z = np.arange(nz)[:, None, None] * dz
    layer = (z >= depth) & (z < depth + 6.0)
    volume = np.where(layer, brightness, np.where(z >= depth + 6.0, 20.0, 0.0))
    got = surface_intensity(volume, depth, dz)
    np.testing.assert_allclose(got, brightness, rtol=1e-6)

    # a band of rows at a time gives the same; a column with no surface has none
    class Bands:
        shape = volume.shape

        @staticmethod
        def rows(y0, y1, z0=0, z1=None):
            return volume[z0:z1, y0:y1, :]

    depth[3, 4] = np.nan
    banded = surface_intensity(Bands(), depth, dz, rows=7)
    whole = surface_intensity(volume, depth, dz)
    assert np.isnan(banded[3, 4]) and np.array_equal(banded, whole, equal_nan=True)
