"""Virtual grid points: regular grids over a region of interest, or points from CSV.

Points are ``(N, 2)`` arrays of ``(x, y)`` pixel coordinates (x = column,
y = row, centre of the top-left pixel at (0, 0)), ordered row by row from the
top-left corner.
"""

from __future__ import annotations

import os

import numpy as np

from strain2d.errors import InputError

__all__ = [
    "MIN_GRID_SPACING_PX",
    "check_grid_spacing",
    "default_roi",
    "grid_at_spacing",
    "make_grid",
    "mask_triangles",
    "masked_grid",
    "parse_grid",
    "parse_roi",
    "points_on_tissue",
    "read_points_csv",
    "validate_points",
]


#: the least distance between neighbouring grid points, px: points closer than this measure
#: the same pixels (every tracker's subset or window is many pixels wide) and only multiply
#: the work and the memory
MIN_GRID_SPACING_PX = 2.0


def parse_grid(text: str) -> tuple[int, int]:
    """Parse ``"COLSxROWS"`` (e.g. ``"7x7"``) into ``(n_cols, n_rows)``."""
    parts = text.lower().split("x")
    try:
        n_cols, n_rows = (int(p) for p in parts)
    except ValueError:
        raise InputError(f"--grid must look like 7x7 (COLSxROWS), got {text!r}") from None
    if n_cols < 2 or n_rows < 2:
        raise InputError(f"--grid needs at least 2 points per side, got {text!r}")
    return n_cols, n_rows


def parse_roi(text: str) -> tuple[float, float, float, float]:
    """Parse ``"X0,Y0,X1,Y1"`` (pixels) into a tuple."""
    try:
        x0, y0, x1, y1 = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"--roi must be X0,Y0,X1,Y1 in pixels, got {text!r}") from None
    return x0, y0, x1, y1


def default_roi(image_shape: tuple[int, int], margin: float = 0.15) -> tuple[float, ...]:
    """The central region leaving ``margin`` of the width and height on each side."""
    h, w = image_shape
    return (margin * (w - 1), margin * (h - 1), (1 - margin) * (w - 1), (1 - margin) * (h - 1))


def check_grid_spacing(
    shape: tuple[int, int], region: tuple[float, float], *, option: str = "--grid"
) -> None:
    """Refuse a grid whose points would be closer than :data:`MIN_GRID_SPACING_PX`.

    Parameters
    ----------
    shape : (n_cols, n_rows)
        Points along x and along y (at least 2 each).
    region : (width, height)
        The extent the grid spans, px (the ROI's ``x1 - x0`` and ``y1 - y0``).
    option : str, keyword-only
        The option that asks for the grid, for the message.

    Raises
    ------
    InputError
        Naming the grid, the spacing it asks for and the densest grid that
        fits the region.

    Examples
    --------
    >>> check_grid_spacing((70, 70), (138.0, 138.0))
    >>> check_grid_spacing((500, 500), (139.3, 139.3))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    tissue_core.errors.InputError: --grid 500x500 puts points 0.279 px apart ... at most 70x70 ...
    """
    n_cols, n_rows = shape
    width, height = region
    spacing = min(width / (n_cols - 1), height / (n_rows - 1))
    if spacing >= MIN_GRID_SPACING_PX:
        return
    most = (int(width // MIN_GRID_SPACING_PX) + 1, int(height // MIN_GRID_SPACING_PX) + 1)
    fits = (
        f"at most {most[0]}x{most[1]} fit this region"
        if min(most) >= 2
        else f"this region is too small for a grid (under {MIN_GRID_SPACING_PX:g} px)"
    )
    raise InputError(
        f"{option} {n_cols}x{n_rows} puts points {spacing:.3g} px apart in the "
        f"{width:g}x{height:g} px region; points closer than {MIN_GRID_SPACING_PX:g} px "
        f"measure the same pixels and only multiply the work: {fits}"
    )


def grid_at_spacing(
    region: tuple[float, float, float, float], spacing: float, *, option: str = "--spacing"
) -> tuple[tuple[int, int], tuple[float, float, float, float]]:
    """The grid of points ``spacing`` px apart that fits ``region`` ``(x0, y0, x1, y1)``:
    ``((n_cols, n_rows), roi)``, the grid centred in the region (the margins that do not
    make a whole spacing shared between both sides).

    Examples
    --------
    >>> grid_at_spacing((10, 20, 55, 40), 10.0)
    ((5, 3), (12.5, 20.0, 52.5, 40.0))
    """
    import math

    if not (math.isfinite(spacing) and spacing > 0):
        raise InputError(f"{option} must be a positive number of pixels, got {spacing:g}")
    if spacing < MIN_GRID_SPACING_PX:
        raise InputError(
            f"{option} {spacing:g} px: points closer than {MIN_GRID_SPACING_PX:g} px measure "
            "the same pixels and only multiply the work"
        )
    x0, y0, x1, y1 = (float(v) for v in region)
    width, height = x1 - x0, y1 - y0
    n_cols = math.floor(width / spacing + 1e-9) + 1
    n_rows = math.floor(height / spacing + 1e-9) + 1
    if n_cols < 2 or n_rows < 2:
        raise InputError(
            f"{option} {spacing:g} px leaves fewer than 2 points across the {width:g}x{height:g} "
            "px region: give a smaller spacing"
        )
    dx = (width - (n_cols - 1) * spacing) / 2
    dy = (height - (n_rows - 1) * spacing) / 2
    roi = (x0 + dx, y0 + dy, x0 + dx + (n_cols - 1) * spacing, y0 + dy + (n_rows - 1) * spacing)
    return (n_cols, n_rows), roi


def make_grid(
    image_shape: tuple[int, int],
    *,
    shape: tuple[int, int] = (7, 7),
    roi: tuple[float, float, float, float] | None = None,
) -> np.ndarray:
    """A regular grid of points spanning a region of interest, corners included.

    Parameters
    ----------
    image_shape : (H, W)
        Frame size in pixels.
    shape : (n_cols, n_rows), keyword-only
        Points along x and along y; the paper uses 7 x 7.
    roi : (x0, y0, x1, y1), keyword-only
        Region in pixels; default :func:`default_roi`.

    Returns
    -------
    points : (n_rows * n_cols, 2) float
        Row-major from the top-left corner.

    Raises
    ------
    InputError
        If the ROI is empty or extends outside the image, or the points
        would be closer than :data:`MIN_GRID_SPACING_PX`.

    Examples
    --------
    >>> make_grid((100, 100), shape=(3, 2), roi=(10, 20, 30, 40)).tolist()
    [[10.0, 20.0], [20.0, 20.0], [30.0, 20.0], [10.0, 40.0], [20.0, 40.0], [30.0, 40.0]]
    """
    h, w = image_shape
    n_cols, n_rows = shape
    if n_cols < 2 or n_rows < 2:
        raise InputError(f"a grid needs at least 2 points per side, got {n_cols}x{n_rows}")
    x0, y0, x1, y1 = default_roi(image_shape) if roi is None else roi
    if not (x1 > x0 and y1 > y0):
        raise InputError(f"--roi must have X1 > X0 and Y1 > Y0, got {x0:g},{y0:g},{x1:g},{y1:g}")
    if x0 < 0 or y0 < 0 or x1 > w - 1 or y1 > h - 1:
        raise InputError(
            f"--roi {x0:g},{y0:g},{x1:g},{y1:g} lies outside the {w}x{h} px image "
            f"(x in 0..{w - 1}, y in 0..{h - 1})"
        )
    check_grid_spacing((n_cols, n_rows), (x1 - x0, y1 - y0))
    xs = np.linspace(x0, x1, n_cols)
    ys = np.linspace(y0, y1, n_rows)
    gx, gy = np.meshgrid(xs, ys)
    return np.column_stack([gx.ravel(), gy.ravel()])


def validate_points(points: np.ndarray, image_shape: tuple[int, int] | None = None) -> np.ndarray:
    """Check a point set can carry a mesh: finite, distinct, at least 3, not collinear,
    inside the image."""
    points = np.asarray(points, dtype=float)
    if points.ndim != 2 or points.shape[1] != 2:
        raise InputError(f"points must have shape (N, 2), got {points.shape}")
    if len(points) < 3:
        raise InputError(f"at least 3 points are needed to compute strain, got {len(points)}")
    if not np.all(np.isfinite(points)):
        raise InputError("points must be finite numbers")
    unique, first = np.unique(points, axis=0, return_index=True)
    if len(unique) < len(points):
        dup = sorted(set(range(len(points))) - set(first.tolist()))[0]
        raise InputError(f"point {dup} at ({points[dup, 0]:g}, {points[dup, 1]:g}) is given twice")
    centred = points - points.mean(axis=0)
    s = np.linalg.svd(centred, compute_uv=False)
    if s[1] <= 1e-9 * max(s[0], 1e-300):
        raise InputError("the points are collinear; strain needs points spanning an area")
    if image_shape is not None:
        h, w = image_shape
        outside = (
            (points[:, 0] < 0)
            | (points[:, 0] > w - 1)
            | (points[:, 1] < 0)
            | (points[:, 1] > h - 1)
        )
        if np.any(outside):
            i = int(np.flatnonzero(outside)[0])
            raise InputError(
                f"point {i} at ({points[i, 0]:g}, {points[i, 1]:g}) lies outside the "
                f"{w}x{h} px image"
            )
    return points


def mask_triangles(points: np.ndarray, triangles: np.ndarray, mask) -> np.ndarray:
    """The triangles that lie on the tissue of ``mask`` (a :class:`tissue_core.masks.Mask`):
    their three corners and their centroid on it (a triangle across a notch of the
    outline has its corners on tissue and its centroid off it)."""
    points = np.asarray(points, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    on = mask.contains(points)
    corners = on[triangles].all(axis=1)
    centroids = points[triangles].mean(axis=1)
    return triangles[corners & mask.contains(centroids)]


def points_on_tissue(points: np.ndarray, mask, *, source: str) -> np.ndarray:
    """Which of ``points`` (from the file ``source``) lie on the tissue of ``mask``;
    refuses fewer than 3 (:class:`InputError`)."""
    on = mask.contains(points)
    if on.sum() < 3:
        raise InputError(
            f"--mask {mask.source}: {int(on.sum())} of the {len(points)} points of {source} "
            "lie on the tissue; at least 3 are needed"
        )
    return on


def masked_grid(
    image_shape: tuple[int, int],
    mask,
    *,
    shape: tuple[int, int] = (7, 7),
    roi: tuple[float, float, float, float] | None = None,
    option: str = "--mask",
) -> tuple[np.ndarray, np.ndarray, dict]:
    """A grid that fills a tissue mask, and its triangles on the tissue.

    The regular grid of ``shape`` over ``roi`` (default: the mask's bounds)
    as :func:`make_grid` makes it, meshed cell by cell along alternating
    diagonals (:func:`surface_strain.grid_triangles`); the triangles kept are
    those on the tissue (:func:`mask_triangles`), the points kept those of a
    kept triangle.  So a grid point of a masked run is the same point as in
    the rectangle's run over the same region, and so is each kept triangle.

    Parameters
    ----------
    image_shape : (H, W)
    mask : tissue_core.masks.Mask
        Of the frames' size.
    shape : (n_cols, n_rows), keyword-only
        Points along x and along y over the region.
    roi : (x0, y0, x1, y1), keyword-only
        The grid's region (default: the mask's bounds).
    option : str, keyword-only
        The option that gave the mask, for the messages.

    Returns
    -------
    points : (M, 2) float
        The kept points, in the grid's row-major order.
    triangles : (K, 3) int
        Indices into ``points``.
    info : dict
        ``grid_points`` (the whole grid's), ``points_off_tissue``,
        ``grid_triangles``, ``triangles_off_tissue``: for the summary.

    Raises
    ------
    InputError
        A mask of another size than the frames, a mask too small for a grid,
        or one that leaves fewer than 3 points with a triangle on the tissue.
    """
    from surface_strain import grid_triangles

    if tuple(mask.shape) != tuple(image_shape):
        raise InputError(
            f"{option} {mask.source} is {mask.shape[1]}x{mask.shape[0]} px, the frames are "
            f"{image_shape[1]}x{image_shape[0]} px"
        )
    n_cols, n_rows = shape
    given = roi is not None
    if roi is None:
        roi = mask.bounds()
        if not (roi[2] > roi[0] and roi[3] > roi[1]):
            raise InputError(
                f"{option} {mask.source} marks {int(roi[2] - roi[0]) + 1}x"
                f"{int(roi[3] - roi[1]) + 1} px of tissue: too narrow for a grid"
            )
    try:
        grid = make_grid(image_shape, shape=shape, roi=roi)
    except InputError as exc:
        if given:
            raise
        width, height = roi[2] - roi[0], roi[3] - roi[1]
        raise InputError(
            f"{option} {mask.source}: its tissue spans {width:g}x{height:g} px, so {exc}"
        ) from None
    every = grid_triangles(n_rows, n_cols)
    kept = mask_triangles(grid, every, mask)
    used = np.unique(kept)
    if used.size < 3:
        raise InputError(
            f"{option} {mask.source}: {used.size} of the {n_cols}x{n_rows} grid's points lie on "
            "the tissue with a whole triangle of the grid around them; at least 3 are needed "
            f"(a finer --grid{'' if roi is None else ', or a --roi over the tissue'})"
        )
    renumber = np.full(len(grid), -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    info = {
        "grid_points": len(grid),
        "points_off_tissue": int(len(grid) - used.size),
        "grid_triangles": len(every),
        "triangles_off_tissue": int(len(every) - len(kept)),
    }
    return grid[used], renumber[kept], info


def read_points_csv(path: str | os.PathLike) -> np.ndarray:
    """Read points from a CSV file with a header holding columns ``x`` and ``y``.

    See :func:`tissue_core.tables.read_xy_csv`, which reads it.

    Returns
    -------
    points : (N, 2) float
    """
    from tissue_core.tables import read_xy_csv

    return read_xy_csv(path, what="points")
