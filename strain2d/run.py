"""Read back an ``analyze`` output folder (a *run*) for reports and studies.

A run folder holds ``summary.json`` and ``strain_nodes.csv`` (see
:mod:`strain2d.export`); :func:`load_run` checks both and returns a
:class:`Run` with the nodal strain of every frame.  Anything missing,
unreadable or inconsistent raises :class:`~strain2d.errors.InputError` naming
the file and the problem, so a study over many runs fails with one clear line
instead of a traceback.
"""

from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from strain2d.errors import InputError
from strain2d.export import NODE_COLUMNS

__all__ = ["Run", "load_run"]

#: The nodal strain components a run provides.
COMPONENTS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J")


@dataclass(frozen=True, repr=False)
class Run:
    """The nodal results of one ``analyze`` run.

    Attributes
    ----------
    path : Path
        The run folder.
    summary : dict
        ``summary.json`` as written by ``analyze``.
    times : (T,) float
        Frame times, in ``time_unit``.
    time_unit : {"s", "frame"}
    positions : (T, N, 2) float
        Node positions in pixels.
    visible : (T, N) bool
    nodal : dict of (T, N) float
        Nodal strain components (:data:`COMPONENTS`), NaN where undefined.
    endpoint : int
        The contraction endpoint frame recorded by ``analyze`` (detected or
        given), or the last frame for runs that did not record one.
    endpoint_source : str
        ``"detected"``, ``"given"`` or ``"last frame"``.
    """

    path: Path
    summary: dict
    times: np.ndarray
    time_unit: str
    positions: np.ndarray
    visible: np.ndarray
    nodal: dict
    endpoint: int
    endpoint_source: str
    meta: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_points(self) -> int:
        return self.positions.shape[1]

    def at(self, frame: int) -> dict[str, np.ndarray]:
        """Nodal values of every component on ``frame``."""
        if not -self.n_frames <= frame < self.n_frames:
            raise InputError(f"{self.path}: frame {frame} is outside 0..{self.n_frames - 1}")
        return {k: v[frame] for k, v in self.nodal.items()}

    def __repr__(self) -> str:
        return (
            f"Run({str(self.path)!r}, {self.n_frames} frames, {self.n_points} nodes, "
            f"endpoint {self.endpoint})"
        )


def _read_summary(path: Path) -> dict:
    file = path / "summary.json"
    if not file.is_file():
        raise InputError(f"{path} is not an analyze output folder: summary.json is missing")
    try:
        with open(file, encoding="utf-8-sig") as f:
            summary = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{file} cannot be read: {exc}") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("software"), dict):
        raise InputError(f"{file} is not a strain2d summary (no 'software' entry)")
    for key in ("source", "time_axis", "contraction_endpoint"):
        if summary.get(key) is not None and not isinstance(summary[key], dict):
            raise InputError(f"{file}: '{key}' must be an object, got {summary[key]!r}")
    return summary


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _read_nodes(file: Path) -> np.ndarray:
    if not file.is_file():
        raise InputError(f"{file.parent}: strain_nodes.csv is missing")
    try:
        with open(file, newline="", encoding="utf-8-sig") as f:
            header = next(csv.reader(f), None)
            rows = f.read()
    except UnicodeDecodeError:
        raise InputError(f"{file} is not a text CSV file") from None
    if header is None:
        raise InputError(f"{file} is empty")
    header = [h.strip() for h in header]
    optional = ("uncertainty_px",)  # written by trackers that measure it
    if tuple(header) not in (NODE_COLUMNS, NODE_COLUMNS + optional):
        missing = [c for c in NODE_COLUMNS if c not in header]
        what = f"lacks the columns {', '.join(missing)}" if missing else "has other columns"
        raise InputError(f"{file} {what} (expected {','.join(NODE_COLUMNS)})")
    if not rows.strip():
        raise InputError(f"{file} has no rows")
    try:
        table = np.loadtxt(rows.splitlines(), delimiter=",", ndmin=2)
    except ValueError as exc:
        raise InputError(f"{file} has a malformed row: {exc}") from None
    if table.shape[1] != len(header):
        raise InputError(f"{file}: rows must have {len(header)} values")
    return table


def load_run(path: str | os.PathLike) -> Run:
    """Load an ``analyze`` output folder.

    Parameters
    ----------
    path : path
        The folder given to ``strain2d analyze --out``.

    Returns
    -------
    Run

    Raises
    ------
    InputError
        The folder, ``summary.json`` or ``strain_nodes.csv`` is missing,
        unreadable, truncated or inconsistent.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"run folder {path} does not exist")
    if not path.is_dir():
        raise InputError(f"{path} is not a folder: give an analyze output folder")
    summary = _read_summary(path)
    file = path / "strain_nodes.csv"
    table = _read_nodes(file)
    col = {name: i for i, name in enumerate(NODE_COLUMNS)}
    frame = table[:, col["frame"]]
    point = table[:, col["point"]]
    whole = np.isfinite(frame) & np.isfinite(point)
    if not (whole.all() and np.all(frame == np.round(frame)) and np.all(point == np.round(point))):
        raise InputError(f"{file}: frame and point must be whole numbers")
    frame = frame.astype(np.int64)
    point = point.astype(np.int64)
    T, N = int(frame.max()) + 1, int(point.max()) + 1
    if frame.min() < 0 or point.min() < 0 or table.shape[0] != T * N:
        raise InputError(
            f"{file} is incomplete: {table.shape[0]} rows for {T} frames x {N} points "
            "(a truncated or edited file?)"
        )
    order = np.lexsort((point, frame))
    table = table[order]
    expected = np.stack(np.meshgrid(np.arange(T), np.arange(N), indexing="ij"), -1).reshape(-1, 2)
    if not np.array_equal(np.column_stack([frame[order], point[order]]), expected):
        raise InputError(f"{file} repeats or skips (frame, point) pairs")
    grid = table.reshape(T, N, -1)
    positions = grid[..., [col["x"], col["y"]]]
    visible = grid[..., col["visible"]] != 0
    # a lost point may have no position (imported tracks); a visible one must
    if not np.isfinite(positions[visible]).all() or not np.isfinite(positions[0]).all():
        raise InputError(f"{file}: positions of visible nodes must be finite")
    nodal = {k: grid[..., col[k]].copy() for k in COMPONENTS}

    frames_used = (summary.get("source") or {}).get("frames_used")
    if frames_used is not None and not _whole(frames_used):
        raise InputError(f"{path / 'summary.json'}: source.frames_used must be a whole number")
    if frames_used is not None and frames_used != T:
        raise InputError(
            f"{path}: summary.json says {frames_used} frames but strain_nodes.csv has {T}"
        )
    fps = (summary.get("time_axis") or {}).get("fps")
    if fps is not None and (
        isinstance(fps, bool)
        or not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0)
    ):
        raise InputError(f"{path / 'summary.json'}: time_axis.fps must be a positive number")
    times = np.arange(T) / fps if fps else np.arange(T, dtype=float)
    ep = summary.get("contraction_endpoint") or {}
    endpoint, source = T - 1, "last frame"
    if "frame" in ep:
        endpoint = ep["frame"]
        if not _whole(endpoint) or not 0 <= endpoint < T:
            raise InputError(
                f"{path / 'summary.json'}: contraction_endpoint.frame must be a frame "
                f"index 0..{T - 1}, got {endpoint!r}"
            )
        source = ep.get("source", "detected")
    return Run(
        path=path,
        summary=summary,
        times=times,
        time_unit="s" if fps else "frame",
        positions=positions,
        visible=visible,
        nodal=nodal,
        endpoint=int(endpoint),
        endpoint_source=str(source),
    )
