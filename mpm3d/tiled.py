"""Stacks larger than memory: the height map and the isosurface in bands of rows.

:func:`mpm3d.analyze.analyze_stack` takes this path when the stack's
in-memory working set (:func:`plan_memory`) would exceed its memory limit,
or when asked to (``lazy=True``, ``--lazy``).  The stack is read a band of
rows at a time (:mod:`mpm3d.lazyio`), every slice of the band at once, and
only ``(Y, X)`` maps are ever whole (the mesh, only with ``--decimate``):

* the detection threshold, background and noise come from the same strided
  subsample of the stack as in memory (:func:`mpm3d.heightmap.surface_levels`),
  read plane by plane;
* each column's first crossing (:func:`mpm3d._kernels.first_crossing`)
  depends on the column and its 3 x 3 lateral neighbours only: bands
  overlap by one row on each side and give every column the value the
  whole stack gives;
* the crossings go to files, and the gap filling, the outlier test and the
  smoothing (:func:`mpm3d.heightmap.from_crossings`) run on them a band of
  rows or a strip of columns at a time (:mod:`mpm3d.diskmaps`: the same
  values, bit for bit; ``TMPDIR`` chooses where the files go); the finished
  maps are read back whole;
* the isosurface's grid (lateral binning, per-column scaling and tissue
  filling) is per column too; each band of binned rows is contoured on the
  whole grid's coordinates (:func:`mpm3d.surface.contour_rows`), bands
  sharing their boundary row; the mesh is merged, cut to its largest piece,
  smoothed and oriented through files a band at a time
  (:mod:`mpm3d.meshstream`: a :class:`mpm3d.meshstream.DiskMesh`, written a
  chunk at a time), or, with ``--decimate``, assembled whole
  (:func:`mpm3d.surface.finish_isosurface`).

So the height map, every metric and the mesh are the same, bit for bit, as
the in-memory path's.
"""

from __future__ import annotations

import contextlib
import math
import re
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np

from mpm3d.errors import InputError
from tissue_core.resources import available_memory

__all__ = [
    "MemoryPlan",
    "StackBands",
    "check_triangles",
    "default_memory_limit",
    "format_bytes",
    "mesh_budget",
    "parse_memory",
    "plan_memory",
    "tiled_height_map",
    "tiled_isosurface",
]

#: resident memory of the process before any stack: Python, NumPy, SciPy,
#: numba, VTK and matplotlib loaded, the figures drawn
BASE_BYTES = 450 * 2**20
#: bytes per column (Y x X) of the maps, their filling and smoothing, the
#: metrics and the figures, all in memory
MAP_BYTES_PER_COLUMN = 200
#: the same on the banded path, where the height map's work maps are on disk
#: (:mod:`mpm3d.diskmaps`) and the metrics, the intensity and the figures take the
#: finished maps (17 bytes a column) a band of rows at a time: a 240 x 4096 x 4096
#: stack without the surface peaked at 817 MiB with the 64 rows a band the plan picks
#: at 1 GiB (18 bytes a column over the base and the band), a 6144 x 6144 one at
#: 1.69 GiB within 2 GiB (about 22); the margin is for the allocator's slack
TILED_MAP_BYTES_PER_COLUMN = 32
#: bytes per binned column of the isosurface: the mesh (about two triangles
#: each) while it is merged, put in order, smoothed, measured and written
MESH_BYTES_PER_COLUMN = 1200
#: bytes per column of the maps still held while the mesh is built and drawn (the height
#: map and its masks, the surface's intensity; the metrics' work maps are gone): a
#: 4096 x 4096 px field held 756 MiB as its streamed mesh was contoured (19 bytes a
#: column over the base)
KEPT_MAP_BYTES_PER_COLUMN = 24
#: bytes per triangle of a piece of the streamed mesh while it is smoothed: its points
#: and triangles read from the files (30), as VTK's PolyData and the smoothing's own
#: (measured 134-153 over them on pieces of 0.5-2 million triangles)
PIECE_BYTES_PER_TRIANGLE = 190
#: bytes per triangle of the isosurface at the run's peak: merged and put in order,
#: smoothed, measured and drawn (measured on a steeply folded 1024 x 1024 px stack:
#: 3.2 million triangles took the run from 457 MiB to 1176 MiB)
MESH_BYTES_PER_TRIANGLE = 240
#: triangles of the isosurface per cell face of surface: a binned pixel's side by the
#: shorter of it and the z-step (a steep flank is cut by the slices); 2.6 on the
#: synthetic stacks, flat and steeply folded, binned 2 and 3 (within 6 %)
TRIANGLES_PER_CELL = 2.6
#: bytes per column of the height map's work maps on disk (:mod:`mpm3d.diskmaps`): the
#: crossings, the contrast, the masks and a gap filling's maps alive at once (69 at most),
#: besides the smoothing's map extended past the edges (:func:`disk_bytes`)
DISK_BYTES_PER_COLUMN = 72
#: the default memory limit: this fraction of the memory available now
DEFAULT_FRACTION = 0.5

_UNITS = {
    "b": 1,
    "kb": 10**3,
    "mb": 10**6,
    "gb": 10**9,
    "tb": 10**12,
    "kib": 2**10,
    "mib": 2**20,
    "gib": 2**30,
    "tib": 2**40,
}


def parse_memory(text: str) -> int:
    """A memory size in bytes from text such as ``"1.5GiB"``, ``"800 MB"``, ``"512MiB"``.

    Units: B, kB, MB, GB, TB (powers of 1000) and KiB, MiB, GiB, TiB (powers
    of 1024), case-insensitive.

    Examples
    --------
    >>> parse_memory("1.5GiB"), parse_memory("800 MB")
    (1610612736, 800000000)
    """
    match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*([A-Za-z]+)\s*", str(text))
    unit = match and _UNITS.get(match.group(2).lower())
    if not unit:
        raise InputError(f"--memory-limit must be a size such as 1.5GiB or 800MB, got {text!r}")
    value = float(match.group(1)) * unit
    if not (math.isfinite(value) and value >= 1):
        raise InputError(f"--memory-limit must be a positive size, got {text!r}")
    return int(value)


def format_bytes(n: float) -> str:
    """``n`` bytes in GiB or MiB, rounded up, as --memory-limit takes them: ``"1.50GiB"``."""
    if n >= 2**30:
        return f"{math.ceil(n / 2**30 * 100) / 100:.2f}GiB"
    return f"{math.ceil(n / 2**20):d}MiB"


def default_memory_limit() -> int:
    """The limit when none is given: half the memory available now."""
    return int(DEFAULT_FRACTION * available_memory())


@dataclass(frozen=True)
class MemoryPlan:
    """How a stack is analysed within a memory limit.

    Attributes
    ----------
    path : {"in-memory", "tiled"}
    limit_bytes : int
    in_memory_bytes : int
        The estimated peak of the in-memory path.
    tile_rows : int or None
        Rows of pixels per band of the height map (tiled path).
    surface_tile_rows : int or None
        Binned rows per band of the isosurface (tiled path).
    mesh_piece_rows : int or None
        Binned rows per piece the streamed mesh is smoothed in (besides the
        :data:`SMOOTHING_HALO_ROWS` either side).
    tiled_bytes : int or None
        The estimated peak of the tiled path with these bands.
    smallest_limit_bytes : int
        The least limit the tiled path works within (bands of one row).
    """

    path: str
    limit_bytes: int
    in_memory_bytes: int
    tile_rows: int | None = None
    surface_tile_rows: int | None = None
    mesh_piece_rows: int | None = None
    tiled_bytes: int | None = None
    smallest_limit_bytes: int = 0
    #: the model's parts, for :func:`plan_surface`: bytes without the mesh, and per row of
    #: a band of the isosurface
    model: dict | None = None

    def record(self, **extra) -> dict:
        """For ``metrics.json``: the path, the limit and the bands."""
        out = {
            "path": self.path,
            "memory_limit_bytes": self.limit_bytes,
            "memory_limit": format_bytes(self.limit_bytes),
            "estimated_in_memory_bytes": self.in_memory_bytes,
        }
        if self.path == "tiled":
            out.update(
                tile_rows=self.tile_rows,
                surface_tile_rows=self.surface_tile_rows,
                mesh_piece_rows=self.mesh_piece_rows,
                estimated_peak_bytes=self.tiled_bytes,
            )
            if self.model and "mesh_triangles" in self.model:
                out["estimated_mesh_triangles"] = self.model["mesh_triangles"]
        out.update(extra)
        return out


def plan_memory(
    shape: Sequence[int],
    itemsize: int,
    *,
    limit: int,
    combined: bool,
    channels_read: int,
    surface: bool,
    bin: int,
    lazy: bool = False,
    tile_rows: int | None = None,
    copies: int = 1,
) -> MemoryPlan:
    """In memory or in bands, and how many rows a band, within ``limit`` bytes.

    A model of the peak resident memory of each path, from the stack's
    shape: a fixed part (:data:`BASE_BYTES`, the ``(Y, X)`` maps, whose work
    the banded path does on disk (:data:`TILED_MAP_BYTES_PER_COLUMN` against
    :data:`MAP_BYTES_PER_COLUMN`), and the mesh, which both paths hold whole)
    and the part that grows with the stack (the whole stack in memory, or one
    band of every slice).

    Parameters
    ----------
    shape : (Z, C, Y, X)
    itemsize : int
        Bytes per voxel as read (4 for float16 files, read as float32).
    limit : int
        Bytes.
    combined : bool
        The channels are combined into one (a uint16 volume).
    channels_read : int
        Channels read for each band: all of them when ``combined``, else 1.
    surface : bool
        The isosurface is built.
    bin : int
        Its lateral binning.
    lazy : bool
        Take the tiled path even when the stack fits.
    tile_rows : int, optional
        Rows per band; by default as many as the limit allows.
    copies : int
        Copies of what is read that are alive at once while it is read: 2 for
        a mosaic (:mod:`mpm3d.mosaic`: the band, and one tile's part of it).

    Raises
    ------
    InputError
        When the tiled path is needed but even bands of one row exceed the
        limit (the message gives the least limit that works).
    """
    nz, nc, ny, nx = (int(n) for n in shape)
    by, bx = max(1, ny // bin), max(1, nx // bin)
    mesh = MESH_BYTES_PER_COLUMN * by * bx if surface else 0
    # banded, the mesh goes through files: a piece of it, with the rows around it that
    # its smoothing needs, is in memory at a time, and a band's contour while it is merged
    # (as a surface of twice the developed area of a flat one, until the height map tells
    # how folded it is: plan_surface)
    mesh_row = int(PIECE_BYTES_PER_TRIANGLE * 2 * TRIANGLES_PER_CELL * bx) if surface else 0
    piece = mesh_row * min(by, 2 * SMOOTHING_HALO_ROWS + 1)
    fixed = BASE_BYTES + MAP_BYTES_PER_COLUMN * ny * nx + mesh
    # banded: the height map's phase (its work maps), then the mesh's (the maps kept)
    banded = BASE_BYTES + TILED_MAP_BYTES_PER_COLUMN * ny * nx
    meshing = BASE_BYTES + KEPT_MAP_BYTES_PER_COLUMN * ny * nx + piece
    voxels = nz * ny * nx
    grid = nz * by * bx if surface else 0
    # the stack as read, the combined channels, the isosurface's float32 grid
    # and VTK's one byte per grid point of flying-edges bookkeeping
    in_memory = fixed + copies * voxels * nc * itemsize + (2 * voxels if combined else 0) + 5 * grid
    # one band of rows, every slice: as read, combined, and its grid
    per_row = nz * nx * (copies * channels_read * itemsize + (2 if combined else 0))
    grid_row = 5 * nz * bx
    per_grid_row = grid_row + 2 * mesh_row  # and the contour's mesh, merged
    height_rows = lambda rows: per_row * (rows + 2)  # noqa: E731 - one halo row each side
    surface_rows = lambda rows: per_row * bin * (rows + 1) + per_grid_row * (rows + 1)  # noqa: E731

    def peak(rows: int, grid_rows: int) -> int:
        top = banded + height_rows(rows)
        if surface:
            top = max(top, meshing + surface_rows(grid_rows))
        return top

    smallest = peak(1, 1)
    if not lazy and tile_rows is None and in_memory <= limit:
        return MemoryPlan(
            "in-memory", limit, in_memory, smallest_limit_bytes=smallest,
            model={"mesh_bytes": mesh},
        )  # fmt: skip
    if tile_rows is not None:
        if tile_rows < 1:
            raise InputError(f"--tile-rows must be >= 1, got {tile_rows}")
        rows = min(int(tile_rows), ny)
        grid_rows = max(1, min(by - 1, rows // bin))
    else:
        if smallest > limit:
            ways = f"use --memory-limit {format_bytes(smallest)} or more"
            without = banded + height_rows(1)
            if surface and without <= limit:
                # the mesh's pieces are what does not fit
                ways += (
                    f", a coarser --iso-bin (now {bin}), or --no-surface (which needs "
                    f"{format_bytes(without)})"
                )
            raise InputError(
                f"a memory limit of {format_bytes(limit)} is too small for this "
                f"{nz} x {nc} x {ny} x {nx} stack: even one row at a time needs "
                f"{format_bytes(smallest)}; {ways}"
            )
        rows = max(1, min(ny, (limit - banded) // per_row - 2))
        grid_rows = 1
        if surface:
            room = limit - meshing
            grid_rows = max(1, min(by - 1, (room // (per_row * bin + per_grid_row)) - 1))
    return MemoryPlan(
        "tiled",
        limit,
        in_memory,
        tile_rows=int(rows),
        surface_tile_rows=int(grid_rows) if surface else None,
        tiled_bytes=peak(rows, grid_rows),
        smallest_limit_bytes=smallest,
        model={
            "without_mesh": BASE_BYTES + KEPT_MAP_BYTES_PER_COLUMN * ny * nx,
            "per_grid_row": per_row * bin + grid_row,
            "binned_rows": by,
            "height_peak": BASE_BYTES + TILED_MAP_BYTES_PER_COLUMN * ny * nx + height_rows(rows),
        },
    )


def mesh_triangles(depth_um: np.ndarray, spacing: Sequence[float], bin: int) -> int:
    """The isosurface's expected triangle count, from the height map's developed area
    (:data:`TRIANGLES_PER_CELL` per cell face of it), a band of rows at a time."""
    dz, dy, dx = (float(v) for v in spacing)
    area = 0.0
    ny = depth_um.shape[0]
    for y0 in range(0, ny, 512):
        a, b = max(0, y0 - 1), min(ny, y0 + 513)  # a row each side: the same gradient
        gy, gx = np.gradient(np.asarray(depth_um[a:b], np.float64), dy, dx)
        keep = slice(y0 - a, y0 - a + min(512, ny - y0))
        area += float(np.sqrt(1.0 + gx[keep] ** 2 + gy[keep] ** 2).sum()) * dy * dx
    side = bin * math.sqrt(dy * dx)
    return int(TRIANGLES_PER_CELL * area / (side * min(side, dz)))


#: binned rows of mesh around each piece the streamed mesh is smoothed in
#: (:func:`mpm3d.meshstream.stream_isosurface`: the smoothing's 40 iterations and 2)
SMOOTHING_HALO_ROWS = 42


def plan_surface(
    plan: MemoryPlan, triangles: int, *, iso_bin: int, streamed: bool = True
) -> MemoryPlan:
    """The tiled ``plan`` with the isosurface's bands sized for a mesh of ``triangles``
    (:func:`mesh_triangles`, known once the height map is) in place of the first plan's
    guess per column.

    ``streamed`` (no decimation): the mesh goes through files
    (:mod:`mpm3d.meshstream`) and only a band of the grid and a piece of the mesh (the
    band's rows and :data:`SMOOTHING_HALO_ROWS` either side) are in memory; otherwise the
    mesh is held whole.

    Raises
    ------
    InputError
        When such a mesh does not fit the limit even built a row at a time (the
        message gives the limit that works, and the other ways out).
    """
    model = plan.model
    by = max(1, model["binned_rows"])
    without = model["without_mesh"]
    if not streamed:
        fixed = without + MESH_BYTES_PER_TRIANGLE * int(triangles) + model["per_grid_row"]
        smallest = int(fixed + model["per_grid_row"])
        rows = max(1, min(by - 1, int((plan.limit_bytes - fixed) // model["per_grid_row"])))
        pieces, peak = None, fixed + model["per_grid_row"] * rows
    else:
        # a binned row of mesh: contoured (a band and the rows still open) and merged,
        # or in a piece being smoothed
        mesh_row = PIECE_BYTES_PER_TRIANGLE * int(triangles) / by
        contour_row = model["per_grid_row"] + 2 * mesh_row
        halo = 2 * SMOOTHING_HALO_ROWS

        def piece_bytes(rows: int) -> float:  # a piece and the rows around it
            return mesh_row * min(by, rows + halo)

        smallest = int(without + max(2 * contour_row, piece_bytes(1)))
        rows = int((plan.limit_bytes - without) // contour_row) - 1
        rows = max(1, min(by - 1, rows))
        pieces = int((plan.limit_bytes - without) // max(mesh_row, 1.0)) - halo
        pieces = max(1, min(by, pieces))
        peak = without + max(contour_row * (rows + 1), piece_bytes(pieces))
    if plan.limit_bytes < smallest:
        held = "" if streamed else " (held whole: --decimate)"
        raise InputError(
            f"a memory limit of {format_bytes(plan.limit_bytes)} is too small for this "
            f"surface's mesh: its folds make about {triangles / 1e6:.1f} million triangles "
            f"at --iso-bin {iso_bin}{held}; use --memory-limit {format_bytes(smallest)} or "
            "more, a coarser --iso-bin, or --no-surface"
        )
    return replace(
        plan,
        surface_tile_rows=int(rows),
        mesh_piece_rows=pieces,
        tiled_bytes=int(max(model["height_peak"], peak)),
        model={**model, "mesh_triangles": int(triangles), "streamed": bool(streamed)},
    )


def mesh_budget(plan: MemoryPlan | None) -> int | None:
    """The most isosurface triangles a ``plan`` holds within its limit (at
    :data:`MESH_BYTES_PER_TRIANGLE`): beside the stack and the maps in memory, or, banded
    (after :func:`plan_surface`), beside the maps and one band of the isosurface's grid
    (the whole mesh), or such that a piece of a streamed mesh fits (as many triangles a
    binned row as that allows, over all rows). None without a plan."""
    model = plan.model if plan is not None else None
    if not model:
        return None
    if plan.path == "in-memory":
        room = plan.limit_bytes - (plan.in_memory_bytes - model["mesh_bytes"])
    elif model.get("streamed"):
        # as dense a mesh as lets a piece, with the rows around it, fit
        by = max(1, model["binned_rows"])
        room = plan.limit_bytes - model["without_mesh"]
        piece_rows = plan.mesh_piece_rows + 2 * SMOOTHING_HALO_ROWS
        return max(0, int(room * by // (PIECE_BYTES_PER_TRIANGLE * piece_rows)))
    elif plan.surface_tile_rows is not None:
        rows = plan.surface_tile_rows
        room = plan.limit_bytes - model["without_mesh"] - model["per_grid_row"] * (rows + 1)
    else:
        return None
    return max(0, int(room // MESH_BYTES_PER_TRIANGLE))


#: how far past its budget a mesh may go before it is refused: the height map's estimate
#: is within 6 % on the synthetic stacks, and the smallest limit a refusal names is sized
#: on it; the refusal is for surfaces several times larger than estimated (a ragged,
#: noisy channel's: 2.8 times on one), and a quarter more mesh is held by the model's
#: other margins (the banded maps counted at 32 bytes a column, measured 18-22)
TRIANGLE_MARGIN = 1.25


def check_triangles(made: int, max_triangles: int | None, when: str = "") -> None:
    """Refuse a mesh of ``made`` triangles (so far) beyond ``max_triangles``
    (:func:`mesh_budget`) and its :data:`TRIANGLE_MARGIN`.

    Raises
    ------
    InputError
        Saying how far it went and the ways out.
    """
    if max_triangles is None or made <= TRIANGLE_MARGIN * max_triangles:
        return

    def count(n: int) -> str:
        return f"{n / 1e6:.1f} million" if n >= 100_000 else f"{n:,}"

    raise InputError(
        f"the surface's mesh is larger than the memory limit holds: {count(made)} "
        f"triangles{' ' + when if when else ''}, against {count(max_triangles)} "
        "(a ragged surface, from noise or debris, makes more than its height map let "
        "estimate); use a larger --memory-limit, a coarser --iso-bin, --no-surface, or "
        "another --channel"
    )


class StackBands:
    """One channel of a lazily read stack (or all combined), a band of rows at a time.

    Parameters
    ----------
    data : (Z, C, Y, X) TiffRows (or array)
    channel : int or None
        The channel read; None combines every channel as
        :func:`mpm3d.io.select_channel` does (each scaled to its 0.1th..99.9th
        percentiles on the same subsample, voxelwise maximum, uint16).
    """

    def __init__(self, data, channel: int | None) -> None:
        self.data = data
        self.channel = channel
        nz, _, ny, nx = data.shape
        self.shape = (nz, ny, nx)
        self.size = nz * ny * nx
        if channel is None:
            from mpm3d.io import channel_ranges

            self.lo, self.hi = channel_ranges(data)
            self.dtype = np.dtype(np.uint16)
        else:
            self.dtype = np.dtype(data.dtype)

    def _combine(self, block: np.ndarray) -> np.ndarray:
        from mpm3d._kernels import combine_channels

        z, _, y, x = block.shape
        out = np.empty((z, y, x), np.uint16)
        combine_channels(block, self.lo, self.hi, out)
        return out

    def rows(self, y0: int, y1: int, z0: int = 0, z1: int | None = None) -> np.ndarray:
        """``volume[z0:z1, y0:y1, :]``: (z1 - z0, y1 - y0, X), read now (every slice by
        default)."""
        if self.channel is None:
            return self._combine(self.data[z0:z1, :, y0:y1, :])
        return self.data[z0:z1, self.channel, y0:y1, :]

    def sample(self, step: int) -> np.ndarray:
        """``volume[::step, ::step, ::step]``, read now."""
        if self.channel is None:
            return self._combine(self.data[::step, :, ::step, ::step])
        return self.data[::step, self.channel, ::step, ::step]


@contextlib.contextmanager
def _counter(progress, description: str) -> Iterator[Callable[[int, int], None]]:
    """``tick(done, total)``: a counter of tissue_core.progress, else a line per band."""
    task = getattr(progress, "task", None)
    if task is not None:
        with task(description, unit="band") as counter:
            yield counter
        return

    def tick(done: int, total: int) -> None:
        if progress is not None:
            progress(f"{description}: {done}/{total} bands")

    yield tick


def disk_bytes(shape: tuple[int, int], spacing: Sequence[float], smooth_um: float) -> int:
    """The temporary disk space :func:`tiled_height_map` takes for a ``(Y, X)`` field: its
    work maps (:data:`DISK_BYTES_PER_COLUMN`), and the smoothing's float64 map extended
    past the edges by four sigma (as :func:`mpm3d.heightmap.smooth_map` extends it)."""
    ny, nx = (int(n) for n in shape)
    dy, dx = (float(v) for v in tuple(spacing)[-2:])
    extended = 0
    if smooth_um > 0:
        py = max(1, min(ny - 1, math.ceil(4 * smooth_um / dy)))
        px = max(1, min(nx - 1, math.ceil(4 * smooth_um / dx)))
        extended = 8 * (ny + 2 * py) * (nx + 2 * px)
    return DISK_BYTES_PER_COLUMN * ny * nx + extended


def tiled_height_map(
    volume: StackBands,
    *,
    spacing: Sequence[float],
    tile_rows: int,
    threshold: float | None = None,
    peak_window_um: float = 20.0,
    smooth_um: float | None = None,
    min_cnr: float = 5.0,
    outlier_um: float | None = None,
    min_coverage: float = 0.05,
    progress=None,
):
    """:func:`mpm3d.heightmap.height_map` of a stack read ``tile_rows`` rows at a time.

    Returns the same :class:`~mpm3d.heightmap.HeightMap` as the whole
    stack in memory (see the module's notes).
    """
    from mpm3d._kernels import first_crossing
    from mpm3d.diskmaps import MapFolder, from_crossings_on_disk
    from mpm3d.heightmap import (
        check_options,
        levels_of_sample,
        otsu_separability,
        sample_step,
    )

    nz, ny, nx = volume.shape
    window, sigma_um = check_options(
        volume.shape,
        spacing=spacing,
        peak_window_um=peak_window_um,
        smooth_um=smooth_um,
        min_cnr=min_cnr,
    )
    threshold_given = threshold is not None
    sub = volume.sample(sample_step(volume.size))
    threshold, background, noise = levels_of_sample(sub, threshold=threshold)
    separability = otsu_separability(sub, threshold)
    del sub
    rows = max(1, int(tile_rows))
    starts = range(0, ny, rows)
    # the crossings and every step after them in files: the (Y, X) maps' work is
    # a band of rows (or a strip of columns) at a time, as the stack's is
    with MapFolder(disk_bytes((ny, nx), spacing, sigma_um)) as folder:
        depth = folder.new((ny, nx), np.float64, "depth")
        peak = folder.new((ny, nx), np.float64, "peak")
        with _counter(progress, "finding the surface") as tick:
            tick(0, len(starts))
            for k, y0 in enumerate(starts):
                y1 = min(ny, y0 + rows)
                a, b = max(0, y0 - 1), min(ny, y1 + 1)  # a halo row each side: the 3 x 3 mean
                band = volume.rows(a, b)
                d = np.empty((b - a, nx), np.float64)
                p = np.empty((b - a, nx), np.float64)
                first_crossing(band, float(threshold), float(background), int(window), d, p)
                del band
                depth.write_rows(y0, d[y0 - a : y1 - a])
                peak.write_rows(y0, p[y0 - a : y1 - a])
                tick(k + 1, len(starts))
        return from_crossings_on_disk(
            depth,
            peak,
            folder,
            spacing=spacing,
            n_slices=nz,
            levels=(threshold, background, noise),
            threshold_given=threshold_given,
            separability=separability,
            peak_window_um=peak_window_um,
            smooth_um=sigma_um,
            min_cnr=min_cnr,
            outlier_um=outlier_um,
            min_coverage=min_coverage,
        )


def tiled_isosurface(
    volume: StackBands,
    *,
    spacing: Sequence[float],
    tile_rows: int,
    level: float,
    depth_um: np.ndarray | None = None,
    band_um: float = 100.0,
    column_scale: tuple[float, np.ndarray] | None = None,
    bin: int | None = None,
    decimate: float = 0.0,
    max_triangles: int | None = None,
    expected_triangles: int = 0,
    piece_rows: int | None = None,
    progress=None,
):
    """:func:`mpm3d.surface.isosurface` of a stack read ``tile_rows`` binned rows at a time.

    Each band of binned rows ``r0 .. r0 + tile_rows`` shares its last row
    with the next band; the mesh is the same as the whole stack's (see the
    module's notes).  Without decimation the mesh is never whole in memory: it is
    merged, smoothed and oriented through files a band at a time
    (:func:`mpm3d.meshstream.stream_isosurface`), and returned as a
    :class:`mpm3d.meshstream.DiskMesh` (``expected_triangles``: the disk space to
    ask for; ``piece_rows``: binned rows per piece it is smoothed in); with
    decimation, assembled whole (a ``pyvista.PolyData``).

    ``max_triangles`` (from :func:`mesh_budget`): the most triangles the memory
    limit holds; a surface that contours into more (noise, debris, a surface less
    smooth than its height map said) is refused as soon as its bands pass it,
    before the mesh is assembled.
    """
    from mpm3d.surface import finish_isosurface, iso_plan

    plan = iso_plan(
        volume.shape,
        volume.dtype,
        spacing=spacing,
        level=level,
        depth_um=depth_um,
        band_um=band_um,
        column_scale=column_scale,
        bin=bin,
        decimate=decimate,
    )
    by = plan.binned[0]
    rows = max(1, int(tile_rows))
    if plan.decimate == 0:
        from mpm3d.diskmaps import MapFolder
        from mpm3d.meshstream import DISK_BYTES_PER_TRIANGLE, stream_isosurface

        folder = MapFolder(int(DISK_BYTES_PER_TRIANGLE * TRIANGLE_MARGIN * expected_triangles),
                           prefix="mpm3d-mesh-")  # fmt: skip
        try:
            with _counter(progress, "building the isosurface") as tick:
                return stream_isosurface(volume, plan, tile_rows=rows, folder=folder,
                                         piece_rows=piece_rows, max_triangles=max_triangles,
                                         tick=tick)  # fmt: skip
        except BaseException:
            folder.close()
            raise
    from mpm3d.surface import _contour_band

    starts = range(0, by - 1, rows)
    pieces = []
    with _counter(progress, "building the isosurface") as tick:
        tick(0, len(starts))
        for k, r0 in enumerate(starts):
            r1 = min(by - 1, r0 + rows)  # the last row, shared with the next band
            pieces.append(_contour_band(volume, plan, r0, r1))
            check_triangles(sum(len(t) for _, t in pieces), max_triangles,
                            f"after {k + 1} of {len(starts)} bands of the isosurface")  # fmt: skip
            tick(k + 1, len(starts))
    return finish_isosurface(pieces, plan)
