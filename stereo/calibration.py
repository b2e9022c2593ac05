"""Stereo calibration from images of a checkerboard, ChArUco or circle-grid target.

:func:`calibrate_stereo` detects the target in every image pair, calibrates
each camera (intrinsics and distortion), rejects pairs whose reprojection
error stands out, and then estimates the rig's extrinsics ``(R, T)`` with
the intrinsics fixed.  OpenCV's ``stereoCalibrate`` minimizes the
reprojection error of the whole rig over all views and board poses jointly:
a bundle adjustment in which the planar target is the known structure.
pycolmap's bundle adjuster would solve the same problem for this input
(known planar points, two cameras), so it would add a dependency without
improving the estimate; it serves where the structure is unknown.

A calibration that cannot be physical is refused where it is made and
wherever it is read: a board size that does not fit the target, the same
pictures on both sides, a reprojection error no real rig has
(:data:`MAX_RMS_PX`), cameras closer than :data:`MIN_BASELINE_MM` or than
:data:`MIN_BASELINE_RATIO` of the distance to what they look at; a poor one
(:data:`POOR_RMS_PX`) is flagged.

A :class:`Calibration` is saved as JSON (:meth:`Calibration.save`), with
``image_size``, ``K_left``, ``dist_left``, ``K_right``, ``dist_right``,
``R``, ``T`` (``x_right = R x_left + T``), ``rms_px`` and ``unit``, and can
be read from that JSON or from OpenCV YAML/XML files
(:func:`load_calibration`).

References
----------
* Z. Zhang, A flexible new technique for camera calibration, IEEE TPAMI 22
  (2000) 1330-1334, doi:10.1109/34.888718.
* S. Garrido-Jurado et al., Automatic generation and detection of highly
  reliable fiducial markers under occlusion, Pattern Recognition 47 (2014)
  2280-2292, doi:10.1016/j.patcog.2014.01.005 (ArUco / ChArUco).
* P. Duda, J. Frese, Accurate detection and localization of checkerboard
  corners for calibration, BMVC 2018 (OpenCV's findChessboardCornersSB).
* J. Heikkila, Geometric camera calibration using circular control points,
  IEEE TPAMI 22 (2000) 1066-1077, doi:10.1109/34.879788 (circle grids; the
  centre of a dot's image is not the image of its centre).
"""

from __future__ import annotations

import json
import logging
import math
import os
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tissue_core.errors import InputError, SourceError

__all__ = [
    "CALIBRATION_KEYS",
    "MAX_RMS_PX",
    "MIN_BASELINE_MM",
    "MIN_BASELINE_RATIO",
    "POOR_RMS_PX",
    "Board",
    "BoardSizeError",
    "Calibration",
    "CalibrationValueError",
    "board_size_in",
    "calibrate_stereo",
    "check_baseline_ratio",
    "detect_board",
    "load_calibration",
    "parse_board",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Board:
    """A calibration target.

    ``kind`` is ``"checkerboard"`` (``cols x rows`` inner corners),
    ``"charuco"`` (``cols x rows`` squares, ArUco markers of ``marker``
    size from ``dictionary``), ``"circles"`` (a symmetric grid of ``cols x
    rows`` dark dots) or ``"acircles"`` (OpenCV's asymmetric dot grid: odd
    rows shifted by ``square``, dots in a row ``2 square`` apart, rows
    ``square`` apart); ``square`` is the square size or dot spacing in the
    unit the results will use (e.g. mm).  ``marker`` holds a dot grid's
    diameter when it was given (checked, not needed for detection).
    """

    kind: str
    cols: int
    rows: int
    square: float
    marker: float | None = None
    dictionary: str | None = None

    def spec(self) -> str:
        """The text form :func:`parse_board` reads."""
        base = f"{self.kind}:{self.cols}x{self.rows}:{self.square:g}"
        if self.kind == "charuco":
            return f"{base}:{self.marker:g}:{self.dictionary}"
        if self.marker is not None:  # a dot grid's diameter
            return f"{base}:{self.marker:g}"
        return base

    def object_points(self) -> np.ndarray:
        """(M, 3) positions of the inner corners or dot centres on the board (z = 0),
        row-major (``cv2.findCirclesGrid``'s order for dot grids)."""
        if self.kind == "charuco":
            nx, ny = self.cols - 1, self.rows - 1
        else:
            nx, ny = self.cols, self.rows
        gy, gx = np.mgrid[0:ny, 0:nx]
        if self.kind == "acircles":
            gx = 2 * gx + gy % 2
        return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)]) * self.square

    def opencv_board(self):
        """The ``cv2.aruco.CharucoBoard`` of a ChArUco target."""
        import cv2

        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(
            (self.cols, self.rows), float(self.square), float(self.marker), dictionary
        )


def parse_board(text: str) -> Board:
    """Parse ``checkerboard:COLSxROWS:SQUARE``, ``charuco:COLSxROWS:SQUARE:MARKER:DICT``,
    ``circles:COLSxROWS:SPACING[:DIAMETER]`` or ``acircles:COLSxROWS:SPACING[:DIAMETER]``.

    Examples
    --------
    >>> parse_board("checkerboard:9x6:10")
    Board(kind='checkerboard', cols=9, rows=6, square=10.0, marker=None, dictionary=None)
    >>> parse_board("charuco:11x8:8:6:DICT_4X4_50").spec()
    'charuco:11x8:8:6:DICT_4X4_50'
    >>> parse_board("acircles:4x11:10").object_points()[4:6, :2].tolist()
    [[10.0, 10.0], [30.0, 10.0]]
    """
    import cv2

    usage = (
        "--board must be checkerboard:COLSxROWS:SQUARE, "
        "charuco:COLSxROWS:SQUARE:MARKER:DICTIONARY, circles:COLSxROWS:SPACING[:DIAMETER] "
        f"or acircles:COLSxROWS:SPACING[:DIAMETER], got {text!r}"
    )
    parts = str(text).strip().split(":")
    kind = parts[0].lower()
    counts = {"checkerboard": (3,), "charuco": (5,), "circles": (3, 4), "acircles": (3, 4)}
    if len(parts) not in counts.get(kind, ()):
        raise InputError(usage)
    try:
        cols, rows = (int(v) for v in parts[1].lower().split("x"))
        square = float(parts[2])
        marker = float(parts[3]) if len(parts) > 3 else None
    except ValueError:
        raise InputError(usage) from None
    if cols < 3 or rows < 3 or not (math.isfinite(square) and square > 0):
        raise InputError(f"{usage}: at least 3 x 3 and a positive square size")
    if kind in ("circles", "acircles"):
        nearest = square * (math.sqrt(2) if kind == "acircles" else 1)
        if marker is not None and not (math.isfinite(marker) and 0 < marker < nearest):
            raise InputError(
                f"{usage}: the dot diameter must be smaller than the distance between "
                f"neighbouring dots ({nearest:g})"
            )
        return Board(kind, cols, rows, square, marker)
    if kind == "charuco":
        if not (math.isfinite(marker) and 0 < marker < square):
            raise InputError(f"{usage}: the marker must be smaller than the square")
        name = parts[4].upper()
        if not name.startswith("DICT_") or not hasattr(cv2.aruco, name):
            raise InputError(f"unknown ArUco dictionary {parts[4]!r} (e.g. DICT_4X4_50)")
        return Board(kind, cols, rows, square, marker, name)
    return Board(kind, cols, rows, square)


class BoardSizeError(InputError):
    """An image holds a target larger than the :class:`Board` given.

    OpenCV finds a part of a larger checkerboard or dot grid as readily as the
    whole (a 4 x 4 corner pattern inside a 9 x 6 board): the calibration would
    then run on corners whose board positions are wrong.  ``found`` is the
    ``(cols, rows)`` the image holds, in the board's order.
    """

    def __init__(self, board: Board, found: tuple[int, int]) -> None:
        self.board, self.found = board, found
        noun = "inner corners" if board.kind == "checkerboard" else "dots"
        super().__init__(
            f"the target continues beyond the {board.cols}x{board.rows} {noun} of --board "
            f"{board.spec()}: the images hold {found[0]}x{found[1]} {noun} (e.g. --board "
            f"{_resized(board, found).spec()})"
        )


def _resized(board: Board, size: tuple[int, int]) -> Board:
    return Board(board.kind, size[0], size[1], board.square, board.marker, board.dictionary)


def _as_given(board: Board, size: tuple[int, int]) -> tuple[int, int]:
    """``size`` (cols, rows) in the order the board names its sides (the longer first or not)."""
    a, b = (int(v) for v in size)
    return (a, b) if (a >= b) == (board.cols >= board.rows) else (b, a)


def _gray_uint8(image: np.ndarray) -> np.ndarray:
    import cv2

    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if gray.dtype != np.uint8:
        lo, hi = float(gray.min()), float(gray.max())
        gray = np.uint8(np.clip((gray - lo) * 255.0 / max(hi - lo, 1e-12), 0, 255))
    return gray


def detect_board(image: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    """Sub-pixel corners of ``board`` in a gray image.

    Returns
    -------
    (image_points (M, 2) float64, ids (M,) int) or None when not found.
    ``ids`` index :meth:`Board.object_points`.

    Raises
    ------
    BoardSizeError
        The image holds a larger checkerboard or symmetric dot grid than
        ``board`` (a part of it was found; the corners' board positions would
        be wrong).  Asymmetric dot grids and ChArUco boards of another size
        are not found at all.
    """
    import cv2

    gray = _gray_uint8(image)
    if board.kind == "checkerboard":
        return _detect_checkerboard(gray, board)
    if board.kind in ("circles", "acircles"):
        return _detect_circles(gray, board)
    detector = cv2.aruco.CharucoDetector(board.opencv_board())
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < 6:
        return None
    return corners.reshape(-1, 2).astype(np.float64), ids.ravel().astype(np.int64)


#: a grid continues past a side when this share of the corners or dots of the next row or
#: column is there
_CONTINUES = 0.75


def _find_checkerboard(gray: np.ndarray, size: tuple[int, int]):
    """``cv2.findChessboardCornersSBWithMeta`` allowing a larger board than ``size``, with the
    exhaustive search for harder images: (corners (M, 2), their grid (rows, cols, 2) or None
    when their layout is unclear), or None when nothing is found."""
    import cv2

    flags = cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_LARGER
    for extra in (0, cv2.CALIB_CB_EXHAUSTIVE):
        found, corners, meta = cv2.findChessboardCornersSBWithMeta(gray, size, flags | extra)
        if found:
            points = corners.reshape(-1, 2).astype(np.float64)
            return points, _as_grid(points, meta.shape[:2])
    return None


def _as_grid(points: np.ndarray, shape: tuple[int, int]) -> np.ndarray | None:
    """Row-major corners as a (rows, cols, 2) grid: the one of ``shape`` or its transpose
    whose neighbours along each axis are evenly spaced (None if neither)."""
    for rows, cols in (shape, shape[::-1]):
        grid = points.reshape(rows, cols, 2)
        steps = [np.linalg.norm(np.diff(grid, axis=a), axis=-1) for a in (0, 1)]
        if all(st.size and st.max() < 3 * np.median(st) for st in steps):
            return grid
    return None


def _detect_checkerboard(gray: np.ndarray, board: Board):
    """The board's inner corners; a larger board than ``board`` raises BoardSizeError.

    OpenCV's detector, allowed to find a larger board (``CALIB_CB_LARGER``),
    finds the whole board around a part of it, and sometimes a row of points
    along the board's edge that are no corners: the board's extent is that of
    the X-corners (:func:`_board_grid`).
    """
    import cv2

    size = (board.cols, board.rows)
    found = _find_checkerboard(gray, size)
    if found is None:
        return None
    pts, grid = found
    if grid is not None:
        rows, cols = _board_grid(gray, grid).shape[:2]
        if rows * cols > board.cols * board.rows:
            raise BoardSizeError(board, _as_given(board, (cols, rows)))
    if grid is None or grid.shape[:2] != (board.rows, board.cols):
        # found the other way round, with false corners, or unclearly: read it as given
        flags = cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
        for extra in (0, cv2.CALIB_CB_EXHAUSTIVE):
            ok, corners = cv2.findChessboardCornersSB(gray, size, flags=flags | extra)
            if ok:
                break
        else:
            return None
        pts = corners.reshape(-1, 2).astype(np.float64)
    return pts, np.arange(len(pts))


def _homography(grid: np.ndarray):
    """The homography from grid indices (col, row) to the image, of a (rows, cols, 2) grid."""
    import cv2

    rows, cols = grid.shape[:2]
    gy, gx = np.mgrid[0:rows, 0:cols]
    index = np.column_stack([gx.ravel(), gy.ravel()]).astype(np.float64)
    return cv2.findHomography(index, grid.reshape(-1, 2), 0)[0]


def _x_corners(smooth: np.ndarray, H: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Whether a checkerboard's X-corner is at each grid index (col, row): of the four squares
    around it, those on one diagonal are both darker than both on the other.

    A point on the board's edge, where squares meet the plain margin, is no X-corner (three
    of its four squares are light, or the margin's level).  ``smooth`` is the image
    averaged over about a third of a square; the squares are sampled at their centres.
    """
    import cv2

    index = np.asarray(index, np.float64).reshape(-1, 2)
    centres = [index + d for d in ((0.5, 0.5), (-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5))]
    image = [cv2.perspectiveTransform(c[None], H)[0].astype(np.float32) for c in centres]
    level = [
        cv2.remap(smooth, p[:, 0:1], p[:, 1:2], cv2.INTER_LINEAR, borderValue=-1.0).ravel()
        for p in image
    ]
    a, b, c, d = level
    inside = np.min(level, axis=0) >= 0
    span = np.max(level, axis=0) - np.min(level, axis=0)
    gap = np.maximum(np.minimum(a, b) - np.maximum(c, d), np.minimum(c, d) - np.maximum(a, b))
    return inside & (gap > 0.3 * span) & (span > 0.1 * 255)


def _edges(rows: int, cols: int, offset: int) -> dict[str, np.ndarray]:
    """Grid indices (col, row) of the edge rows and columns of a rows x cols grid (offset 0),
    or of those just outside it (offset 1)."""
    top, bottom, left, right = -offset, rows - 1 + offset, -offset, cols - 1 + offset
    return {
        "top": np.column_stack([np.arange(cols), np.full(cols, top)]),
        "bottom": np.column_stack([np.arange(cols), np.full(cols, bottom)]),
        "left": np.column_stack([np.full(rows, left), np.arange(rows)]),
        "right": np.column_stack([np.full(rows, right), np.arange(rows)]),
    }


def _board_grid(gray: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The X-corners around a detected corner grid (rows, cols, 2): edge rows or columns of
    points that are mostly no X-corners are dropped, one at a time; then rows or columns
    of X-corners just outside (:data:`_CONTINUES` of them) are added, one at a time."""
    import cv2

    steps = np.linalg.norm(np.diff(grid, axis=1), axis=-1)
    k = max(3, int(np.median(steps) / 3) | 1)
    smooth = cv2.blur(gray.astype(np.float32), (k, k))
    while min(grid.shape[:2]) > 2:
        H = _homography(grid)
        if H is None:
            return grid
        share = {
            side: _x_corners(smooth, H, index).mean()
            for side, index in _edges(*grid.shape[:2], 0).items()
        }
        side = min(share, key=share.get)
        if share[side] >= 0.5:
            break
        grid = {"top": grid[1:], "bottom": grid[:-1], "left": grid[:, 1:],
                "right": grid[:, :-1]}[side]  # fmt: skip
    for _ in range(max(gray.shape)):  # a row or a column more each time: it ends
        H = _homography(grid)
        if H is None:
            break
        rows, cols = grid.shape[:2]
        for side, index in _edges(rows, cols, 1).items():
            if _x_corners(smooth, H, index).mean() >= _CONTINUES:
                line = cv2.perspectiveTransform(index.astype(np.float64)[None], H)[0]
                axis = 0 if side in ("top", "bottom") else 1
                parts = [np.expand_dims(line, axis), grid]
                grid = np.concatenate(parts if side in ("top", "left") else parts[::-1], axis)
                break
        else:
            break
    return grid


def _detect_circles(gray: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    """Dot centres by ``cv2.findCirclesGrid`` (dark dots on light, or light on dark).

    The blob detector is OpenCV's, with the area limits set by the grid: from 4
    px to the image's area shared among the dots (a dot cannot be larger; a
    larger limit lets the bright board itself, thresholded near its own gray
    level, count as a blob and pull a dot's centre away).  A dot's centre is
    its image's centroid (OpenCV's estimate), not corrected for perspective
    (Heikkila 2000): small dots keep the bias small.  A symmetric grid found
    inside a larger one (rows or columns of dots continue it) raises
    :class:`BoardSizeError`.
    """
    found = _find_circles(gray, board)
    if found is None:
        return None
    pts, blobs = found
    if board.kind == "circles":
        size = _grid_extent(pts, blobs, (board.cols, board.rows))
        if size != (board.cols, board.rows):
            raise BoardSizeError(board, size)
    return pts, np.arange(len(pts))


def _find_circles(gray: np.ndarray, board: Board):
    """(dot centres (M, 2), every blob's centre (K, 2)) of ``board``'s grid, or None."""
    import cv2

    params = cv2.SimpleBlobDetector_Params()
    params.minArea = 4.0
    params.maxArea = max(gray.size / (board.cols * board.rows), 8.0)
    params.minDistBetweenBlobs = 2.0
    size = (board.cols, board.rows)
    grid = cv2.CALIB_CB_ASYMMETRIC_GRID if board.kind == "acircles" else cv2.CALIB_CB_SYMMETRIC_GRID
    for image in (gray, 255 - gray):  # dark dots first, then light ones
        detector = cv2.SimpleBlobDetector_create(params)
        for flags in (grid, grid | cv2.CALIB_CB_CLUSTERING):
            found, centers = cv2.findCirclesGrid(image, size, flags=flags, blobDetector=detector)
            if found:
                blobs = np.array([k.pt for k in detector.detect(image)], np.float64)
                return centers.reshape(-1, 2).astype(np.float64), blobs.reshape(-1, 2)
    return None


def _grid_extent(points: np.ndarray, blobs: np.ndarray, size: tuple[int, int]) -> tuple[int, int]:
    """The (cols, rows) of the symmetric dot grid that holds ``points`` (a ``size`` grid,
    row-major): grown a row or a column at a time while blobs continue it.

    Each step maps grid indices to the image by the homography of the dots
    known so far and looks for a blob within a third of the dot spacing of
    each predicted dot of the next row or column on each side; a side grows
    when :data:`_CONTINUES` of them are there.
    """
    import cv2

    cols, rows = size
    gy, gx = np.mgrid[0:rows, 0:cols]
    index = np.column_stack([gx.ravel(), gy.ravel()]).astype(np.float64)
    known = np.asarray(points, np.float64)
    spacing = np.median(np.linalg.norm(np.diff(known.reshape(rows, cols, 2), axis=1), axis=-1))
    x0, x1, y0, y1 = 0, cols - 1, 0, rows - 1
    for _ in range(len(blobs) + 1):  # each step takes new blobs: it ends
        H = cv2.findHomography(index, known, 0)[0]
        if H is None or len(blobs) == 0:
            break
        grown = False
        for side in ("x0", "x1", "y0", "y1"):
            if side in ("x0", "x1"):
                x = x0 - 1 if side == "x0" else x1 + 1
                candidates = np.column_stack([np.full(y1 - y0 + 1, x), np.arange(y0, y1 + 1)])
            else:
                y = y0 - 1 if side == "y0" else y1 + 1
                candidates = np.column_stack([np.arange(x0, x1 + 1), np.full(x1 - x0 + 1, y)])
            candidates = candidates.astype(np.float64)
            predicted = cv2.perspectiveTransform(candidates[None], H)[0]
            distance = np.linalg.norm(predicted[:, None] - blobs[None], axis=-1)
            nearest = distance.argmin(axis=1)
            hit = distance[np.arange(len(predicted)), nearest] < spacing / 3
            if hit.mean() < _CONTINUES:
                continue
            index = np.vstack([index, candidates[hit]])
            known = np.vstack([known, blobs[nearest[hit]]])
            x0, x1, y0, y1 = (
                x0 - (side == "x0"), x1 + (side == "x1"), y0 - (side == "y0"), y1 + (side == "y1")
            )  # fmt: skip
            grown = True
        if not grown:
            break
    return x1 - x0 + 1, y1 - y0 + 1


def board_size_in(image: np.ndarray, board: Board) -> tuple[int, int] | None:
    """The size (cols, rows) of the checkerboard or symmetric dot grid an image holds, in the
    order ``board`` names its sides; None when none is found or for other targets.

    For the message of a target that was not found: it tells which size to give.
    """
    gray = _gray_uint8(image)
    if board.kind == "checkerboard":
        found = _find_checkerboard(gray, (3, 3))
        if found is None or found[1] is None:
            return None
        rows, cols = _board_grid(gray, found[1]).shape[:2]
        return _as_given(board, (cols, rows))
    if board.kind == "circles":
        found = _find_circles(gray, _resized(board, (3, 3)))
        return None if found is None else _as_given(board, _grid_extent(*found, (3, 3)))
    return None


#: largest deviation of ``R @ R.T`` from the identity accepted for a rotation
ROTATION_TOLERANCE = 1e-6
#: px: a rig whose RMS reprojection error over the target views is above this is a poor
#: calibration (good ones reach 0.1-0.3 px): ``stereo calibrate`` warns and flags it in the
#: calibration file, and the reconstruction's report flags it
POOR_RMS_PX = 0.5
#: px: above this RMS no real rig was calibrated (a wrong board size, pairs out of step):
#: refused wherever a calibration is made or read
MAX_RMS_PX = 5.0
#: mm: two cameras are never closer than this (lenses have apertures); a smaller baseline is
#: that of the same images on both sides, or of a T in another unit than the calibration's
MIN_BASELINE_MM = 1.0
#: the least baseline as a share of the distance to the target or the surface (a
#: triangulation angle of 0.6 degrees): below it depth is 100 times less certain than the
#: position across the view, and is not measured
MIN_BASELINE_RATIO = 0.01
#: millimetres per length unit, for :data:`MIN_BASELINE_MM` (other units are not checked)
_MM_PER_UNIT = {
    "nm": 1e-6, "um": 1e-3, "\u00b5m": 1e-3, "\u03bcm": 1e-3, "micron": 1e-3, "microns": 1e-3,
    "mm": 1.0, "cm": 10.0, "dm": 100.0, "m": 1000.0, "in": 25.4, "inch": 25.4, "ft": 304.8,
}  # fmt: skip
#: the lengths of OpenCV's distortion vectors (0: no distortion)
DISTORTION_LENGTHS = (0, 4, 5, 8, 12, 14)
#: the keys :meth:`Calibration.save` always writes (how a calibration of this toolkit is known)
CALIBRATION_KEYS = (
    "image_size", "K_left", "dist_left", "K_right", "dist_right", "R", "T", "rms_px", "unit",
    "baseline", "convention",
)  # fmt: skip
_REQUIRED = ("image_size", "K_left", "dist_left", "K_right", "dist_right", "R", "T")


class CalibrationValueError(InputError):
    """A calibration value that is not part of a camera model; ``field`` names it."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field} {message}")
        self.field = field


def _is_number(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


def _numbers(value, field: str, shape_text: str, *, max_depth: int = 2) -> np.ndarray:
    """``value`` (nested lists of numbers, or a numeric array) as a float64 array.

    Text, booleans, ``None``, objects and ragged lists are refused: a calibration
    holds numbers only.
    """
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "iuf":
            raise CalibrationValueError(field, f"must be {shape_text} of numbers")
        return value.astype(np.float64)

    def numeric(v, depth: int) -> bool:
        if _is_number(v):
            return True
        return (
            isinstance(v, list | tuple)
            and depth < max_depth
            and all(numeric(x, depth + 1) for x in v)
        )

    if not numeric(value, 0):
        raise CalibrationValueError(
            field, f"must be {shape_text} of numbers, got {_describe(value)}"
        )
    try:
        return np.array(value, dtype=np.float64)
    except OverflowError:  # an integer beyond float range
        raise CalibrationValueError(field, "must hold finite numbers") from None
    except ValueError:  # ragged
        raise CalibrationValueError(
            field, f"must be {shape_text} of numbers, got {_describe(value)}"
        ) from None


def _describe(value) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _matrix(value, field: str) -> np.ndarray:
    m = _numbers(value, field, "a 3 x 3 matrix")
    if m.shape != (3, 3):
        raise CalibrationValueError(field, f"must be a 3 x 3 matrix, got shape {m.shape}")
    if not np.isfinite(m).all():
        raise CalibrationValueError(field, "must hold finite numbers (it holds NaN or inf)")
    return m


def _camera_matrix(value, field: str) -> np.ndarray:
    K = _matrix(value, field)
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise CalibrationValueError(
            field, f"must have positive focal lengths fx, fy, got {K[0, 0]:g}, {K[1, 1]:g}"
        )
    if K[1, 0] != 0 or tuple(K[2]) != (0, 0, 1):
        raise CalibrationValueError(
            field, "must be a camera matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]]"
        )
    return K


def _rotation(value, field: str) -> np.ndarray:
    R = _matrix(value, field)
    # a rotation's entries lie in [-1, 1]: bound them before multiplying (no overflow)
    off = float(np.abs(np.clip(R, -2, 2) @ np.clip(R, -2, 2).T - np.eye(3)).max())
    if off > ROTATION_TOLERANCE or np.abs(R).max() > 2:
        raise CalibrationValueError(
            field,
            f"is not a rotation: R R^T differs from the identity by {off:.3g} "
            f"(at most {ROTATION_TOLERANCE:g} allowed)",
        )
    if np.linalg.det(R) < 0:
        raise CalibrationValueError(field, "is not a rotation: it is a reflection (det R = -1)")
    return R


def _translation(value, field: str, unit: str) -> np.ndarray:
    T = _numbers(value, field, "3 numbers").ravel()
    if T.size != 3:
        raise CalibrationValueError(field, f"must hold 3 numbers, got {T.size}")
    if not np.isfinite(T).all():
        raise CalibrationValueError(field, "must hold finite numbers (it holds NaN or inf)")
    scale = float(np.abs(T).max())
    baseline = scale * float(np.linalg.norm(T / scale)) if scale > 0 else 0.0
    if not 0 < baseline < 1e9:
        raise CalibrationValueError(
            field,
            f"gives the baseline |T| = {baseline:g}: the two cameras must be apart "
            "(0 < |T| < 1e9 in the calibration's unit)",
        )
    mm = _MM_PER_UNIT.get(unit.strip().lower())
    if mm is not None and baseline * mm < MIN_BASELINE_MM:
        in_mm = f" ({baseline * mm:.3g} mm)" if mm != 1 else ""
        raise CalibrationValueError(
            field,
            f"gives the baseline |T| = {baseline:.3g} {unit}{in_mm}: two cameras are never "
            f"closer than "
            f"{MIN_BASELINE_MM:g} mm (the same images on both sides give about 0; if T is in "
            "another unit, say which: stereo import-calib --unit)",
        )
    return T


def _distortion(value, field: str) -> np.ndarray:
    from stereo.camera import _coefficients

    d = _numbers(value, field, "a list").ravel()
    if d.size not in DISTORTION_LENGTHS:
        raise CalibrationValueError(
            field, f"must hold 4, 5, 8, 12 or 14 coefficients (OpenCV's models), got {d.size}"
        )
    if not np.isfinite(d).all():
        raise CalibrationValueError(field, "must hold finite numbers (it holds NaN or inf)")
    try:
        _coefficients(d)
    except ValueError:
        raise CalibrationValueError(
            field, "has tilted-sensor terms (tau x, tau y), which are not supported"
        ) from None
    if d.size < 5:
        d = np.concatenate([d, np.zeros(5 - d.size)])
    return d


def _image_size(value) -> tuple[int, int]:
    size = _numbers(value, "image_size", "[width, height]").ravel()
    if (
        size.size != 2
        or not np.isfinite(size).all()
        or (size != np.round(size)).any()
        or (size < 1).any()
        or (size > 2**31 - 1).any()
    ):
        raise CalibrationValueError(
            "image_size", f"must be [width, height] in whole pixels > 0, got {_describe(value)}"
        )
    return int(size[0]), int(size[1])


@dataclass
class Calibration:
    """A calibrated stereo rig (OpenCV conventions, see :mod:`stereo.camera`).

    Every value is checked when the calibration is made (so also when it is
    read): ``R`` must be a rotation (orthonormal to :data:`ROTATION_TOLERANCE`,
    det +1), the focal lengths positive, every number finite, the distortion
    vectors of a length OpenCV accepts, the image size whole pixels, the
    baseline ``|T|`` positive and, in a length unit it knows (mm, m, um...), at
    least :data:`MIN_BASELINE_MM`, and ``rms_px`` (when known) at most
    :data:`MAX_RMS_PX`.

    Attributes
    ----------
    image_size : (width, height) px
    K_left, K_right : (3, 3) camera matrices ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``;
        the skew ``s`` is part of the model (see :mod:`stereo.camera`), 0 for
        OpenCV's own calibrations
    dist_left, dist_right : (5,) distortion (k1, k2, p1, p2, k3), or OpenCV's
        8, 12 or 14 coefficients
    R, T : (3, 3), (3,) ``x_right = R x_left + T``
    rms_px : float
        RMS reprojection error of the rig over all kept views (NaN: unknown).
    unit : str
        Unit of ``T`` and of triangulated points (the board's square size unit).
    extra : dict
        Per-camera RMS, per-view errors, rejected images and why, board,
        software version.

    Raises
    ------
    CalibrationValueError
        (an :class:`~tissue_core.errors.InputError`) naming the value that is wrong.
    """

    image_size: tuple[int, int]
    K_left: np.ndarray
    dist_left: np.ndarray
    K_right: np.ndarray
    dist_right: np.ndarray
    R: np.ndarray
    T: np.ndarray
    rms_px: float = float("nan")
    unit: str = "mm"
    extra: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.image_size = _image_size(self.image_size)
        self.K_left = _camera_matrix(self.K_left, "K_left")
        self.K_right = _camera_matrix(self.K_right, "K_right")
        self.dist_left = _distortion(self.dist_left, "dist_left")
        self.dist_right = _distortion(self.dist_right, "dist_right")
        self.R = _rotation(self.R, "R")
        if not isinstance(self.unit, str) or not self.unit.strip():
            raise CalibrationValueError("unit", f"must be a name such as mm, got {self.unit!r}")
        self.T = _translation(self.T, "T", self.unit)
        rms = float("nan") if self.rms_px is None else self.rms_px
        if not _is_number(rms) or math.isinf(rms) or rms < 0:
            raise CalibrationValueError(
                "rms_px", f"must be a number >= 0 (or null), got {_describe(self.rms_px)}"
            )
        if rms > MAX_RMS_PX:
            raise CalibrationValueError(
                "rms_px",
                f"is {rms:.3g} px: no real rig calibrates that poorly (at most {MAX_RMS_PX:g} px); "
                "the calibration is wrong (a wrong board size, pairs out of step): calibrate again",
            )
        self.rms_px = float(rms)
        if not isinstance(self.extra, dict):
            raise CalibrationValueError("extra", "must be a dict")

    @property
    def baseline(self) -> float:
        """Distance between the two optical centres, in ``unit``."""
        return float(np.linalg.norm(self.T))

    def to_dict(self) -> dict:
        out = {
            "image_size": list(self.image_size),
            "K_left": self.K_left.tolist(),
            "dist_left": self.dist_left.tolist(),
            "K_right": self.K_right.tolist(),
            "dist_right": self.dist_right.tolist(),
            "R": self.R.tolist(),
            "T": self.T.tolist(),
            "rms_px": None if not math.isfinite(self.rms_px) else float(self.rms_px),
            "unit": self.unit,
            "baseline": self.baseline,
            "convention": "OpenCV: x_right = R x_left + T; pixel (0, 0) is the centre "
            "of the top-left pixel; distortion (k1, k2, p1, p2, k3)",
        }
        out.update({k: v for k, v in self.extra.items() if k not in out})
        return out

    @classmethod
    def from_dict(cls, d: dict) -> Calibration:
        """A calibration from :meth:`to_dict`'s layout (``baseline`` is recomputed)."""
        if not isinstance(d, dict):
            raise InputError(
                f"a calibration must be an object with the keys {', '.join(_REQUIRED)}"
            )
        missing = [k for k in _REQUIRED if k not in d]
        if missing:
            verb = "is" if len(missing) == 1 else "are"
            raise InputError(
                f"{', '.join(missing)} {verb} missing (a calibration holds {', '.join(_REQUIRED)})"
            )
        extra = {k: v for k, v in d.items() if k not in CALIBRATION_KEYS}
        return cls(
            **{k: d[k] for k in _REQUIRED},
            rms_px=d.get("rms_px"),
            unit=d.get("unit", "mm"),
            extra=extra,
        )

    def save(self, path: str | os.PathLike) -> None:
        """Write the calibration as strict JSON (non-finite numbers in ``extra`` as null)."""
        from tissue_core.jsonio import write_json

        write_json(path, self.to_dict())


def _node_value(node):
    """A FileStorage node as a number, an array, a string, or a list (ragged or mixed).

    None for empty nodes and maps that are not matrices.
    """
    if node.isInt() or node.isReal():
        return node.real()
    if node.isString():
        return node.string()
    if node.isSeq():
        items = [_node_value(node.at(i)) for i in range(node.size())]
        try:
            return np.asarray(items, np.float64)
        except (ValueError, TypeError):  # ragged, or not numbers: the checks say what
            return items
    if node.isMap():
        try:
            mat = node.mat()  # an !!opencv-matrix
        except Exception:  # cv2.error: a map that is not a matrix
            return None
        return None if mat is None else np.asarray(mat, np.float64)
    return None


def _opencv_file(path: Path) -> dict:
    """Values of an OpenCV FileStorage (YAML/XML) file by lower-case name: (name, value)."""
    import cv2

    from tissue_core.filenames import utf8_alias
    from tissue_core.interrupt import is_interrupt

    try:
        # OpenCV crashes on a name that is not UTF-8; it reads the whole file on opening
        with utf8_alias(path) as name:
            fs = cv2.FileStorage(str(name), cv2.FILE_STORAGE_READ)
        opened = fs.isOpened()
    except (cv2.error, SystemError) as exc:
        if is_interrupt(exc):
            raise KeyboardInterrupt from None
        opened = False
    if not opened:
        raise InputError(f"{path}: not a readable calibration file (OpenCV YAML/XML or JSON)")
    try:
        root = fs.root()
        if not root.isMap():
            raise InputError(
                f"{path}: not a readable calibration file (OpenCV YAML/XML holding named "
                "matrices such as M1, D1, R, T)"
            )
        out = {}
        for key in root.keys():
            value = _node_value(fs.getNode(key))
            if value is not None:
                out[key.lower()] = (key, value)
        return out
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: not a readable calibration file (names that are not UTF-8 text)"
        ) from None
    except (cv2.error, SystemError) as exc:
        if is_interrupt(exc):
            raise KeyboardInterrupt from None
        reason = getattr(exc, "err", None) or str(exc)
        raise InputError(f"{path}: cannot read the calibration ({reason.strip()})") from None
    finally:
        fs.release()


#: names under which OpenCV files hold each value (matched ignoring case)
_ALIASES = {
    "K_left": ("M1", "K_left", "cameraMatrix1", "camera_matrix_left", "cameraMatrixLeft", "K1"),
    "dist_left": ("D1", "dist_left", "distCoeffs1", "dist_coeffs_left", "distortion_left"),
    "K_right": ("M2", "K_right", "cameraMatrix2", "camera_matrix_right", "cameraMatrixRight", "K2"),
    "dist_right": ("D2", "dist_right", "distCoeffs2", "dist_coeffs_right", "distortion_right"),
    "R": ("R",),
    "T": ("T",),
}


def _read_json_calibration(path: Path, *, unit: str | None = None) -> Calibration:
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a valid calibration JSON ({exc})") from None
    except RecursionError:
        raise InputError(f"{path}: not a valid calibration JSON (nested too deeply)") from None
    if not isinstance(data, dict):
        raise InputError(
            f"{path}: a calibration JSON must hold an object, not {type(data).__name__}"
        )
    own = data.get("unit", "mm")
    if unit is not None and isinstance(own, str) and own.strip():  # a malformed one is named
        data = {**data, "unit": unit}
    try:
        return Calibration.from_dict(data)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


def load_calibration(
    *paths: str | os.PathLike,
    image_size: tuple[int, int] | None = None,
    unit: str | None = None,
) -> Calibration:
    """Read a calibration: this package's JSON, OpenCV YAML/XML file(s), VIC-3D or DICe XML.

    OpenCV files (e.g. the ``intrinsics.yml`` and ``extrinsics.yml`` of
    OpenCV's stereo sample) may be given together; matrices are found under
    the usual names (``M1/D1/M2/D2``, ``K1/K2``, ``cameraMatrix1``...,
    ``R``, ``T``), the image size under ``image_size``/``imageSize`` or
    ``image_width``/``image_height``, or from ``image_size`` (OpenCV's
    stereo sample writes none).  VIC-3D and DICe XML files are converted by
    :mod:`stereo.calib_formats` (their conventions are described there).

    Parameters
    ----------
    *paths : the file(s)
    image_size : (width, height) px, keyword-only
        For files that hold no image size (``--image-size``); a file that
        holds another one is refused, a calibration JSON included.
    unit : str, keyword-only
        The unit of T (``--unit``): that of a calibration JSON is replaced,
        other files are taken to be in mm without it.

    Raises
    ------
    SourceError
        A file that is missing, a folder, or empty.
    InputError
        A file that is not a calibration, or a value that is not part of a
        camera model; one line naming the file and the value.
        :class:`stereo.calib_formats.ImageSizeMissing` (an ``InputError``): the
        files hold no image size and ``image_size`` is None.

    Notes
    -----
    Every value is checked (see :class:`Calibration`).
    """
    if not paths:
        raise InputError("no calibration file given")
    paths = tuple(Path(p) for p in paths)
    for p in paths:
        if p.is_dir():
            raise SourceError(f"{p} is a folder, not a calibration file")
        if not p.is_file():
            raise SourceError(f"calibration file not found: {p}")
        if p.stat().st_size == 0:
            raise SourceError(f"{p} is empty: not a calibration file")
    first = paths[0]
    from stereo.calib_formats import ImageSizeMissing, read_dice, read_vic3d, sniff

    kinds = [sniff(p) for p in paths]
    if any(kinds):
        if len(paths) > 1:
            names = ", ".join(map(str, paths))
            raise InputError(f"give one VIC-3D or DICe calibration file, not {names}")
        reader = read_vic3d if kinds[0] == "vic3d" else read_dice
        return reader(first, image_size=image_size, unit=unit)

    def is_json(p: Path) -> bool:
        with open(p, "rb") as f:
            head = f.read(64).removeprefix(b"\xef\xbb\xbf").lstrip()
        return p.suffix.lower() == ".json" or head.startswith(b"{")

    if any(is_json(p) for p in paths):
        if len(paths) > 1:
            names = ", ".join(map(str, paths))
            raise InputError(
                f"give one calibration JSON, or OpenCV YAML/XML files (intrinsics, "
                f"extrinsics), not {names}"
            )
        calib = _read_json_calibration(first, unit=unit)
        if image_size is not None and tuple(calib.image_size) != tuple(image_size):
            w, h = calib.image_size
            raise InputError(
                f"{first}: the calibration is for {w}x{h} px images, --image-size says "
                f"{image_size[0]}x{image_size[1]}"
            )
        return calib
    merged: dict = {}  # lower-case name -> (file, name in the file, value)
    for p in paths:
        for key, (name, value) in _opencv_file(p).items():
            merged[key] = (p, name, value)
    values, origin = {}, {}
    for field_name, aliases in _ALIASES.items():
        found = next((merged[a.lower()] for a in aliases if a.lower() in merged), None)
        if found is None:
            raise InputError(
                f"{', '.join(map(str, paths))}: no {field_name} (looked for {', '.join(aliases)})"
            )
        origin[field_name] = found[:2]
        values[field_name] = found[2]
    if "image_size" in merged or "imagesize" in merged:
        found = merged.get("image_size", merged.get("imagesize"))
        origin["image_size"] = found[:2]
        size = found[2]
    elif "image_width" in merged and "image_height" in merged:
        origin["image_size"] = (merged["image_width"][0], "image_width, image_height")
        size = [merged["image_width"][2], merged["image_height"][2]]
    elif image_size is not None:
        size = list(image_size)
    else:
        raise ImageSizeMissing(
            f"{', '.join(map(str, paths))}: no image size (image_size, or image_width and "
            "image_height; OpenCV's stereo_calib sample writes none): give --image-size WxH"
        )
    if image_size is not None and "image_size" in origin:
        try:
            same = np.array_equal(np.asarray(size, np.float64).ravel(), np.asarray(image_size))
        except (TypeError, ValueError):
            same = True  # a malformed size in the file: the checks below name it
        if not same:
            path, name = origin["image_size"]
            raise InputError(
                f"{path}: {name} says the images are not {image_size[0]}x{image_size[1]} px "
                "as --image-size says"
            )
    try:
        return Calibration(
            image_size=size, **values, unit=unit or "mm", extra={"imported_format": "opencv"}
        )
    except CalibrationValueError as exc:
        path, name = origin.get(exc.field, (first, exc.field))
        label = exc.field if name == exc.field else f"{name} ({exc.field})"
        raise InputError(f"{path}: {label}{str(exc)[len(exc.field) :]}") from None


def _per_view_rms(obj, img, rvecs, tvecs, K, dist) -> np.ndarray:
    import cv2

    out = []
    for o, i, r, t in zip(obj, img, rvecs, tvecs, strict=True):
        proj = cv2.projectPoints(o, r, t, K, dist)[0].reshape(-1, 2)
        out.append(float(np.sqrt(np.mean(np.sum((proj - i.reshape(-1, 2)) ** 2, axis=1)))))
    return np.asarray(out)


def _reversed(left: np.ndarray, right: np.ndarray) -> bool:
    """Whether two detections of a checkerboard run in opposite directions."""
    a, b = left[-1] - left[0], right[-1] - right[0]
    return float(a @ b) < 0


def calibrate_stereo(
    left: Sequence[np.ndarray],
    right: Sequence[np.ndarray],
    board: Board,
    *,
    names: Sequence[str] | None = None,
    unit: str = "mm",
    outlier_factor: float = 3.0,
    min_views: int = 4,
    fix_k3: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Calibration:
    """Calibrate a stereo rig from image pairs of a calibration target.

    1. Refuse a picture that is on both sides (the same images for --left
       and --right): a calibration needs two cameras.
    2. Detect the target in each pair; a pair is rejected (with the reason)
       when it is missing from either view or the two views share fewer
       than 6 corners.  A target larger than ``board`` (OpenCV finds a part
       of it as readily as the whole) is refused, naming the size the images
       hold; so is a target found in too few pairs, naming it when it can.
    3. Calibrate each camera on its views (Zhang 2000); a pair is rejected
       when a view's reprojection RMS exceeds ``outlier_factor`` times the
       median and 0.5 px, and the cameras are calibrated again.
    4. Estimate ``(R, T)`` by ``cv2.stereoCalibrate`` with the intrinsics
       fixed, then refine everything together from there.
    5. Refuse a rig RMS reprojection error above :data:`MAX_RMS_PX` (no real
       rig: a wrong board, pairs out of step) and a baseline below
       :data:`MIN_BASELINE_RATIO` of the distance to the target; warn of an
       RMS above :data:`POOR_RMS_PX` and record it in ``extra["flags"]``.

    Parameters
    ----------
    left, right : sequences of gray (H, W) images, same count and size
    board : Board
    names : per-pair names for the report (default ``pair 0``, ...)
    unit : unit of the square size (and of everything measured later)
    fix_k3 : bool
        Keep the sixth-order radial term at zero (the default, as OpenCV
        advises for ordinary lenses): from planar targets it is poorly
        determined and trades off against k1, k2.

    Returns
    -------
    Calibration
        With ``extra`` holding ``rms_left_px``, ``rms_right_px``,
        ``views`` (name, per-view RMS), ``rejected`` (name, reason),
        ``flags`` (sentences: what a reader should know), the board spec and
        the software version.

    Raises
    ------
    InputError
        The refusals above, in one line.

    Warns
    -----
    UserWarning
        A poor calibration (RMS above :data:`POOR_RMS_PX`).
    """
    import cv2

    say = progress or (lambda message: None)
    if len(left) != len(right):
        raise InputError(f"unequal image counts: {len(left)} left and {len(right)} right")
    if len(left) == 0:
        raise InputError("no calibration images")
    names = list(names) if names is not None else [f"pair {i}" for i in range(len(left))]
    size = left[0].shape[:2]
    for i, (a, b) in enumerate(zip(left, right, strict=True)):
        if a.shape[:2] != size or b.shape[:2] != size:
            raise InputError(
                f"images differ in size: {names[i]} is {b.shape[1]}x{b.shape[0]} or "
                f"{a.shape[1]}x{a.shape[0]}, the first is {size[1]}x{size[0]}"
            )
    image_size = (int(size[1]), int(size[0]))
    _check_two_cameras(left, right, names)
    objp = board.object_points().astype(np.float32)
    rejected: list[dict] = []
    views = []  # (name, object points, left points, right points)
    for i, (a, b) in enumerate(zip(left, right, strict=True)):
        say(f"detecting the target: {names[i]} ({i + 1}/{len(left)})")
        try:
            dl, dr = detect_board(a, board), detect_board(b, board)
        except BoardSizeError as exc:
            raise InputError(f"{names[i]}: {exc}") from None
        if dl is None or dr is None:
            side = (
                "both views" if dl is None and dr is None else ("left" if dl is None else "right")
            )
            rejected.append({"image": names[i], "reason": f"no target found ({side})"})
            continue
        if board.kind in ("checkerboard", "circles") and _reversed(dl[0], dr[0]):
            # a checkerboard or symmetric dot grid has no marked origin: the detector may
            # start at the opposite corner in one view; the two views of a rig see the
            # board the same way round
            dr = (dr[0][::-1].copy(), dr[1])
        common, il, ir = np.intersect1d(dl[1], dr[1], return_indices=True)
        if common.size < 6:
            rejected.append({"image": names[i], "reason": f"only {common.size} common corners"})
            continue
        spread = np.linalg.svd(objp[common, :2] - objp[common, :2].mean(axis=0), compute_uv=False)
        if spread[-1] < 0.5 * board.square:
            rejected.append({"image": names[i], "reason": "the visible corners lie along a line"})
            continue
        views.append(
            (
                names[i],
                objp[common],
                dl[0][il].astype(np.float32),
                dr[0][ir].astype(np.float32),
            )
        )
    if len(views) < min_views:
        found = ", ".join(f"{r['image']}: {r['reason']}" for r in rejected[:3])
        held = [board_size_in(image, board) for image in left[:3]]
        held = max((h for h in held if h is not None), key=lambda h: h[0] * h[1], default=None)
        hint = (
            f": the images hold {held[0]}x{held[1]} "
            f"{'inner corners' if board.kind == 'checkerboard' else 'dots'} (e.g. --board "
            f"{_resized(board, held).spec()})"
            if held is not None and held != (board.cols, board.rows)
            else ""
        )
        raise InputError(
            f"the target was found in only {len(views)} of {len(left)} image pairs "
            f"(need {min_views}); check --board ({board.spec()}){hint}. {found}"
        )

    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    while True:
        say(f"calibrating each camera on {len(views)} views")
        obj = [v[1] for v in views]
        cams = []
        for side in (2, 3):
            pts = [v[side] for v in views]
            rms, K, dist, rv, tv = cv2.calibrateCamera(
                obj, pts, image_size, None, None, flags=flags
            )
            cams.append(
                (rms, K, dist.ravel(), _per_view_rms(obj, pts, rv, tv, K, dist), (obj, rv, tv))
            )
        worst = np.maximum(cams[0][3], cams[1][3])
        limit = max(outlier_factor * float(np.median(worst)), 0.5)
        bad = np.flatnonzero(worst > limit)
        if bad.size == 0 or len(views) - bad.size < min_views:
            break
        for j in sorted(bad, reverse=True):
            rejected.append(
                {
                    "image": views[j][0],
                    "reason": f"reprojection error {worst[j]:.2f} px "
                    f"(over {limit:.2f} px: {outlier_factor:g} x the median)",
                }
            )
            del views[j]

    say("estimating the rig's extrinsics")
    obj = [v[1] for v in views]
    pl, pr = [v[2] for v in views], [v[3] for v in views]
    Kl, dl, Kr, dr = cams[0][1], cams[0][2], cams[1][1], cams[1][2]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-10)
    try:
        rms, Kl, dl, Kr, dr, R, T, *_ = cv2.stereoCalibrate(
            obj, pl, pr, Kl, dl, Kr, dr, image_size, criteria=crit, flags=cv2.CALIB_FIX_INTRINSIC
        )
        rms, Kl, dl, Kr, dr, R, T, _, _, _, _, per_view = cv2.stereoCalibrateExtended(
            obj,
            pl,
            pr,
            Kl,
            dl,
            Kr,
            dr,
            image_size,
            R,
            T,
            criteria=crit,
            flags=cv2.CALIB_USE_INTRINSIC_GUESS | flags,
        )
    except cv2.error as exc:
        raise InputError(f"stereo calibration failed: {exc.err}") from None
    per_view = np.asarray(per_view, np.float64).reshape(len(views), 2)
    rms, baseline = float(rms), float(np.linalg.norm(T))
    if not rms <= MAX_RMS_PX:
        raise InputError(
            f"the rig's RMS reprojection error is {rms:.3g} px over {len(views)} pairs: no real "
            f"rig calibrates that poorly (at most {MAX_RMS_PX:g} px); check --board "
            f"({board.spec()}: the size and the square), that each left image was taken at the "
            "same moment as its right one and that both sides list the pairs in the same order"
        )
    check_baseline_ratio(baseline, _target_distance(*cams[0][4]), unit=unit, what="the target")
    flags_raised = []
    if rms > POOR_RMS_PX:
        flags_raised.append(
            f"The rig's RMS reprojection error is {rms:.3g} px, above {POOR_RMS_PX:g} px: a poor "
            "calibration (good ones reach 0.1-0.3 px); 3D positions carry its error. "
            "Recalibrate with sharp, well-lit target views at varied tilts."
        )
    for text in flags_raised:
        warnings.warn(text, UserWarning, stacklevel=2)
    from tissue_core.version import __version__

    extra = {
        "rms_left_px": float(cams[0][0]),
        "rms_right_px": float(cams[1][0]),
        "views": [  # reprojection RMS of each kept pair in the final rig fit
            {"image": v[0], "rms_left_px": float(e[0]), "rms_right_px": float(e[1])}
            for v, e in zip(views, per_view, strict=True)
        ],
        "rejected": rejected,
        "flags": flags_raised,
        "board": board.spec(),
        "software": {"package": "tissue-strain", "module": "stereo", "version": __version__},
    }
    return Calibration(
        image_size=image_size,
        K_left=Kl,
        dist_left=dl.ravel(),
        K_right=Kr,
        dist_right=dr.ravel(),
        R=R,
        T=T.ravel(),
        rms_px=rms,
        unit=unit,
        extra=extra,
    )


def _check_two_cameras(left: Sequence[np.ndarray], right: Sequence[np.ndarray], names) -> None:
    """Refuse a left image that is also a right image (the same picture on both sides)."""
    import hashlib

    def digest(image: np.ndarray) -> tuple:
        return image.shape, hashlib.sha256(np.ascontiguousarray(image)).digest()

    seen = {digest(a): i for i, a in enumerate(left)}
    for j, b in enumerate(right):
        i = seen.get(digest(b))
        if i is None:
            continue
        which = (
            f"{names[i]}: the left and right images are the same picture"
            if i == j
            else f"the left image of {names[i]} is the right image of {names[j]}"
        )
        raise InputError(
            f"{which}; a stereo calibration needs each camera's own views of the target "
            "(--left and --right)"
        )


def _target_distance(objects, rvecs, tvecs) -> float:
    """The median distance from the camera to the centre of the target over the views."""
    import cv2

    centres = [
        cv2.Rodrigues(r)[0] @ o.reshape(-1, 3).mean(axis=0) + np.ravel(t)
        for o, r, t in zip(objects, rvecs, tvecs, strict=True)
    ]
    return float(np.median(np.linalg.norm(centres, axis=1)))


def check_baseline_ratio(baseline: float, distance: float, *, unit: str, what: str) -> None:
    """Refuse a baseline below :data:`MIN_BASELINE_RATIO` of the distance to ``what``.

    Two cameras that close see ``what`` from nearly the same place: the rays
    to a point meet at a glancing angle and its depth is not measured.

    Parameters
    ----------
    baseline : float
        ``|T|``, in ``unit``.
    distance : float
        The median distance from the left camera to ``what`` (the target's
        views, the reconstructed surface), in ``unit``.
    unit : str, keyword-only
    what : str, keyword-only
        What the distance is to, for the message.

    Raises
    ------
    InputError

    Examples
    --------
    >>> check_baseline_ratio(120.0, 450.0, unit="mm", what="the target")
    >>> check_baseline_ratio(0.8, 450.0, unit="mm", what="the target")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    tissue_core.errors.InputError: the cameras are 0.8 mm apart for the target 450 mm away ...
    """
    if not (math.isfinite(distance) and distance > 0):
        return
    ratio = baseline / distance
    if ratio < MIN_BASELINE_RATIO:
        raise InputError(
            f"the cameras are {baseline:.3g} {unit} apart for {what} {distance:.3g} {unit} away "
            f"({100 * ratio:.2g} % of the distance; at least {100 * MIN_BASELINE_RATIO:g} % "
            "needed): they see it from nearly the same place and depth is not measured; use "
            "images of two cameras set apart"
        )
