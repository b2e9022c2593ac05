"""Tissue masks: which pixels of a frame hold the specimen.

Real specimens are not rectangles.  A mask says where the tissue is, in one
of the forms the tools of a lab write:

* an image the size of the frame, PNG or TIFF, binary or labelled (as Fiji's
  *Create Mask*, napari's labels layer or ilastik export it): every pixel
  that is not 0 is tissue, whatever its label; a colour image counts where
  any colour channel is not 0 (its alpha channel where the colours, or the
  gray of a gray + alpha image, are all 0);
* an ImageJ ROI (``.roi``, as Fiji's ROI Manager saves one) or a set of ROIs
  (``.zip``): rectangles, ovals, polygons, freehand and traced outlines, and
  composite ROIs; the union of the areas;
* a polygon as CSV (``.csv``, columns ``x,y`` in pixels, the vertices in
  order, as a points file).

Pixel coordinates are the toolkit's (x = column, y = row, the centre of the
top-left pixel at (0, 0)); a pixel is inside a polygon when its centre is.
ImageJ counts from the top-left pixel's corner, so its outlines are shifted
by half a pixel on reading: a rectangle at ``left=10, width=20`` covers
columns 10 to 29, as in Fiji.

Every way a mask can be wrong (missing, unreadable, the wrong size, empty, a
line or point ROI that encloses nothing) is one :class:`InputError` or
:class:`SourceError` naming the file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tissue_core.errors import InputError, SourceError

__all__ = ["MASK_SUFFIXES", "Mask", "polygon_inside", "read_mask"]

#: the files a mask may be, by suffix
MASK_SUFFIXES = (".png", ".tif", ".tiff", ".bmp", ".roi", ".zip", ".csv")


@dataclass(frozen=True)
class Mask:
    """Where the tissue is in a frame.

    Attributes
    ----------
    inside : (H, W) bool
        True on the tissue's pixels.
    source : str
        The file it was read from.
    kind : {"image", "imagej-roi", "polygon-csv"}
    """

    inside: np.ndarray
    source: str
    kind: str

    @property
    def shape(self) -> tuple[int, int]:
        return self.inside.shape

    @property
    def fraction(self) -> float:
        """The share of the frame's pixels that are tissue."""
        return float(self.inside.mean())

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)``: the first and last column and row holding tissue."""
        rows = np.flatnonzero(self.inside.any(axis=1))
        cols = np.flatnonzero(self.inside.any(axis=0))
        return float(cols[0]), float(rows[0]), float(cols[-1]), float(rows[-1])

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Per point ``(x, y)``, whether the pixel under it is tissue (False outside the
        frame or for a NaN point)."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        h, w = self.inside.shape
        ok = np.isfinite(points).all(axis=1)
        col = np.full(len(points), -1)
        row = np.full(len(points), -1)
        col[ok] = np.floor(points[ok, 0] + 0.5).astype(int)
        row[ok] = np.floor(points[ok, 1] + 0.5).astype(int)
        ok &= (col >= 0) & (col < w) & (row >= 0) & (row < h)
        out = np.zeros(len(points), bool)
        out[ok] = self.inside[row[ok], col[ok]]
        return out

    def outline(self) -> list[np.ndarray]:
        """The mask's boundary as closed polylines ``(K, 2)`` of ``(x, y)`` (for figures)."""
        from skimage import measure

        padded = np.pad(self.inside, 1).astype(float)
        return [c[:, ::-1] - 1.0 for c in measure.find_contours(padded, 0.5)]

    def summary(self) -> dict:
        """For ``summary.json``: the file, its kind, the tissue's pixels and share."""
        return {
            "file": self.source,
            "kind": self.kind,
            "pixels": int(self.inside.sum()),
            "fraction_of_frame": round(self.fraction, 6),
            "bounds_px": list(self.bounds()),
        }


def read_mask(path: str | os.PathLike, shape: tuple[int, int], *, option: str = "--mask") -> Mask:
    """Read a tissue mask for frames of ``shape`` ``(H, W)``.

    Parameters
    ----------
    path : path
        An image (``.png``, ``.tif``, ``.tiff``, ``.bmp``), an ImageJ ROI
        (``.roi``) or ROI set (``.zip``), or a polygon CSV (``.csv``).
    shape : (H, W)
        The frames' size: an image mask must have it; outlines are drawn
        into it.
    option : str, keyword-only
        The option that gave the file, for the messages.

    Raises
    ------
    SourceError
        A missing, empty, truncated or undecodable file.
    InputError
        A mask of another size than the frames, one without tissue, a ROI
        that encloses no area, a CSV without ``x,y`` columns or with fewer
        than 3 vertices.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> csv = pathlib.Path(tempfile.mkdtemp()) / "outline.csv"
    >>> _ = csv.write_text("x,y\\n2,1\\n6,1\\n6,3\\n2,3\\n")
    >>> mask = read_mask(csv, (5, 8))
    >>> mask.inside.astype(int)
    array([[0, 0, 0, 0, 0, 0, 0, 0],
           [0, 0, 1, 1, 1, 1, 1, 0],
           [0, 0, 1, 1, 1, 1, 1, 0],
           [0, 0, 1, 1, 1, 1, 1, 0],
           [0, 0, 0, 0, 0, 0, 0, 0]])
    """
    path = Path(path)
    h, w = (int(v) for v in shape)
    suffix = path.suffix.lower()
    if path.is_dir():
        raise SourceError(f"{option} {path} is a folder, not a mask file")
    if not path.exists():
        raise SourceError(f"{option}: no such file: {path}")
    if suffix not in MASK_SUFFIXES:
        raise InputError(
            f"{option} {path}: a mask is an image (PNG, TIFF, BMP), an ImageJ ROI (.roi, "
            f".zip) or a polygon CSV (.csv), not {suffix or 'a file without a suffix'!r}"
        )
    if suffix in (".roi", ".zip"):
        inside, kind = _from_imagej(path, (h, w), option), "imagej-roi"
    elif suffix == ".csv":
        inside, kind = _from_polygon_csv(path, (h, w), option), "polygon-csv"
    else:
        inside, kind = _from_image(path, (h, w), option), "image"
    if not inside.any():
        where = "marks no pixel (it is 0 everywhere)" if kind == "image" else (
            f"encloses no pixel of the {w}x{h} px frame"
        )  # fmt: skip
        raise InputError(f"{option} {path} {where}: there is no tissue to measure")
    return Mask(inside, str(path), kind)


def _from_image(path: Path, shape: tuple[int, int], option: str) -> np.ndarray:
    if path.suffix.lower() in (".tif", ".tiff"):
        image = _read_tiff(path, option)
    else:
        import cv2

        from tissue_core.images import read_image

        # any depth, colour and alpha as stored; refuses truncated files
        image = read_image(path, flags=cv2.IMREAD_UNCHANGED)
    image = np.asarray(image)
    if image.ndim == 3:  # gray + alpha, colour (BGR, RGB) or colour + alpha: any channel
        channels = image.shape[-1]
        colour = image[..., :3] if channels in (3, 4) else image[..., :1]
        inside = (colour != 0).any(axis=-1)
        if not inside.any() and channels in (2, 4):  # drawn in the alpha channel alone
            inside = image[..., -1] != 0
    elif image.ndim == 2:
        inside = image != 0
    else:
        raise InputError(f"{option} {path} holds a {image.ndim}-D array, not one image")
    if np.issubdtype(image.dtype, np.floating) and not np.isfinite(image).all():
        raise InputError(f"{option} {path} holds NaN or infinite values")
    if inside.shape != shape:
        raise InputError(
            f"{option} {path} is {inside.shape[1]}x{inside.shape[0]} px, the frames are "
            f"{shape[1]}x{shape[0]} px: the mask must be drawn on a frame of the video"
        )
    return inside


def _read_tiff(path: Path, option: str) -> np.ndarray:
    import tifffile

    from tissue_core.tiff_files import check_complete, tifffile_messages

    if path.stat().st_size == 0:
        raise SourceError(f"{option} {path} is empty (0 bytes), not an image")
    try:
        with tifffile_messages() as messages, tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            check_complete(tif, series, str(path), messages)
            image, axes = series.asarray(), series.axes
    except SourceError:
        raise
    except Exception as exc:  # tifffile raises many types on damaged files
        raise SourceError(f"{option} {path} is not a TIFF image that can be read ({exc})") from None
    if "S" in axes:  # colour samples, planar or not: last
        image = np.moveaxis(image, axes.index("S"), -1)
    image = np.squeeze(image)
    if image.ndim == 3 and image.shape[-1] not in (2, 3, 4):
        raise InputError(
            f"{option} {path} is a stack of {image.shape[0]} images; a mask is one image "
            "(save the one drawn on the reference frame)"
        )
    return image


def polygon_inside(vertices: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The pixels whose centres lie inside the polygon ``vertices`` ``(K, 2)`` of (x, y)."""
    from skimage.draw import polygon

    inside = np.zeros(shape, bool)
    rows, cols = polygon(vertices[:, 1], vertices[:, 0], shape=shape)
    inside[rows, cols] = True
    return inside


def _from_polygon_csv(path: Path, shape: tuple[int, int], option: str) -> np.ndarray:
    from tissue_core.tables import read_xy_csv

    try:
        vertices = read_xy_csv(path, what="polygon")
    except InputError as exc:
        raise InputError(f"{option}: {exc}") from None
    if len(vertices) < 3:
        raise InputError(
            f"{option} {path} has {len(vertices)} vertices; a polygon needs at least 3 (x,y in "
            "pixels, in order around the outline)"
        )
    if not np.isfinite(vertices).all():
        raise InputError(f"{option} {path}: every vertex needs a finite x and y")
    return polygon_inside(vertices, shape)


#: ImageJ ROI types that enclose an area (lines, angles and points do not)
_AREA_TYPES = ("RECT", "OVAL", "POLYGON", "FREEHAND", "TRACED")


def _from_imagej(path: Path, shape: tuple[int, int], option: str) -> np.ndarray:
    import roifile

    if path.stat().st_size == 0:
        raise SourceError(f"{option} {path} is empty (0 bytes), not an ImageJ ROI")
    try:
        rois = roifile.roiread(path)
    except Exception as exc:  # roifile raises ValueError, KeyError, zipfile errors ...
        raise SourceError(f"{option} {path} is not an ImageJ ROI file ({exc})") from None
    rois = rois if isinstance(rois, list) else [rois]
    if not rois:
        raise InputError(f"{option} {path} holds no ROI")
    inside = np.zeros(shape, bool)
    for k, roi in enumerate(rois):
        name = roi.name or f"ROI {k + 1}"
        kind = getattr(roi.roitype, "name", str(roi.roitype))
        if kind not in _AREA_TYPES:
            raise InputError(
                f"{option} {path}: {name} is a {kind.lower()} ROI, which encloses no area; "
                "draw the tissue with a rectangle, oval, polygon or freehand selection"
            )
        try:
            outlines = roi.coordinates(multi=True) if roi.composite else [roi.coordinates()]
        except Exception as exc:
            raise SourceError(f"{option} {path}: {name} cannot be read ({exc})") from None
        area = np.zeros(shape, bool)
        for outline in outlines:
            if outline is None or len(outline) < 3:
                continue
            # ImageJ counts from the top-left pixel's corner; the toolkit from its centre.
            # A composite ROI's outlines alternate: holes are removed (even-odd rule)
            area ^= polygon_inside(np.asarray(outline, dtype=float) - 0.5, shape)
        inside |= area
    return inside
