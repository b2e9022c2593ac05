"""Compiled (numba) steps of the animation's frames: the gray frame sampled into a
panel, the banded strain field filled over it, the mesh's edges shaded, and the panel
put into the output.

Each gives the same pixels, bit for bit, as the NumPy path it stands for in
:mod:`strain2d.figures._animation` (tests check them): the same float32
arithmetic in the same order, a pixel on an edge between two triangles
taking the later triangle's band.  :func:`fill_bands` runs some four times
faster than NumPy, the two others some three times, once numba's compiler
is loaded: the animation uses them where a tracker already loaded it (gdic,
dic) or the video is long enough to pay for loading it (see
``_animation._COMPILED_FROM``).  They are compiled on their first use, about
2 s once: numba keeps them in its cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["compose", "fill_bands", "gray", "shade_edges"]


@njit(cache=True)
def fill_bands(rgb, corners, plane, low, step, n, colours, opacity):  # pragma: no cover
    """Blend the banded field over ``rgb`` (h, w, 3) float32, in place; returns the bands.

    ``corners`` (m, 3, 2) float64: each triangle's corners in ``rgb``'s pixel
    coordinates (pixel centres at whole numbers); ``plane`` (m, 5) float32:
    each triangle's field ``gx x + gy y + g0`` and its range ``lo, hi``; the
    scale's bands start at ``low`` (float) in steps of ``step``, ``n`` bands
    between; ``colours`` (n + 3, 3) and ``opacity`` (n + 3,) float32 as
    :func:`strain2d.figures._animation._bands` gives them.  Returns the (h,
    w) int16 band of each pixel (-1: none).
    """
    h, w = rgb.shape[0], rgb.shape[1]
    band = np.full((h, w), -1, np.int16)
    low32, step32 = np.float32(low), np.float32(step)
    zero, highest = np.float32(0.0), np.float32(n + 1)
    for t in range(corners.shape[0]):
        ys = corners[t, :, 1]
        top = int(min(max(math.ceil(ys.min()), 0.0), float(h)))
        bottom = int(min(max(math.floor(ys.max()), -1.0), float(h - 1)))
        gx, gy, g0, lo, hi = plane[t, 0], plane[t, 1], plane[t, 2], plane[t, 3], plane[t, 4]
        for row in range(top, bottom + 1):
            # where the row's centre line crosses the triangle's edges
            left, right = np.inf, -np.inf
            for i in range(3):
                j = (i + 1) % 3
                xa, ya = corners[t, i, 0], corners[t, i, 1]
                xb, yb = corners[t, j, 0], corners[t, j, 1]
                if min(ya, yb) <= row and row <= max(ya, yb) and ya != yb:
                    at = xa + (row - ya) * (xb - xa) / (yb - ya)
                    left, right = min(left, at), max(right, at)
            if left == np.inf:
                continue
            first = int(min(max(math.ceil(left), 0.0), float(w)))
            last = int(min(max(math.floor(right), -1.0), float(w - 1)))
            y32 = np.float32(row)
            for col in range(first, last + 1):
                value = min(max(gx * np.float32(col) + gy * y32 + g0, lo), hi)
                level = np.float32(math.ceil((value - low32) / step32))
                band[row, col] = np.int16(min(max(level, zero), highest))
    for r in range(h):
        for c in range(w):
            b = band[r, c]
            if b >= 0:
                for k in range(3):
                    rgb[r, c, k] += (colours[b, k] - rgb[r, c, k]) * opacity[b]
    # a pixel beside a higher band is covered by it too (tricontourf fills each band up to
    # the pixels its edge touches): the highest band beside it, blended again
    for r in range(h):
        for c in range(w):
            b = band[r, c]
            if b < 0:
                continue
            beside = np.int16(-1)
            if c > 0:
                beside = max(beside, band[r, c - 1])
            if c < w - 1:
                beside = max(beside, band[r, c + 1])
            if r > 0:
                beside = max(beside, band[r - 1, c])
            if r < h - 1:
                beside = max(beside, band[r + 1, c])
            if beside > b:
                for k in range(3):
                    rgb[r, c, k] += (colours[beside, k] - rgb[r, c, k]) * opacity[beside]
    return band


@njit(cache=True)
def gray(image, rows, cols, table):  # pragma: no cover
    """(h, w, 3) float32: ``table[image[rows[i], cols[j]]]``, an 8-bit frame sampled at the
    panel's pixels and coloured by the gray map's (257, 3) table."""
    out = np.empty((rows.size, cols.size, 3), np.float32)
    for i in range(rows.size):
        for j in range(cols.size):
            v = image[rows[i], cols[j]]
            for k in range(3):
                out[i, j, k] = table[v, k]
    return out


@njit(cache=True)
def compose(out, dark, through, rgb):  # pragma: no cover
    """``out`` (h, w, 3) uint8 = ``dark + through * rgb``, within 0..255, rounded half to
    even (what ``clip``, ``round`` and ``astype(uint8)`` give)."""
    lowest, highest = np.float32(0.0), np.float32(255.0)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            for k in range(3):
                v = dark[i, j, k] + through[i, j, k] * rgb[i, j, k]
                out[i, j, k] = np.uint8(np.rint(min(max(v, lowest), highest)))


@njit(cache=True)
def shade_edges(rgb, cover, per_level, node_rows, node_cols, darkest):  # pragma: no cover
    """Darken ``rgb`` (h, w, 3) float32 in place by the edges' coverage ``cover`` (h, w)
    uint8: by ``1 - per_level * cover`` (``per_level`` float32), and at the pixel of each
    node (``node_rows``, ``node_cols``, once each) by at most ``darkest`` (float64, one
    per node)."""
    h, w = cover.shape
    one = np.float32(1.0)
    shade = np.empty((h, w), np.float32)
    for i in range(h):
        for j in range(w):
            shade[i, j] = one - per_level * np.float32(cover[i, j])
    for e in range(node_rows.size):
        i, j = node_rows[e], node_cols[e]
        shade[i, j] = np.float32(min(np.float64(shade[i, j]), darkest[e]))
    for i in range(h):
        for j in range(w):
            s = shade[i, j]
            for k in range(3):
                rgb[i, j, k] *= s
