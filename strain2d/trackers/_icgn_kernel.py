"""Compiled IC-GN (numba): the same iteration as ``dic._Correlator.match``, fused per point.

One pass per point and iteration computes the warped subset coordinates,
evaluates the cubic B-spline (mirror boundaries, as ``scipy.ndimage`` with
``mode="mirror"``), the ZNSSD residual, the Gauss-Newton step and the
inverse-compositional update; points run in parallel.  ``dic`` uses it when
numba is importable and checks it against the NumPy implementation in the
tests.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange


@njit(cache=True, inline="always")
def _mirror(k: int, n: int) -> int:
    if k < 0:
        k = -k
    if k > n - 1:
        k = 2 * (n - 1) - k
    return min(max(k, 0), n - 1)


@njit(cache=True, inline="always")
def _bspline(c: np.ndarray, x: float, y: float) -> float:
    h, w = c.shape
    ix = int(np.floor(x))
    iy = int(np.floor(y))
    tx = x - ix
    ty = y - iy
    wx0 = (1 - tx) ** 3 / 6
    wx1 = (3 * tx**3 - 6 * tx**2 + 4) / 6
    wx2 = (-3 * tx**3 + 3 * tx**2 + 3 * tx + 1) / 6
    wx3 = tx**3 / 6
    wy0 = (1 - ty) ** 3 / 6
    wy1 = (3 * ty**3 - 6 * ty**2 + 4) / 6
    wy2 = (-3 * ty**3 + 3 * ty**2 + 3 * ty + 1) / 6
    wy3 = ty**3 / 6
    x0 = _mirror(ix - 1, w)
    x1 = _mirror(ix, w)
    x2 = _mirror(ix + 1, w)
    x3 = _mirror(ix + 2, w)
    total = 0.0
    for dy in range(4):
        wy = wy0 if dy == 0 else (wy1 if dy == 1 else (wy2 if dy == 2 else wy3))
        row = _mirror(iy - 1 + dy, h)
        total += wy * (wx0 * c[row, x0] + wx1 * c[row, x1] + wx2 * c[row, x2] + wx3 * c[row, x3])
    return total


@njit(cache=True, inline="always")
def _residual(coeff, cx, cy, p, ex, ey, f_row, norm_i, G_row, g, b):
    """Sample the warped subset into ``g``, set ``b = G (f - g_normalized) norm``.

    The warp is affine for ``len(p) == 6`` and quadratic for 12.  Returns the
    ZNCC, or -2 where the warped subset is flat (no texture).
    """
    s2 = g.shape[0]
    quadratic = p.shape[0] == 12
    mean = 0.0
    for j in range(s2):
        x = cx + p[0] + (1 + p[2]) * ex[j] + p[3] * ey[j]
        y = cy + p[1] + p[4] * ex[j] + (1 + p[5]) * ey[j]
        if quadratic:
            qx = 0.5 * ex[j] * ex[j]
            qxy = ex[j] * ey[j]
            qy = 0.5 * ey[j] * ey[j]
            x += p[6] * qx + p[7] * qxy + p[8] * qy
            y += p[9] * qx + p[10] * qxy + p[11] * qy
        g[j] = _bspline(coeff, x, y)
        mean += g[j]
    mean /= s2
    ss = 0.0
    for j in range(s2):
        g[j] -= mean
        ss += g[j] * g[j]
    if ss < 1e-18:
        return -2.0
    gnorm = np.sqrt(ss)
    dist = 0.0
    b[:] = 0.0
    for j in range(s2):
        d = f_row[j] - g[j] / gnorm
        dist += d * d
        r = d * norm_i
        for k in range(b.shape[0]):
            b[k] += G_row[k, j] * r
    return 1.0 - 0.5 * dist


@njit(cache=True, parallel=True)
def icgn(
    coeff: np.ndarray,
    centers: np.ndarray,
    f: np.ndarray,
    norm: np.ndarray,
    G: np.ndarray,
    p0: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    half: int,
    tolerance: float,
    max_iterations: int,
    zncc_min: float,
):
    """IC-GN for every row; returns (p (n, 6), zncc (n,), converged (n,))."""
    n, s2 = f.shape
    p_out = p0.copy()
    zncc_out = np.full(n, -1.0)
    conv_out = np.zeros(n, dtype=np.bool_)
    for i in prange(n):
        p = p_out[i].copy()
        g = np.empty(s2)
        b = np.empty(6)
        cx = centers[i, 0]
        cy = centers[i, 1]
        for iteration in range(max_iterations):
            zncc = _residual(coeff, cx, cy, p, ex, ey, f[i], norm[i], G[i], g, b)
            if zncc == -2.0:
                zncc_out[i] = -1.0
                break
            zncc_out[i] = zncc
            b0, b1, b2, b3, b4, b5 = b[0], b[1], b[2], b[3], b[4], b[5]
            # dp = -b; W(p) <- W(p) o W(dp)^-1
            a, bb, c, dd = 1 - b2, -b3, -b4, 1 - b5
            det = a * dd - bb * c
            if not np.isfinite(det) or abs(det) < 1e-12:
                break
            ia, ib, ic, idd = dd / det, -bb / det, -c / det, a / det
            itx = -(ia * -b0 + ib * -b1)
            ity = -(ic * -b0 + idd * -b1)
            m00, m01, m02 = 1 + p[2], p[3], p[0]
            m10, m11, m12 = p[4], 1 + p[5], p[1]
            p[0] = m00 * itx + m01 * ity + m02
            p[1] = m10 * itx + m11 * ity + m12
            p[2] = m00 * ia + m01 * ic - 1
            p[3] = m00 * ib + m01 * idd
            p[4] = m10 * ia + m11 * ic
            p[5] = m10 * ib + m11 * idd - 1
            step = np.sqrt(
                b0 * b0 + b1 * b1 + half * half * (b2 * b2 + b3 * b3 + b4 * b4 + b5 * b5)
            )
            finite = np.isfinite(step)
            for k in range(6):
                finite = finite and np.isfinite(p[k])
            wild = False
            for k in range(2, 6):
                wild = wild or abs(p[k]) > 2.0
            if not finite or wild:
                break
            if step < tolerance:
                conv_out[i] = True
                break
            if iteration >= 7 and zncc < zncc_min:
                break
        for k in range(6):
            p_out[i, k] = p[k] if np.isfinite(p[k]) else 0.0
    return p_out, zncc_out, conv_out


@njit(cache=True, inline="always")
def _matrix2(p: np.ndarray) -> np.ndarray:
    """6 x 6 matrix of a second-order warp (see ``dic._matrix2``)."""
    u, v, ux, uy, vx, vy = p[0], p[1], p[2], p[3], p[4], p[5]
    uxx, uxy, uyy, vxx, vxy, vyy = p[6], p[7], p[8], p[9], p[10], p[11]
    a1, a2, b1, b2 = 1 + ux, uy, vx, 1 + vy
    M = np.zeros((6, 6))
    M[0, 0] = a1 * a1 + u * uxx
    M[0, 1] = 2 * a1 * a2 + 2 * u * uxy
    M[0, 2] = a2 * a2 + u * uyy
    M[0, 3] = 2 * u * a1
    M[0, 4] = 2 * u * a2
    M[0, 5] = u * u
    M[1, 0] = a1 * b1 + 0.5 * (u * vxx + v * uxx)
    M[1, 1] = a1 * b2 + a2 * b1 + u * vxy + v * uxy
    M[1, 2] = a2 * b2 + 0.5 * (u * vyy + v * uyy)
    M[1, 3] = u * b1 + v * a1
    M[1, 4] = u * b2 + v * a2
    M[1, 5] = u * v
    M[2, 0] = b1 * b1 + v * vxx
    M[2, 1] = 2 * b1 * b2 + 2 * v * vxy
    M[2, 2] = b2 * b2 + v * vyy
    M[2, 3] = 2 * v * b1
    M[2, 4] = 2 * v * b2
    M[2, 5] = v * v
    M[3, 0] = 0.5 * uxx
    M[3, 1] = uxy
    M[3, 2] = 0.5 * uyy
    M[3, 3] = a1
    M[3, 4] = a2
    M[3, 5] = u
    M[4, 0] = 0.5 * vxx
    M[4, 1] = vxy
    M[4, 2] = 0.5 * vyy
    M[4, 3] = b1
    M[4, 4] = b2
    M[4, 5] = v
    M[5, 5] = 1.0
    return M


@njit(cache=True, parallel=True)
def icgn2(
    coeff: np.ndarray,
    centers: np.ndarray,
    f: np.ndarray,
    norm: np.ndarray,
    G: np.ndarray,
    p0: np.ndarray,
    ex: np.ndarray,
    ey: np.ndarray,
    half: int,
    tolerance: float,
    max_iterations: int,
    zncc_min: float,
):
    """IC-GN with the second-order shape function (12 parameters), as :func:`icgn`."""
    n, s2 = f.shape
    p_out = p0.copy()
    zncc_out = np.full(n, -1.0)
    conv_out = np.zeros(n, dtype=np.bool_)
    for i in prange(n):
        p = p_out[i].copy()
        g = np.empty(s2)
        b = np.empty(12)
        cx = centers[i, 0]
        cy = centers[i, 1]
        for iteration in range(max_iterations):
            zncc = _residual(coeff, cx, cy, p, ex, ey, f[i], norm[i], G[i], g, b)
            if zncc == -2.0:
                zncc_out[i] = -1.0
                break
            zncc_out[i] = zncc
            dp = -b
            Md = _matrix2(dp)
            if not np.all(np.isfinite(Md)):
                break
            M = _matrix2(p) @ np.linalg.inv(Md)
            p[0], p[1] = M[3, 5], M[4, 5]
            p[2], p[3], p[4], p[5] = M[3, 3] - 1, M[3, 4], M[4, 3], M[4, 4] - 1
            p[6], p[7], p[8] = 2 * M[3, 0], M[3, 1], 2 * M[3, 2]
            p[9], p[10], p[11] = 2 * M[4, 0], M[4, 1], 2 * M[4, 2]
            first = dp[2] ** 2 + dp[3] ** 2 + dp[4] ** 2 + dp[5] ** 2
            second = 0.0
            for k in range(6, 12):
                second += dp[k] ** 2
            step = np.sqrt(dp[0] ** 2 + dp[1] ** 2 + half * half * first + 0.25 * half**4 * second)
            finite = np.isfinite(step)
            for k in range(12):
                finite = finite and np.isfinite(p[k])
            wild = False
            for k in range(2, 6):
                wild = wild or abs(p[k]) > 2.0
            if not finite or wild:
                break
            if step < tolerance:
                conv_out[i] = True
                break
            if iteration >= 7 and zncc < zncc_min:
                break
        for k in range(12):
            p_out[i, k] = p[k] if np.isfinite(p[k]) else 0.0
    return p_out, zncc_out, conv_out
