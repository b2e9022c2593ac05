import numpy as np

from surface_strain import compute_strain, delaunay_triangles, nodal_average

TRI = np.array([[0, 1, 2], [1, 3, 2]])


def test_area_weighted_average():
    out = nodal_average(np.array([1.0, 3.0]), TRI, 4, weights=np.array([1.0, 3.0]))
    np.testing.assert_allclose(out, [1.0, 2.5, 2.5, 3.0])


def test_nan_triangles_do_not_leak_into_neighbours():
    out = nodal_average(np.array([np.nan, 3.0]), TRI, 4)
    assert np.isnan(out[0])  # only adjacent to the lost triangle
    np.testing.assert_allclose(out[1:], 3.0)


def test_frames_and_components_are_kept():
    values = np.arange(2 * 2 * 4, dtype=float).reshape(2, 2, 2, 2)  # (T, M, 2, 2)
    out = nodal_average(values, TRI, 4, axis=1)
    assert out.shape == (2, 4, 2, 2)
    np.testing.assert_allclose(out[:, 0], values[:, 0])
    np.testing.assert_allclose(out[:, 3], values[:, 1])


def test_lost_point_masks_only_its_triangles():
    ref = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2) * 10
    tri = delaunay_triangles(ref)
    cur = np.stack([ref, ref * 1.2])
    visible = np.ones((2, 25), bool)
    visible[1, 12] = False  # the centre point is lost on frame 1
    cur[1, 12] = np.nan
    field = compute_strain(ref, cur, tri, visible=visible)
    lost_tri = np.any(tri == 12, axis=1)
    assert not field.element_valid[1, lost_tri].any()
    assert field.element_valid[1, ~lost_tri].all()
    assert np.isnan(field.nodal_E[1, 12]).all()  # no valid triangle around it
    others = np.delete(field.nodal_E[1], 12, axis=0)
    np.testing.assert_allclose(others[:, 0, 0], 0.5 * (1.2**2 - 1), atol=1e-12)
    assert not field.visible[1, 12]
