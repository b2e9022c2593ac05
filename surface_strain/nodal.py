"""Per-triangle values averaged to the nodes.

Nodal value = area-weighted mean of the adjacent triangles (the approach of
the source paper).  Triangles whose value is NaN (lost points, masks) are left
out of the average instead of spreading NaN to their neighbours; a node with
no valid adjacent triangle gets NaN.

Directions are axes (``v`` and ``-v`` are the same principal direction), so
:func:`nodal_axes` aligns their signs before averaging.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from surface_strain._typing import FloatArray, IntArray

__all__ = ["nodal_average", "nodal_axes"]


def nodal_average(
    values: FloatArray,
    triangles: IntArray,
    n_points: int,
    *,
    weights: FloatArray | None = None,
    axis: int = 0,
) -> FloatArray:
    """Average per-triangle values onto the nodes.

    Parameters
    ----------
    values : float array with a triangle axis of length M
        E.g. ``(M,)``, ``(M, 2, 2)`` with ``axis=0`` or ``(T, M, 2, 2)`` with
        ``axis=1``.  Other axes are kept.
    triangles : (M, 3) int
    n_points : int
        Number of nodes N.
    weights : (M,) float, optional, keyword-only
        Triangle weights, typically reference areas.  Default: equal weights.
    axis : int, keyword-only
        The triangle axis of ``values``.

    Returns
    -------
    nodal : float array, ``values.shape`` with the triangle axis replaced by N

    Examples
    --------
    >>> import numpy as np
    >>> tri = np.array([[0, 1, 2], [1, 3, 2]])
    >>> nodal_average(np.array([1.0, 3.0]), tri, 4, weights=np.array([1.0, 3.0]))
    array([1. , 2.5, 2.5, 3. ])
    """
    triangles = np.asarray(triangles)
    m = len(triangles)
    values = np.asarray(values, dtype=float)
    if values.ndim == 0 or values.shape[axis] != m:
        raise ValueError(f"values must have length M={m} along axis {axis}, got {values.shape}")
    w = np.ones(m) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (m,):
        raise ValueError(f"weights must have shape ({m},), got {w.shape}")
    rows = triangles.ravel()
    cols = np.repeat(np.arange(m), 3)
    A = sp.csr_matrix((np.repeat(w, 3), (rows, cols)), shape=(n_points, m))
    v = np.moveaxis(values, axis, 0)  # (M, ...)
    rest = v.shape[1:]
    v = v.reshape(m, -1)
    valid = np.isfinite(v)
    num = A @ np.where(valid, v, 0.0)
    den = A @ valid.astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)
    return np.moveaxis(out.reshape((n_points, *rest)), 0, axis)


def _corner_sum(values: np.ndarray, triangles: np.ndarray, n_points: int) -> np.ndarray:
    """Sum per-corner values ``(..., M, 3, k)`` onto the nodes: ``(..., N, k)``."""
    m = len(triangles)
    lead = values.shape[:-3]
    k = values.shape[-1]
    B = sp.csr_matrix(
        (np.ones(3 * m), (triangles.ravel(), np.arange(3 * m))), shape=(n_points, 3 * m)
    )
    v = np.moveaxis(values.reshape((*lead, 3 * m, k)), -2, 0).reshape(3 * m, -1)
    out = (B @ v).reshape((n_points, *lead, k))
    return np.moveaxis(out, 0, -2)


def _triangle_sum(values: np.ndarray, triangles: np.ndarray, n_points: int) -> np.ndarray:
    """Sum per-triangle values ``(..., M, k)`` onto the triangles' nodes: ``(..., N, k)``."""
    m = len(triangles)
    lead = values.shape[:-2]
    k = values.shape[-1]
    A = sp.csr_matrix(
        (np.ones(3 * m), (triangles.ravel(), np.repeat(np.arange(m), 3))), shape=(n_points, m)
    )
    v = np.moveaxis(values, -2, 0).reshape(m, -1)
    return np.moveaxis((A @ v).reshape((n_points, *lead, k)), 0, -2)


def _aligned_axes(
    axes: np.ndarray, triangles: np.ndarray, n_points: int, weights: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sign-aligned weighted sums of triangle axes at the nodes, and the signs used.

    Returns the unnormalized sums ``(..., N, d)`` (NaN where no adjacent
    triangle is valid) and the sign ``+-1`` of each triangle corner ``(..., M, 3)``
    (0 for invalid triangles).
    """
    d = axes.shape[-1]
    valid = np.all(np.isfinite(axes), axis=-1)  # (..., M)
    a = np.where(valid[..., None], axes, 0.0)
    wa = weights[:, None] * a
    tensor = np.einsum("...mi,...mj->...mij", wa, a).reshape((*a.shape[:-1], d * d))
    A = _triangle_sum(tensor, triangles, n_points).reshape((*a.shape[:-2], n_points, d, d))
    _, vecs = np.linalg.eigh(A)
    dominant = vecs[..., :, -1]  # (..., N, d), sign arbitrary
    dots = np.einsum("...mcd,...md->...mc", dominant[..., triangles, :], a)
    signs = np.where(dots < 0, -1.0, 1.0) * valid[..., None]
    total = _corner_sum(signs[..., None] * wa[..., None, :], triangles, n_points)
    count = _triangle_sum((weights * valid)[..., None], triangles, n_points)
    total = np.where(count > 0, total, np.nan)
    return total, signs


def nodal_axes(
    axes: FloatArray,
    triangles: IntArray,
    n_points: int,
    *,
    weights: FloatArray | None = None,
    normals: FloatArray | None = None,
    orient: FloatArray | None = None,
) -> FloatArray:
    """Average per-triangle axes (directions without sign) onto the nodes.

    A direction field such as a principal strain direction is defined up to
    sign, so a plain average of adjacent triangles' vectors can cancel.  At
    each node the adjacent vectors are first aligned with a reference axis,
    the dominant eigenvector ``r`` of the weighted orientation tensor
    ``A = sum_e w_e v_e v_e^T`` (which does not depend on the signs): each
    ``v_e`` is flipped where ``v_e . r < 0``.  The aligned vectors are averaged
    with the weights, projected onto the node's tangent plane (if ``normals``
    are given) and normalized.  The aligned average never vanishes, since its
    component along ``r`` is ``sum_e w_e |v_e . r| > 0``.

    Parameters
    ----------
    axes : (..., M, d) float
        One vector per triangle (any leading axes, e.g. frames).  Non-finite
        vectors (lost triangles) are left out.
    triangles : (M, 3) int
    n_points : int
    weights : (M,) float, optional, keyword-only
        Triangle weights, typically reference areas; default equal weights.
    normals : (..., N, d) float, optional, keyword-only
        Unit normals of the nodes' tangent planes to project the result onto.
    orient : (..., N, d) float, optional, keyword-only
        The result is flipped where it points away from this vector; otherwise
        the sign of each nodal axis is arbitrary.

    Returns
    -------
    nodal : (..., N, d) float
        Unit vectors; NaN at nodes without a valid adjacent triangle.

    Examples
    --------
    >>> import numpy as np
    >>> tri = np.array([[0, 1, 2], [1, 3, 2]])
    >>> v = np.array([[1.0, 0.0], [-1.0, 0.0]])       # the same axis, opposite signs
    >>> nodal_axes(v, tri, 4, orient=np.array([1.0, 0.0]))
    array([[1., 0.],
           [1., 0.],
           [1., 0.],
           [1., 0.]])
    """
    triangles = np.asarray(triangles)
    axes = np.asarray(axes, dtype=float)
    m = len(triangles)
    if axes.ndim < 2 or axes.shape[-2] != m:
        raise ValueError(f"axes must have shape (..., {m}, d), got {axes.shape}")
    w = np.ones(m) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != (m,):
        raise ValueError(f"weights must have shape ({m},), got {w.shape}")
    total, _ = _aligned_axes(axes, triangles, n_points, w)
    if normals is not None:
        n = np.asarray(normals, dtype=float)
        total = total - np.sum(total * n, axis=-1, keepdims=True) * n
    if orient is not None:
        total = np.where(np.sum(total * orient, axis=-1, keepdims=True) < 0, -total, total)
    norm = np.linalg.norm(total, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, total / norm, np.nan)
