"""Per-triangle values averaged to the nodes.

Nodal value = area-weighted mean of the adjacent triangles (the approach of
the source paper).  Triangles whose value is NaN (lost points, masks) are left
out of the average instead of spreading NaN to their neighbours; a node with
no valid adjacent triangle gets NaN.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from surface_strain._typing import FloatArray, IntArray

__all__ = ["nodal_average"]


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
