"""Calibration targets: checkerboards, ChArUco boards and circle grids, their points and textures.

Board coordinates are millimetres, ``X_board = (x, y, 0)`` with ``x`` along
the board's columns, ``y`` along its rows and ``z`` into the board; where
each board's origin lies and how its poses are given: the conventions of
:mod:`sample_data_synth.stereo`.  :func:`parse_board` reads the command-line
spelling (``checkerboard:9x6:10``, ``charuco:11x8:8:6``, ``circles:9x6:10:5``,
``acircles:4x11:10:7``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from sample_data_synth._common import non_negative as _non_negative
from sample_data_synth._common import positive as _positive
from sample_data_synth._raytrace import _DARK, _LIGHT, _Raster

__all__ = ["Board", "CharucoBoard", "Checkerboard", "CircleGrid", "parse_board"]


_DICTIONARIES = {f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)} | {
    "DICT_ARUCO_ORIGINAL": 1024,
    "DICT_APRILTAG_16h5": 30,
    "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_36h10": 2320,
    "DICT_APRILTAG_36h11": 587,
    "DICT_ARUCO_MIP_36h12": 250,
}


def _check_counts(board, names: tuple[str, ...]) -> None:
    """Make the named fields of a frozen board integers >= 2, or raise ValueError."""
    for name in names:
        value = getattr(board, name)
        if int(value) != value or value < 2:
            raise ValueError(f"{name} must be an integer >= 2, got {value!r}")
        object.__setattr__(board, name, int(value))


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard target.

    Parameters
    ----------
    cols, rows : int
        Inner corners per row and per column (``patternSize = (cols, rows)``
        for ``cv2.findChessboardCorners``); the board has ``(cols + 1) x
        (rows + 1)`` squares, the top-left one black.
    square : float
        Square size in mm.
    margin : float or None
        White border around the squares in mm (default: one square).
    """

    cols: int = 9
    rows: int = 6
    square: float = 10.0
    margin: float | None = None

    def __post_init__(self) -> None:
        _check_counts(self, ("cols", "rows"))
        object.__setattr__(self, "square", _positive(self.square, "square"))
        margin = self.square if self.margin is None else _non_negative(self.margin, "margin")
        object.__setattr__(self, "margin", margin)

    kind = "checkerboard"

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)`` of inner corners, as ``cv2.findChessboardCorners`` wants."""
        return (self.cols, self.rows)

    def object_points(self) -> np.ndarray:
        """Inner corners ``(rows * cols, 3)`` in board mm, row-major: ``(j sq, i sq, 0)``."""
        jj, ii = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.column_stack(
            [jj.ravel() * self.square, ii.ravel() * self.square, np.zeros(jj.size)]
        )

    def extent(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the board with its margin, in board mm."""
        sq, m = self.square, self.margin
        return (-sq - m, -sq - m, self.cols * sq + m, self.rows * sq + m)

    def spec(self) -> str:
        """The command-line spelling, e.g. ``checkerboard:9x6:10``."""
        return f"checkerboard:{self.cols}x{self.rows}:{self.square:g}"

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "spec": self.spec(),
            "cols": self.cols,
            "rows": self.rows,
            "square_mm": self.square,
            "margin_mm": self.margin,
            "origin": "first inner corner; object points (j * square, i * square, 0) row-major",
        }

    def _texture(self, per_square: int) -> _Raster:
        d = self.square / per_square
        m = round(self.margin / d)
        cells = (np.add.outer(np.arange(self.rows + 1), np.arange(self.cols + 1)) % 2).astype(float)
        img = np.kron(cells, np.ones((per_square, per_square)))
        img = np.pad(img * (_LIGHT - _DARK) + _DARK, m, constant_values=_LIGHT)
        x0 = -self.square - m * d + 0.5 * d
        img = ndimage.gaussian_filter(img, 1.0, mode="nearest")
        return _Raster(img.astype(np.float32), (x0, x0), d)


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco target, drawn by ``cv2.aruco.CharucoBoard.generateImage``.

    Parameters
    ----------
    squares_x, squares_y : int
        Squares per row and per column.
    square, marker : float
        Square and marker side lengths in mm (``marker < square``).
    dictionary : str
        An ``cv2.aruco`` predefined dictionary name, e.g. ``"DICT_4X4_50"``.
    margin : float or None
        White border around the squares in mm (default: one square).
    """

    squares_x: int = 11
    squares_y: int = 8
    square: float = 8.0
    marker: float = 6.0
    dictionary: str = "DICT_4X4_50"
    margin: float | None = None

    def __post_init__(self) -> None:
        _check_counts(self, ("squares_x", "squares_y"))
        object.__setattr__(self, "square", _positive(self.square, "square"))
        object.__setattr__(self, "marker", _positive(self.marker, "marker"))
        if self.marker >= self.square:
            raise ValueError(f"marker ({self.marker}) must be smaller than square ({self.square})")
        if self.dictionary not in _DICTIONARIES:
            raise ValueError(
                f"dictionary must be a cv2.aruco predefined dictionary such as DICT_4X4_50, "
                f"got {self.dictionary!r}"
            )
        if self.squares_x * self.squares_y // 2 > _DICTIONARIES[self.dictionary]:
            raise ValueError(
                f"{self.dictionary} has too few markers for {self.squares_x}x{self.squares_y}"
            )
        margin = self.square if self.margin is None else _non_negative(self.margin, "margin")
        object.__setattr__(self, "margin", margin)

    kind = "charuco"

    def cv2_board(self):
        """The ``cv2.aruco.CharucoBoard`` (for ``cv2.aruco.CharucoDetector``)."""
        import cv2

        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square, self.marker, dictionary
        )

    def object_points(self) -> np.ndarray:
        """Chessboard corners ``(N, 3)`` in board mm, in ChArUco id order."""
        return np.asarray(self.cv2_board().getChessboardCorners(), dtype=float).reshape(-1, 3)

    def extent(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the board with its margin, in board mm."""
        m = self.margin
        return (-m, -m, self.squares_x * self.square + m, self.squares_y * self.square + m)

    def spec(self) -> str:
        """The command-line spelling, e.g. ``charuco:11x8:8:6:DICT_4X4_50``."""
        return (
            f"charuco:{self.squares_x}x{self.squares_y}:{self.square:g}:{self.marker:g}:"
            f"{self.dictionary}"
        )

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "spec": self.spec(),
            "squares_x": self.squares_x,
            "squares_y": self.squares_y,
            "square_mm": self.square,
            "marker_mm": self.marker,
            "dictionary": self.dictionary,
            "margin_mm": self.margin,
            "origin": "outer top-left corner; object points from getChessboardCorners()",
        }

    def _texture(self, per_square: int) -> _Raster:
        d = self.square / per_square
        m = round(self.margin / d)
        img = self.cv2_board().generateImage(
            (self.squares_x * per_square, self.squares_y * per_square), marginSize=0, borderBits=1
        )
        img = img.astype(float) / 255.0 * (_LIGHT - _DARK) + _DARK
        img = np.pad(img, m, constant_values=_LIGHT)
        x0 = -m * d + 0.5 * d
        img = ndimage.gaussian_filter(img, 1.0, mode="nearest")
        return _Raster(img.astype(np.float32), (x0, x0), d)


@dataclass(frozen=True)
class CircleGrid:
    """A grid of dark dots on a light board (``cv2.findCirclesGrid``'s target).

    Parameters
    ----------
    cols, rows : int
        Dots per row and rows (``patternSize = (cols, rows)``).
    spacing : float
        mm.  Symmetric grid: the distance between neighbouring dots along a
        row and a column.  Asymmetric grid (OpenCV's ``ASYMMETRIC_GRID``):
        odd rows are shifted by ``spacing``, so dots in a row are ``2 spacing``
        apart and rows ``spacing`` apart (the ``squareSize`` of OpenCV's
        calibration sample).
    diameter : float
        Dot diameter in mm, smaller than the nearest-neighbour distance
        (``spacing``, or ``sqrt(2) spacing`` for the asymmetric grid).
    asymmetric : bool
    margin : float or None
        Light border from the outermost dot centres in mm (default: one
        spacing, at least the diameter).
    """

    cols: int = 9
    rows: int = 6
    spacing: float = 10.0
    diameter: float = 5.0
    asymmetric: bool = False
    margin: float | None = None

    def __post_init__(self) -> None:
        _check_counts(self, ("cols", "rows"))
        object.__setattr__(self, "spacing", _positive(self.spacing, "spacing"))
        object.__setattr__(self, "diameter", _positive(self.diameter, "diameter"))
        nearest = self.spacing * (np.sqrt(2.0) if self.asymmetric else 1.0)
        if self.diameter >= nearest:
            raise ValueError(
                f"diameter ({self.diameter:g}) must be smaller than the distance between "
                f"neighbouring dots ({nearest:g})"
            )
        default = max(self.spacing, self.diameter)
        margin = default if self.margin is None else _non_negative(self.margin, "margin")
        if margin < self.diameter / 2:
            raise ValueError(f"margin must be at least the dot radius, got {margin!r}")
        object.__setattr__(self, "margin", margin)

    @property
    def kind(self) -> str:
        return "acircles" if self.asymmetric else "circles"

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)``, as ``cv2.findCirclesGrid`` wants."""
        return (self.cols, self.rows)

    def object_points(self) -> np.ndarray:
        """Dot centres ``(rows * cols, 3)`` in board mm, row-major, in
        ``cv2.findCirclesGrid``'s order: ``(j s, i s, 0)``, or ``((2 j + i % 2) s,
        i s, 0)`` for the asymmetric grid."""
        jj, ii = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        x = (2 * jj + ii % 2) if self.asymmetric else jj
        return np.column_stack(
            [x.ravel() * self.spacing, ii.ravel() * self.spacing, np.zeros(jj.size)]
        )

    def extent(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the board with its margin, in board mm."""
        p, m = self.object_points(), self.margin
        return (-m, -m, float(p[:, 0].max()) + m, float(p[:, 1].max()) + m)

    def spec(self) -> str:
        """The command-line spelling, e.g. ``circles:9x6:10:5``."""
        return f"{self.kind}:{self.cols}x{self.rows}:{self.spacing:g}:{self.diameter:g}"

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "spec": self.spec(),
            "cols": self.cols,
            "rows": self.rows,
            "spacing_mm": self.spacing,
            "diameter_mm": self.diameter,
            "margin_mm": self.margin,
            "origin": "first dot's centre; object points row-major as cv2.findCirclesGrid: "
            + (
                "((2 j + i % 2) * spacing, i * spacing, 0)"
                if self.asymmetric
                else "(j * spacing, i * spacing, 0)"
            ),
        }

    def _texture(self, per_square: int) -> _Raster:
        d = self.spacing / per_square
        x0, y0, x1, y1 = self.extent()
        w, h = int(np.ceil((x1 - x0) / d)), int(np.ceil((y1 - y0) / d))
        dark = np.zeros((h, w))
        r = self.diameter / 2
        half = int(np.ceil(r / d)) + 2
        for cx, cy, _ in self.object_points():
            # texel centres near the dot; coverage from the signed distance to its edge
            j0, i0 = int((cx - x0) / d), int((cy - y0) / d)
            js = np.arange(max(j0 - half, 0), min(j0 + half + 1, w))
            is_ = np.arange(max(i0 - half, 0), min(i0 + half + 1, h))
            xs, ys = x0 + (js + 0.5) * d, y0 + (is_ + 0.5) * d
            dist = np.hypot(xs[None, :] - cx, ys[:, None] - cy)
            cover = np.clip(0.5 + (r - dist) / d, 0.0, 1.0)
            block = dark[is_[0] : is_[-1] + 1, js[0] : js[-1] + 1]
            np.maximum(block, cover, out=block)
        img = _LIGHT - (_LIGHT - _DARK) * dark
        img = ndimage.gaussian_filter(img, 1.0, mode="nearest")
        return _Raster(img.astype(np.float32), (x0 + 0.5 * d, y0 + 0.5 * d), d)


Board = Checkerboard | CharucoBoard | CircleGrid


def parse_board(text: str) -> Board:
    """A board from its command-line spelling.

    ``checkerboard:COLSxROWS:SQUARE`` (inner corners, mm),
    ``charuco:SXxSY:SQUARE:MARKER[:DICTIONARY]`` (squares, mm; the dictionary
    defaults to ``DICT_4X4_50``), ``circles:COLSxROWS:SPACING:DIAMETER`` or
    ``acircles:COLSxROWS:SPACING:DIAMETER`` (dots, mm; see :class:`CircleGrid`;
    the renderer needs the diameter, the detector of ``stereo calibrate`` not).

    Examples
    --------
    >>> parse_board("checkerboard:9x6:10")
    Checkerboard(cols=9, rows=6, square=10.0, margin=10.0)
    >>> parse_board("charuco:11x8:8:6").dictionary
    'DICT_4X4_50'
    >>> parse_board("acircles:4x11:10:7").spec()
    'acircles:4x11:10:7'
    """
    parts = str(text).strip().split(":")
    try:
        kind = parts[0].lower()
        nx, ny = (int(v) for v in parts[1].lower().split("x"))
        if kind == "checkerboard" and len(parts) == 3:
            return Checkerboard(nx, ny, float(parts[2]))
        if kind == "charuco" and len(parts) in (4, 5):
            dictionary = parts[4] if len(parts) == 5 else "DICT_4X4_50"
            return CharucoBoard(nx, ny, float(parts[2]), float(parts[3]), dictionary)
        if kind in ("circles", "acircles") and len(parts) == 4:
            return CircleGrid(
                nx, ny, float(parts[2]), float(parts[3]), asymmetric=kind == "acircles"
            )
    except (IndexError, ValueError) as exc:
        if "must" in str(exc):  # the board's own validation: say what is wrong
            raise ValueError(f"board {text!r}: {exc}") from None
    raise ValueError(
        f"board must be checkerboard:COLSxROWS:SQUARE, "
        f"charuco:SXxSY:SQUARE:MARKER[:DICTIONARY] or "
        f"circles|acircles:COLSxROWS:SPACING:DIAMETER, got {text!r}"
    )
