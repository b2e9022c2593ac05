"""Virtual grid points: regular grids over a region of interest, or points from CSV.

Points are ``(N, 2)`` arrays of ``(x, y)`` pixel coordinates (x = column,
y = row, centre of the top-left pixel at (0, 0)), ordered row by row from the
top-left corner.
"""

from __future__ import annotations

import csv
import os

import numpy as np

from strain2d.errors import InputError

__all__ = [
    "MIN_GRID_SPACING_PX",
    "check_grid_spacing",
    "default_roi",
    "make_grid",
    "parse_grid",
    "parse_roi",
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


def read_points_csv(path: str | os.PathLike) -> np.ndarray:
    """Read points from a CSV file with a header holding columns ``x`` and ``y``.

    A byte-order mark (as spreadsheet programs write) is accepted.  Every row
    must have as many cells as the header (a decimal comma, ``10,5`` for
    10.5, makes one too many) and numbers for ``x`` and ``y``; errors name the
    file and the line.

    Returns
    -------
    points : (N, 2) float
    """
    from tissue_core.tables import cell_count_error

    line = 1
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            fields = [c.strip().lower() for c in next(reader, [])]
            if "x" not in fields or "y" not in fields:
                raise InputError(f"{path} needs a header with columns x,y (found {fields})")
            ix, iy = fields.index("x"), fields.index("y")
            rows = []
            for cells in reader:
                line = reader.line_num
                if not cells:
                    continue  # a blank line
                if len(cells) != len(fields):
                    raise cell_count_error(path, line, len(cells), len(fields), ",".join(cells))
                rows.append((float(cells[ix]), float(cells[iy])))
    except FileNotFoundError:
        raise InputError(f"no such points file: {path}") from None
    except IsADirectoryError:
        raise InputError(f"{path} is a folder, not a points CSV file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path} is not a text CSV file") from None
    except (TypeError, ValueError, csv.Error) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}, line {line}: x and y must be numbers ({exc})") from None
    return np.array(rows, dtype=float).reshape(-1, 2)
