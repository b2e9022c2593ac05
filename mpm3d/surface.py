"""Triangulated lumen surfaces: from the height map, and as an isosurface.

Meshes are :class:`pyvista.PolyData` in micrometres with points
``(x, y, z)`` = (column, row, depth below slice 0): the stack's own
right-handed frame, so a mesh overlays the stack in ParaView or napari.
Normals point out of the tissue into the lumen (towards the objective,
negative z).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpm3d.errors import InputError

__all__ = [
    "IsoPlan",
    "add_height",
    "column_work",
    "contour_rows",
    "finish_isosurface",
    "heightmap_mesh",
    "iso_plan",
    "isosurface",
    "largest_component",
    "mesh_quality",
    "orient_outward",
    "vertical_error",
]

log = logging.getLogger(__name__)


def _pyvista():
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkSMPTools

    # VTK's wheel starts with the sequential backend; flying edges and the
    # other SMP filters use every core with the STDThread one.
    smp = vtkSMPTools()
    if smp.GetBackend() != "STDThread":
        smp.SetBackend("STDThread")
    return pv


def heightmap_mesh(depth_um: np.ndarray, *, spacing: Sequence[float], stride: int = 1, mask=None):
    """Triangulate a depth map on its pixel grid.

    Parameters
    ----------
    depth_um : (Y, X) float
        Surface depth below slice 0, um.
    spacing : (dz, dy, dx) or (dy, dx) um
    stride : int
        Keep every ``stride``-th row and column.
    mask : (Y, X) bool, optional
        Drop triangles with a corner outside the mask.

    Returns
    -------
    pyvista.PolyData
        Points ``(x, y, depth)``; a ``depth_um`` point array; normals
        towards the lumen.

    Examples
    --------
    >>> m = heightmap_mesh(np.full((3, 4), 5.0), spacing=(2.0, 1.0))
    >>> m.n_points, m.n_cells, float(m.point_normals[0, 2])
    (12, 12, -1.0)
    """
    pv = _pyvista()
    spacing = tuple(float(s) for s in spacing)
    dy, dx = spacing[-2:]
    if stride < 1:
        raise InputError(f"stride must be >= 1, got {stride}")
    d = np.asarray(depth_um, np.float64)[::stride, ::stride]
    ny, nx = d.shape
    if ny < 2 or nx < 2:
        raise InputError("the depth map needs at least 2 x 2 samples")
    yy, xx = np.meshgrid(np.arange(ny) * dy * stride, np.arange(nx) * dx * stride, indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), d.ravel()])
    idx = np.arange(ny * nx).reshape(ny, nx)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, e = idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    # (x right, y down, z down) is right-handed: a -> c -> b turns about -z
    tris = np.concatenate([np.column_stack([a, c, b]), np.column_stack([b, c, e])])
    if mask is not None:
        keep = np.asarray(mask, bool)[::stride, ::stride].ravel()
        tris = tris[keep[tris].all(axis=1)]
    faces = np.column_stack([np.full(len(tris), 3), tris]).ravel()
    mesh = pv.PolyData(points, faces)
    mesh.point_data["depth_um"] = d.ravel()
    if mesh.n_cells == 0:
        return mesh
    mesh = mesh.compute_normals(
        cell_normals=False,
        split_vertices=False,
        consistent_normals=False,
        auto_orient_normals=False,
    )
    return mesh


def largest_component(mesh):
    """The connected piece of ``mesh`` with the most triangles.

    Uses a sparse-graph labelling of the vertices (much faster than VTK's
    connectivity filter on multi-million triangle meshes).
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    pv = _pyvista()
    if mesh.n_cells == 0:
        return mesh
    faces = mesh.regular_faces
    n = mesh.n_points
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = sp.csr_matrix((np.ones(rows.size, np.int8), (rows, cols)), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    if count == 1:
        return mesh
    face_label = labels[faces[:, 0]]
    best = np.bincount(face_label).argmax()
    keep = faces[face_label == best]
    used, inverse = np.unique(keep, return_inverse=True)
    out = pv.PolyData(
        mesh.points[used], np.column_stack([np.full(len(keep), 3), inverse.reshape(-1, 3)])
    )
    for name in mesh.point_data:
        out.point_data[name] = mesh.point_data[name][used]
    log.info("largest component: %d of %d pieces, %d triangles", 1, count, len(keep))
    return out


def outward_sign(chunks) -> float:
    """The z-component of a mesh's area-weighted normal (twice the signed projected
    area), summed over ``chunks`` of ``(points, triangles, first point)``
    (:func:`mpm3d.meshstream.chunks_of`) in float64: positive where the triangles face
    into the tissue (+z)."""
    total = 0.0
    for p, t, _ in chunks:
        u, v = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
        total += float((u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]).sum())
    return total


def orient_outward(mesh):
    """Flip the triangles if the area-weighted normal points into the tissue (+z)."""
    from mpm3d.meshstream import chunks_of

    if mesh.n_cells == 0:
        return mesh
    if outward_sign(chunks_of(mesh)()) > 0:
        mesh = mesh.flip_faces()
    return mesh.compute_normals(
        cell_normals=False,
        split_vertices=False,
        consistent_normals=False,
        auto_orient_normals=False,
    )


def isosurface(
    volume: np.ndarray,
    *,
    spacing: Sequence[float],
    level: float,
    depth_um: np.ndarray | None = None,
    band_um: float = 100.0,
    column_scale: tuple[float, np.ndarray] | None = None,
    bin: int | None = None,
    smooth_iterations: int = 40,
    pass_band: float = 0.02,
    decimate: float = 0.0,
    max_triangles: int | None = None,
):
    """The lumen surface as a VTK flying-edges isosurface of the stack.

    Parameters
    ----------
    volume : (Z, Y, X) array
        The stack channel, read in place.
    spacing : (dz, dy, dx) um
    level : float
        Grey level of the surface (e.g. :attr:`HeightMap.level`).  For
        integer data a level half-way between grey values keeps the
        surface from passing through voxels exactly (no holes or
        duplicate points); it is nudged by 0.5 when it falls on an integer.
    depth_um : (Y, X) float, optional
        A height map (see :func:`mpm3d.heightmap.height_map`).  When given,
        only a band of ``band_um`` around it is contoured from the data:
        voxels further above are taken as lumen and further below as tissue,
        so collagen fibres and dark pockets deep in the tissue, or debris in
        the lumen, do not add surfaces.  Folds that overhang by less than the
        band are kept.
    column_scale : (background, peak (Y, X)), optional
        Contour each column at its own half-maximum: the volume is scaled to
        ``(v - background) / (peak - background)`` per column (``peak`` as in
        :attr:`mpm3d.heightmap.HeightMap.peak`) and ``level`` should be 0.5.
        The surface then follows the height map's definition where the
        surface layer is dimmer or brighter than average.
    bin : int, optional
        Average ``bin`` x ``bin`` lateral blocks first.  By default the
        lateral voxel size is brought close to the z-step
        (``round(dz / max(dy, dx))``, at most 4), which gives near-cubic
        voxels and a mesh of the resolution the stack really has in 3D.
    smooth_iterations, pass_band : int, float
        Windowed-sinc smoothing (Taubin, Zhang & Golub 1996, doi:10.1007/BFb0015544),
        which does not shrink the surface; 0 iterations turn it off.
    decimate : float in [0, 1)
        Fraction of triangles to remove by quadric decimation (slow on
        large meshes; 0 = off).
    max_triangles : int, optional
        Refuse (:class:`InputError`) a contour of more triangles, before the
        mesh is merged and smoothed (:func:`mpm3d.tiled.mesh_budget`: what a
        memory limit holds).

    Returns
    -------
    pyvista.PolyData
        The largest connected piece, points ``(x, y, depth)`` in um,
        outward (towards the lumen) normals.

    References
    ----------
    Schroeder, Maynard, Geveci, Flying edges: a high-performance scalable
    isocontouring algorithm, IEEE LDAV 2015, doi:10.1109/LDAV.2015.7348069.
    """
    if volume.ndim != 3:
        raise InputError(f"volume must be (Z, Y, X), got shape {volume.shape}")
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
    work = column_work(volume, plan, 0)
    piece = contour_rows(work, plan, 0)
    del work
    if max_triangles is not None:
        from mpm3d.tiled import check_triangles

        check_triangles(len(piece[1]), max_triangles, "contoured")
    return finish_isosurface(
        [piece], plan, smooth_iterations=smooth_iterations, pass_band=pass_band
    )


@dataclass(frozen=True, eq=False)
class IsoPlan:
    """What :func:`isosurface` does to every column, decided once for the whole stack.

    The per-column work (:func:`column_work`) and the contouring
    (:func:`contour_rows`) of any band of rows then give exactly the
    triangles and points the whole stack gives in that band.

    Attributes
    ----------
    shape : (Z, Y, X)
    spacing : (dz, dy, dx) um
    bin : int
        Lateral binning.
    level : float
        The contour level (nudged off integers for integer data without
        ``column_scale``).
    background : float or None
        ``column_scale``'s background.
    scale : (Y // bin, X // bin) float32 or None
        ``1 / (peak - background)`` per binned column.
    top, bottom : (Y // bin, X // bin) int64
        The band contoured from the data, in slices.
    decimate : float
    """

    shape: tuple[int, int, int]
    spacing: tuple[float, float, float]
    bin: int
    level: float
    background: float | None
    scale: np.ndarray | None
    top: np.ndarray
    bottom: np.ndarray
    decimate: float

    @property
    def binned(self) -> tuple[int, int]:
        """``(Y // bin, X // bin)``: the rows and columns of the contoured grid."""
        return self.top.shape


def default_bin(spacing: Sequence[float]) -> int:
    """The isosurface's lateral binning when none is given: voxels near cubic (1 to 4)."""
    dz, dy, dx = (float(v) for v in spacing)
    return int(min(4, max(1, round(dz / max(dx, dy)))))


def iso_plan(
    shape: Sequence[int],
    dtype,
    *,
    spacing: Sequence[float],
    level: float,
    depth_um: np.ndarray | None = None,
    band_um: float = 100.0,
    column_scale: tuple[float, np.ndarray] | None = None,
    bin: int | None = None,
    decimate: float = 0.0,
) -> IsoPlan:
    """Check :func:`isosurface`'s options for a ``(Z, Y, X)`` stack and plan its columns."""
    dz, dy, dx = (float(s) for s in spacing)
    nz, ny, nx = (int(n) for n in shape)
    if bin is None:
        bin = default_bin(spacing)
    if bin < 1:
        raise InputError(f"bin must be >= 1, got {bin}")
    if ny // bin < 2 or nx // bin < 2:
        raise InputError(
            f"bin {bin} (--iso-bin) leaves {ny // bin} x {nx // bin} columns of the "
            f"{ny} x {nx} px stack; use at most {min(ny, nx) // 2}"
        )
    if not 0 <= decimate < 1:
        raise InputError(f"decimate must be in [0, 1), got {decimate}")
    integer = np.issubdtype(dtype, np.integer)
    if column_scale is None and integer and float(level).is_integer():
        level = float(level) + 0.5
    by, bx = ny // bin, nx // bin

    def blocks(a: np.ndarray, name: str) -> np.ndarray:
        """The mean of each bin x bin block, 256 binned rows at a time (no map-sized
        float64 copy)."""
        if np.shape(a) != (ny, nx):
            raise InputError(f"{name} must be {(ny, nx)}, got {np.shape(a)}")
        out = np.empty((by, bx))
        for r in range(0, by, 256):
            part = np.asarray(a[r * bin : min(by, r + 256) * bin, : bx * bin], np.float64)
            out[r : r + 256] = part.reshape(-1, bin, bx, bin).mean(axis=(1, 3))
        return out

    background = scale = None
    if column_scale is not None:
        background, peak = column_scale
        background = float(background)
        span = blocks(peak, "the peak map") - background
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = np.where(np.isfinite(span) & (span > 0), 1.0 / span, 0.0).astype(np.float32)
    if depth_um is not None:
        d = blocks(depth_um, "depth_um")
        top = np.clip(np.floor((d - band_um) / dz), 0, nz).astype(np.int64)
        bottom = np.clip(np.ceil((d + band_um) / dz) + 1, 0, nz).astype(np.int64)
    else:
        top = np.zeros((by, bx), np.int64)
        bottom = np.full((by, bx), nz, np.int64)
    return IsoPlan(
        shape=(nz, ny, nx),
        spacing=(dz, dy, dx),
        bin=int(bin),
        level=float(level),
        background=background,
        scale=scale,
        top=top,
        bottom=bottom,
        decimate=float(decimate),
    )


def column_work(volume: np.ndarray, plan: IsoPlan, row0: int) -> np.ndarray:
    """The grid contoured for binned rows ``row0 ..``: binned, scaled, tissue filled.

    Parameters
    ----------
    volume : (Z, R * bin (+ up to bin - 1), X) array
        The stack's rows ``row0 * bin`` onwards (the whole stack for
        ``row0 = 0``); rows past the last whole bin are left out, as are
        the columns past ``(X // bin) * bin``.
    plan : IsoPlan
    row0 : int
        The first binned row of ``volume``.

    Returns
    -------
    (Z, R, X // bin) array
        float32 (the stack's type for ``bin = 1`` without ``column_scale``).
    """
    from mpm3d._kernels import bin_lateral

    nz = volume.shape[0]
    b = plan.bin
    rows = min(volume.shape[1] // b, plan.binned[0] - row0)
    bx = plan.binned[1]
    if b > 1:
        work = np.empty((nz, rows, bx), np.float32)
        bin_lateral(volume, b, work)
    elif plan.scale is not None:
        work = np.asarray(volume[:, :rows, :bx], dtype=np.float32).copy()
    else:
        work = np.array(volume[:, :rows, :bx])  # a copy in the stack's own type: filled below
    level = plan.level
    if plan.scale is not None:
        np.subtract(work, np.float32(plan.background), out=work)
        np.multiply(work, plan.scale[None, row0 : row0 + rows], out=work)
    if np.issubdtype(work.dtype, np.floating):
        np.nan_to_num(work, copy=False, nan=level - 1.0, posinf=level + 1.0)
    rows_of = slice(row0, row0 + rows)
    _fill_tissue(work, level, plan.top[rows_of], plan.bottom[rows_of])
    return work


def contour_rows(work: np.ndarray, plan: IsoPlan, row0: int) -> tuple[np.ndarray, np.ndarray]:
    """Flying-edges triangles of :func:`column_work`'s grid for binned rows ``row0 ..``.

    The grid keeps the whole stack's origin and spacing and is placed at its
    rows by its VTK extent, so every point is computed exactly as on the
    whole grid: bands that share their boundary row give bit-identical
    points there (merged by :func:`finish_isosurface`).

    Returns
    -------
    points : (P, 3) float32
        ``(x, y, depth)`` um.
    triangles : (T, 3) int64
    """
    pv = _pyvista()
    dz, dy, dx = plan.spacing
    b = plan.bin
    nz, rows, bx = work.shape
    grid = pv.ImageData(
        dimensions=(bx, rows, nz),
        spacing=(dx * b, dy * b, dz),
        origin=((b - 1) * dx / 2, (b - 1) * dy / 2, 0.0),
    )
    grid.extent = (0, bx - 1, row0, row0 + rows - 1, 0, nz - 1)
    grid.point_data["v"] = work.reshape(-1)
    mesh = grid.contour(
        [plan.level],
        scalars="v",
        method="flying_edges",
        compute_normals=False,
        compute_gradients=False,
        compute_scalars=False,
    )
    del grid
    if mesh.n_cells == 0:
        return np.empty((0, 3), np.float32), np.empty((0, 3), np.int64)
    mesh = mesh.triangulate()
    return np.asarray(mesh.points), np.asarray(mesh.regular_faces, np.int64)


def _contour_band(volume, plan: IsoPlan, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
    """Binned rows ``r0 .. r1`` of a :class:`mpm3d.tiled.StackBands` contoured
    (:func:`contour_rows`)."""
    b = plan.bin
    raw = volume.rows(r0 * b, (r1 + 1) * b)
    work = column_work(raw, plan, r0)
    del raw
    return contour_rows(work, plan, r0)


def finish_isosurface(
    pieces: Sequence[tuple[np.ndarray, np.ndarray]],
    plan: IsoPlan,
    *,
    smooth_iterations: int = 40,
    pass_band: float = 0.02,
):
    """One mesh from the contoured bands: merged, its largest piece, smoothed, oriented.

    Points shared by two bands (bit-identical, see :func:`contour_rows`)
    are merged; points and triangles are put in one canonical order (points
    sorted by their coordinates, triangles by their points), so the mesh,
    and everything measured on it, is the same whatever the bands.
    """
    pv = _pyvista()
    points = np.concatenate([p for p, _ in pieces]) if pieces else np.empty((0, 3), np.float32)
    offsets = np.cumsum([0] + [len(p) for p, _ in pieces[:-1]])
    tris = [t + o for (_, t), o in zip(pieces, offsets, strict=True)]
    tris = np.concatenate(tris) if tris else np.empty((0, 3), np.int64)
    if len(tris) == 0:
        raise InputError(f"no isosurface at grey level {plan.level:g}")
    points, tris = _canonical(points, tris)
    mesh = pv.PolyData(points, np.column_stack([np.full(len(tris), 3), tris]).ravel())
    del points, tris
    mesh = largest_component(mesh)
    if smooth_iterations > 0:
        mesh = smooth_mesh(mesh, plan, iterations=smooth_iterations, pass_band=pass_band)
    if plan.decimate > 0:
        mesh = mesh.decimate(plan.decimate)
    mesh = orient_outward(mesh)
    dz, dy, dx = plan.spacing
    mesh.point_data["depth_um"] = mesh.points[:, 2].copy()
    mesh.field_data["level"] = np.array([plan.level])
    mesh.field_data["spacing_um"] = np.array([dz, dy, dx])
    mesh.field_data["lateral_bin"] = np.array([plan.bin])
    return mesh


def smooth_mesh(mesh, plan: IsoPlan, *, iterations: int = 40, pass_band: float = 0.02):
    """Windowed-sinc smoothing (VTK's) of an isosurface in coordinates normalized by the
    stack's extent (its centre and half its largest side), not by the mesh's own bounds.

    The normalization depends on the stack alone, and each smoothing step on a
    vertex's neighbours alone: a piece of the mesh with ``iterations + 1`` binned
    rows of mesh around it is smoothed, in that piece, exactly as the whole mesh
    is (a test holds this, for a mesh too large to be smoothed whole).
    """
    nz, ny, nx = plan.shape
    dz, dy, dx = plan.spacing
    extent = np.array([nx * dx, ny * dy, nz * dz])
    centre, scale = extent / 2, float(extent.max() / 2)
    pv = _pyvista()
    points = np.asarray(mesh.points, np.float64)
    # new points for a shallow copy (the points setter would write into the shared ones)
    mesh = mesh.copy(deep=False)
    mesh.SetPoints(pv.vtk_points((points - centre) / scale, deep=True))
    mesh = mesh.smooth_taubin(
        n_iter=int(iterations),
        pass_band=float(pass_band),
        boundary_smoothing=False,
        non_manifold_smoothing=True,
        normalize_coordinates=False,
    )
    mesh.points = (np.asarray(mesh.points, np.float64) * scale + centre).astype(np.float32)
    return mesh


def _canonical(points: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Equal points merged, points sorted by (y, x, z), each triangle from its least point,
    sorted.

    Sorted by row first, the points of bands of rows follow each other in the
    whole mesh's order (a band's points, then the next band's)."""
    yxz, inverse = np.unique(points[:, [1, 0, 2]], axis=0, return_inverse=True)
    points = yxz[:, [1, 0, 2]]
    tris = inverse.reshape(-1)[tris]
    first = np.argmin(tris, axis=1)
    tris = np.take_along_axis(tris, (first[:, None] + np.arange(3)) % 3, axis=1)  # same winding
    tris = tris[np.lexsort(tris.T[::-1])]
    return points, tris


def _fill_tissue(work: np.ndarray, level: float, top: np.ndarray, bottom: np.ndarray) -> None:
    """Make every voxel below a column's first bright one read as tissue, in place.

    Voxels above ``top`` count as lumen and from ``bottom`` down as tissue;
    in between, each column keeps the running maximum of its grey values
    from the objective side, so dark gaps below the urothelium and dim
    pockets in the tissue no longer cross ``level``: the only surface left
    is where the tissue begins, placed between voxels by the data.
    """
    nz = work.shape[0]
    if np.issubdtype(work.dtype, np.integer):
        info = np.iinfo(work.dtype)
        lumen_value = max(math.floor(level - 0.25), info.min)
        tissue_value = min(math.ceil(level + 0.25), info.max)
    else:
        lumen_value, tissue_value = level - 1.0, level + 1.0
    z = np.arange(nz)[:, None, None]
    chunk = 32
    for z0 in range(0, nz, chunk):
        zz = z[z0 : z0 + chunk]
        block = work[z0 : z0 + chunk]
        block[zz < top[None]] = lumen_value
        block[zz >= bottom[None]] = tissue_value
    np.maximum.accumulate(work, axis=0, out=work)


def vertical_error(mesh, depth_um: np.ndarray, *, spacing: Sequence[float]) -> np.ndarray:
    """Depth of each mesh vertex minus a reference depth map at its (x, y), um.

    The reference is interpolated bilinearly; vertices outside the map are
    dropped.  Useful to compare a surface with a known one.
    """
    from mpm3d.meshstream import point_chunks_of

    parts = [_vertical(p, depth_um, spacing) for p in point_chunks_of(mesh)]
    return np.concatenate(parts) if parts else np.zeros(0)


def _vertical(points: np.ndarray, depth_um: np.ndarray, spacing: Sequence[float]) -> np.ndarray:
    from scipy import ndimage

    dy, dx = (float(s) for s in tuple(spacing)[-2:])
    p = np.asarray(points, np.float64)
    ny, nx = depth_um.shape
    inside = (p[:, 0] >= 0) & (p[:, 0] <= (nx - 1) * dx) & (p[:, 1] >= 0)
    inside &= p[:, 1] <= (ny - 1) * dy
    p = p[inside]
    ref = ndimage.map_coordinates(
        np.asarray(depth_um, np.float64), [p[:, 1] / dy, p[:, 0] / dx], order=1
    )
    if not math.isfinite(float(ref.sum())):
        raise InputError("the reference depth map has NaN")
    return p[:, 2] - ref


def vertical_error_summary(mesh, depth_um: np.ndarray, *, spacing: Sequence[float]) -> dict:
    """The median, 95th percentile and largest of :func:`vertical_error`'s absolute
    values (None where no vertex lies over the map): for a
    :class:`mpm3d.meshstream.DiskMesh`, a chunk of points at a time and the order
    statistics found exactly (:func:`mpm3d.diskmaps.exact_median`), the same numbers."""
    from mpm3d.meshstream import DiskMesh, point_chunks_of

    if not isinstance(mesh, DiskMesh):
        err = np.abs(vertical_error(mesh, depth_um, spacing=spacing))
        if not err.size:
            return None
        return {"median_abs": float(np.median(err)), "p95_abs": float(np.percentile(err, 95)),
                "max_abs": float(err.max())}  # fmt: skip
    from mpm3d.diskmaps import exact_median, exact_percentiles
    from mpm3d.meshstream import _Rows

    errors = _Rows(Path(mesh.folder.path) / "vertical-errors.bin", np.float64, 1)
    largest = -np.inf
    for p in point_chunks_of(mesh):
        e = np.abs(_vertical(p, depth_um, spacing))
        errors.append(e)
        largest = max(largest, float(e.max())) if e.size else largest
    try:
        if not len(errors):
            return None

        def read():
            for chunk in errors.chunks():
                yield chunk[:, 0]

        return {"median_abs": exact_median(read, len(errors)),
                "p95_abs": float(exact_percentiles(read, len(errors), [95])[0]),
                "max_abs": largest}  # fmt: skip
    finally:
        errors.path.unlink(missing_ok=True)


def add_height(mesh, datum_depth_um: float, *, datum: str = ""):
    """Add the height above a datum to a mesh: a ``height_um`` point array and field data.

    Parameters
    ----------
    mesh : pyvista.PolyData
        Points ``(x, y, depth)`` in um; changed in place and returned.
    datum_depth_um : float
        Depth of the datum plane below slice 0 (for the package's datum,
        :attr:`mpm3d.heightmap.HeightMap.datum_depth_um`).
    datum : str
        The datum in words, stored as the field data ``height_datum``.

    Returns
    -------
    pyvista.PolyData
        With ``point_data["height_um"] = datum_depth_um - depth`` and field
        data ``height_datum`` (text), ``height_datum_depth_um`` and
        ``length_unit`` (``"um"``).

    Examples
    --------
    >>> m = add_height(heightmap_mesh(np.full((2, 2), 30.0), spacing=(1.0, 1.0)), 100.0)
    >>> m.point_data["height_um"].tolist(), str(m.field_data["length_unit"][0])
    ([70.0, 70.0, 70.0, 70.0], 'um')
    """
    from mpm3d.meshstream import DiskMesh

    if isinstance(mesh, DiskMesh):  # its height_um is made as it is written
        mesh.datum_depth_um = float(datum_depth_um)
    else:
        depth = np.asarray(mesh.points[:, 2], np.float64)
        mesh.point_data["height_um"] = float(datum_depth_um) - depth
    mesh.field_data["height_datum"] = np.array(
        [datum or f"the plane {float(datum_depth_um):g} um below slice 0"]
    )
    mesh.field_data["height_datum_depth_um"] = np.array([float(datum_depth_um)])
    mesh.field_data["length_unit"] = np.array(["um"])
    return mesh


def mesh_quality(mesh, *, edge_um: float = 0.0) -> dict:
    """Counts that say whether a surface mesh is one clean, open sheet.

    Parameters
    ----------
    mesh : pyvista.PolyData
        A triangle mesh, points ``(x, y, depth)`` in um.
    edge_um : float
        A boundary loop with every vertex further than this from the
        mesh's lateral bounding box is a **hole**; the others are the
        sheet's outer edge (where it meets the field of view's sides).

    Returns
    -------
    dict
        ``triangles``, ``points``, ``boundary_edges``, ``boundary_loops``,
        ``holes``, ``non_manifold_edges`` (shared by more than two
        triangles), ``degenerate_triangles`` (zero area), ``area_um2``
        (developed area) and ``projected_area_um2`` (net area of the
        projection on the (x, y) plane: overhangs count once).

    Examples
    --------
    A 4 x 4 point grid (3 x 3 squares, two triangles each) without its
    middle square has one hole:

    >>> m = heightmap_mesh(np.zeros((4, 4)), spacing=(1.0, 1.0))
    >>> q = mesh_quality(m.remove_cells([4, 13]), edge_um=0.5)
    >>> q["holes"], q["boundary_loops"], q["triangles"]
    (1, 2, 16)
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from mpm3d.meshstream import chunks_of, point_chunks_of

    out = {
        "triangles": int(mesh.n_cells),
        "points": int(mesh.n_points),
        "boundary_edges": 0,
        "boundary_loops": 0,
        "holes": 0,
        "non_manifold_edges": 0,
        "degenerate_triangles": 0,
        "area_um2": 0.0,
        "projected_area_um2": 0.0,
    }
    if mesh.n_cells == 0:
        return out
    read = chunks_of(mesh)  # fixed chunks of triangles: the same sums for any mesh's form
    n_points = np.int64(mesh.n_points)
    largest, lowest = 0.0, []
    for p, t, lo in read():
        largest = max(largest, float(_crossed(p, t)[1].max()))
        lowest.append(int(t.min(axis=1).min()) + lo)
    # an edge whose lower point lies below every later chunk's triangles is complete
    suffix = np.minimum.accumulate(np.array(lowest[::-1], np.int64))[::-1]
    later = np.append(suffix[1:], np.iinfo(np.int64).max)
    keys = np.zeros(0, np.int64)
    counts = np.zeros(0, np.int64)
    border, area, projected, degenerate, non_manifold = [], 0.0, 0.0, 0, 0
    for (p, t, lo), bound in zip(read(), later, strict=True):
        cross, a = _crossed(p, t)
        degenerate += int((a <= 1e-12 * max(largest, 1e-300)).sum())
        area += float(a.sum())
        # normals point into the lumen (-z): the signed projection counts overhangs once
        projected += float(0.5 * cross[:, 2].sum())
        g = t + lo
        u, v = g.ravel(), g[:, [1, 2, 0]].ravel()  # every triangle's three edges
        new = np.minimum(u, v) * n_points + np.maximum(u, v)
        keys, at = np.unique(np.concatenate([keys, new]), return_inverse=True)
        counts = np.bincount(at, weights=np.concatenate([counts, np.ones(len(new), np.int64)]),
                             minlength=len(keys)).astype(np.int64)  # fmt: skip
        done = keys // n_points < bound
        non_manifold += int((counts[done] > 2).sum())
        border.append(keys[done][counts[done] == 1])
        keys, counts = keys[~done], counts[~done]
    once = np.concatenate(border)
    out["non_manifold_edges"] = non_manifold
    out["degenerate_triangles"] = degenerate
    out["area_um2"] = area
    out["projected_area_um2"] = abs(projected)
    out["boundary_edges"] = len(once)
    if len(once):
        border = np.column_stack([once // n_points, once % n_points])
        used, inverse = np.unique(border, return_inverse=True)
        inverse = inverse.reshape(-1, 2)
        n = len(used)
        graph = sp.csr_matrix((np.ones(len(border)), (inverse[:, 0], inverse[:, 1])), shape=(n, n))
        n_loops, label = connected_components(graph, directed=False)
        xy = np.empty((n, 2))
        lo, hi = np.full(2, np.inf), np.full(2, -np.inf)
        start = 0
        for p in point_chunks_of(mesh):
            q = np.asarray(p[:, :2], np.float64)
            lo, hi = np.minimum(lo, q.min(axis=0)), np.maximum(hi, q.max(axis=0))
            a, b = np.searchsorted(used, [start, start + len(p)])
            xy[a:b] = q[used[a:b] - start]
            start += len(p)
        near = ((xy - lo) <= edge_um).any(axis=1) | ((hi - xy) <= edge_um).any(axis=1)
        touches = np.zeros(n_loops, bool)
        np.logical_or.at(touches, label, near)
        out["boundary_loops"] = int(n_loops)
        out["holes"] = int((~touches).sum())
    return out


def _crossed(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's edge cross product and area."""
    u, v = p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]]
    cross = np.column_stack(
        [
            u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1],
            u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
            u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0],
        ]
    )
    return cross, 0.5 * np.linalg.norm(cross, axis=1)
