"""Compiled IC-GN (numba): the subset matcher behind ``dic._Correlator.match``, fused per point.

One kernel, :func:`icgn`, serves both shape functions; the width of the warp
parameters picks the order (6: affine, first order; 12: quadratic, second
order). One pass per point and iteration computes the warped subset
coordinates, evaluates the cubic B-spline (mirror boundaries, as
``scipy.ndimage`` with ``mode="mirror"``), the ZNSSD residual, the
Gauss-Newton step and the inverse-compositional update; points run in
parallel. The tests check it against a vectorized NumPy oracle
(``tests/strain2d/icgn_oracle.py``).

:func:`prefilter` computes the cubic B-spline coefficients that the kernel
interpolates (rows and columns in parallel; SciPy's filter keeps the GIL).

Only the two innermost helpers (:func:`_mirror`, :func:`_bspline`) are
inlined in numba's IR; inlining the larger ones too gave the same speed and
the same results but took numba four times as long to compile (about 40 s
against 10 s on 2 cores), which every user's first run and every fresh test
worker paid.

References
----------
.. [1] Pan, B., Li, K., & Tong, W. (2013). Fast, robust and accurate digital
   image correlation calculation without redundant computations.
   Experimental Mechanics 53, 1277-1289. https://doi.org/10.1007/s11340-013-9717-6
.. [2] Gao, Y., Cheng, T., Su, Y., Xu, X., Zhang, Y., & Zhang, Q. (2015).
   High-efficiency and high-accuracy digital image correlation for
   three-dimensional measurement. Optics and Lasers in Engineering 65, 73-80.
   https://doi.org/10.1016/j.optlaseng.2014.05.013
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


@njit(cache=True)
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


@njit(cache=True)
def _matrix2(p: np.ndarray) -> np.ndarray:
    """6 x 6 matrix of a second-order warp from its 12 parameters.

    The warp acts on ``(dx^2, dx dy, dy^2, dx, dy, 1)``; rows 3-4 are the exact
    quadratic map and rows 0-2 its products truncated at second order, so that
    composition and inversion are matrix products (Gao et al. 2015 [2]_).
    """
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


@njit(cache=True)
def _params2(M: np.ndarray, p: np.ndarray) -> None:
    """Write the 12 parameters of the second-order warp matrix ``M`` into ``p``."""
    p[0], p[1] = M[3, 5], M[4, 5]
    p[2], p[3], p[4], p[5] = M[3, 3] - 1, M[3, 4], M[4, 3], M[4, 4] - 1
    p[6], p[7], p[8] = 2 * M[3, 0], M[3, 1], 2 * M[3, 2]
    p[9], p[10], p[11] = 2 * M[4, 0], M[4, 1], 2 * M[4, 2]


@njit(cache=True)
def _update_affine(p: np.ndarray, b: np.ndarray) -> bool:
    """``W(p) <- W(p) o W(dp)^-1`` with ``dp = -b`` (affine, closed form), in place.

    Returns False, leaving ``p`` as it was, where ``W(dp)`` is singular.
    """
    b0, b1, b2, b3, b4, b5 = b[0], b[1], b[2], b[3], b[4], b[5]
    a, bb, c, dd = 1 - b2, -b3, -b4, 1 - b5
    det = a * dd - bb * c
    if not np.isfinite(det) or abs(det) < 1e-12:
        return False
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
    return True


@njit(cache=True)
def _update_quadratic(p: np.ndarray, b: np.ndarray) -> bool:
    """As :func:`_update_affine` for the second-order warp (6 x 6 matrix form)."""
    Md = _matrix2(-b)
    if not np.all(np.isfinite(Md)):
        return False
    _params2(_matrix2(p) @ np.linalg.inv(Md), p)
    return True


@njit(cache=True)
def _match_point(
    coeff, cx, cy, p, b, g, ex, ey, f_row, norm_i, G_row, half, tolerance, max_iterations, zncc_min
):
    """IC-GN of one subset, updating its warp ``p`` in place: returns (zncc, converged).

    ``b`` (scratch for the Gauss-Newton step) has as many entries as ``p``: 6
    for the affine warp, 12 for the quadratic one. :func:`icgn` allocates it
    with a constant size in each branch, so each inlined copy of this loop is
    compiled for its own warp order.
    """
    n_params = b.shape[0]
    zncc_last = -1.0
    for iteration in range(max_iterations):
        zncc = _residual(coeff, cx, cy, p, ex, ey, f_row, norm_i, G_row, g, b)
        if zncc == -2.0:
            return -1.0, False
        zncc_last = zncc
        if n_params == 12:
            composed = _update_quadratic(p, b)
        else:
            composed = _update_affine(p, b)
        if not composed:
            break
        # largest move of a subset pixel (first-order terms at the edge, second-order
        # terms at the corner)
        first = b[2] * b[2] + b[3] * b[3] + b[4] * b[4] + b[5] * b[5]
        second = 0.0
        for k in range(6, n_params):
            second += b[k] * b[k]
        step = np.sqrt(b[0] * b[0] + b[1] * b[1] + half * half * first + 0.25 * half**4 * second)
        finite = np.isfinite(step)
        for k in range(n_params):
            finite = finite and np.isfinite(p[k])
        wild = False
        for k in range(2, 6):
            wild = wild or abs(p[k]) > 2.0
        if not finite or wild:
            break
        if step < tolerance:
            return zncc_last, True
        if iteration >= 7 and zncc < zncc_min:
            break
    return zncc_last, False


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
    """IC-GN of every subset against one frame, affine or quadratic.

    Parameters
    ----------
    coeff : (H, W) float
        Cubic B-spline coefficients of the frame (mirror boundaries).
    centers : (n, 2) float
        Reference centre (x, y) of each subset, pixels.
    f : (n, S2) float
        Zero-mean reference subsets divided by their norm (``S2 = len(ex)``).
    norm : (n,) float
        Norm of each zero-mean reference subset.
    G : (n, P, S2) float
        Gauss-Newton step operator ``H^-1 J^T`` of each subset.
    p0 : (n, P) float
        Initial warps; ``P = 6`` selects the affine (first-order) shape
        function, ``P = 12`` the quadratic (second-order) one.
    ex, ey : (S2,) float
        Pixel offsets of the subset from its centre.
    half : int
        Half the subset side, pixels.
    tolerance : (n,) float
        Convergence when the update moves every subset pixel by less (pixels), per
        subset.
    max_iterations : int
    zncc_min : float
        A point still below this correlation after 8 iterations is abandoned.

    Returns
    -------
    p : (n, P) float
        Final warps (non-finite entries set to 0).
    zncc : (n,) float
        ZNCC at the last iterate before the final update; -1 for a flat subset.
    converged : (n,) bool
    """
    n, s2 = f.shape
    n_params = p0.shape[1]
    if n_params != 6 and n_params != 12:
        raise ValueError("p0 must have 6 (affine) or 12 (quadratic) columns")
    if G.shape[1] != n_params:
        raise ValueError("G must have one row per warp parameter (as many as p0 has columns)")
    p_out = p0.copy()
    zncc_out = np.empty(n)
    conv_out = np.zeros(n, dtype=np.bool_)
    for i in prange(n):
        p = p_out[i].copy()
        g = np.empty(s2)
        cx = centers[i, 0]
        cy = centers[i, 1]
        f_row, norm_i, G_row = f[i], norm[i], G[i]
        # one inlined copy of the iteration per order, each with a constant-size step
        if n_params == 12:
            zncc, converged = _match_point(
                coeff, cx, cy, p, np.empty(12), g, ex, ey, f_row, norm_i, G_row,
                half, tolerance[i], max_iterations, zncc_min,
            )  # fmt: skip
        else:
            zncc, converged = _match_point(
                coeff, cx, cy, p, np.empty(6), g, ex, ey, f_row, norm_i, G_row,
                half, tolerance[i], max_iterations, zncc_min,
            )  # fmt: skip
        zncc_out[i] = zncc
        conv_out[i] = converged
        for k in range(n_params):
            p_out[i, k] = p[k] if np.isfinite(p[k]) else 0.0
    return p_out, zncc_out, conv_out


#: the pole of the cubic B-spline's direct filter, and the filter's gain
_POLE = np.sqrt(3.0) - 2.0
_GAIN = (1.0 - _POLE) * (1.0 - 1.0 / _POLE)


@njit(cache=True)
def _causal_start(line: np.ndarray, z: float) -> float:
    """The causal filter's first value for mirror boundaries (exact; SciPy's formula)."""
    n = line.shape[0]
    z_n1 = z ** (n - 1)
    c0 = line[0] + z_n1 * line[n - 1]
    z_i = z
    for i in range(1, n - 1):
        c0 += z_i * (line[i] + z_n1 * line[n - 1 - i])
        z_i *= z
    return c0 / (1.0 - z_n1 * z_n1)


@njit(cache=True, parallel=True)
def prefilter(image: np.ndarray) -> np.ndarray:
    """Cubic B-spline coefficients of ``image`` (mirror boundaries), rows and columns in
    parallel: ``scipy.ndimage.spline_filter(image, order=3, mode="mirror")`` to round-off.

    The direct filter of Unser et al. (one pole ``sqrt(3) - 2``, a causal and an
    anticausal pass) along x on every row, then along y on every column; the
    columns run in blocks of adjacent columns, so each pass reads rows of memory.
    Each line is filtered whole, so the result does not depend on the thread count.
    """
    z = _POLE
    h, w = image.shape
    c = np.empty((h, w))
    for r in prange(h):
        line = c[r]
        gain = _GAIN if w > 1 else 1.0  # a line of one value is left as it is
        for j in range(w):
            line[j] = image[r, j] * gain
        if w > 1:
            line[0] = _causal_start(line, z)
            for j in range(1, w):
                line[j] += z * line[j - 1]
            line[w - 1] = (z * line[w - 2] + line[w - 1]) * z / (z * z - 1.0)
            for j in range(w - 2, -1, -1):
                line[j] = z * (line[j + 1] - line[j])
    if h > 1:  # the columns, a block of adjacent ones at a time, row by row in memory
        block = 64
        z_n1 = z ** (h - 1)
        for b in prange((w + block - 1) // block):
            j0 = b * block
            cols = min(j0 + block, w) - j0
            B = np.empty((h, cols))
            for i in range(h):
                for j in range(cols):
                    B[i, j] = c[i, j0 + j] * _GAIN
            # the causal start of each column (as _causal_start, in the same order)
            start = np.empty(cols)
            for j in range(cols):
                start[j] = B[0, j] + z_n1 * B[h - 1, j]
            z_i = z
            for i in range(1, h - 1):
                for j in range(cols):
                    start[j] += z_i * (B[i, j] + z_n1 * B[h - 1 - i, j])
                z_i *= z
            for j in range(cols):
                B[0, j] = start[j] / (1.0 - z_n1 * z_n1)
            for i in range(1, h):
                for j in range(cols):
                    B[i, j] += z * B[i - 1, j]
            for j in range(cols):
                B[h - 1, j] = (z * B[h - 2, j] + B[h - 1, j]) * z / (z * z - 1.0)
            for i in range(h - 2, -1, -1):
                for j in range(cols):
                    B[i, j] = z * (B[i + 1, j] - B[i, j])
            for i in range(h):
                for j in range(cols):
                    c[i, j0 + j] = B[i, j]
    return c


@njit(cache=True, parallel=True)
def lattice_residual(
    coeff: np.ndarray,
    state: np.ndarray,
    cells: np.ndarray,
    origins: np.ndarray,
    offsets: np.ndarray,
    N: np.ndarray,
    f: np.ndarray,
    mean: float,
    mask: np.ndarray,
    corner: np.ndarray,
    frame_shape: np.ndarray,
):
    """The lattice field's residual at every sampled pixel of every cell, fused.

    Parameters
    ----------
    coeff : (h, w) float
        Cubic B-spline coefficients of the frame, or of the part of it from
        ``corner`` on that holds every position sampled (mirror boundaries).
    state : (nodes, 4) float
        Per node: displacement (u, v), gain and offset.
    cells : (cells, 4) int
        Each cell's corner nodes.
    origins : (cells, 2) float
        Each cell's reference corner (x, y), pixels.
    offsets : (m, 2) float
        The sampled pixels' offsets in a cell.
    N : (m, 4) float
        The corners' bilinear shape functions at those pixels.
    f : (cells, m) float
        The reference's values there.
    mean : float
        The reference's mean (the gain multiplies the image about it).
    mask : (H, W) bool
        The frame's highlight pixels (a 0 x 0 array for none).
    corner : (2,) int
        Where ``coeff`` starts in the frame: its (x, y) (0, 0 for the whole frame).
    frame_shape : (2,) int
        The frame's (H, W).

    Returns
    -------
    r : (cells, m) float
        ``f - (1 + a)(g - mean) - mean - b`` with ``g`` the frame at the pixel's current
        position; 0 where the position is within 1 px of the frame's edge or beyond.
    out : (cells, m) bool
        Where the position is that close to the edge.
    hidden : (cells, m) bool
        Where the nearest pixel of the position (clipped to the frame) is in ``mask``.
    """
    H, W = frame_shape[0], frame_shape[1]
    cx0, cy0 = corner[0], corner[1]
    n_cells, m = f.shape
    has_mask = mask.shape[0] == H and mask.shape[1] == W
    r = np.zeros((n_cells, m))
    out = np.zeros((n_cells, m), dtype=np.bool_)
    hidden = np.zeros((n_cells, m), dtype=np.bool_)
    for c in prange(n_cells):
        corners = cells[c]
        for p in range(m):
            u = 0.0
            v = 0.0
            a = 0.0
            b = 0.0
            for i in range(4):
                w = N[p, i]
                node = corners[i]
                u += w * state[node, 0]
                v += w * state[node, 1]
                a += w * state[node, 2]
                b += w * state[node, 3]
            x = origins[c, 0] + offsets[p, 0] + u
            y = origins[c, 1] + offsets[p, 1] + v
            if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(a) and np.isfinite(b)):
                r[c, p] = np.nan  # a state gone wrong: the solver sees it and stops
                continue
            if has_mask:  # the nearest pixel, clipped to the frame (also once outside it)
                xi = min(max(int(np.rint(x)), 0), W - 1)
                yi = min(max(int(np.rint(y)), 0), H - 1)
                hidden[c, p] = mask[yi, xi]
            if x < 1 or x > W - 2 or y < 1 or y > H - 2:
                out[c, p] = True
                continue
            g = _bspline(coeff, x - cx0, y - cy0)
            r[c, p] = f[c, p] - (1 + a) * (g - mean) - mean - b
    return r, out, hidden


@njit(cache=True, parallel=True)
def lattice_gradient(
    N: np.ndarray, r: np.ndarray, w: np.ndarray, q: np.ndarray, T: np.ndarray, scale: float
) -> np.ndarray:
    """Per cell, the lattice field's gradient ``scale * T_c (sum_p w_c r_cp N_p (x) q_cp)``
    as ``(cells, 4 corners, 4 components)``: ``N`` (m, 4), ``r`` (cells, m), ``w`` (cells,),
    ``q`` (cells, m, 4), ``T`` (cells, 4, 4)."""
    n_cells, m = r.shape
    out = np.zeros((n_cells, 4, 4))
    for c in prange(n_cells):
        if w[c] == 0.0:
            continue
        g = np.zeros((4, 4))
        for p in range(m):
            s = r[c, p] * w[c]
            for i in range(4):
                t = N[p, i] * s
                for k in range(4):
                    g[i, k] += t * q[c, p, k]
        for i in range(4):
            for k in range(4):
                acc = 0.0
                for K in range(4):
                    acc += T[c, k, K] * g[i, K]
                out[c, i, k] = acc * scale
    return out
