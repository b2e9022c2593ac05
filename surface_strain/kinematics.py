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

import numpy as np

from surface_strain._typing import FloatArray, IntArray

__all__ = [
    "area_ratio",
    "deformation_gradient",
    "directional_components",
    "euler_almansi",
    "green_lagrange",
    "logarithmic_strain",
    "principal_strains",
    "reference_frames",
    "right_cauchy_green",
    "triangle_areas",
]

_I2 = np.eye(2)


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


def directional_components(
    E: FloatArray,
    basis: FloatArray,
    directions: Sequence[Sequence[float]] | FloatArray | None = None,
) -> FloatArray:
    """Rotate ``E`` into a frame built from material directions.

    The first direction is projected onto each reference tangent plane and
    normalized (``e1``); the second is projected, made orthogonal to ``e1`` and
    normalized (``e2``).  The result holds ``[[Exx, Exy], [Exy, Eyy]]`` in the
    ``(e1, e2)`` frame.  On a planar surface with the default directions (global
    X and Y) this returns ``E`` unchanged.

    Parameters
    ----------
    E : (..., M, 2, 2) float
        Strain in the tangent basis of :func:`reference_frames`.
    basis : (M, d, 2) float
        Tangent bases from :func:`reference_frames`.
    directions : (2, d) float, optional
        Material directions, default global X and Y.

    Returns
    -------
    E_dir : (..., M, 2, 2) float

    Raises
    ------
    ValueError
        If a direction is (nearly) normal to a triangle, or the two directions
        are (nearly) parallel once projected.
    """
    basis = np.asarray(basis, dtype=float)
    d = basis.shape[1]
    if directions is None:
        directions = np.eye(d)[:2]
    a = np.asarray(directions, dtype=float)
    if a.shape != (2, d):
        raise ValueError(f"directions must have shape (2, {d}), got {a.shape}")
    local = np.einsum("mdi,kd->mki", basis, a)  # (M, 2 directions, 2 local comps)
    n1 = np.linalg.norm(local[:, 0], axis=-1, keepdims=True)
    if np.any(n1 < 1e-8 * np.linalg.norm(a[0])):
        raise ValueError("the first direction is normal to at least one triangle")
    e1 = local[:, 0] / n1
    e2 = local[:, 1] - np.sum(local[:, 1] * e1, axis=-1, keepdims=True) * e1
    n2 = np.linalg.norm(e2, axis=-1, keepdims=True)
    if np.any(n2 < 1e-8 * np.linalg.norm(a[1])):
        raise ValueError("the two directions are parallel on at least one triangle")
    e2 = e2 / n2
    R = np.stack([e1, e2], axis=-1)  # (M, 2, 2), columns e1, e2
    return np.einsum("mki,...mkl,mlj->...mij", R, E, R)
