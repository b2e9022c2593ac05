"""Reading point tracks and triangles from CSV files.

``POINTS3D.csv`` has a header with at least ``frame,point,X,Y,Z`` (lower-case
names are accepted too) and one row per frame and point; an optional
``visible`` column (0/1) marks lost points, which may also have empty or
NaN coordinates.  This is the layout ``python -m stereo reconstruct``
writes.  ``TRI.csv`` has columns ``p0,p1,p2`` (point indices).
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
        Missing columns, non-numeric values, a frame or point missing, or
        duplicate rows; the message names the file and the row.
    """
    path = Path(path)
    if path.is_dir():
        raise PointsError(f"{path} is a folder, not a points file (frame,point,X,Y,Z)")
    if not path.is_file():
        raise PointsError(f"points file not found: {path}")
    table = read_long_table(path, required=("X", "Y", "Z"), optional=("visible",))
    points = np.stack([table["x"], table["y"], table["z"]], axis=-1)
    infinite = np.argwhere(np.isinf(points).any(axis=-1))
    if infinite.size:
        frame, point = infinite[0]
        raise InputError(
            f"{path}: point {point} on frame {frame} has an infinite coordinate "
            "(write lost points as NaN, or empty, with visible = 0)"
        )
    flag = table["visible"] if "visible" in table else np.ones(points.shape[:2])
    if np.isinf(flag).any():
        raise InputError(f"{path}: visible must be 0 or 1, got an infinite value")
    visible = np.where(np.isnan(flag), True, np.trunc(flag) != 0)
    visible &= np.isfinite(points).all(axis=-1)
    points[~visible] = np.nan
    if not visible[0].any():
        raise InputError(f"{path}: no point is visible on the reference frame 0")
    return Tracks(points, visible, np.ones(visible.shape), {"source": str(path)})


def read_triangles(path: str | os.PathLike, n_points: int) -> np.ndarray:
    """Read ``p0,p1,p2`` rows (a header line optional); (M, 3) int."""
    path = Path(path)
    if path.is_dir():
        raise PointsError(f"{path} is a folder, not a triangles file (p0,p1,p2)")
    if not path.is_file():
        raise PointsError(f"triangles file not found: {path}")
    out = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            for line, row in enumerate(csv.reader(f), start=1):
                if not row or all(not c.strip() for c in row):
                    continue
                try:
                    if len(row) < 3:
                        raise ValueError
                    out.append([int(c) for c in row[:3]])
                except ValueError:
                    if line == 1:
                        continue  # the header
                    raise PointsError(
                        f"{path}, line {line}: not three point indices: {row}"
                    ) from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise PointsError(f"{path}: not a text CSV file of triangles ({exc})") from None
    tri = np.asarray(out, np.int64).reshape(-1, 3)
    if len(tri) == 0:
        raise PointsError(f"{path}: no triangles")
    if tri.min() < 0 or tri.max() >= n_points:
        raise PointsError(f"{path}: point index out of range 0..{n_points - 1}")
    if (np.diff(np.sort(tri, axis=1), axis=1) == 0).any():
        raise PointsError(f"{path}: a triangle repeats a point")
    return tri
