"""Microscope mosaics: z-stack tiles at their stage positions, read as one stack.

A multiphoton microscope covers a field wider than one view as a mosaic of
tiles, each a z-stack, that overlap by a margin (typically 5-20 %).  A tile
list (a CSV, ``file,x_um,y_um``: each tile's TIFF, relative to the CSV, and
the stage position in micrometres of its pixel (0, 0), x along its columns,
y along its rows) is read by :func:`open_mosaic` as one ``(Z, C, Y, X)``
stack, without stitching it first: :class:`MosaicRows` reads, for each band
of rows, only the tiles under it, a band at a time (each tile is opened as
:func:`mpm3d.lazyio.open_stack_lazily` opens a stack).  So ``mpm3d analyze
tiles.csv`` runs the banded path of :mod:`mpm3d.tiled` on a mosaic of any
size within its memory limit, and :func:`write_stitched` writes the stitched
stack as a TIFF, a band at a time too.

How the tiles are put together:

* the stage positions are rounded to the nearest pixel of the tiles' common
  grid (the largest rounding is reported: a stage is rarely accurate to
  better than a pixel, and tiles are not resampled);
* where tiles overlap, each pixel is read from the tile whose centre is
  nearest (the middle of a tile is trusted before its edge, where
  vignetting and the scan's turn-around lie), the first listed on a tie;
* a pixel in no tile reads 0, the lowest intensity: no surface is found
  there and the height map fills it in (the share is reported).

Every tile must have the same number of slices and channels, the same pixel
type and the same voxel size (within 0.1 %).
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpm3d.errors import InputError, MosaicGapWarning
from mpm3d.io import Stack

__all__ = [
    "MosaicRows",
    "TilePlacement",
    "is_tile_list",
    "mosaic_record",
    "open_mosaic",
    "write_stitched",
]

#: relative difference of voxel sizes under which tiles share a grid
_SPACING_TOLERANCE = 1e-3
#: the least share of their extent that the tiles must cover (less is a unit mistake)
_LEAST_COVER = 0.25


def is_tile_list(path) -> bool:
    """Whether ``path`` names a mosaic's tile list (a ``.csv`` file) rather than a stack."""
    return isinstance(path, str | os.PathLike) and Path(path).suffix.lower() == ".csv"


@dataclass(frozen=True)
class TilePlacement:
    """Where one tile lies in the mosaic: its file, its first row and column in the
    mosaic's pixels, its size, and how far its stage position was from that pixel."""

    path: str
    row: int
    col: int
    rows: int
    cols: int
    rounding_px: float

    @property
    def centre(self) -> tuple[float, float]:
        return self.row + (self.rows - 1) / 2, self.col + (self.cols - 1) / 2


class MosaicRows:
    """A ``(Z, C, Y, X)`` view of a mosaic that reads only the tiles under what is indexed.

    Indexing takes integers and slices (any steps) on the four axes, as
    :class:`mpm3d.lazyio.TiffRows` does, and returns an in-memory array.
    Use it as a context manager, or call :meth:`close`.

    Attributes
    ----------
    shape : (Z, C, Y, X)
    dtype : numpy.dtype
    placements : list of TilePlacement
    covered_fraction : float
        The share of the mosaic's pixels that some tile holds.
    """

    def __init__(self, tiles: Sequence, placements: Sequence[TilePlacement]) -> None:
        self._tiles = list(tiles)  # each a TiffRows
        self.placements = list(placements)
        first = self._tiles[0]
        nz, nc = first.shape[:2]
        ny = max(p.row + p.rows for p in self.placements)
        nx = max(p.col + p.cols for p in self.placements)
        self.shape = (int(nz), int(nc), int(ny), int(nx))
        self.dtype = first.dtype
        self.contiguous = all(t.contiguous for t in self._tiles)
        self._owners: tuple | None = None
        self.covered_fraction = self._covered() / (ny * nx)

    @property
    def ndim(self) -> int:
        return 4

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def nbytes(self) -> int:
        return self.size * self.dtype.itemsize

    def __repr__(self) -> str:
        return f"<MosaicRows {self.shape} {self.dtype} from {len(self._tiles)} tiles>"

    def __enter__(self) -> MosaicRows:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        for tile in self._tiles:
            tile.close()

    def _covered(self) -> int:
        """Pixels in at least one tile (on the grid of the tiles' edges: no pixel loop)."""
        ys = np.unique([v for p in self.placements for v in (p.row, p.row + p.rows)])
        xs = np.unique([v for p in self.placements for v in (p.col, p.col + p.cols)])
        hit = np.zeros((len(ys) - 1, len(xs) - 1), bool)
        for p in self.placements:
            r0, r1 = np.searchsorted(ys, [p.row, p.row + p.rows])
            c0, c1 = np.searchsorted(xs, [p.col, p.col + p.cols])
            hit[r0:r1, c0:c1] = True
        return int((np.diff(ys)[:, None] * np.diff(xs)[None, :] * hit).sum())

    def owners(self, ys: range, xs: range) -> np.ndarray:
        """Per pixel of rows ``ys`` and columns ``xs``, the index of the tile it is read
        from (the one holding it whose centre is nearest; -1 in no tile).  The last
        answer is kept: a plane at a time asks the same every time."""
        if self._owners is not None and self._owners[0] == (ys, xs):
            return self._owners[1]
        owner = self._owners_of(ys, xs)
        self._owners = ((ys, xs), owner)
        return owner

    def _window(self, p: TilePlacement, ys: range, xs: range) -> tuple[int, int, int, int]:
        """The rows ``r0:r1`` and columns ``c0:c1`` of ``ys`` x ``xs`` that tile ``p`` holds."""
        r0, r1 = (int(v) for v in np.searchsorted(np.asarray(ys), [p.row, p.row + p.rows]))
        c0, c1 = (int(v) for v in np.searchsorted(np.asarray(xs), [p.col, p.col + p.cols]))
        return r0, r1, c0, c1

    def _owners_of(self, ys: range, xs: range) -> np.ndarray:
        # twice the squared distance to each centre, in whole numbers (centres lie on half
        # pixels): exact, and 4 bytes a pixel while the window is under 16,000 px
        big = 2 * max(self.shape[2], self.shape[3]) > 2**15
        kind = np.int64 if big else np.int32
        best = np.full((len(ys), len(xs)), np.iinfo(kind).max, kind)
        owner = np.full((len(ys), len(xs)), -1, np.int32)
        y2, x2 = 2 * np.asarray(ys, kind), 2 * np.asarray(xs, kind)
        for i, p in enumerate(self.placements):
            r0, r1, c0, c1 = self._window(p, ys, xs)
            if r0 >= r1 or c0 >= c1:
                continue  # only the tile's own rectangle is measured
            cy, cx = (round(2 * c) for c in p.centre)
            d = (y2[r0:r1, None] - cy) ** 2 + (x2[None, c0:c1] - cx) ** 2
            near = best[r0:r1, c0:c1]
            take = d < near  # strictly nearer: the first listed keeps a tie
            near[take] = d[take]
            owner[r0:r1, c0:c1][take] = i
        return owner

    def __getitem__(self, key) -> np.ndarray:
        from mpm3d.lazyio import index_ranges

        ranges, drop = index_ranges(key, self.shape, "MosaicRows")
        if any(r.step < 0 for r in ranges):
            raise IndexError("MosaicRows reads each axis in increasing order (step > 0)")
        # the same ranges as slices, for the tiles' own reads
        plain = [slice(r.start, r.start + len(r) * r.step, r.step) for r in ranges]
        zs, cs, ys, xs = ranges
        out = np.zeros((len(zs), len(cs), len(ys), len(xs)), self.dtype)
        if out.size:
            owner = self.owners(ys, xs)
            for i, (p, tile) in enumerate(zip(self.placements, self._tiles, strict=True)):
                w0, w1, v0, v1 = self._window(p, ys, xs)
                if w0 >= w1 or v0 >= v1:
                    continue
                mine = owner[w0:w1, v0:v1] == i  # within the tile's own rectangle
                if not mine.any():
                    continue
                rows, cols = np.flatnonzero(mine.any(axis=1)), np.flatnonzero(mine.any(axis=0))
                r0, r1, c0, c1 = w0 + rows[0], w0 + rows[-1] + 1, v0 + cols[0], v0 + cols[-1] + 1
                mine = mine[r0 - w0 : r1 - w0, c0 - v0 : c1 - v0]
                # the same rows and columns in the tile's own pixels (the same steps)
                ty = slice(ys[r0] - p.row, ys[r1 - 1] - p.row + 1, ys.step)
                tx = slice(xs[c0] - p.col, xs[c1 - 1] - p.col + 1, xs.step)
                part = tile[plain[0], plain[1], ty, tx]
                # in place: no copy of the tile's part
                np.copyto(out[:, :, r0:r1, c0:c1], part, where=mine[None, None])
                del part
        return out[tuple(0 if d else slice(None) for d in drop)]


def _same_spacing(a: Sequence[float], b: Sequence[float]) -> bool:
    pairs = zip(a, b, strict=True)
    return all(abs(x - y) <= _SPACING_TOLERANCE * max(abs(x), abs(y)) for x, y in pairs)


def open_mosaic(path: str | os.PathLike, *, spacing: Sequence[float] | None = None) -> Stack:
    """A :class:`~mpm3d.io.Stack` whose ``data`` is a :class:`MosaicRows` of the tiles
    listed in ``path`` (see the module's notes); no pixels read yet.

    The voxel size is the tiles' (or ``spacing``, for all of them); the
    stack's ``path`` is the tile list's.  Close ``stack.data`` when done.

    Raises
    ------
    InputError
        When the list cannot be read, a tile cannot be read as a stack, or
        the tiles disagree in slices, channels, pixel type or voxel size
        (the message names the list's line).
    """
    from mpm3d.errors import SourceError
    from mpm3d.lazyio import open_stack_lazily
    from tissue_core.tables import read_tile_list

    path = Path(path)
    entries = read_tile_list(path)
    stacks: list[Stack] = []
    try:
        for entry in entries:
            where = f"{path}, line {entry.line}"
            if is_tile_list(entry.path):
                raise InputError(f"{where}: a tile cannot be a mosaic itself")
            try:
                stack = open_stack_lazily(entry.path, spacing=spacing)
            except (InputError, SourceError) as exc:
                raise type(exc)(f"{where}: {exc}") from None
            stacks.append(stack)
            first = stacks[0]
            if stack.shape[:2] != first.shape[:2]:
                raise InputError(
                    f"{where}: {entry.path.name} has {stack.shape[0]} slices and "
                    f"{stack.shape[1]} channels, the first tile {first.shape[0]} and "
                    f"{first.shape[1]}: the tiles of a mosaic share their slices and channels"
                )
            if stack.data.dtype != first.data.dtype:
                raise InputError(
                    f"{where}: {entry.path.name} holds {stack.data.dtype} pixels, the first "
                    f"tile {first.data.dtype}"
                )
            if not _same_spacing(stack.spacing, first.spacing):
                raise InputError(
                    f"{where}: {entry.path.name}'s voxel size {_um(stack.spacing)} is not the "
                    f"first tile's {_um(first.spacing)} (give --spacing if the files are wrong)"
                )
        _, dy, dx = stacks[0].spacing
        x0 = min(e.x_um for e in entries)
        y0 = min(e.y_um for e in entries)
        placements = []
        for entry, stack in zip(entries, stacks, strict=True):
            fx, fy = (entry.x_um - x0) / dx, (entry.y_um - y0) / dy
            col, row = round(fx), round(fy)
            placements.append(
                TilePlacement(
                    path=str(entry.path),
                    row=int(row),
                    col=int(col),
                    rows=int(stack.shape[2]),
                    cols=int(stack.shape[3]),
                    rounding_px=float(math.hypot(fx - col, fy - row)),
                )
            )
        data = MosaicRows([s.data for s in stacks], placements)
        if data.covered_fraction < _LEAST_COVER:
            ny, nx = data.shape[2:]
            raise InputError(
                f"{path}: the tiles cover only {100 * data.covered_fraction:.2g} % of the "
                f"{nx} x {ny} px they span: are x_um and y_um in micrometres, and the voxel "
                f"size {_um(stacks[0].spacing)}?"
            )
        if data.covered_fraction < 1:
            warnings.warn(
                MosaicGapWarning(
                    f"{path}: {100 * (1 - data.covered_fraction):.1f} % of the mosaic lies in "
                    "no tile (read as 0: no surface is found there, the height map fills it in)"
                ),
                stacklevel=2,
            )
        first = stacks[0]
        return Stack(
            data=data,
            spacing=first.spacing,
            spacing_source=first.spacing_source,
            channel_names=first.channel_names,
            path=str(path),
            axes="ZCYX",
        )
    except BaseException:
        for stack in stacks:
            stack.data.close()
        raise


def _um(spacing: Sequence[float]) -> str:
    return " x ".join(f"{s:g}" for s in spacing) + " um"


def mosaic_record(data: MosaicRows) -> dict:
    """For ``metrics.json``: the tiles, where each lies, the coverage and the rounding."""
    return {
        "tiles": len(data.placements),
        "shape_yx": list(data.shape[2:]),
        "covered_fraction": data.covered_fraction,
        "max_position_rounding_px": max(p.rounding_px for p in data.placements),
        "placements": [
            {"file": p.path, "row": p.row, "col": p.col, "rows": p.rows, "cols": p.cols}
            for p in data.placements
        ],
        "overlaps": "each pixel from the tile whose centre is nearest",
    }


def write_stitched(
    path: str | os.PathLike,
    out: str | os.PathLike,
    *,
    spacing: Sequence[float] | None = None,
    overwrite: bool = False,
    progress=None,
) -> dict:
    """Write the mosaic listed in ``path`` as one ImageJ TIFF stack at ``out`` (ZCYX, the
    voxel size in um, the channels' names), a plane at a time: memory holds one plane of
    the mosaic and one of each tile.  The file is written whole or not at all (a
    temporary file beside it, renamed); ``progress(done, total)`` is called per plane.

    Returns :func:`mosaic_record` of the mosaic.
    """
    import tifffile

    from tissue_core.outputs import atomic_file

    stack = open_mosaic(path, spacing=spacing)
    data = stack.data
    nz, nc, ny, nx = data.shape
    dz, dy, dx = stack.spacing

    def planes():
        for z in range(nz):
            for c in range(nc):
                yield data[z, c]
                if progress is not None:
                    progress(z * nc + c + 1, nz * nc)

    try:
        inputs = [path, *(p.path for p in data.placements)]
        with atomic_file(out, overwrite=overwrite, inputs=inputs) as tmp:
            tifffile.imwrite(
                tmp,
                planes(),
                shape=(nz, nc, ny, nx),
                dtype=data.dtype,
                imagej=True,
                resolution=(1 / dx, 1 / dy),
                metadata={
                    "axes": "ZCYX",
                    "spacing": dz,
                    "unit": "um",
                    "Labels": list(stack.channel_names) * nz,
                },
            )
        return mosaic_record(data)
    finally:
        data.close()
