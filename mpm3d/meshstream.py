"""An isosurface too large for memory: contoured, merged, smoothed and written a band of
rows at a time through files.

The banded path of :func:`mpm3d.analyze.analyze_stack` (:mod:`mpm3d.tiled`) builds its
mesh here, into a :class:`DiskMesh`; each step gives what
:func:`mpm3d.surface.finish_isosurface` gives for the whole stack, bit for bit:

* bands of binned rows are contoured on the whole grid's coordinates, bands sharing
  their boundary row (:func:`mpm3d.surface.contour_rows`); a band's points are merged
  with the points still open from the bands before and put in the whole mesh's order
  (sorted by ``(y, x, z)``, :func:`mpm3d.surface._canonical`).  A point below the
  band's last row is final (no later band has points there); a triangle is written
  once no open triangle can sort before it (by its least point);
* the largest connected piece: each batch of written triangles is split into its
  connected pieces, and pieces that share a point with an earlier batch's are joined
  (a union-find); the piece with most triangles wins, ties to the one with the lowest
  point (as :func:`mpm3d.surface.largest_component`'s labelling gives);
* the smoothing (:func:`mpm3d.surface.smooth_mesh`) runs on pieces of rows with
  ``iterations + 2`` binned rows of mesh around them: each of its steps moves a vertex
  by its neighbours alone, in the stack's frame;
* the outward flip is decided on the sum over every triangle
  (:func:`mpm3d.surface.outward_sign`), and the point normals are computed on pieces
  with :data:`NORMAL_HALO` rows of mesh around them.

Only a band's contour, a piece of mesh and small per-row counts are in memory at any
time: the files are read and written by offsets (no mapping stays resident).
"""

from __future__ import annotations

import errno
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from mpm3d.errors import InputError

__all__ = ["DiskMesh", "stream_isosurface"]

#: binned rows of mesh around a piece whose point normals are computed (2 are enough:
#: a vertex's normal comes from its own triangles)
NORMAL_HALO = 3
#: triangles per chunk when the mesh's files are read through
CHUNK = 1 << 18
#: bytes of temporary disk per triangle: the contour's triangles and their pieces, the
#: largest piece's, its points before and after smoothing, the normals (about half a
#: point per triangle) and the vertical errors
DISK_BYTES_PER_TRIANGLE = 96


class _Rows:
    """A file of rows of ``width`` numbers, appended to and read by offsets (never
    mapped: nothing of it stays resident)."""

    def __init__(self, path: Path, dtype, width: int) -> None:
        self.path, self.dtype, self.width = Path(path), np.dtype(dtype), int(width)
        self.row_bytes = self.dtype.itemsize * self.width
        self.n = 0
        self.path.write_bytes(b"")

    def __len__(self) -> int:
        return self.n

    def append(self, values: np.ndarray) -> None:
        values = np.ascontiguousarray(values, self.dtype).reshape(-1, self.width)
        with _disk_full(), open(self.path, "ab") as f:
            values.tofile(f)
        self.n += len(values)

    def put(self, start: int, values: np.ndarray) -> None:
        """Overwrite rows from ``start`` (the file grows as needed)."""
        values = np.ascontiguousarray(values, self.dtype).reshape(-1, self.width)
        with _disk_full(), open(self.path, "r+b") as f:
            f.seek(int(start) * self.row_bytes)
            values.tofile(f)
        self.n = max(self.n, int(start) + len(values))

    def read(self, start: int, stop: int) -> np.ndarray:
        start, stop = max(0, int(start)), min(int(stop), self.n)
        if stop <= start:
            return np.empty((0, self.width), self.dtype)
        with open(self.path, "rb") as f:
            f.seek(start * self.row_bytes)
            data = np.fromfile(f, self.dtype, (stop - start) * self.width)
        return data.reshape(-1, self.width)

    def chunks(self, size: int | None = None) -> Iterator[np.ndarray]:
        size = size or CHUNK
        for start in range(0, self.n, size):
            yield self.read(start, start + size)


class _disk_full:
    """Turns a full disk while the mesh's files are written into one clear error."""

    def __enter__(self):
        return self

    def __exit__(self, kind, error, tb):
        if isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT):
            raise InputError(
                "the disk filled up while the isosurface's work files were written; set "
                "TMPDIR to a folder with more space, or use --no-surface"
            ) from None
        return False


class _Pieces:
    """The connected pieces of a mesh whose triangles come in batches (sorted by their
    least point): each batch's own pieces, joined through the points shared with earlier
    batches."""

    def __init__(self) -> None:
        self.parent = np.zeros(0, np.int64)
        self.count = np.zeros(0, np.int64)  # triangles per piece of a batch
        self.low = np.zeros(0, np.int64)  # its lowest point
        self.carry_ids = np.zeros(0, np.int64)  # points later batches may share
        self.carry_node = np.zeros(0, np.int64)

    def find(self, x: int) -> int:
        parent = self.parent
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = int(parent[x])
        return x

    def union(self, a: int, b: int) -> None:
        a, b = self.find(a), self.find(b)
        if a != b:
            self.parent[max(a, b)] = min(a, b)

    def add(self, tris: np.ndarray, later_from: int) -> np.ndarray:
        """The piece (node) of each triangle of a batch; ``later_from``: the least point
        a later batch's triangle may have."""
        import scipy.sparse as sp
        from scipy.sparse.csgraph import connected_components

        if len(tris) == 0:
            return np.zeros(0, np.int64)
        verts, inverse = np.unique(tris, return_inverse=True)
        inverse = inverse.reshape(-1, 3)
        n = len(verts)
        rows = np.concatenate([inverse[:, 0], inverse[:, 1]])
        cols = np.concatenate([inverse[:, 1], inverse[:, 2]])
        graph = sp.csr_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(n, n))
        c, labels = connected_components(graph, directed=False)
        start = len(self.parent)
        nodes = start + labels.astype(np.int64)
        _, first = np.unique(labels, return_index=True)  # verts are sorted: the lowest
        self.parent = np.concatenate([self.parent, np.arange(start, start + c)])
        self.count = np.concatenate([self.count, np.bincount(labels[inverse[:, 0]], minlength=c)])
        self.low = np.concatenate([self.low, verts[first]])
        _, ia, ib = np.intersect1d(self.carry_ids, verts, assume_unique=True, return_indices=True)
        for a, b in zip(self.carry_node[ia].tolist(), nodes[ib].tolist(), strict=True):
            self.union(a, b)
        keep = self.carry_ids >= later_from
        new = verts >= later_from
        ids = np.concatenate([self.carry_ids[keep], verts[new]])
        owner = np.concatenate([self.carry_node[keep], nodes[new]])
        self.carry_ids, at = np.unique(ids, return_index=True)
        self.carry_node = owner[at]
        return nodes[inverse[:, 0]]

    def roots(self) -> np.ndarray:
        return np.array([self.find(x) for x in range(len(self.parent))], np.int64)

    def largest(self) -> tuple[np.ndarray, int, int]:
        """Each node's root, the largest piece's root, and the number of pieces."""
        roots = self.roots()
        if not len(roots):
            return roots, -1, 0
        unique, inverse = np.unique(roots, return_inverse=True)
        count = np.bincount(inverse, weights=self.count).astype(np.int64)
        low = np.full(len(unique), np.iinfo(np.int64).max)
        np.minimum.at(low, inverse, self.low)
        best = np.lexsort((low, -count))[0]
        return roots, int(unique[best]), len(unique)


class DiskMesh:
    """An isosurface held in files: points ``(x, y, depth)`` um (float32, sorted by
    ``(y, x, z)``), triangles (sorted by their least point) and point normals, read a
    chunk or a piece of rows at a time.

    Made by :func:`stream_isosurface`; :meth:`polydata` loads it whole (where it fits).
    Its files are removed by :meth:`close` (and when the object is collected).

    Attributes
    ----------
    n_points, n_cells : int
    field_data : dict
        As the in-memory mesh's: ``level``, ``spacing_um``, ``lateral_bin`` and, after
        :func:`mpm3d.surface.add_height`, the height's datum.
    datum_depth_um : float or None
        Set by :func:`mpm3d.surface.add_height`: the point array ``height_um`` is
        ``datum_depth_um - depth``.
    """

    def __init__(self, folder, points: _Rows, triangles: _Rows, normals: _Rows, *,
                 flipped: bool, field_data: dict) -> None:  # fmt: skip
        import weakref

        self.folder = folder
        self._points, self._triangles, self._normals = points, triangles, normals
        self.flipped = bool(flipped)
        self.field_data = field_data
        self.datum_depth_um: float | None = None
        self._finalizer = weakref.finalize(self, folder.close)

    @property
    def n_points(self) -> int:
        return len(self._points)

    @property
    def n_cells(self) -> int:
        return len(self._triangles)

    def close(self) -> None:
        """Remove the mesh's files."""
        self._finalizer()

    # ------------------------------------------------------------------ reading

    def points(self, start: int, stop: int) -> np.ndarray:
        return self._points.read(start, stop)

    def normals(self, start: int, stop: int) -> np.ndarray:
        return self._normals.read(start, stop)

    def triangles(self, start: int, stop: int) -> np.ndarray:
        """Triangles ``start .. stop`` as the mesh has them (reversed where flipped outward)."""
        t = self._triangles.read(start, stop)
        return t[:, ::-1].copy() if self.flipped else t

    def point_chunks(self, size: int | None = None) -> Iterator[np.ndarray]:
        size = size or CHUNK
        for start in range(0, self.n_points, size):
            yield self.points(start, start + size)

    def triangle_chunks(self, size: int | None = None) -> Iterator[np.ndarray]:
        size = size or CHUNK
        for start in range(0, self.n_cells, size):
            yield self.triangles(start, start + size)

    def point_arrays(self) -> dict[str, tuple[str, int, Callable[[], Iterator[np.ndarray]]]]:
        """The point arrays as the in-memory mesh has them: name -> (type, components,
        chunks)."""

        def normals():
            return self._normals.chunks()

        def depth():
            for p in self.point_chunks():
                yield p[:, 2].copy()

        def height():
            for p in self.point_chunks():
                yield float(self.datum_depth_um) - np.asarray(p[:, 2], np.float64)

        arrays = {"Normals": ("float32", 3, normals), "depth_um": ("float32", 1, depth)}
        if self.datum_depth_um is not None:
            arrays["height_um"] = ("float64", 1, height)
        return arrays

    def polydata(self):
        """The whole mesh as a ``pyvista.PolyData`` (the in-memory mesh's arrays)."""
        import pyvista as pv

        points = self.points(0, self.n_points)
        tris = self.triangles(0, self.n_cells)
        mesh = pv.PolyData(points, np.column_stack([np.full(len(tris), 3), tris]).ravel())
        for name, (_, _, chunks) in self.point_arrays().items():
            mesh.point_data[name] = np.concatenate(list(chunks()) or [np.zeros(0)])
        mesh.point_data.active_normals_name = "Normals"
        for name, value in self.field_data.items():
            mesh.field_data[name] = value
        return mesh

    # ------------------------------------------------------------------ writing

    def save(self, path) -> None:
        """Write the mesh as ``.vtp`` (:meth:`save_vtp`) or ``.ply`` (:meth:`save_ply`),
        as ``pyvista.PolyData.save`` would for those two."""
        suffix = Path(path).suffix.lower()
        if suffix == ".vtp":
            self.save_vtp(path)
        elif suffix == ".ply":
            self.save_ply(path)
        else:
            raise ValueError(f"a mesh on disk is written as .vtp or .ply, not {suffix or path!r}")

    def save_vtp(self, path) -> None:
        """VTK XML PolyData, zlib-compressed, written a chunk at a time."""
        from tissue_core.vtkio import write_triangles_streamed

        fields = {k: (list(v) if v.dtype.kind in "US" else v) for k, v in self.field_data.items()}
        write_triangles_streamed(
            path, self.n_points, self.n_cells, self.point_chunks, self.triangle_chunks,
            self.point_arrays(), fields, normals="Normals",
        )  # fmt: skip

    def save_ply(self, path) -> None:
        """Binary PLY, byte for byte as VTK's writer makes it of the in-memory mesh
        (points and normals as float32, triangles as uchar-counted int lists)."""
        header = (
            "ply\nformat binary_little_endian 1.0\ncomment VTK generated PLY File\n"
            "obj_info vtkPolyData points and polygons: vtk4.0\n"
            f"element vertex {self.n_points}\nproperty float x\nproperty float y\n"
            "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
            f"element face {self.n_cells}\nproperty list uchar int vertex_indices\n"
            "end_header\n"
        )
        vertex = np.dtype([("p", "<f4", 3), ("n", "<f4", 3)])
        face = np.dtype([("k", "u1"), ("v", "<i4", 3)])
        with open(path, "wb") as f:  # an output: a full disk is the writer's OSError
            f.write(header.encode("ascii"))
            for start in range(0, self.n_points, CHUNK):
                rows = np.empty(min(CHUNK, self.n_points - start), vertex)
                rows["p"] = self.points(start, start + CHUNK)
                rows["n"] = self.normals(start, start + CHUNK)
                rows.tofile(f)
            for t in self.triangle_chunks():
                rows = np.empty(len(t), face)
                rows["k"], rows["v"] = 3, t
                rows.tofile(f)


def stream_isosurface(
    volume,
    plan,
    *,
    tile_rows: int,
    folder,
    piece_rows: int | None = None,
    smooth_iterations: int = 40,
    pass_band: float = 0.02,
    max_triangles: int | None = None,
    tick: Callable[[int, int], None] | None = None,
) -> DiskMesh:
    """The isosurface of a stack read a band of ``tile_rows`` binned rows at a time,
    into files in ``folder`` (a :class:`mpm3d.diskmaps.MapFolder`, closed with the mesh):
    the mesh :func:`mpm3d.surface.finish_isosurface` makes of the whole stack, bit for
    bit (see the module's notes; ``plan.decimate`` must be 0).

    Parameters
    ----------
    volume : :class:`mpm3d.tiled.StackBands`
    plan : :class:`mpm3d.surface.IsoPlan`
    tile_rows : int
        Binned rows per band of the contour.
    piece_rows : int, optional
        Binned rows per piece the mesh is smoothed and its normals computed in
        (besides the rows around them); ``tile_rows`` by default.
    max_triangles : int, optional
        Refuse a contour of more triangles (:func:`mpm3d.tiled.check_triangles`).
    tick : callable, optional
        ``tick(done, total)`` over the contour's bands and the pieces' passes.
    """
    from mpm3d.surface import _contour_band, outward_sign, smooth_mesh
    from mpm3d.tiled import check_triangles

    if plan.decimate > 0:
        raise ValueError("a mesh streamed through files cannot be decimated")
    tick = tick or (lambda done, total: None)
    path = Path(folder.path)
    rows = max(1, int(tile_rows))
    by = plan.binned[0]
    b = plan.bin
    dy = plan.spacing[1]
    y0, step = (b - 1) * dy / 2, dy * b  # the binned rows' y (um)
    starts = range(0, by - 1, rows)
    piece = max(1, int(piece_rows or rows))
    passes = len(starts) + 2 * len(range(0, by, piece))
    raw_points = _Rows(path / "contour-points.bin", np.float32, 3)
    raw_tris = _Rows(path / "contour-triangles.bin", np.int64, 3)
    nodes = _Rows(path / "contour-pieces.bin", np.int64, 1)
    pieces = _Pieces()
    open_points = np.empty((0, 3), np.float32)
    open_tris = np.empty((0, 3), np.int64)
    base, made = 0, 0
    tick(0, passes)
    for k, r0 in enumerate(starts):
        r1 = min(by - 1, r0 + rows)
        band = _contour_band(volume, plan, r0, r1)
        made += len(band[1])
        check_triangles(made, max_triangles,
                        f"after {k + 1} of {len(starts)} bands of the isosurface")  # fmt: skip
        seam = None if r1 == by - 1 else y0 + (r1 - 0.25) * step
        base, open_points, open_tris, written = _merge(band, open_points, open_tris, base, seam)
        raw_points.append(written[0])
        later = min(base, int(open_tris[:, 0].min()) if len(open_tris) else base)
        raw_tris.append(written[1])
        nodes.append(pieces.add(written[1], later))
        del band, written
        tick(k + 1, passes)
    if len(open_points) or len(open_tris):
        raise AssertionError("the last band left points or triangles open")  # pragma: no cover
    if len(raw_tris) == 0:
        raise InputError(f"no isosurface at grey level {plan.level:g}")
    roots, best, count = pieces.largest()
    points, tris, row_starts = _keep_piece(
        raw_points, raw_tris, nodes, roots == best if count > 1 else None, path, by, y0, step
    )
    for f in (raw_points, raw_tris, nodes):
        f.path.unlink()
    done = len(starts)
    # the smoothing, a piece of rows at a time (into a new file: the pieces around read
    # the points before it)
    smooth = points
    if smooth_iterations > 0:
        smooth = _Rows(path / "smoothed-points.bin", np.float32, 3)
        halo = int(smooth_iterations) + 2
        for a in range(0, by, piece):
            part, core = _piece(points, tris, row_starts, a, min(a + piece, by), halo, by)
            if part is not None:
                moved = smooth_mesh(part, plan, iterations=smooth_iterations, pass_band=pass_band)
                smooth.put(core[0], np.asarray(moved.points)[core[1] : core[2]])
            done += 1
            tick(done, passes)
        points.path.unlink()
    flipped = outward_sign(_triangle_chunks(smooth.read, tris.read, len(tris))) > 0
    normals = _Rows(path / "normals.bin", np.float32, 3)
    for a in range(0, by, piece):
        part, core = _piece(smooth, tris, row_starts, a, min(a + piece, by), NORMAL_HALO, by,
                            flip=flipped)  # fmt: skip
        if part is not None:
            part = part.compute_normals(
                cell_normals=False,
                split_vertices=False,
                consistent_normals=False,
                auto_orient_normals=False,
            )
            normals.put(core[0], np.asarray(part.point_data["Normals"])[core[1] : core[2]])
        done += 1
        tick(done, passes)
    dz, dy_, dx = plan.spacing
    field_data = {
        "level": np.array([plan.level]),
        "spacing_um": np.array([dz, dy_, dx]),
        "lateral_bin": np.array([plan.bin]),
    }
    return DiskMesh(folder, smooth, tris, normals, flipped=flipped, field_data=field_data)


def _merge(band, open_points, open_tris, base: int, seam_y: float | None):
    """A band's points and triangles merged with those still open: the new number of
    final points, the points and triangles still open, and (points, triangles) final now.

    Open triangles hold final points by their index (< ``base``) and open points by
    ``base`` + their place among the open points."""
    points, tris = band
    merged = np.concatenate([open_points, np.asarray(points, np.float32)])
    yxz, inverse = np.unique(merged[:, [1, 0, 2]], axis=0, return_inverse=True)
    lut = inverse.reshape(-1).astype(np.int64) + base
    merged = yxz[:, [1, 0, 2]]
    held = open_tris.copy()
    later = held >= base
    held[later] = lut[held[later] - base]
    tris = np.concatenate([held, lut[len(open_points) + np.asarray(tris, np.int64)]])
    first = np.argmin(tris, axis=1)
    tris = np.take_along_axis(tris, (first[:, None] + np.arange(3)) % 3, axis=1)
    # points below the seam row are final: no later band has any there
    final = len(merged) if seam_y is None else int(np.searchsorted(merged[:, 1], seam_y))
    new_base = base + final
    waiting = tris.max(axis=1) >= new_base
    least = int(tris[waiting, 0].min()) if waiting.any() else np.iinfo(np.int64).max
    out = tris[:, 0] < least  # no triangle still open sorts before these
    written = tris[out]
    written = written[np.lexsort(written.T[::-1])]
    return new_base, merged[final:], tris[~out], (merged[:final], written)


def _row_of(y: np.ndarray, y0: float, step: float) -> np.ndarray:
    """Each point's binned row (a point between two rows counts with the upper one)."""
    return np.floor((np.asarray(y, np.float64) - y0) / step + 1e-3).astype(np.int64)


def _keep_piece(raw_points: _Rows, raw_tris: _Rows, nodes: _Rows, keep_node, path: Path,
                by: int, y0: float, step: float):  # fmt: skip
    """The triangles of the largest piece (``keep_node[node]``; all where None) and their
    points, renumbered in order; the first point of each binned row."""
    used = np.zeros(len(raw_points), bool)
    for start in range(0, len(raw_tris), CHUNK):
        t = raw_tris.read(start, start + CHUNK)
        if keep_node is not None:
            t = t[keep_node[nodes.read(start, start + CHUNK)[:, 0]]]
        used[t.ravel()] = True
    block = 1 << 16
    per_block = np.bincount(np.flatnonzero(used) >> 16, minlength=len(used) // block + 1)
    before = np.concatenate([[0], np.cumsum(per_block)]).astype(np.int64)
    points = _Rows(path / "points.bin", np.float32, 3)
    per_row = np.zeros(by + 1, np.int64)
    for start in range(0, len(raw_points), CHUNK):
        p = raw_points.read(start, start + CHUNK)[used[start : start + CHUNK]]
        points.append(p)
        per_row += np.bincount(np.clip(_row_of(p[:, 1], y0, step), 0, by), minlength=by + 1)
    row_starts = np.concatenate([[0], np.cumsum(per_row)])[: by + 1]
    tris = _Rows(path / "triangles.bin", np.int64, 3)
    for start in range(0, len(raw_tris), CHUNK):
        t = raw_tris.read(start, start + CHUNK)
        if keep_node is not None:
            t = t[keep_node[nodes.read(start, start + CHUNK)[:, 0]]]
        if not len(t):
            continue
        lo, hi = int(t.min()), int(t.max()) + 1
        skipped = before[lo // block] + int(used[(lo // block) * block : lo].sum())
        rank = np.cumsum(used[lo:hi]) - 1 + skipped
        tris.append(rank[t - lo])
    return points, tris, row_starts


def _piece(points: _Rows, tris: _Rows, row_starts: np.ndarray, a: int, b: int, halo: int,
           by: int, *, flip: bool = False):  # fmt: skip
    """The mesh's piece in binned rows ``a - halo .. b + halo`` (its points and triangles
    in the mesh's order) and where its rows ``a .. b`` lie: (first point in the mesh,
    first and end in the piece); None where the piece has no triangle."""
    import pyvista as pv

    p0, p1 = row_starts[max(a - halo, 0)], row_starts[min(b + halo, by)]
    c0, c1 = row_starts[a], row_starts[b]
    if c1 <= c0:
        return None, None
    # the triangles whose least point lies in the piece, the whole triangle inside it
    t = _triangles_from(tris, p0, p1)
    t = t[t.max(axis=1) < p1] - p0
    if not len(t):
        return None, None
    if flip:
        t = t[:, ::-1]
    part = pv.PolyData(points.read(p0, p1), np.column_stack([np.full(len(t), 3), t]).ravel())
    return part, (c0, c0 - p0, c1 - p0)


def _triangles_from(tris: _Rows, p0: int, p1: int) -> np.ndarray:
    """The triangles whose least point is in ``p0 .. p1`` (found by bisection: the
    triangles are sorted by their least point)."""

    def least(i: int) -> int:
        return int(tris.read(i, i + 1)[0, 0])

    def first_at(value: int) -> int:
        lo, hi = 0, len(tris)
        while lo < hi:
            mid = (lo + hi) // 2
            if least(mid) < value:
                lo = mid + 1
            else:
                hi = mid
        return lo

    return tris.read(first_at(p0), first_at(p1))


def _triangle_chunks(points, triangles, n_triangles: int):
    """``(points, triangles, first point)`` per fixed chunk of :data:`CHUNK` triangles:
    ``triangles(a, b)`` read in order, the range of points they use as float64
    (``points(lo, hi)``) and the triangles indexing it."""
    for start in range(0, n_triangles, CHUNK):
        t = triangles(start, start + CHUNK)
        lo, hi = int(t.min()), int(t.max()) + 1
        yield np.asarray(points(lo, hi), np.float64), t - lo, lo


def chunks_of(mesh) -> Callable[[], Iterator[tuple[np.ndarray, np.ndarray, int]]]:
    """For a :class:`DiskMesh` or an in-memory mesh: a callable yielding ``(points,
    triangles, first point)`` per fixed chunk of :data:`CHUNK` triangles in the mesh's
    order (the points a range the chunk uses, the triangles indexing it), so sums over a
    mesh come out the same either way."""
    if isinstance(mesh, DiskMesh):
        return lambda: _triangle_chunks(mesh.points, mesh.triangles, mesh.n_cells)
    points = np.asarray(mesh.points)
    faces = np.asarray(mesh.regular_faces, np.int64)
    return lambda: _triangle_chunks(lambda a, b: points[a:b], lambda a, b: faces[a:b], len(faces))


def point_chunks_of(mesh, size: int | None = None) -> Iterator[np.ndarray]:
    """The points of a :class:`DiskMesh` or an in-memory mesh, a chunk at a time."""
    size = size or CHUNK
    if isinstance(mesh, DiskMesh):
        yield from mesh.point_chunks(size)
        return
    points = np.asarray(mesh.points)
    for start in range(0, len(points), size):
        yield points[start : start + size]


def bounds_of(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The lowest and highest ``(x, y, z)`` of a mesh's points (on disk or in memory),
    read once, a chunk at a time."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for p in point_chunks_of(mesh):
        lo, hi = np.minimum(lo, p.min(axis=0)), np.maximum(hi, p.max(axis=0))
    return lo, hi
