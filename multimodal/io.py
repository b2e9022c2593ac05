"""Reading the microscope's height maps, landmark pairs and transforms."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from multimodal.geometry import Similarity, SurfaceMap, SurfaceMosaic
from tissue_core.errors import InputError

__all__ = [
    "read_landmarks",
    "read_landmarks3d",
    "read_microscope_image",
    "read_surface_map",
    "read_transform",
]


def _calibrated(path: Path, pixel_um: float | None, what: str) -> tuple[np.ndarray, tuple]:
    """A TIFF's pixels and its pixel size ``(dy, dx)`` in um: ``pixel_um`` where given,
    else the file's own (ImageJ calibration, OME, resolution tags)."""
    import tifffile

    from tissue_core.tiff_units import lateral_pixel_size_um

    if not path.is_file():
        raise InputError(f"{what} {path} does not exist")
    try:
        with tifffile.TiffFile(path) as tif:
            data = tif.asarray()
            size = lateral_pixel_size_um(tif)
    except (OSError, ValueError, KeyError, IndexError, tifffile.TiffFileError) as exc:
        raise InputError(f"{path}: cannot read it as a TIFF {what} ({exc})") from None
    return data, _pixel_size(path, pixel_um, size)


def _pixel_size(path: Path, pixel_um: float | None, found) -> tuple[float, float]:
    if pixel_um is not None:
        if not (math.isfinite(pixel_um) and pixel_um > 0):
            raise InputError(f"--pixel-um must be a positive number, got {pixel_um}")
        return float(pixel_um), float(pixel_um)
    if isinstance(found, tuple):
        return found[0], found[1]
    why = f" ({found})" if isinstance(found, str) else ""
    raise InputError(f"{path}: its pixel size is unknown{why}; give --pixel-um")


def read_surface_map(
    path: str | os.PathLike, *, pixel_um: float | None = None
) -> SurfaceMap | SurfaceMosaic:
    """A height map: an ``mpm3d analyze`` run folder (its ``heightmap.tif``), a TIFF, or a
    mosaic of them (a CSV of tiles: ``file,x_um,y_um``, each tile's file, relative to the
    CSV, and the stage position of its pixel (0, 0)).

    The TIFF holds heights in micrometres, (Y, X), or ``mpm3d``'s two
    channels (height with its gaps filled, and 1 where the surface was
    measured: the share of each triangle's edges over filled heights is
    reported).  NaN heights are gaps: no length is measured over them.  Its
    pixel size comes from the file (ImageJ calibration, OME, resolution
    tags) or ``pixel_um``.
    """
    path = Path(path)
    if path.suffix.lower() == ".csv":
        return _mosaic(path, pixel_um)
    if path.is_dir():
        inner = path / "heightmap.tif"
        if not inner.is_file():
            raise InputError(f"{path}: no heightmap.tif in it (give an mpm3d analyze folder)")
        path = inner
    data, (dy, dx) = _calibrated(path, pixel_um, "height map")
    if np.iscomplexobj(data) or np.asarray(data).dtype == bool:
        raise InputError(f"{path}: heights must be real numbers, got {np.asarray(data).dtype}")
    data = np.asarray(data, dtype=float)
    measured = None
    if data.ndim == 3 and data.shape[0] == 2:  # mpm3d: height (gaps filled), measured
        height, measured = data[0], data[1] > 0.5
    elif data.ndim == 2:
        height = data
    else:
        raise InputError(
            f"{path}: a height map is one 2D image (or mpm3d's height and measured channels), "
            f"got shape {data.shape}"
        )
    if np.isinf(height).any():
        raise InputError(f"{path}: infinite heights (give NaN where nothing was measured)")
    finite = height[np.isfinite(height)]
    if finite.size and np.ptp(finite) > 1e6:
        raise InputError(
            f"{path}: heights span {np.ptp(finite):.3g} um, over a metre: are they in um?"
        )
    return SurfaceMap(height, (dy, dx), source=str(path), measured=measured)


def read_microscope_image(
    path: str | os.PathLike, *, pixel_um: float | None = None
) -> tuple[np.ndarray, float]:
    """The microscope's surface-intensity projection and its pixel size (um): an ``mpm3d
    analyze`` folder (its ``surface_intensity.tif``), a calibrated TIFF, or any image with
    ``pixel_um``."""
    from tissue_core.images import read_image

    path = Path(path)
    if path.is_dir():
        inner = path / "surface_intensity.tif"
        if not inner.is_file():
            raise InputError(f"{path}: no surface_intensity.tif in it (an mpm3d analyze folder)")
        path = inner
    if path.suffix.lower() in (".tif", ".tiff"):
        image, (dy, dx) = _calibrated(path, pixel_um, "microscope image")
    else:
        if not path.is_file():
            raise InputError(f"microscope image {path} does not exist")
        image = read_image(path)
        dy, dx = _pixel_size(path, pixel_um, None)
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[-1] in (3, 4):
        image = image[..., :3].mean(axis=-1)
    if image.ndim != 2:
        raise InputError(f"{path}: give one 2D image (the surface projection), got {image.shape}")
    return image, (dy + dx) / 2


def _mosaic(path: Path, pixel_um: float | None) -> SurfaceMosaic:
    from tissue_core.tables import read_tile_list

    tiles = []
    for entry in read_tile_list(path):
        where = f"{path}, line {entry.line}"
        if entry.path.suffix.lower() == ".csv":
            raise InputError(f"{where}: a tile cannot be a mosaic itself")
        try:
            tile = read_surface_map(entry.path, pixel_um=pixel_um)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        origin = (entry.x_um, entry.y_um)
        tiles.append(SurfaceMap(tile.height_um, tile.pixel_um, origin, tile.source, tile.measured))
    return SurfaceMosaic(tiles, source=str(path))


def read_landmarks(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Landmark pairs from a CSV: ``camera_x, camera_y`` (px), ``microscope_x,
    microscope_y`` (um), one pair per row."""
    from tissue_core.tables import read_number_columns

    columns = ("camera_x", "camera_y", "microscope_x", "microscope_y")
    table = read_number_columns(path, columns, what="landmarks")
    return table[:, :2], table[:, 2:]


def read_landmarks3d(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """3D landmark pairs from a CSV: ``camera_x, camera_y, camera_z`` (the stereo run's
    units), ``microscope_x, microscope_y, microscope_z`` (um; z is the height, as in the
    height map), one pair per row; returned as camera ``(K, 3)`` and microscope
    ``(x, y, depth)`` ``(K, 3)`` with ``depth = -height``."""
    from tissue_core.tables import read_number_columns

    columns = ("camera_x", "camera_y", "camera_z", "microscope_x", "microscope_y", "microscope_z")
    table = read_number_columns(path, columns, what="landmarks")
    microscope = table[:, 3:].copy()
    microscope[:, 2] *= -1
    return table[:, :3], microscope


def read_transform(text: str) -> Similarity:
    """A transform: a JSON file (``scale_um_per_px``, ``angle_deg``, ``shift_um``,
    ``mirrored``), or ``SCALE,ANGLE,SHIFT_X,SHIFT_Y``."""
    path = Path(text)
    if path.suffix.lower() == ".json" or path.is_file():
        try:
            data = json.loads(path.read_text(encoding="utf-8-sig"))
        except OSError as exc:
            raise InputError(f"--transform {text}: cannot read it ({exc.strerror})") from None
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise InputError(f"--transform {text}: not a JSON file") from None

        def number(value) -> float:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise TypeError(value)
            return float(value)

        try:
            shift = data["shift_um"]
            values = (number(data["scale_um_per_px"]), number(data.get("angle_deg", 0.0)),
                      (number(shift[0]), number(shift[1])))  # fmt: skip
            if len(shift) != 2:
                raise IndexError(shift)
            mirrored = data.get("mirrored", False)
            if not isinstance(mirrored, bool):
                raise InputError(f"--transform {text}: mirrored must be true or false")
        except (KeyError, TypeError, IndexError):
            raise InputError(
                f"--transform {text}: needs numbers scale_um_per_px, angle_deg and shift_um [x, y]"
            ) from None
        try:
            return Similarity(*values, mirrored)
        except InputError as exc:
            raise InputError(f"--transform {text}: {exc}") from None
    try:
        scale, angle, x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise InputError(
            f"--transform must be a JSON file or SCALE,ANGLE,SHIFT_X,SHIFT_Y, got {text!r}"
        ) from None
    return Similarity(scale, angle, (x, y))
