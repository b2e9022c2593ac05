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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tissue_core.errors import InputError, SourceError

__all__ = [
    "CALIBRATION_KEYS",
    "Board",
    "Calibration",
    "CalibrationValueError",
    "calibrate_stereo",
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


def detect_board(image: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    """Sub-pixel corners of ``board`` in a gray image.

    Returns
    -------
    (image_points (M, 2) float64, ids (M,) int) or None when not found.
    ``ids`` index :meth:`Board.object_points`.
    """
    import cv2

    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if gray.dtype != np.uint8:
        lo, hi = float(gray.min()), float(gray.max())
        gray = np.uint8(np.clip((gray - lo) * 255.0 / max(hi - lo, 1e-12), 0, 255))
    if board.kind == "checkerboard":
        size = (board.cols, board.rows)
        flags = cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCornersSB(gray, size, flags=flags)
        if not found:  # harder images: a slower, exhaustive search
            flags |= cv2.CALIB_CB_EXHAUSTIVE
            found, corners = cv2.findChessboardCornersSB(gray, size, flags=flags)
        if not found:
            return None
        pts = corners.reshape(-1, 2).astype(np.float64)
        return pts, np.arange(len(pts))
    if board.kind in ("circles", "acircles"):
        return _detect_circles(gray, board)
    detector = cv2.aruco.CharucoDetector(board.opencv_board())
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < 6:
        return None
    return corners.reshape(-1, 2).astype(np.float64), ids.ravel().astype(np.int64)


def _detect_circles(gray: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    """Dot centres by ``cv2.findCirclesGrid`` (dark dots on light, or light on dark).

    The blob detector is OpenCV's, with the area limits set by the grid: from 4
    px to the image's area shared among the dots (a dot cannot be larger; a
    larger limit lets the bright board itself, thresholded near its own gray
    level, count as a blob and pull a dot's centre away).  A dot's centre is
    its image's centroid (OpenCV's estimate), not corrected for perspective
    (Heikkila 2000): small dots keep the bias small.
    """
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
                pts = centers.reshape(-1, 2).astype(np.float64)
                return pts, np.arange(len(pts))
    return None


#: largest deviation of ``R @ R.T`` from the identity accepted for a rotation
ROTATION_TOLERANCE = 1e-6
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


def _translation(value, field: str) -> np.ndarray:
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
    vectors of a length OpenCV accepts, the image size whole pixels and the
    baseline ``|T|`` positive.

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
        self.T = _translation(self.T, "T")
        rms = float("nan") if self.rms_px is None else self.rms_px
        if not _is_number(rms) or math.isinf(rms) or rms < 0:
            raise CalibrationValueError(
                "rms_px", f"must be a number >= 0 (or null), got {_describe(self.rms_px)}"
            )
        self.rms_px = float(rms)
        if not isinstance(self.unit, str) or not self.unit.strip():
            raise CalibrationValueError("unit", f"must be a name such as mm, got {self.unit!r}")
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


def _read_json_calibration(path: Path) -> Calibration:
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
    try:
        return Calibration.from_dict(data)
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None


def load_calibration(
    *paths: str | os.PathLike, image_size: tuple[int, int] | None = None
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

    Every value is checked (see :class:`Calibration`).

    Raises
    ------
    SourceError
        A file that is missing, a folder, or empty.
    InputError
        A file that is not a calibration, or a value that is not part of a
        camera model; one line naming the file and the value.
        :class:`stereo.calib_formats.ImageSizeMissing` (an ``InputError``): the
        files hold no image size and ``image_size`` is None.
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
        return reader(first, image_size=image_size)

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
        calib = _read_json_calibration(first)
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
        return Calibration(image_size=size, **values, extra={"imported_format": "opencv"})
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

    1. Detect the target in each pair; a pair is rejected (with the reason)
       when it is missing from either view or the two views share fewer
       than 6 corners.
    2. Calibrate each camera on its views (Zhang 2000); a pair is rejected
       when a view's reprojection RMS exceeds ``outlier_factor`` times the
       median and 0.5 px, and the cameras are calibrated again.
    3. Estimate ``(R, T)`` by ``cv2.stereoCalibrate`` with the intrinsics
       fixed, then refine everything together from there.

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
        ``views`` (name, per-view RMS), ``rejected`` (name, reason), the
        board spec and the software version.
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
    objp = board.object_points().astype(np.float32)
    rejected: list[dict] = []
    views = []  # (name, object points, left points, right points)
    for i, (a, b) in enumerate(zip(left, right, strict=True)):
        say(f"detecting the target: {names[i]} ({i + 1}/{len(left)})")
        dl, dr = detect_board(a, board), detect_board(b, board)
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
        raise InputError(
            f"the target was found in only {len(views)} of {len(left)} image pairs "
            f"(need {min_views}); check --board ({board.spec()}). {found}"
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
            cams.append((rms, K, dist.ravel(), _per_view_rms(obj, pts, rv, tv, K, dist)))
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
    from tissue_core.version import __version__

    extra = {
        "rms_left_px": float(cams[0][0]),
        "rms_right_px": float(cams[1][0]),
        "views": [  # reprojection RMS of each kept pair in the final rig fit
            {"image": v[0], "rms_left_px": float(e[0]), "rms_right_px": float(e[1])}
            for v, e in zip(views, per_view, strict=True)
        ],
        "rejected": rejected,
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
        rms_px=float(rms),
        unit=unit,
        extra=extra,
    )
