import numpy as np
import pytest

from surface_strain import delaunay_triangles, grid_triangles, triangle_areas, triangle_quality


def square_grid(n, m):
    return np.stack(np.meshgrid(np.arange(m, dtype=float), np.arange(n, dtype=float)), -1).reshape(
        -1, 2
    )


def test_delaunay_of_a_grid_covers_it_once():
    pts = square_grid(7, 7) * 50
    tri = delaunay_triangles(pts)
    assert tri.shape == (72, 3)
    assert triangle_areas(pts, tri).sum() == pytest.approx(300 * 300)
    # counter-clockwise in (x, y)
    p = pts[tri]
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    cross = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    assert np.all(cross > 0)


def test_slivers_on_the_hull_are_removed():
    pts = np.vstack([square_grid(3, 3) * 10, [[10.0, -0.05]]])  # almost on the bottom edge
    all_tri = delaunay_triangles(pts, min_quality=0.0)
    tri = delaunay_triangles(pts, min_quality=0.1)
    q = triangle_quality(pts, all_tri)
    assert q.min() < 0.1
    assert len(tri) == len(all_tri) - np.sum(q < 0.1)
    assert triangle_quality(pts, tri).min() >= 0.1


def test_triangle_quality_known_values():
    eq = np.array([[0, 0], [1, 0], [0.5, np.sqrt(3) / 2]])
    half_square = np.array([[0, 0], [1, 0], [0, 1]], dtype=float)
    flat = np.array([[0, 0], [1, 0], [2, 0]], dtype=float)
    t = np.array([[0, 1, 2]])
    assert triangle_quality(eq, t)[0] == pytest.approx(1.0)
    assert triangle_quality(half_square, t)[0] == pytest.approx(2 * (np.sqrt(2) - 1), rel=1e-12)
    assert triangle_quality(flat, t)[0] == 0.0


@pytest.mark.parametrize(
    ("pts", "match"),
    [
        (np.array([[0.0, 0], [1, 1]]), "at least 3"),
        (np.array([[0.0, 0], [1, 1], [2, 2], [3, 3]]), "collinear"),
        (np.array([[0.0, 0], [0, 0], [0, 0]]), "coincide"),
        (np.array([[0.0, 0], [1, np.nan], [0, 1]]), "finite"),
    ],
)
def test_bad_point_sets_are_refused(pts, match):
    with pytest.raises(ValueError, match=match):
        delaunay_triangles(pts)


def test_delaunay_of_a_tilted_3d_plane_matches_its_2d_layout():
    pts2 = square_grid(4, 5) * 3.0
    tilt = np.array([[1, 0], [0, np.cos(0.6)], [0, np.sin(0.6)]])
    pts3 = pts2 @ tilt.T + [1, 2, 3]
    tri3 = delaunay_triangles(pts3)
    assert len(tri3) == 2 * 3 * 4
    assert triangle_areas(pts3, tri3).sum() == pytest.approx(9 * 12)


def test_grid_triangles_tile_the_grid():
    pts = square_grid(4, 6)
    tri = grid_triangles(4, 6)
    assert tri.shape == (2 * 3 * 5, 3)
    assert triangle_areas(pts, tri).sum() == pytest.approx(3 * 5)
    assert np.all(triangle_areas(pts, tri) == pytest.approx(0.5))
