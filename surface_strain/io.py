"""Reading point tracks and triangles from CSV files.

``POINTS3D.csv`` has a header with at least ``frame,point,X,Y,Z`` (lower-case
names are accepted too) and one row per frame and point; an optional
``visible`` column (0/1) marks lost points, which may also have empty or
NaN coordinates.  This is the layout ``python -m stereo reconstruct``
writes.  ``TRI.csv`` has columns ``p0,p1,p2`` (point indices).
"""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np

from tissue_core.errors import InputError

__all__ = ["PointsError", "read_points3d", "read_triangles"]


#: A points or triangles file that cannot be used: the toolkit's InputError (one clear line).
PointsError = InputError


def _float(text: str) -> float:
    text = text.strip()
    if text == "" or text.lower() in ("nan", "none", "null"):
        return math.nan
    return float(text)


def read_points3d(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read 3D point tracks.

    Returns
    -------
    points : (T, N, 3) float, NaN where lost
    visible : (T, N) bool

    Raises
    ------
    PointsError
        Missing columns, non-numeric values, a frame or point missing, or
        duplicate rows; the message names the file and the row.
    """
    path = Path(path)
    if not path.is_file():
        raise PointsError(f"points file not found: {path}")
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            header = next(reader, None)
            if header is None:
                raise PointsError(f"{path}: empty file")
            names = [h.strip().lower() for h in header]
            need = ("frame", "point", "x", "y", "z")
            missing = [n for n in need if n not in names]
            if missing:
                raise PointsError(
                    f"{path}: missing column(s) {', '.join(missing)} (need frame,point,X,Y,Z)"
                )
            col = {n: names.index(n) for n in need}
            vis_col = names.index("visible") if "visible" in names else None
            rows = []
            for line, row in enumerate(reader, start=2):
                if not row or all(not c.strip() for c in row):
                    continue
                try:
                    frame, point = int(row[col["frame"]]), int(row[col["point"]])
                    xyz = [_float(row[col[k]]) for k in ("x", "y", "z")]
                    vis = bool(int(float(row[vis_col]))) if vis_col is not None else True
                except (ValueError, IndexError, OverflowError):
                    raise PointsError(f"{path}, line {line}: not a number: {row}") from None
                if frame < 0 or point < 0:
                    raise PointsError(f"{path}, line {line}: negative frame or point index")
                rows.append((frame, point, *xyz, vis))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise PointsError(f"{path}: not a text CSV file ({exc})") from None
    if not rows:
        raise PointsError(f"{path}: no rows")
    data = np.array([r[:5] for r in rows], np.float64)
    vis = np.array([r[5] for r in rows], bool)
    infinite = np.flatnonzero(np.isinf(data[:, 2:5]).any(axis=1))
    if infinite.size:
        frame, point = (int(v) for v in data[infinite[0], :2])
        raise PointsError(
            f"{path}: point {point} on frame {frame} has an infinite coordinate "
            "(write lost points as NaN, or empty, with visible = 0)"
        )
    T, N = int(data[:, 0].max()) + 1, int(data[:, 1].max()) + 1
    if len(rows) != T * N:
        raise PointsError(
            f"{path}: expected one row for each of {T} frames x {N} points "
            f"({T * N} rows), found {len(rows)}"
        )
    points = np.full((T, N, 3), np.nan)
    visible = np.zeros((T, N), bool)
    f, p = data[:, 0].astype(int), data[:, 1].astype(int)
    seen = np.zeros((T, N), bool)
    seen[f, p] = True
    if not seen.all():
        raise PointsError(f"{path}: some frame/point pairs appear twice, others not at all")
    points[f, p] = data[:, 2:5]
    visible[f, p] = vis & np.isfinite(data[:, 2:5]).all(axis=1)
    points[~visible] = np.nan
    if T < 1 or not visible[0].any():
        raise PointsError(f"{path}: no point is visible on the reference frame 0")
    return points, visible


def read_triangles(path: str | os.PathLike, n_points: int) -> np.ndarray:
    """Read ``p0,p1,p2`` rows (a header line optional); (M, 3) int."""
    path = Path(path)
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
