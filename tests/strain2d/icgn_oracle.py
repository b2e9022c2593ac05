"""Test oracle for the compiled IC-GN kernel: the same iteration in vectorized NumPy.

:func:`match_numpy` runs IC-GN for many points at once with NumPy arrays and
``scipy.ndimage.map_coordinates``, so the numba kernel
(:func:`strain2d.trackers._icgn_kernel.icgn`) can be checked against it on
known inputs. It is slower and only the tests use it.

The affine warp is composed here independently, as 3 x 3 matrices; the
second-order warp uses the kernel's own 6 x 6 matrix form
(:func:`strain2d.trackers._icgn_kernel._matrix2`), row by row, so that the
formula exists once (the tests check that form on its own).
"""

from __future__ import annotations

import numpy as np

from strain2d.trackers._icgn_kernel import _matrix2, _params2
from strain2d.trackers.dic import _Correlator, _sample, _Subsets, _warp


def matrix(p: np.ndarray) -> np.ndarray:
    """Affine warps ``(n, 3, 3)`` from parameters ``(n, 6)``."""
    M = np.zeros((len(p), 3, 3))
    M[:, 0] = np.stack([1 + p[:, 2], p[:, 3], p[:, 0]], axis=-1)
    M[:, 1] = np.stack([p[:, 4], 1 + p[:, 5], p[:, 1]], axis=-1)
    M[:, 2, 2] = 1.0
    return M


def params(M: np.ndarray) -> np.ndarray:
    """Affine parameters ``(n, 6)`` from warps ``(n, 3, 3)``."""
    return np.stack(
        [M[:, 0, 2], M[:, 1, 2], M[:, 0, 0] - 1, M[:, 0, 1], M[:, 1, 0], M[:, 1, 1] - 1], axis=-1
    )


def matrix2(p: np.ndarray) -> np.ndarray:
    """Second-order warps ``(n, 6, 6)`` from parameters ``(n, 12)`` (the kernel's form)."""
    return np.stack([_matrix2(np.ascontiguousarray(row, dtype=np.float64)) for row in p])


def params2(M: np.ndarray) -> np.ndarray:
    """Second-order parameters ``(n, 12)`` from warps ``(n, 6, 6)``."""
    p = np.empty((len(M), 12))
    for row, matrix_ in zip(p, M, strict=True):
        _params2(np.ascontiguousarray(matrix_), row)
    return p


def compose_inverse(p: np.ndarray, dp: np.ndarray) -> np.ndarray:
    """``W(p) o W(dp)^-1`` for warps ``(n, 6)`` or ``(n, 12)``."""
    if p.shape[1] == 6:
        return params(matrix(p) @ np.linalg.inv(matrix(dp)))
    return params2(matrix2(p) @ np.linalg.inv(matrix2(dp)))


def match_numpy(
    corr: _Correlator,
    coefficients: np.ndarray,
    ref: _Subsets,
    idx: np.ndarray,
    p0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IC-GN for points ``idx`` from warps ``p0`` ``(len(idx), corr.n_params)``.

    Returns ``(p, zncc, converged)`` as :meth:`strain2d.trackers.dic._Correlator.match`:
    ``zncc`` is measured at the last iterate before the final (sub-tolerance)
    update, and a point whose correlation is still below ``zncc_min`` after 8
    iterations is abandoned.
    """
    p = np.array(p0, dtype=np.float64)
    f, G, norm, centers = ref.f[idx], ref.G[idx], ref.norm[idx], ref.centers[idx]
    active = np.arange(len(idx))
    converged = np.zeros(len(idx), dtype=bool)
    zncc = np.full(len(idx), -1.0)
    h = corr.half
    for iteration in range(corr.max_iterations):
        if active.size == 0:
            break
        pa = p[active]
        x, y = _warp(centers[active], pa, corr.ex, corr.ey)
        g = _sample(coefficients, x, y)
        gm = g - g.mean(axis=1, keepdims=True)
        gnorm = np.sqrt(np.sum(gm**2, axis=1, keepdims=True))
        flat = gnorm[:, 0] < 1e-9
        gnorm[flat] = 1.0
        gn = gm / gnorm
        fa = f[active]
        za = np.where(flat, -1.0, 1.0 - 0.5 * np.sum((fa - gn) ** 2, axis=1))
        zncc[active] = za
        r = (fa - gn) * norm[active]  # ZNSSD residual, f's scale
        dp = -(G[active] @ r[..., None])[..., 0]
        p[active] = compose_inverse(pa, dp)
        # largest move of a subset pixel (first-order terms at the edge, second-order
        # terms at the corner)
        step = np.sqrt(
            dp[:, 0] ** 2
            + dp[:, 1] ** 2
            + np.sum((h * dp[:, 2:6]) ** 2, axis=1)
            + np.sum((0.5 * h * h * dp[:, 6:]) ** 2, axis=1)
        )
        finite = np.isfinite(step) & np.isfinite(p[active]).all(axis=1)
        done = finite & (step < corr.tolerance)
        failed = ~finite | (np.abs(p[active, 2:6]) > 2.0).any(axis=1)
        if iteration >= 7:
            failed |= za < corr.zncc_min
        converged[active[done & ~failed]] = True
        active = active[~(done | failed)]
    return np.nan_to_num(p), zncc, converged
