"""Constant-strain-triangle kinematics in 2D and on surfaces in 3D.

For a triangle with reference vertices ``X1, X2, X3`` and current vertices
``x1, x2, x3`` (2D or 3D), reference edges ``D1 = X2 - X1``, ``D2 = X3 - X1`` are
expressed in an orthonormal basis ``(t1, t2)`` of the reference triangle's plane,
``G = [[t1.D1, t1.D2], [t2.D1, t2.D2]]``, and the in-plane deformation map is
``F = [d1 d2] G^-1`` with shape ``(d, 2)``.  For planar input the basis is the
global ``(x, y)`` axes and ``F = I + grad u`` exactly as in the constant-strain
triangle.  From ``F``: right Cauchy-Green ``C = F^T F``, Green-Lagrange
``E = (C - I) / 2``, area ratio ``J = sqrt(det C)``.

All functions are vectorized over any leading axes (frames) and over triangles.

References
----------
.. [1] Holzapfel, G. A. (2000). Nonlinear Solid Mechanics. Wiley. Ch. 2.
.. [2] Solav, D., Moerman, K. M., Jaeger, A. M., Genovesi, K., & Herr, H. M. (2018).
   MultiDIC: an open-source toolbox for multi-view 3D digital image correlation.
   IEEE Access 6, 30520-30535. https://doi.org/10.1109/ACCESS.2018.2843725
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from surface_strain._typing import FloatArray, IntArray

__all__ = [
    "DIRECTION_TOLERANCE",
    "PrincipalDirections",
    "area_ratio",
    "cylindrical_directions",
    "deformation_gradient",
    "directional_components",
    "euler_almansi",
    "green_lagrange",
    "logarithmic_strain",
    "material_frame",
    "principal_directions",
    "principal_strains",
    "reference_frames",
    "right_cauchy_green",
    "spherical_directions",
    "triangle_areas",
    "triangle_normals",
]

_I2 = np.eye(2)

#: A material direction whose component in a tangent plane is below this fraction
#: of its length (within about 0.00006 degrees of the normal) gives no usable frame.
DIRECTION_TOLERANCE = 1e-6


def _check_points(points: FloatArray, name: str) -> np.ndarray:
    points = np.asarray(points, dtype=float)
    if points.ndim < 2 or points.shape[-1] not in (2, 3):
        raise ValueError(f"{name} must have shape (..., N, 2) or (..., N, 3), got {points.shape}")
    return points


def _check_triangles(triangles: IntArray, n_points: int) -> np.ndarray:
    triangles = np.asarray(triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3:
        raise ValueError(f"triangles must have shape (M, 3), got {triangles.shape}")
    if not np.issubdtype(triangles.dtype, np.integer):
        raise ValueError("triangles must hold integer point indices")
    if triangles.size and (triangles.min() < 0 or triangles.max() >= n_points):
        raise ValueError(f"triangles index points outside 0..{n_points - 1}")
    return triangles


def triangle_areas(points: FloatArray, triangles: IntArray) -> FloatArray:
    """Area of each triangle.

    Parameters
    ----------
    points : (..., N, 2) or (..., N, 3) float
    triangles : (M, 3) int

    Returns
    -------
    areas : (..., M) float
        In the squared unit of ``points``.
    """
    points = _check_points(points, "points")
    triangles = _check_triangles(triangles, points.shape[-2])
    p = points[..., triangles, :]
    d1 = p[..., 1, :] - p[..., 0, :]
    d2 = p[..., 2, :] - p[..., 0, :]
    if points.shape[-1] == 2:
        return 0.5 * np.abs(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])
    return 0.5 * np.linalg.norm(np.cross(d1, d2), axis=-1)


def reference_frames(reference: FloatArray, triangles: IntArray) -> tuple[FloatArray, FloatArray]:
    """Orthonormal tangent basis and reference edge matrix of each triangle.

    For 2D input the basis is the global x, y axes.  For 3D input ``t1`` is the
    normalized first edge and ``t2`` completes a right-handed frame with the
    triangle normal ``n = D1 x D2``.

    Parameters
    ----------
    reference : (N, 2) or (N, 3) float
        Reference vertex positions.
    triangles : (M, 3) int

    Returns
    -------
    basis : (M, d, 2) float
        Columns ``t1, t2``.
    G : (M, 2, 2) float
        Reference edges in that basis, ``G[:, :, 0] = (t1.D1, t2.D1)``.

    Raises
    ------
    ValueError
        If a triangle is degenerate (zero area) in the reference configuration.
    """
    reference = _check_points(reference, "reference")
    if reference.ndim != 2:
        raise ValueError(f"reference must have shape (N, d), got {reference.shape}")
    triangles = _check_triangles(triangles, reference.shape[0])
    p = reference[triangles]
    D = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], axis=-1)  # (M, d, 2)
    d = reference.shape[1]
    if d == 2:
        basis = np.broadcast_to(_I2, (len(triangles), 2, 2)).copy()
    else:
        n = np.cross(D[:, :, 0], D[:, :, 1])
        t1 = D[:, :, 0] / np.linalg.norm(D[:, :, 0], axis=-1, keepdims=True)
        n_norm = np.linalg.norm(n, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            t2 = np.cross(n / n_norm, t1)
        basis = np.stack([t1, t2], axis=-1)
    G = np.einsum("mdi,mdj->mij", basis, D)
    det = np.linalg.det(G) if len(G) else np.zeros(0)
    scale = np.einsum("mdi,mdi->m", D, D)
    bad = ~(np.abs(det) > 1e-12 * scale)
    if np.any(bad):
        raise ValueError(
            f"{int(bad.sum())} reference triangle(s) are degenerate (zero area), "
            f"first is triangle {int(np.flatnonzero(bad)[0])}"
        )
    return basis, G


def deformation_gradient(
    reference: FloatArray, current: FloatArray, triangles: IntArray
) -> FloatArray:
    """In-plane deformation map ``F = [d1 d2] G^-1`` of each triangle.

    Parameters
    ----------
    reference : (N, d) float
        Reference positions, d = 2 or 3.
    current : (..., N, d) float
        Current positions; leading axes (e.g. frames) are kept.
    triangles : (M, 3) int

    Returns
    -------
    F : (..., M, d, 2) float
        Maps reference tangent coordinates to current positions.  For planar
        input ``F = I + grad u``.

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    >>> deformation_gradient(X, 1.5 * X, np.array([[0, 1, 2]]))[0]
    array([[1.5, 0. ],
           [0. , 1.5]])
    """
    reference = _check_points(reference, "reference")
    current = _check_points(current, "current")
    if current.shape[-2:] != reference.shape:
        raise ValueError(
            f"current must have shape (..., {reference.shape[0]}, {reference.shape[1]}), "
            f"got {current.shape}"
        )
    _, G = reference_frames(reference, triangles)
    Ginv = np.linalg.inv(G)
    q = current[..., triangles, :]  # (..., M, 3, d)
    d = np.stack([q[..., 1, :] - q[..., 0, :], q[..., 2, :] - q[..., 0, :]], axis=-1)
    return d @ Ginv


def right_cauchy_green(F: FloatArray) -> FloatArray:
    """``C = F^T F``, shape ``(..., 2, 2)``."""
    F = np.asarray(F, dtype=float)
    return np.einsum("...ki,...kj->...ij", F, F)


def green_lagrange(F: FloatArray) -> FloatArray:
    """Green-Lagrange strain ``E = (F^T F - I) / 2``, shape ``(..., 2, 2)``.

    Components are in the reference tangent basis (global x, y for 2D input).
    See Holzapfel (2000), eq. 2.67.
    """
    return 0.5 * (right_cauchy_green(F) - _I2)


def area_ratio(F: FloatArray) -> FloatArray:
    """Area ratio ``J = sqrt(det(F^T F))`` (current / reference area), shape ``(...)``."""
    C = right_cauchy_green(F)
    det = C[..., 0, 0] * C[..., 1, 1] - C[..., 0, 1] * C[..., 1, 0]
    return np.sqrt(np.maximum(det, 0.0))


def euler_almansi(F: FloatArray) -> FloatArray:
    """Euler-Almansi strain ``e = F^+T E F^+`` in current coordinates (NaN where F is).

    For 2D input this is the classical ``e = (I - (F F^T)^-1) / 2``; for a membrane
    in 3D (``F`` of shape ``(3, 2)``) the pseudo-inverse gives the in-plane
    tensor embedded in 3D.

    Returns
    -------
    e : (..., d, d) float
    """
    F = np.asarray(F, dtype=float)
    lost = np.isnan(F).any(axis=(-2, -1))
    F = np.where(lost[..., None, None], np.eye(*F.shape[-2:]), F)
    E = green_lagrange(F)
    Fp = np.linalg.pinv(F)  # (..., 2, d)
    e = np.einsum("...ki,...kl,...lj->...ij", Fp, E, Fp)
    e[lost] = np.nan
    return e


def logarithmic_strain(F: FloatArray) -> FloatArray:
    """Material (Hencky) logarithmic strain ``ln U = ln(C) / 2``, shape ``(..., 2, 2)``
    (NaN where F is)."""
    C = right_cauchy_green(F)
    lost = np.isnan(C).any(axis=(-2, -1))
    w, v = np.linalg.eigh(np.where(lost[..., None, None], np.eye(2), C))
    with np.errstate(divide="ignore", invalid="ignore"):
        lw = 0.5 * np.log(w)
    out = np.einsum("...ik,...k,...jk->...ij", v, lw, v)
    out[lost] = np.nan
    return out


def principal_strains(E: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Principal values and directions of a symmetric 2x2 strain tensor.

    Closed form: ``E1,2 = (Exx + Eyy)/2 +- sqrt(((Exx - Eyy)/2)^2 + Exy^2)`` and
    the ``E1`` direction at ``theta = atan2(2 Exy, Exx - Eyy) / 2`` from the x axis.

    Parameters
    ----------
    E : (..., 2, 2) float

    Returns
    -------
    values : (..., 2) float
        ``E1 >= E2``; NaN where ``E`` holds NaN.
    directions : (..., 2, 2) float
        Unit eigenvectors as columns, ``directions[..., :, 0]`` belongs to ``E1``
        and lies at an angle in (-90, 90] degrees from the x axis, in the same
        basis as ``E`` (global x, y for 2D input; multiply by the tangent basis
        of :func:`reference_frames` for 3D vectors).
    """
    E = np.asarray(E, dtype=float)
    a, b, d = E[..., 0, 0], 0.5 * (E[..., 0, 1] + E[..., 1, 0]), E[..., 1, 1]
    mean = 0.5 * (a + d)
    radius = np.hypot(0.5 * (a - d), b)
    theta = 0.5 * np.arctan2(2 * b, a - d)
    theta = np.where(theta <= -np.pi / 2, theta + np.pi, theta)
    c, s = np.cos(theta), np.sin(theta)
    values = np.stack([mean + radius, mean - radius], axis=-1)
    directions = np.stack([np.stack([c, s], axis=-1), np.stack([-s, c], axis=-1)], axis=-1)
    return values, directions


def triangle_normals(points: FloatArray, triangles: IntArray) -> FloatArray:
    """Unit normal ``n = D1 x D2 / |D1 x D2|`` of each triangle in 3D.

    Parameters
    ----------
    points : (..., N, 3) float
    triangles : (M, 3) int

    Returns
    -------
    normals : (..., M, 3) float
        Oriented by the vertex order (counter-clockwise seen from the tip of
        ``n``); NaN for degenerate or lost triangles.
    """
    points = _check_points(points, "points")
    if points.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., N, 3), got {points.shape}")
    triangles = _check_triangles(triangles, points.shape[-2])
    p = points[..., triangles, :]
    n = np.cross(p[..., 1, :] - p[..., 0, :], p[..., 2, :] - p[..., 0, :])
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, n / norm, np.nan)


def _unit(v: np.ndarray) -> np.ndarray:
    """Normalize along the last axis; zero or NaN vectors give NaN."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, v / norm, np.nan)


def _parse_axis(axis, name: str = "axis") -> tuple[np.ndarray, np.ndarray]:
    try:
        point, direction = axis
        point = np.asarray(point, dtype=float)
        direction = np.asarray(direction, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(
            f"{name} must be a pair (point, direction) of 3-vectors, got {axis!r}"
        ) from None
    if point.shape != (3,) or direction.shape != (3,):
        raise ValueError(
            f"{name} must be a pair (point, direction) of 3-vectors, "
            f"got shapes {point.shape} and {direction.shape}"
        )
    norm = np.linalg.norm(direction)
    if not (np.all(np.isfinite(point)) and np.isfinite(norm) and norm > 0):
        raise ValueError(f"{name} needs a finite point and a finite non-zero direction")
    return point, direction / norm


def cylindrical_directions(
    points: FloatArray, *, axis: tuple[Sequence[float], Sequence[float]]
) -> FloatArray:
    """Axial and circumferential unit vectors about an axis.

    ``e1 = a`` (the axis direction) and ``e2 = a x r / |a x r|`` with ``r`` the
    vector from the axis point to the point: the right-handed circumferential
    direction.  On a surface of revolution about the axis (a tube) ``e2`` is
    tangent to the surface and ``e1`` projects onto its meridian; on a cylinder
    both are tangent.  Pass the result, or ``directions="cylindrical"`` with the
    same ``axis``, to :func:`surface_strain.compute_strain`.

    Parameters
    ----------
    points : (K, 3) float
        Where to evaluate the frame (e.g. reference triangle centroids).
    axis : (point, direction), keyword-only
        A point on the axis and its direction, each a 3-vector (any length).

    Returns
    -------
    directions : (K, 2, 3) float
        ``directions[:, 0]`` axial, ``directions[:, 1]`` circumferential; NaN
        for points on the axis, where the circumferential direction is undefined.

    Examples
    --------
    >>> cylindrical_directions(np.array([[2.0, 0.0, 5.0]]), axis=([0, 0, 0], [0, 0, 3]))
    array([[[0., 0., 1.],
            [0., 1., 0.]]])
    """
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (K, 3), got {p.shape}")
    origin, a = _parse_axis(axis)
    circ = _unit(np.cross(a, p - origin))
    return np.stack([np.broadcast_to(a, p.shape), circ], axis=1)


def spherical_directions(
    points: FloatArray,
    normals: FloatArray,
    *,
    axis: tuple[Sequence[float], Sequence[float]],
) -> FloatArray:
    """Meridional and circumferential unit vectors about an axis (polar frame).

    The circumferential direction is ``c = a x r / |a x r|`` (``r`` from the axis
    point to the point) and the meridional direction ``m = c x n / |c x n|``,
    so ``(m, c, n)`` is right-handed.  On any surface of revolution about the
    axis (a dome, a spherical cap, a flat disc normal to the axis) both are
    tangent: ``m`` follows the meridian, pointing away from the pole where
    ``n`` points away from the centre of curvature (outward on a dome whose
    pole lies along ``+a``; ``n = +a`` on a flat disc).  On a flat disc this is
    the polar frame (radial, circumferential).

    Parameters
    ----------
    points : (K, 3) float
        Where to evaluate the frame (e.g. reference triangle centroids).
    normals : (K, 3) float
        Surface normals there (e.g. :func:`triangle_normals`).
    axis : (point, direction), keyword-only
        A point on the axis and its direction, each a 3-vector.

    Returns
    -------
    directions : (K, 2, 3) float
        ``directions[:, 0]`` meridional, ``directions[:, 1]`` circumferential;
        NaN on the axis (the pole) and where ``n`` is circumferential.

    Examples
    --------
    >>> spherical_directions(np.array([[2.0, 0, 0]]), np.array([[0, 0, 1.0]]),
    ...                      axis=([0, 0, 0], [0, 0, 1]))
    array([[[1., 0., 0.],
            [0., 1., 0.]]])
    """
    p = np.asarray(points, dtype=float)
    n = np.asarray(normals, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must have shape (K, 3), got {p.shape}")
    if n.shape != p.shape:
        raise ValueError(f"normals must have shape {p.shape}, got {n.shape}")
    origin, a = _parse_axis(axis)
    circ = _unit(np.cross(a, p - origin))
    merid = _unit(np.cross(circ, n))
    return np.stack([merid, circ], axis=1)


def material_frame(
    basis: FloatArray,
    directions: Sequence[Sequence[float]] | FloatArray | None = None,
) -> FloatArray:
    """Orthonormal frame of each triangle built from two material directions.

    The first direction is projected onto the triangle's reference tangent
    plane and normalized (``e1``); the second is projected, made orthogonal to
    ``e1`` (Gram-Schmidt) and normalized (``e2``).

    Parameters
    ----------
    basis : (M, d, 2) float
        Tangent bases from :func:`reference_frames`.
    directions : (2, d) or (M, 2, d) float, optional
        Two material directions, the same for every triangle or one pair per
        triangle (e.g. from :func:`cylindrical_directions` at the centroids).
        Default global X and Y.

    Returns
    -------
    frame : (M, d, 2) float
        Columns ``e1, e2`` as vectors in space.

    Raises
    ------
    ValueError
        If a direction is not finite, is normal to a triangle's tangent plane
        (in-plane component below :data:`DIRECTION_TOLERANCE` of its length),
        or the two are parallel once projected.  The message names the first
        triangle concerned.  There is no silent fallback: pick directions
        with an in-plane component everywhere, or per-triangle directions.
    """
    basis = np.asarray(basis, dtype=float)
    if basis.ndim != 3 or basis.shape[2] != 2 or basis.shape[1] not in (2, 3):
        raise ValueError(f"basis must have shape (M, d, 2), got {basis.shape}")
    m, d = basis.shape[:2]
    if directions is None:
        directions = np.eye(d)[:2]
    a = np.asarray(directions, dtype=float)
    if a.shape not in ((2, d), (m, 2, d)):
        raise ValueError(f"directions must have shape (2, {d}) or ({m}, 2, {d}), got {a.shape}")
    a = np.broadcast_to(a, (m, 2, d))
    length = np.linalg.norm(a, axis=-1)  # (M, 2)
    _check_frame(~np.all(np.isfinite(a), axis=(1, 2)), "directions are not finite")
    _check_frame(~np.all(length > 0, axis=1), "a direction has zero length")
    local = np.einsum("mdi,mkd->mki", basis, a)  # (M, 2 directions, 2 tangent comps)
    n1 = np.linalg.norm(local[:, 0], axis=-1)
    _check_frame(
        n1 < DIRECTION_TOLERANCE * length[:, 0],
        "the first direction is normal to the tangent plane",
    )
    e1 = local[:, 0] / n1[:, None]
    e2 = local[:, 1] - np.sum(local[:, 1] * e1, axis=-1, keepdims=True) * e1
    n2 = np.linalg.norm(e2, axis=-1)
    _check_frame(
        n2 < DIRECTION_TOLERANCE * length[:, 1],
        "the two directions are parallel (or the second is normal) in the tangent plane",
    )
    e2 = e2 / n2[:, None]
    return np.einsum("mdi,mik->mdk", basis, np.stack([e1, e2], axis=-1))


def _check_frame(bad: np.ndarray, what: str) -> None:
    if np.any(bad):
        raise ValueError(
            f"{what} of {int(bad.sum())} triangle(s), first is triangle "
            f"{int(np.flatnonzero(bad)[0])}; choose directions with an in-plane "
            "component on every triangle"
        )


def directional_components(
    E: FloatArray,
    basis: FloatArray,
    directions: Sequence[Sequence[float]] | FloatArray | None = None,
) -> FloatArray:
    """Rotate ``E`` into a frame built from material directions.

    The frame is that of :func:`material_frame`: the first direction projected
    onto each reference tangent plane (``e1``), the second projected and made
    orthogonal to it (``e2``).  The result holds ``[[Exx, Exy], [Exy, Eyy]]``
    with ``Exx = e1 . E e1``, ``Eyy = e2 . E e2``, ``Exy = e1 . E e2`` (tensor,
    not engineering, shear).  On a planar surface with the default directions
    (global X and Y) this returns ``E`` unchanged.

    Parameters
    ----------
    E : (..., M, 2, 2) float
        Strain in the tangent basis of :func:`reference_frames`.
    basis : (M, d, 2) float
        Tangent bases from :func:`reference_frames`.
    directions : (2, d) or (M, 2, d) float, optional
        Material directions, constant or one pair per triangle; default global
        X and Y.

    Returns
    -------
    E_dir : (..., M, 2, 2) float

    Raises
    ------
    ValueError
        If a direction is (nearly) normal to a triangle, or the two directions
        are (nearly) parallel once projected (see :func:`material_frame`).
    """
    basis = np.asarray(basis, dtype=float)
    frame = material_frame(basis, directions)
    R = np.einsum("mdi,mdk->mik", basis, frame)  # columns: e1, e2 in tangent coordinates
    return np.einsum("mki,...mkl,mlj->...mij", R, E, R)


class PrincipalDirections(NamedTuple):
    """Principal strain directions as unit vectors in space.

    Each field has shape ``(..., d)`` (``(T, M, d)`` per triangle, ``(T, N, d)``
    per node); NaN where the strain is unknown.  ``dir1`` belongs to ``E1``
    (the larger principal strain) and ``dir2`` to ``E2``.
    """

    #: ``E1`` direction in the reference configuration (a material direction)
    dir1_ref: FloatArray
    #: ``E2`` direction in the reference configuration, ``n x dir1_ref``
    dir2_ref: FloatArray
    #: ``E1`` direction in the current configuration, ``F dir1 / |F dir1|``
    dir1_cur: FloatArray
    #: ``E2`` direction in the current configuration, ``F dir2 / |F dir2|``
    dir2_cur: FloatArray


def principal_directions(
    E: FloatArray,
    F: FloatArray,
    basis: FloatArray,
    *,
    frame: FloatArray | None = None,
) -> PrincipalDirections:
    """Principal strain directions as vectors, before and after deformation.

    With ``v1, v2`` the unit eigenvectors of ``E`` in the tangent coordinates of
    each triangle, the reference directions are ``basis @ v`` and the current
    ones ``F @ v / |F @ v|``.  Because ``v1, v2`` are eigenvectors of
    ``C = F^T F``, ``F v1`` and ``F v2`` are orthogonal as well: the principal
    axes of stretch stay orthogonal (Holzapfel 2000, sec. 2.6).

    Sign conventions (a direction is an axis; these fix its sign):
    ``dir1_ref`` makes an angle in (-90, 90] degrees with the frame's first
    axis ``e1`` (as ``theta1_deg`` of :func:`surface_strain.scalar_fields`), and
    ``dir2_ref = n x dir1_ref`` with ``n = t1 x t2`` the triangle's reference
    normal (the global z axis for 2D input), so ``(dir1, dir2, n)`` is
    right-handed.  The current directions are the images of these, so
    ``(dir1_cur, dir2_cur, n_cur)`` is right-handed for ``J > 0``.

    Parameters
    ----------
    E : (..., M, 2, 2) float
        Green-Lagrange strain in the coordinates of ``frame``.
    F : (..., M, d, 2) float
        Deformation map in the coordinates of ``basis`` (as from
        :func:`deformation_gradient`).
    basis : (M, d, 2) float
        Tangent bases from :func:`reference_frames`.
    frame : (M, d, 2) float, optional, keyword-only
        The frame ``E`` is expressed in (:func:`material_frame`, or
        ``StrainField.frame``).  Default ``basis`` (``E = green_lagrange(F)``).

    Returns
    -------
    PrincipalDirections
        ``(dir1_ref, dir2_ref, dir1_cur, dir2_cur)``, each ``(..., M, d)``
        unit vectors; NaN where ``E`` or ``F`` holds NaN.  Where ``E1 = E2``
        (isotropic strain, rigid motion) every direction is principal and the
        returned pair is an arbitrary orthonormal one.

    Examples
    --------
    >>> X = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    >>> x = X @ np.array([[1.0, 0.0], [0.0, 1.5]]).T   # stretch along y
    >>> F = deformation_gradient(X, x, np.array([[0, 1, 2]]))
    >>> basis, _ = reference_frames(X, np.array([[0, 1, 2]]))
    >>> principal_directions(green_lagrange(F), F, basis).dir1_ref.round(6)
    array([[0., 1.]])
    """
    basis = np.asarray(basis, dtype=float)
    F = np.asarray(F, dtype=float)
    R = _I2 if frame is None else np.einsum("mdi,mdk->mik", basis, np.asarray(frame, float))
    _, vectors = principal_strains(E)
    v1 = np.einsum("...ik,...k->...i", R, vectors[..., :, 0])  # tangent coordinates
    v2 = np.stack([-v1[..., 1], v1[..., 0]], axis=-1)  # n x v1 in the tangent plane
    dir1_ref = np.einsum("mdi,...mi->...md", basis, v1)
    dir2_ref = np.einsum("mdi,...mi->...md", basis, v2)
    dir1_cur = _unit(np.einsum("...di,...i->...d", F, v1))
    dir2_cur = _unit(np.einsum("...di,...i->...d", F, v2))
    return PrincipalDirections(dir1_ref, dir2_ref, dir1_cur, dir2_cur)
