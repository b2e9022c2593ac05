"""Compiled inner loops for the height map and the isosurface volume (numba).

Each loop reads the stack where it lies (a memory map or an array, any
strides) and writes small outputs, so no floating-point copy of the stack is
ever made.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

__all__ = ["bin_lateral", "first_crossing"]


@njit(cache=True, inline="always")
def _mean3x3(vol, z, y, x, ny, nx):
    """Mean of the 3 x 3 lateral neighbourhood of voxel (z, y, x).

    On the map's edges the neighbourhood shrinks symmetrically (to 1 x 3,
    3 x 1 or 1 x 1), so a sloping surface is not pulled towards its inner
    side there.
    """
    ry = 1 if 0 < y < ny - 1 else 0
    rx = 1 if 0 < x < nx - 1 else 0
    total = 0.0
    count = 0
    for yy in range(y - ry, y + ry + 1):
        for xx in range(x - rx, x + rx + 1):
            total += vol[z, yy, xx]
            count += 1
    return total / count


@njit(parallel=True, cache=True)
def first_crossing(vol, level, background, window, depth, peak):  # pragma: no cover - compiled
    """Sub-voxel depth of the first rise of each column above ``level``.

    Scanning each column (3 x 3 laterally averaged, against noise) from
    slice 0, find the first slice at or above ``level``; then, on the column
    itself, the first local maximum within ``window`` slices below it (the
    surface layer's peak), and where the rising edge crosses half-way
    between ``background`` and that peak, interpolating linearly between
    slices.  The half-maximum of a blurred step lies on the step whatever
    the blur, so the depth does not depend on ``level`` or on how bright the
    layer is.

    Writes ``depth[y, x]`` in slice units (NaN where no slice reaches
    ``level``, -1 where the column is bright from slice 0 on: the surface
    lies above the stack) and ``peak[y, x]`` (NaN where none).
    """
    nz, ny, nx = vol.shape
    for y in prange(ny):
        done = np.zeros(nx, np.bool_)
        start = np.full(nx, -1, np.int64)
        remaining = nx
        for z in range(nz):
            for x in range(nx):
                if not done[x] and _mean3x3(vol, z, y, x, ny, nx) >= level:
                    done[x] = True
                    start[x] = z
                    remaining -= 1
            if remaining == 0:
                break
        for x in range(nx):
            z0 = start[x]
            if z0 < 0:
                depth[y, x] = np.nan
                peak[y, x] = np.nan
                continue
            # refine on the column itself: a lateral mean would pull the edge of a
            # steep wall towards its shallow side
            # the layer's peak: the first local maximum below the crossing (a
            # brighter structure further down must not set the half level)
            top = float(vol[z0, y, x])
            zp = z0
            for z in range(z0 + 1, min(nz, z0 + window + 1)):
                v = float(vol[z, y, x])
                if v <= top:
                    break
                top = v
                zp = z
            if top < level:  # only the neighbours are bright: no surface in this column
                depth[y, x] = np.nan
                peak[y, x] = np.nan
                continue
            half = background + 0.5 * (top - background)
            # walk up from the peak to the last slice below the half level
            j = zp
            below = top
            while j > 0:
                j -= 1
                below = float(vol[j, y, x])
                if below < half:
                    break
            if below >= half:  # bright from the first slice on: the surface is cut off
                depth[y, x] = -1.0
            else:
                above = float(vol[j + 1, y, x])
                depth[y, x] = j + (half - below) / (above - below)
            peak[y, x] = top


@njit(parallel=True, cache=True)
def bin_lateral(vol, factor, out):  # pragma: no cover - compiled
    """Mean over ``factor`` x ``factor`` lateral blocks: ``out[z, i, j]`` (float32)."""
    nz, by, bx = out.shape
    scale = np.float32(1.0 / (factor * factor))
    for z in prange(nz):
        acc = np.empty(bx * factor, np.float32)
        for i in range(by):
            acc[:] = 0
            for yy in range(i * factor, (i + 1) * factor):
                for x in range(bx * factor):  # contiguous: vectorizes
                    acc[x] += vol[z, yy, x]
            for j in range(bx):
                total = np.float32(0)
                for k in range(factor):
                    total += acc[j * factor + k]
                out[z, i, j] = total * scale


@njit(parallel=True, cache=True)
def combine_channels(data, lo, hi, out):  # pragma: no cover - compiled
    """``out[z, y, x]`` = 65535 x max over channels of ``(data[z, c] - lo[c]) / (hi[c] - lo[c])``.

    ``data`` is ``(Z, C, Y, X)``; each scaled value is clipped to [0, 1];
    channels with ``hi <= lo`` and NaN voxels are left out.
    """
    nz, nc, ny, nx = data.shape
    scale = np.zeros(nc, np.float32)
    offset = np.zeros(nc, np.float32)
    for c in range(nc):
        if hi[c] > lo[c]:
            scale[c] = 1.0 / (hi[c] - lo[c])
            offset[c] = lo[c]
    for z in prange(nz):
        best = np.empty(nx, np.float32)
        for y in range(ny):
            best[:] = 0
            for c in range(nc):
                if scale[c] == 0:
                    continue
                for x in range(nx):  # contiguous: vectorizes
                    v = (np.float32(data[z, c, y, x]) - offset[c]) * scale[c]
                    if v > best[x]:  # False for NaN
                        best[x] = v
            for x in range(nx):
                out[z, y, x] = np.uint16(min(best[x], np.float32(1.0)) * np.float32(65535) + 0.5)
