"""Triangle meshes on reference point sets.

Delaunay triangulation of the reference points (in their plane for 3D input)
with removal of degenerate slivers.  Sliver quality is the normalized radius
ratio ``q = 2 r_in / r_circ``: 1 for an equilateral triangle, 0.83 for the two
halves of a square, 0 for collinear vertices.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError

from surface_strain._typing import FloatArray, IntArray

__all__ = ["best_fit_plane", "delaunay_triangles", "grid_triangles", "triangle_quality"]


def triangle_quality(points: FloatArray, triangles: IntArray) -> FloatArray:
    """Radius ratio ``2 r_in / r_circ`` of each triangle, in [0, 1].

    Parameters
    ----------
    points : (N, 2) or (N, 3) float
    triangles : (M, 3) int

    Returns
    -------
    q : (M,) float
    """
    p = np.asarray(points, dtype=float)[np.asarray(triangles)]
    a = np.linalg.norm(p[:, 1] - p[:, 2], axis=-1)
    b = np.linalg.norm(p[:, 2] - p[:, 0], axis=-1)
    c = np.linalg.norm(p[:, 0] - p[:, 1], axis=-1)
    # 2 r/R = (b + c - a)(c + a - b)(a + b - c) / (a b c)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = (b + c - a) * (c + a - b) * (a + b - c) / (a * b * c)
    return np.nan_to_num(np.clip(q, 0.0, 1.0))


def best_fit_plane(points: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Centroid and in-plane axes of the least-squares plane through 3D points.

    Returns
    -------
    centroid : (3,) float
    axes : (3, 2) float
        Orthonormal columns spanning the plane (largest spread first).
    """
    p = np.asarray(points, dtype=float)
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c, full_matrices=False)
    return c, vt[:2].T


def delaunay_triangles(points: FloatArray, *, min_quality: float = 0.1) -> IntArray:
    """Delaunay triangulation of reference points without slivers.

    Parameters
    ----------
    points : (N, 2) or (N, 3) float
        Reference positions.  3D points are triangulated in their best-fit
        plane, which suits surfaces that are a graph over that plane.
    min_quality : float, keyword-only
        Triangles whose radius ratio (see :func:`triangle_quality`) falls below
        this are removed; 0 keeps all non-degenerate triangles.

    Returns
    -------
    triangles : (M, 3) int
        Counter-clockwise in the (plane) x-y coordinates.

    Raises
    ------
    ValueError
        Fewer than 3 points, all points collinear, or no triangle passes the
        quality filter.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=float)
    >>> delaunay_triangles(pts).shape
    (2, 3)
    """
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (N, 2) or (N, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError("points must be finite to build a mesh")
    if len(p) < 3:
        raise ValueError(f"at least 3 points are needed for a triangle mesh, got {len(p)}")
    if not 0.0 <= min_quality < 1.0:
        raise ValueError(f"min_quality must be in [0, 1), got {min_quality}")
    if p.shape[1] == 3:
        c, axes = best_fit_plane(p)
        p2 = (p - c) @ axes
    else:
        p2 = p
    extent = np.ptp(p2, axis=0).max()
    if extent == 0:
        raise ValueError("all points coincide; cannot build a mesh")
    try:
        tri = Delaunay(p2)
    except QhullError as exc:  # collinear or otherwise flat input
        raise ValueError("points are collinear; cannot build a triangle mesh") from exc
    simplices = tri.simplices.astype(np.int64)
    # Qhull returns counter-clockwise simplices only up to orientation; enforce it.
    q2 = p2[simplices]
    cross = (q2[:, 1, 0] - q2[:, 0, 0]) * (q2[:, 2, 1] - q2[:, 0, 1]) - (
        q2[:, 1, 1] - q2[:, 0, 1]
    ) * (q2[:, 2, 0] - q2[:, 0, 0])
    simplices[cross < 0] = simplices[cross < 0][:, [0, 2, 1]]
    quality = triangle_quality(p2, simplices)
    keep = (quality > max(min_quality, 1e-9)) & (np.abs(cross) > 1e-12 * extent**2)
    if not np.any(keep):
        raise ValueError("points are collinear or too close; no usable triangle remains")
    return simplices[keep]


def grid_triangles(n_rows: int, n_cols: int) -> IntArray:
    """Structured triangulation of a row-major grid of ``n_rows x n_cols`` points.

    Each cell is split along alternating diagonals (a "union jack"-free
    criss-cross pattern), which avoids the directional bias of a single diagonal.

    Returns
    -------
    triangles : (2 (n_rows - 1) (n_cols - 1), 3) int
    """
    if n_rows < 2 or n_cols < 2:
        raise ValueError(f"a grid needs at least 2 x 2 points, got {n_rows} x {n_cols}")
    r, c = np.meshgrid(np.arange(n_rows - 1), np.arange(n_cols - 1), indexing="ij")
    r, c = r.ravel(), c.ravel()
    a = r * n_cols + c
    b, d, e = a + 1, a + n_cols, a + n_cols + 1
    alt = (r + c) % 2 == 1
    t1 = np.where(alt[:, None], np.stack([a, b, d], 1), np.stack([a, b, e], 1))
    t2 = np.where(alt[:, None], np.stack([b, e, d], 1), np.stack([a, e, d], 1))
    return np.concatenate([t1, t2]).astype(np.int64)
