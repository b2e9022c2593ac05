"""Long tables: the CSV layout of every per-frame, per-point file the toolkit reads.

One row per frame and point, a header naming the columns::

    frame,point,x,y,...

``tracks.csv``, ``strain_nodes.csv`` (2D: ``x,y,u,v``; 3D: ``X,Y,Z,U,V,W``,
the same names in capitals), ``points3d.csv`` and tracks written by other
tools all have it.  :func:`write_long_table` writes them (one row per frame
and point, frame by frame); :func:`read_long_table` reads any of them into
``(T, N)`` arrays per column and refuses, in one line naming the file and the row,
what is not such a table: no text, missing columns, a row with more or fewer
cells than the header (a decimal comma, ``1,5`` for ``1.5``, makes one too
many), values that are not numbers, a flag (``visible``) that is not 0 or 1,
negative or fractional indices, a frame or point missing or given twice.
Column names are matched without regard to case or surrounding spaces; empty
cells and ``nan``/``none``/``null`` are NaN.
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tissue_core.errors import InputError

__all__ = [
    "LongTable",
    "cell_count_error",
    "read_long_table",
    "read_number_columns",
    "read_tile_list",
    "read_xy_csv",
    "write_long_table",
]

_MISSING = ("", "nan", "none", "null")
#: rows :func:`write_long_table` formats at a time (whole frames, at least one)
_BLOCK_ROWS = 4096


@dataclass(frozen=True, repr=False)
class LongTable:
    """The columns of a long table as ``(T, N)`` float arrays (frames x points).

    Attributes
    ----------
    path : Path
    names : tuple of str
        The header's column names as written (stripped).
    columns : dict of str -> (T, N) float
        The columns read, by lower-case name (``frame`` and ``point`` left out).
    """

    path: Path
    names: tuple[str, ...]
    columns: dict

    @property
    def n_frames(self) -> int:
        return next(iter(self.columns.values())).shape[0]

    @property
    def n_points(self) -> int:
        return next(iter(self.columns.values())).shape[1]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name.lower()]

    def __contains__(self, name: str) -> bool:
        return name.lower() in self.columns

    def __repr__(self) -> str:
        return (
            f"LongTable({str(self.path)!r}, {self.n_frames} frames x {self.n_points} points, "
            f"columns {', '.join(self.columns)})"
        )


def _number(text: str) -> float:
    text = text.strip()
    if text.lower() in _MISSING:
        return math.nan
    return float(text)


def read_long_table(
    path: str | os.PathLike,
    *,
    required: Sequence[str],
    optional: Sequence[str] = (),
    flags: Sequence[str] = (),
) -> LongTable:
    """Read a long table (one row per frame and point) into ``(T, N)`` arrays.

    Parameters
    ----------
    path : path-like
    required : sequence of str
        Columns besides ``frame`` and ``point`` that must be there.
    optional : sequence of str
        Columns read when present.
    flags : sequence of str
        Columns among those read that hold 0 or 1 (``visible``): any other
        number is refused naming its line; an empty cell stays NaN.

    Returns
    -------
    LongTable

    Raises
    ------
    InputError
        The file is missing, not text, empty, lacks a column, holds a row
        whose cells do not match the header's columns, a value that is not a
        number or a flag that is not 0 or 1, or does not hold exactly one row
        for each frame and point; the message names the file (and the line).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> _ = p.write_text("frame,point,X,Y\\n0,0,1,2\\n0,1,3,4\\n1,0,1.5,2\\n1,1,,\\n")
    >>> t = read_long_table(p, required=["x", "y"])
    >>> t["x"]
    array([[1. , 3. ],
           [1.5, nan]])
    """
    path = Path(path)
    if not path.is_file():
        what = "is a folder, not a CSV file" if path.is_dir() else "does not exist"
        raise InputError(f"{path} {what}")
    wanted = ["frame", "point", *required]  # as the caller names them, for messages
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            text = f.read().splitlines()
        header = next(csv.reader(text[:1]), None)
        if header is None:
            raise InputError(f"{path} is empty")
        names = tuple(h.strip() for h in header)
        lower = [n.lower() for n in names]
        missing = [c for c in wanted if c.lower() not in lower]
        if missing:
            s = "s" if len(missing) > 1 else ""
            raise InputError(
                f"{path} lacks the column{s} {', '.join(missing)} (needs {','.join(wanted)})"
            )
        keep = [c.lower() for c in wanted]
        keep += [c.lower() for c in optional if c.lower() in lower]
        index = [lower.index(c) for c in keep]
        _check_cell_counts(text[1:], path, len(names))
        data, lines = _rows(text[1:], path, index)
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path} is not a text CSV file ({exc})") from None
    if len(data) == 0:
        raise InputError(f"{path} has no rows")
    frame, point = data[:, 0], data[:, 1]
    bad = ~(np.isfinite(frame) & np.isfinite(point) & (frame == np.round(frame))
            & (point == np.round(point)))  # fmt: skip
    if bad.any():
        raise InputError(
            f"{path}, line {lines[bad.argmax()]}: frame and point must be whole numbers"
        )
    if frame.min() < 0 or point.min() < 0:
        line = lines[np.argmax((frame < 0) | (point < 0))]
        raise InputError(f"{path}, line {line}: negative frame or point index")
    n = len(data)
    if frame.max() >= n or point.max() >= n:  # more frames or points than rows: incomplete
        raise InputError(
            f"{path} is incomplete: it has {n} rows but frame indices up to {frame.max():.6g} "
            f"and point indices up to {point.max():.6g} (one row for each frame and point)"
        )
    for name in flags:
        if name.lower() in keep:
            values = data[:, keep.index(name.lower())]
            wrong = ~(np.isnan(values) | (values == 0) | (values == 1))
            if wrong.any():
                k = int(wrong.argmax())
                raise InputError(
                    f"{path}, line {lines[k]}: {name} must be 0 or 1, got {values[k]:g}"
                )
    frame, point = frame.astype(np.int64), point.astype(np.int64)
    T, N = int(frame.max()) + 1, int(point.max()) + 1
    seen = np.zeros((T, N), np.int64)
    np.add.at(seen, (frame, point), 1)
    if n != T * N or not (seen == 1).all():
        how = "is incomplete" if n < T * N else "repeats or skips rows"
        raise InputError(
            f"{path} {how}: it must hold exactly one row for each of {T} frames x {N} points "
            f"({T * N} rows), found {n}"
        )
    columns = {}
    for k, name in enumerate(keep[2:], start=2):
        values = np.empty((T, N))
        values[frame, point] = data[:, k]
        columns[name] = values
    return LongTable(path, names, columns)


def _shown(row: str) -> str:
    """A row as a message shows it: at most 80 characters."""
    return row if len(row) <= 80 else row[:77] + "..."


def _check_cell_counts(body: list[str], path: Path, n_cells: int) -> None:
    """Refuse the first row that has more or fewer cells than the header.

    Blank rows (nothing but commas and spaces) are skipped, as the readers
    skip them.  A row with quotes is split as CSV; the others at their commas.
    """
    counts = np.fromiter((row.count(",") for row in body), np.int64, len(body)) + 1
    for k in np.flatnonzero(counts != n_cells):
        row = body[k]
        if not row.strip(", \t"):
            continue
        found = len(next(csv.reader([row]))) if '"' in row else int(counts[k])
        if found == n_cells:
            continue
        raise cell_count_error(path, k + 2, found, n_cells, row)


def cell_count_error(
    path: str | os.PathLike,
    line: int,
    found: int,
    expected: int,
    row: str,
    *,
    reference: str = "the header",
    decimals: bool = True,
) -> InputError:
    """The error of a CSV row with ``found`` cells where ``reference`` has ``expected``.

    One wording for every CSV reader of the toolkit (long tables, points,
    triangles, manifests).  In a table of numbers (``decimals``) a cell too
    many is most often a decimal comma, and the message says so.

    Examples
    --------
    >>> print(cell_count_error("p.csv", 3, 3, 2, "10,5,20"))
    p.csv, line 3: 3 cells where the header has 2 (a decimal comma?): 10,5,20
    """
    hint = " (a decimal comma?)" if decimals and found > expected else ""
    cells = "1 cell" if found == 1 else f"{found} cells"
    return InputError(
        f"{path}, line {line}: {cells} where {reference} has {expected}{hint}: {_shown(row)}"
    )


def _rows(body: list[str], path: Path, index: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The chosen columns of the rows after the header, and each row's line number.

    NumPy's reader takes a clean table at once; a table with empty cells,
    ``none``/``null``, ragged rows or text is read row by row, which names the
    line of a value that is not a number.
    """
    lines = np.array([k + 2 for k, row in enumerate(body) if row.strip(", \t")], dtype=np.int64)
    if lines.size == 0:
        return np.empty((0, len(index))), lines
    try:
        data = np.loadtxt(body, delimiter=",", usecols=index, ndmin=2, dtype=float, comments=None)
        if len(data) == len(lines):
            return data, lines
    except ValueError:
        pass
    rows, lines = [], []
    for line, row in enumerate(csv.reader(body), start=2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            rows.append([_number(row[i]) for i in index])
        except (ValueError, IndexError):
            what = "too few values" if len(row) <= max(index) else "not a number"
            raise InputError(f"{path}, line {line}: {what}: {_shown(','.join(row))}") from None
        lines.append(line)
    return np.array(rows, dtype=float).reshape(-1, len(index)), np.array(lines, dtype=np.int64)


class PerFrame:
    """A ``(T, ...)`` column computed a range of frames at a time: ``function(start, stop)``.

    For :func:`write_long_table`: a column derived from others (a
    displacement, a position in mm) without holding it for every frame.

    Examples
    --------
    >>> x = np.arange(6.0).reshape(3, 2)
    >>> twice = PerFrame(x.shape, lambda a, b: 2 * x[a:b])
    >>> twice[1:3].tolist()
    [[4.0, 6.0], [8.0, 10.0]]
    """

    def __init__(self, shape: tuple[int, ...], function) -> None:
        self.shape = tuple(shape)
        self._function = function

    def __getitem__(self, frames: slice) -> np.ndarray:
        if not isinstance(frames, slice):
            raise TypeError("a PerFrame column is read by slices of frames")
        start, stop, step = frames.indices(self.shape[0])
        if step != 1:
            raise TypeError("a PerFrame column is read by contiguous slices of frames")
        return np.asarray(self._function(start, max(start, stop)))


def write_long_table(
    path: str | os.PathLike,
    columns: Mapping[str, tuple[np.ndarray, str]],
    *,
    index: str = "point",
) -> None:
    """Write ``(T, N)`` arrays as a long table: ``frame,INDEX,column...``, one row each.

    Parameters
    ----------
    path : path-like
    columns : mapping of name -> ((T, N) array, printf format)
        In the order of the header, e.g. ``{"x": (x, "%.6f")}``; booleans are
        written as 0/1 with ``"%d"``.  A column may also be anything with a
        ``shape`` that gives the arrays of frames ``a:b`` when sliced
        (:class:`PerFrame`, :class:`surface_strain.FrameArray`): it is read a
        block of frames at a time, never whole.
    index : str, keyword-only
        Name of the second column (``"point"``, or ``"triangle"``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "t.csv"
    >>> write_long_table(p, {"x": (np.array([[1.0, 2.0]]), "%.1f")})
    >>> print(p.read_text(), end="")
    frame,point,x
    0,0,1.0
    0,1,2.0
    """
    # columns that compute their frames when sliced (PerFrame, a streamed field's arrays)
    # are read a block of frames at a time like the arrays
    arrays = [
        v if hasattr(v, "shape") and hasattr(v, "__getitem__") else np.asarray(v)
        for v, _ in columns.values()
    ]
    T, N = arrays[0].shape[:2]
    line = ",".join(["%d", "%d", *(f for _, f in columns.values())]) + "\n"  # as np.savetxt
    # frames a block at a time: the text and the float table of a block, never of the
    # whole run (3,000 frames of a 15 x 15 grid's triangles are 1.2 million rows)
    step = max(1, _BLOCK_ROWS // max(N, 1))
    point = np.arange(N)
    with open(path, "w", encoding="utf-8") as f:
        f.write(",".join(["frame", index, *columns]) + "\n")
        for t0 in range(0, T, step):
            t1 = min(t0 + step, T)
            frame, points = np.meshgrid(np.arange(t0, t1), point, indexing="ij")
            table = np.column_stack(
                [frame.ravel(), points.ravel(), *(a[t0:t1].reshape(-1) for a in arrays)]
            )
            f.writelines(line % tuple(row) for row in table.tolist())


def read_xy_csv(path: str | os.PathLike, *, what: str = "points") -> np.ndarray:
    """Read ``(x, y)`` rows from a CSV file with a header holding columns ``x`` and ``y``.

    Points files and polygon outlines (``what`` names them in the messages)
    have this form; see :func:`read_number_columns`.

    Returns
    -------
    points : (N, 2) float
    """
    return read_number_columns(path, ("x", "y"), what=what)


def read_number_columns(
    path: str | os.PathLike, columns: tuple[str, ...], *, what: str = "points"
) -> np.ndarray:
    """Read the numbers of ``columns`` (named in a header, in any order among others).

    A byte-order mark (as spreadsheet programs write) is accepted.  Every row
    must have as many cells as the header (a decimal comma, ``10,5`` for
    10.5, makes one too many) and numbers in ``columns``; errors name the
    file and the line.

    Returns
    -------
    (N, len(columns)) float
    """
    line = 1
    names = " and ".join([", ".join(columns[:-1]), columns[-1]] if len(columns) > 1 else columns)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            fields = [c.strip().lower() for c in next(reader, [])]
            if any(c not in fields for c in columns):
                raise InputError(
                    f"{path} needs a header with columns {','.join(columns)} (found {fields})"
                )
            index = [fields.index(c) for c in columns]
            rows = []
            for cells in reader:
                line = reader.line_num
                if not cells:
                    continue  # a blank line
                if len(cells) != len(fields):
                    raise cell_count_error(path, line, len(cells), len(fields), ",".join(cells))
                rows.append(tuple(float(cells[i]) for i in index))
    except FileNotFoundError:
        raise InputError(f"no such {what} file: {path}") from None
    except IsADirectoryError:
        raise InputError(f"{path} is a folder, not a {what} CSV file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path} is not a text CSV file") from None
    except (TypeError, ValueError, csv.Error) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{path}, line {line}: {names} must be numbers ({exc})") from None
    return np.array(rows, dtype=float).reshape(-1, len(columns))


@dataclass(frozen=True)
class Tile:
    """One row of a mosaic's tile list: the tile's file and the stage position (um) of
    its pixel (0, 0), with the list's line (for messages)."""

    path: Path
    x_um: float
    y_um: float
    line: int


def read_tile_list(path: str | os.PathLike, *, what: str = "mosaic") -> list[Tile]:
    """A microscope mosaic's tiles: a CSV with a header ``file,x_um,y_um`` (in any order
    among other columns) and one row per tile: its file, relative to the CSV (or
    absolute), and the stage position in micrometres of its pixel (0, 0), x along its
    columns and y along its rows.

    Errors name the file and the line: a missing column, a position that is not a finite
    number, a row with no file, a tile listed twice, or no tile at all.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path} is a folder, not a {what} CSV file")
    if not path.is_file():
        raise InputError(f"{what} {path} does not exist")
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
    except OSError as exc:
        raise InputError(f"{path}: cannot read it ({exc.strerror})") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"{path}: cannot read it as a CSV of tiles ({exc})") from None
    header = [c.strip().lower() for c in rows[0]] if rows else []
    if not {"file", "x_um", "y_um"} <= set(header):
        raise InputError(f"{path}: a {what} needs a header file,x_um,y_um and one row per tile")
    at = {name: header.index(name) for name in ("file", "x_um", "y_um")}
    tiles: list[Tile] = []
    seen: dict[Path, int] = {}
    for line, cells in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in cells):
            continue  # a blank line
        if len(cells) != len(header):
            raise cell_count_error(path, line, len(cells), len(header), ",".join(cells))
        name = cells[at["file"]].strip()
        if not name:
            raise InputError(f"{path}, line {line}: no file named")
        try:
            x, y = float(cells[at["x_um"]]), float(cells[at["y_um"]])
        except ValueError:
            raise InputError(f"{path}, line {line}: x_um and y_um must be numbers") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise InputError(f"{path}, line {line}: x_um and y_um must be finite")
        tile = path.parent / name
        if tile.resolve() in seen:
            raise InputError(
                f"{path}, line {line}: {name} is listed twice (line {seen[tile.resolve()]} too)"
            )
        seen[tile.resolve()] = line
        tiles.append(Tile(tile, x, y, line))
    if not tiles:
        raise InputError(f"{path}: no tiles listed")
    return tiles
