"""Triangle meshes on reference point sets.

Delaunay triangulation of the reference points: in their plane for 2D input;
for 3D input in a 2D parameterization of the surface (its best-fit plane, or
its best-fit sphere or cylinder when it is too curved to be a graph over one
plane).  Slivers and triangles with overlong edges (which bridge concave parts
of the outline) are removed.  Sliver quality is the normalized radius ratio
``q = 2 r_in / r_circ``: 1 for an equilateral triangle, 0.83 for the two
halves of a square, 0 for collinear vertices.

Points that come from a grid are better meshed from its topology
(:func:`grid_triangles`), which needs no projection at all.

References
----------
.. [1] Hoppe, H., DeRose, T., Duchamp, T., McDonald, J., & Stuetzle, W. (1992).
   Surface reconstruction from unorganized points. SIGGRAPH '92, 71-78.
   https://doi.org/10.1145/142920.134011 (normals by local PCA, orientation
   propagated along a minimum spanning tree).
.. [2] Brown, K. Q. (1979). Voronoi diagrams from convex hulls. Information
   Processing Letters 9(5), 223-228. https://doi.org/10.1016/0020-0190(79)90074-7
   (the stereographic image of a Delaunay triangulation on a sphere is Delaunay).
.. [3] Kasa, I. (1976). A circle fitting procedure and its error analysis. IEEE
   Trans. Instrum. Meas. IM-25(1), 8-14. https://doi.org/10.1109/TIM.1976.6312298
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree
from scipy.spatial import Delaunay, QhullError, cKDTree

from surface_strain._typing import BoolArray, FloatArray, IntArray

__all__ = [
    "FOLD_TOLERANCE",
    "best_fit_cylinder",
    "best_fit_plane",
    "best_fit_sphere",
    "delaunay_triangles",
    "edge_lengths",
    "folded_triangles",
    "grid_triangles",
    "point_normals",
    "triangle_quality",
]

#: A point whose (consistently oriented) normal has a component below
#: ``-FOLD_TOLERANCE`` along the best-fit plane's normal faces away from the
#: plane: the surface folds over it (overhangs by more than about 6 degrees).
FOLD_TOLERANCE = 0.1

Projection = Literal["plane", "sphere", "cylinder"]


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


def _unit_rows(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _check_points3(points: FloatArray, name: str = "points") -> np.ndarray:
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} must be finite")
    return p


def best_fit_sphere(points: FloatArray) -> tuple[FloatArray, float]:
    """Least-squares sphere through 3D points.

    An algebraic fit (linear in the centre, Kasa 1976) refined by minimizing
    the geometric distances ``|p - c| - R`` (Levenberg-Marquardt).

    Parameters
    ----------
    points : (N, 3) float, N >= 4, not coplanar

    Returns
    -------
    center : (3,) float
    radius : float
        In the unit of ``points``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> p = rng.normal(size=(50, 3))
    >>> c, r = best_fit_sphere(2.0 * p / np.linalg.norm(p, axis=1, keepdims=True) + 1.0)
    >>> np.round(c, 6).tolist(), round(r, 6)
    ([1.0, 1.0, 1.0], 2.0)
    """
    from scipy.optimize import least_squares

    p = _check_points3(points)
    if len(p) < 4:
        raise ValueError(f"a sphere needs at least 4 points, got {len(p)}")
    mean = p.mean(axis=0)
    q = p - mean
    A = np.column_stack([2 * q, np.ones(len(q))])
    sol, *_ = np.linalg.lstsq(A, np.sum(q * q, axis=1), rcond=None)
    c0 = sol[:3]
    r0 = np.sqrt(max(sol[3] + c0 @ c0, 0.0))
    if not (np.isfinite(r0) and r0 > 0):
        raise ValueError("points are coplanar or degenerate; no sphere fits them")
    fit = least_squares(
        lambda x: np.linalg.norm(q - x[:3], axis=1) - x[3], np.append(c0, r0), method="lm"
    )
    return fit.x[:3] + mean, float(abs(fit.x[3]))


def point_normals(
    points: FloatArray, *, k: int = 10, orient: FloatArray | None = None
) -> FloatArray:
    """Unit normals of a 3D point cloud, consistently oriented.

    Each normal is the least-variance direction of the point's ``k`` nearest
    neighbours (local PCA); signs are made consistent by propagation along a
    minimum spanning tree of the neighbour graph weighted by ``1 - |n_i . n_j|``
    (Hoppe et al. 1992), starting, in each connected part, from the point
    whose normal is most parallel to ``orient`` and pointing it along
    ``orient``.

    Parameters
    ----------
    points : (N, 3) float
    k : int, keyword-only
        Neighbours per point (including itself), at least 3.
    orient : (3,) float, optional, keyword-only
        Preferred side; default the best-fit plane's normal.

    Returns
    -------
    normals : (N, 3) float
    """
    p = _check_points3(points)
    n_pts = len(p)
    if n_pts < 3:
        raise ValueError(f"at least 3 points are needed for normals, got {n_pts}")
    if k < 3:
        raise ValueError(f"k must be at least 3, got {k}")
    k = min(k, n_pts)
    _, idx = cKDTree(p).query(p, k=k)
    nb = p[idx] - p[idx].mean(axis=1, keepdims=True)
    _, vecs = np.linalg.eigh(np.einsum("nki,nkj->nij", nb, nb))
    normals = vecs[:, :, 0]
    if orient is None:
        _, axes = best_fit_plane(p)
        orient = np.cross(axes[:, 0], axes[:, 1])
    orient = np.asarray(orient, dtype=float)
    rows = np.repeat(np.arange(n_pts), k)
    cols = idx.ravel()
    weight = 1.0 - np.abs(np.sum(normals[rows] * normals[cols], axis=1)) + 1e-9
    off = rows != cols
    graph = coo_matrix((weight[off], (rows[off], cols[off])), shape=(n_pts, n_pts)).tocsr()
    graph = graph.maximum(graph.T)
    tree = minimum_spanning_tree(graph)
    _, labels = connected_components(tree, directed=False)
    align = normals @ orient
    for label in np.unique(labels):
        members = np.flatnonzero(labels == label)
        root = members[np.argmax(np.abs(align[members]))]
        if align[root] < 0:
            normals[root] = -normals[root]
        order, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        for i in order[1:]:
            if normals[i] @ normals[pred[i]] < 0:
                normals[i] = -normals[i]
    return normals


def best_fit_cylinder(
    points: FloatArray, *, direction: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, float]:
    """Least-squares circular cylinder through 3D points.

    The axis direction starts as the direction most perpendicular to the
    points' normals (:func:`point_normals`: every normal of a cylinder is
    perpendicular to its axis), the axis position and radius as a circle fit
    (Kasa 1976) of the points projected along it; then the distances to the
    axis minus the radius are minimized (Levenberg-Marquardt).

    Parameters
    ----------
    points : (N, 3) float, N >= 5
    direction : (3,) float, optional, keyword-only
        A known axis direction, kept fixed.

    Returns
    -------
    point : (3,) float
        The point of the axis nearest the points' centroid.
    direction : (3,) float
        Unit axis direction (sign arbitrary unless given).
    radius : float

    Examples
    --------
    >>> t, z = np.meshgrid(np.linspace(0, 2, 9), np.linspace(-1, 1, 5))
    >>> p = np.column_stack([3 * np.cos(t.ravel()), 3 * np.sin(t.ravel()), z.ravel()])
    >>> point, a, r = best_fit_cylinder(p)
    >>> round(r, 6), np.abs(np.round(a, 6)).tolist()
    (3.0, [0.0, 0.0, 1.0])
    """
    from scipy.optimize import least_squares

    p = _check_points3(points)
    if len(p) < 5:
        raise ValueError(f"a cylinder needs at least 5 points, got {len(p)}")
    mean = p.mean(axis=0)
    q = p - mean
    if direction is None:
        n = point_normals(p)
        _, vecs = np.linalg.eigh(n.T @ n)
        a0 = vecs[:, 0]
    else:
        a0 = np.asarray(direction, dtype=float)
        if a0.shape != (3,) or not np.all(np.isfinite(a0)) or not np.linalg.norm(a0) > 0:
            raise ValueError(f"direction must be a finite non-zero 3-vector, got {direction!r}")
        a0 = a0 / np.linalg.norm(a0)
    b1 = np.cross(a0, [1.0, 0.0, 0.0] if abs(a0[0]) < 0.9 else [0.0, 1.0, 0.0])
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(a0, b1)
    uv = np.column_stack([q @ b1, q @ b2])
    A = np.column_stack([2 * uv, np.ones(len(uv))])
    sol, *_ = np.linalg.lstsq(A, np.sum(uv * uv, axis=1), rcond=None)
    r0 = np.sqrt(max(sol[2] + sol[:2] @ sol[:2], 0.0))
    if not (np.isfinite(r0) and r0 > 0):
        raise ValueError("points are degenerate; no cylinder fits them")

    free = direction is None  # fit the direction too, or only position and radius

    def axis_of(x):
        a = a0 + x[0] * b1 + x[1] * b2 if free else a0
        o = x[-3] * b1 + x[-2] * b2
        return o, a / np.linalg.norm(a)

    def residual(x):
        o, a = axis_of(x)
        r = q - o
        return np.linalg.norm(r - np.outer(r @ a, a), axis=1) - x[-1]

    x0 = np.array([sol[0], sol[1], r0])
    fit = least_squares(residual, np.concatenate([np.zeros(2), x0]) if free else x0, method="lm")
    o, a = axis_of(fit.x)
    o = o - (o @ a) * a  # nearest the centroid (the origin of q)
    return o + mean, a, float(abs(fit.x[-1]))


def edge_lengths(points: FloatArray, triangles: IntArray) -> FloatArray:
    """Lengths of the three edges of each triangle.

    Returns
    -------
    lengths : (M, 3) float
        Edges opposite vertex 0, 1, 2 (``|p1 - p2|, |p2 - p0|, |p0 - p1|``).
    """
    p = np.asarray(points, dtype=float)[np.asarray(triangles)]
    return np.linalg.norm(p[:, [1, 2, 0]] - p[:, [2, 0, 1]], axis=-1)


#: |cos| of the angle between a triangle's normal and a plane's below which it is edge-on
_EDGE_ON = 1e-9


def folded_triangles(
    points: FloatArray, triangles: IntArray, *, normal: FloatArray | None = None
) -> BoolArray:
    """Triangles that face away from a plane's normal: where a mesh folds over it.

    For a consistently oriented mesh (e.g. :func:`grid_triangles` on a grid
    that was tracked over a surface) every triangle of a surface that is a
    graph over the plane faces the same side; triangles facing the other side
    mark an overhang (or a flipped, tangled region).

    Parameters
    ----------
    points : (N, 3) float
    triangles : (M, 3) int
    normal : (3,) float, optional, keyword-only
        Plane normal; default the best-fit plane's, signed so that the larger
        (area-weighted) part of the mesh faces along it.

    Returns
    -------
    folded : (M,) bool
        Triangles standing edge-on to the plane (their normal within
        ``1e-9`` rad of perpendicular to it) do not count as folded: which side
        they face is decided by round-off, so it would differ between machines.
    """
    p = _check_points3(points)
    tri = np.asarray(triangles)
    q = p[tri]
    n = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])  # length = twice the area
    if normal is None:
        _, axes = best_fit_plane(p)
        normal = np.cross(axes[:, 0], axes[:, 1])
        if np.sum(n @ normal) < 0:
            normal = -normal
    normal = np.asarray(normal, dtype=float)
    tolerance = _EDGE_ON * np.linalg.norm(n, axis=1) * np.linalg.norm(normal)
    return np.asarray(n @ normal < -tolerance)


def _sphere_coordinates(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stereographic coordinates about the cap's middle, and outward normals."""
    center, radius = best_fit_sphere(p)
    u = _unit_rows(p - center)
    pole = u.mean(axis=0)
    if np.linalg.norm(pole) < 1e-3:
        raise ValueError(
            "the points cover the whole sphere; a closed surface cannot be meshed "
            "by one projection (split it, or mesh it from its grid topology)"
        )
    pole /= np.linalg.norm(pole)
    b1 = np.cross(pole, [1.0, 0.0, 0.0] if abs(pole[0]) < 0.9 else [0.0, 1.0, 0.0])
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(pole, b1)
    z = u @ pole
    if np.any(z < -1 + 1e-6):
        raise ValueError("a point lies opposite the middle of the cap; cannot project it")
    uv = radius * np.column_stack([u @ b1, u @ b2]) / (1 + z)[:, None]
    return uv, u


def _cylinder_coordinates(p: np.ndarray, axis) -> tuple[np.ndarray, np.ndarray]:
    """Unrolled coordinates (arc length, axial) and outward normals."""
    if axis is None:
        o, a, radius = best_fit_cylinder(p)
    else:
        from surface_strain.kinematics import _parse_axis

        o, a = _parse_axis(axis)
        o, a, radius = best_fit_cylinder(p, direction=a)
    r = p - o
    t = r @ a
    radial = r - np.outer(t, a)
    b1 = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    b1 /= np.linalg.norm(b1)
    b2 = np.cross(a, b1)
    theta = np.arctan2(radial @ b2, radial @ b1)
    # cut the circle in the middle of the widest angular gap between points
    s = np.sort(theta)
    gaps = np.diff(np.append(s, s[0] + 2 * np.pi))
    g = int(np.argmax(gaps))
    cut = s[g] + 0.5 * gaps[g]
    theta = np.mod(theta - cut, 2 * np.pi)
    return np.column_stack([radius * theta, t]), _unit_rows(radial)


def delaunay_triangles(
    points: FloatArray,
    *,
    min_quality: float = 0.1,
    max_edge_ratio: float | None = 3.0,
    projection: Projection = "plane",
    axis: tuple[FloatArray, FloatArray] | None = None,
) -> IntArray:
    """Delaunay triangulation of reference points without slivers or bridges.

    Parameters
    ----------
    points : (N, 2) or (N, 3) float
        Reference positions.
    min_quality : float, keyword-only
        Triangles whose radius ratio (see :func:`triangle_quality`, measured on
        the points themselves, in 3D for 3D input) falls below this are
        removed; 0 keeps all non-degenerate triangles.
    max_edge_ratio : float or None, keyword-only
        Triangles with an edge longer than this many times the median edge
        length (of the triangles left by the quality filter) are removed: they
        bridge concave parts of the outline (an L- or C-shaped point set) or
        gaps in the points.  None keeps them.  The default 3 leaves a regular
        grid (edges 1 and sqrt(2) times the spacing) untouched.
    projection : {"plane", "sphere", "cylinder"}, keyword-only
        Where 3D points are triangulated (ignored for 2D input):

        * "plane": in their best-fit plane (:func:`best_fit_plane`), which
          suits surfaces that are a graph over that plane.  A surface that
          folds over it (points whose consistently oriented normal,
          :func:`point_normals`, faces away from the plane by more than
          :data:`FOLD_TOLERANCE`) is refused with a message;
        * "sphere": stereographically projected from the point of the
          best-fit sphere (:func:`best_fit_sphere`) opposite the points' middle,
          for domes and caps up to nearly the whole sphere (Delaunay in the
          stereographic plane is Delaunay on the sphere, Brown 1979);
        * "cylinder": unrolled about the best-fit cylinder's axis
          (:func:`best_fit_cylinder`, or ``axis``), cut at the widest angular gap
          between points, for tubes and arches.  A closed tube keeps an
          unmeshed seam; mesh closed tubes from their grid topology.

        With "sphere" and "cylinder" the triangles are oriented with normals
        pointing away from the centre or axis, and a triangle facing inwards
        (the points are far from the fitted surface) is refused.
    axis : (point, direction), optional, keyword-only
        With ``projection="cylinder"``: the axis direction to use (its point
        and the radius are still fitted).

    Returns
    -------
    triangles : (M, 3) int
        Counter-clockwise in the (plane, stereographic or unrolled) parameter
        coordinates.

    Raises
    ------
    ValueError
        Fewer than 3 points, all points collinear, no triangle passes the
        filters, or the surface folds over the chosen projection.

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
    if max_edge_ratio is not None and not max_edge_ratio > 1.0:
        raise ValueError(f"max_edge_ratio must be above 1 (or None), got {max_edge_ratio}")
    if projection not in ("plane", "sphere", "cylinder"):
        raise ValueError(f"projection must be 'plane', 'sphere' or 'cylinder', got {projection!r}")
    if axis is not None and projection != "cylinder":
        raise ValueError("axis is only used with projection='cylinder'")
    outward = None
    if p.shape[1] == 2:
        p2 = p
    elif projection == "plane":
        c, axes = best_fit_plane(p)
        p2 = (p - c) @ axes
    if np.ptp(p, axis=0).max() == 0:
        raise ValueError("all points coincide; cannot build a mesh")
    if p.shape[1] == 3 and projection == "sphere":
        if len(p) < 4:
            raise ValueError("projection='sphere' needs at least 4 points")
        p2, outward = _sphere_coordinates(p)
    elif p.shape[1] == 3 and projection == "cylinder":
        if len(p) < 5:
            raise ValueError("projection='cylinder' needs at least 5 points")
        p2, outward = _cylinder_coordinates(p, axis)
    extent = np.ptp(p2, axis=0).max()
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
    quality = triangle_quality(p, simplices)
    keep = (quality > max(min_quality, 1e-9)) & (np.abs(cross) > 1e-12 * extent**2)
    if not np.any(keep):
        raise ValueError("points are collinear or too close; no usable triangle remains")
    if max_edge_ratio is not None:
        lengths = edge_lengths(p, simplices)
        kept = simplices[keep]
        edges = np.sort(np.concatenate([kept[:, [1, 2]], kept[:, [2, 0]], kept[:, [0, 1]]]), 1)
        _, first = np.unique(edges, axis=0, return_index=True)
        median = np.median(lengths[keep].T.ravel()[first])
        keep &= lengths.max(axis=1) <= max_edge_ratio * median
    simplices = simplices[keep]
    if p.shape[1] == 3:
        _check_folds(p, simplices, projection, outward)
        if outward is not None:
            simplices = _orient_outward(p, simplices, outward)
    return simplices


def _orient_outward(p: np.ndarray, simplices: np.ndarray, outward: np.ndarray) -> np.ndarray:
    q = p[simplices]
    n = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0])
    facing = np.sum(n * outward[simplices].mean(axis=1), axis=1)
    if np.sum(facing > 0) < np.sum(facing < 0):  # the projection reversed the orientation
        simplices = simplices[:, [0, 2, 1]]
        facing = -facing
    inward = facing <= 0
    if np.any(inward):
        raise ValueError(
            f"{int(inward.sum())} triangle(s) face towards the fitted surface's centre or "
            f"axis (first: triangle {int(np.flatnonzero(inward)[0])}): the points are far "
            "from a sphere or cylinder, or the surface folds; try another projection"
        )
    return simplices


def _check_folds(p: np.ndarray, simplices: np.ndarray, projection: str, outward) -> None:
    if projection != "plane" or len(p) < 4:
        return
    _, axes = best_fit_plane(p)
    plane_normal = np.cross(axes[:, 0], axes[:, 1])
    normals = point_normals(p, orient=plane_normal)
    away = normals @ plane_normal < -FOLD_TOLERANCE
    if np.any(away):
        raise ValueError(
            f"the surface folds over its best-fit plane: {int(away.sum())} of {len(p)} "
            f"points (first: point {int(np.flatnonzero(away)[0])}) face away from it, so "
            "a Delaunay mesh in that plane would overlap itself; pass "
            "projection='sphere' or 'cylinder', or mesh the points from their grid "
            "topology (grid_triangles)"
        )


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
