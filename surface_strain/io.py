"""Reading point tracks and triangles from CSV files.

``POINTS3D.csv`` has a header with at least ``frame,point,X,Y,Z`` (lower-case
names are accepted too) and one row per frame and point; an optional
``visible`` column (0/1) marks lost points, which may also have empty or
NaN coordinates.  This is the layout ``python -m stereo reconstruct``
writes.  ``TRI.csv`` has columns ``p0,p1,p2`` (point indices), each triangle once.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from surface_strain.tracks import Tracks
from tissue_core.errors import InputError
from tissue_core.tables import read_long_table

__all__ = ["PointsError", "read_points3d", "read_triangles"]


#: A points or triangles file that cannot be used: the toolkit's InputError (one clear line).
PointsError = InputError


def read_points3d(path: str | os.PathLike) -> Tracks:
    """Read 3D point tracks.

    Returns
    -------
    Tracks
        ``positions`` (T, N, 3) float, NaN where lost; ``visible`` (T, N) bool;
        ``quality`` 1.

    Raises
    ------
    PointsError
        Missing columns, a row whose cells do not match the header,
        non-numeric values, ``visible`` other than 0 or 1, a frame or point
        missing, or duplicate rows; the message names the file and the row.
    """
    path = Path(path)
    if path.is_dir():
        raise PointsError(f"{path} is a folder, not a points file (frame,point,X,Y,Z)")
    if not path.is_file():
        raise PointsError(f"points file not found: {path}")
    table = read_long_table(
        path, required=("X", "Y", "Z"), optional=("visible",), flags=("visible",)
    )
    points = np.stack([table["x"], table["y"], table["z"]], axis=-1)
    infinite = np.argwhere(np.isinf(points).any(axis=-1))
    if infinite.size:
        frame, point = infinite[0]
        raise InputError(
            f"{path}: point {point} on frame {frame} has an infinite coordinate "
            "(write lost points as NaN, or empty, with visible = 0)"
        )
    flag = table["visible"] if "visible" in table else np.ones(points.shape[:2])
    visible = np.where(np.isnan(flag), True, flag == 1)
    visible &= np.isfinite(points).all(axis=-1)
    points[~visible] = np.nan
    if not visible[0].any():
        raise InputError(f"{path}: no point is visible on the reference frame 0")
    return Tracks(points, visible, np.ones(visible.shape), {"source": str(path)})


def read_triangles(path: str | os.PathLike, n_points: int) -> np.ndarray:
    """Read ``p0,p1,p2`` rows (a header line optional); (M, 3) int.

    Every row has as many cells as the header (or, without one, as the first
    row; the first three are the triangle's points).  A triangle given twice
    (the same three points in any order) is refused naming both lines, as are
    a point index out of range and a triangle that repeats a point.
    """
    from tissue_core.tables import cell_count_error

    path = Path(path)
    if path.is_dir():
        raise PointsError(f"{path} is a folder, not a triangles file (p0,p1,p2)")
    if not path.is_file():
        raise PointsError(f"triangles file not found: {path}")
    out, lines = [], []
    width, width_from = None, ""  # the cells of a row: the header's, or the first row's
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            for line, row in enumerate(csv.reader(f), start=1):
                if not row or all(not c.strip() for c in row):
                    continue
                if width is not None and len(row) != width:
                    raise cell_count_error(
                        path, line, len(row), width, ",".join(row), reference=width_from,
                        decimals=False,
                    )  # fmt: skip
                try:
                    if len(row) < 3:
                        raise ValueError
                    out.append([int(c) for c in row[:3]])
                    lines.append(line)
                except ValueError:
                    if line == 1:
                        width, width_from = len(row), "the header"
                        continue
                    raise PointsError(
                        f"{path}, line {line}: not three point indices: {row}"
                    ) from None
                if width is None:
                    width, width_from = len(row), f"the first row (line {line})"
    except (UnicodeDecodeError, csv.Error) as exc:
        raise PointsError(f"{path}: not a text CSV file of triangles ({exc})") from None
    tri = np.asarray(out, np.int64).reshape(-1, 3)
    if len(tri) == 0:
        raise PointsError(f"{path}: no triangles")
    outside = ((tri < 0) | (tri >= n_points)).any(axis=1)
    if outside.any():
        k = int(outside.argmax())
        raise PointsError(
            f"{path}, line {lines[k]}: point index out of range 0..{n_points - 1}: "
            f"{', '.join(map(str, tri[k]))}"
        )
    corners = np.sort(tri, axis=1)
    repeats = (np.diff(corners, axis=1) == 0).any(axis=1)
    if repeats.any():
        k = int(repeats.argmax())
        raise PointsError(
            f"{path}, line {lines[k]}: a triangle repeats a point: {', '.join(map(str, tri[k]))}"
        )
    _, first, inverse = np.unique(corners, axis=0, return_index=True, return_inverse=True)
    again = np.flatnonzero(first[inverse.ravel()] != np.arange(len(tri)))
    if again.size:
        k = int(again[0])
        j = int(first[inverse.ravel()[k]])
        raise PointsError(
            f"{path}, lines {lines[j]} and {lines[k]} give the same triangle: "
            f"{', '.join(map(str, tri[j]))} and {', '.join(map(str, tri[k]))}"
        )
    return tri
