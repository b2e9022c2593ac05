"""Files of 2D tracks (:class:`surface_strain.Tracks`, the toolkit's one tracks type).

CSV layout (one row per frame and point)::

    frame,point,x,y,visible,quality[,uncertainty_px]

``uncertainty_px`` (trackers that measure it, e.g. ``gdic``) is the standard
deviation of each coordinate of the position in pixels (empty where unknown).
NumPy layouts: ``.npy`` holding positions ``(T, N, 2)``; ``.npz`` with
``positions`` (or ``tracks``) ``(T, N, 2)`` and optional ``visible`` ``(T, N)``,
``quality`` ``(T, N)`` and ``uncertainty_px`` (or ``uncertainty``) ``(T, N)``.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from strain2d.errors import InputError
from surface_strain import Tracks

__all__ = ["TRACK_COLUMNS", "Tracks", "read_tracks", "write_tracks_csv"]

TRACK_COLUMNS = ("frame", "point", "x", "y", "visible", "quality")


def write_tracks_csv(
    path: str | os.PathLike,
    tracks: Tracks,
    *,
    length_scale: float | None = None,
    length_unit: str | None = None,
) -> None:
    """Write tracks as CSV with columns ``frame,point,x,y,visible,quality`` (and
    ``uncertainty_px`` when the tracks carry one).

    ``length_scale`` (``length_unit`` per pixel, e.g. 0.012 mm) adds the
    positions in that unit, ``x_mm,y_mm`` after ``x,y`` (and ``uncertainty_mm``);
    ``x`` and ``y`` stay in pixels.
    """
    from tissue_core.tables import write_long_table

    if length_scale is not None and not (np.isfinite(length_scale) and length_scale > 0):
        raise ValueError(f"length_scale must be a positive number, got {length_scale}")
    columns = {
        "x": (tracks.positions[..., 0], "%.6f"),
        "y": (tracks.positions[..., 1], "%.6f"),
    }
    if length_scale is not None:
        columns[f"x_{length_unit}"] = (tracks.positions[..., 0] * length_scale, "%.8g")
        columns[f"y_{length_unit}"] = (tracks.positions[..., 1] * length_scale, "%.8g")
    columns["visible"] = (tracks.visible, "%d")
    columns["quality"] = (tracks.quality, "%.6g")
    if tracks.uncertainty is not None:
        columns["uncertainty_px"] = (tracks.uncertainty, "%.4g")
        if length_scale is not None:
            columns[f"uncertainty_{length_unit}"] = (tracks.uncertainty * length_scale, "%.4g")
    write_long_table(path, columns)


def _read_csv(path: Path) -> Tracks:
    from tissue_core.tables import read_long_table

    table = read_long_table(
        path,
        required=("x", "y"),
        optional=("visible", "quality", "uncertainty_px"),
        flags=("visible",),
    )
    pos = np.stack([table["x"], table["y"]], axis=-1)
    flag = table["visible"] if "visible" in table else np.full(pos.shape[:2], np.nan)
    vis = np.where(np.isnan(flag), True, flag == 1)  # an empty flag: visible
    qual = table["quality"] if "quality" in table else np.ones(pos.shape[:2])
    unc = None
    if "uncertainty_px" in table and np.isfinite(table["uncertainty_px"]).any():
        unc = _uncertainty(path, table["uncertainty_px"])
    return Tracks(pos, vis & np.all(np.isfinite(pos), axis=-1), qual, {"source": str(path)}, unc)


def _uncertainty(path: Path, values: np.ndarray) -> np.ndarray:
    """A file's uncertainty column, refused if negative (NaN stays: unknown)."""
    if np.any(values[np.isfinite(values)] < 0):
        raise InputError(f"{path}: uncertainty must not be negative")
    return values


def _read_numpy(path: Path, suffix: str):
    with open(path, "rb") as f:  # closed also when NumPy gives up on a damaged file
        if suffix == ".npy":
            return _real(path, "positions", np.load(f, allow_pickle=False)), None, None, None
        return _read_npz(path, np.load(f, allow_pickle=False))


def _real(path: Path, name: str, array) -> np.ndarray:
    """``array`` as float, refusing what is not real numbers (text, complex, objects)."""
    array = np.asarray(array)
    if array.dtype.kind not in "biuf":
        raise InputError(f"{path}: {name} must hold real numbers, got {array.dtype}")
    return array.astype(float)


def _read_npz(path: Path, data):
    with data:
        key = next((k for k in ("positions", "tracks") if k in data.files), None)
        if key is None:
            raise InputError(f"{path} needs an array named 'positions' (T, N, 2)")
        pos = _real(path, key, data[key])
        vis = _real(path, "visible", data["visible"]) if "visible" in data.files else None
        qual = _real(path, "quality", data["quality"]) if "quality" in data.files else None
        name = next((k for k in ("uncertainty_px", "uncertainty") if k in data.files), None)
        unc = _real(path, name, data[name]) if name else None
    return pos, vis, qual, unc


def read_tracks(path: str | os.PathLike) -> Tracks:
    """Read tracks from ``.csv``, ``.npy`` or ``.npz`` (see the module docstring)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path} is a folder, not a tracks file (CSV, NPY or NPZ)")
    if not path.is_file():
        raise InputError(f"no such tracks file: {path}")
    suffix = path.suffix.lower()
    if suffix == ".csv":
        return _read_csv(path)
    if suffix in (".npy", ".npz"):
        try:
            pos, vis, qual, unc = _read_numpy(path, suffix)
        except InputError:
            raise
        except (
            ValueError,
            TypeError,
            OSError,
            EOFError,
            KeyError,
            zipfile.BadZipFile,
            zlib.error,
        ) as exc:
            raise InputError(f"cannot read {path} as NumPy tracks: {exc}") from None
        if pos.ndim != 3 or pos.shape[2] != 2:
            raise InputError(f"{path}: positions must have shape (T, N, 2), got {pos.shape}")
        for name, arr in (("visible", vis), ("quality", qual), ("uncertainty", unc)):
            if arr is not None and np.shape(arr) != pos.shape[:2]:
                raise InputError(
                    f"{path}: {name} must have shape {pos.shape[:2]}, got {np.shape(arr)}"
                )
        if vis is not None and not np.isin(vis, (0, 1)).all():
            value = vis[~np.isin(vis, (0, 1))][0]
            raise InputError(f"{path}: visible must hold 0 or 1 (or booleans), got {value:g}")
        finite = np.all(np.isfinite(pos), axis=-1)
        vis = finite if vis is None else np.asarray(vis, dtype=bool) & finite
        qual = np.ones(pos.shape[:2]) if qual is None else qual
        unc = None if unc is None else _uncertainty(path, unc)
        return Tracks(pos, vis, qual, {"source": str(path)}, unc)
    raise InputError(f"tracks file must be .csv, .npy or .npz, got {path.name}")
