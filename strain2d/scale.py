"""The physical size of a pixel: ``--scale 0.012mm/px`` or a ruler in the first frame.

A :class:`PixelScale` says how long one pixel is on the specimen.  It comes
from a number (``--scale``) or from a known length measured on the first
frame (``--scale-ruler X0,Y0,X1,Y1:LENGTH``: two pixel positions on a ruler,
a calibration target or a scale bar, and the length between them), or from
the pixel size a TIFF records (``--scale auto``: ImageJ/Fiji's calibration,
OME-TIFF's ``PhysicalSizeX``, or the TIFF resolution in centimetres).  With a
scale, a run's positions and displacements are written in that unit as well
as in pixels (``x_mm``, ``u_mm``... beside ``x``, ``u``), its figures' axes
are in the unit, its ParaView files are in the unit, and ``summary.json``
and the report say which.  Strain is dimensionless and does not change.

Lengths are accepted in ``nm``, ``um`` (or ``µm``), ``mm``, ``cm`` and ``m``.

Examples
--------
>>> parse_scale("0.012mm/px")
PixelScale(per_px=0.012, unit='mm', source='given: 0.012 mm/px')
>>> parse_scale("83.3 px/mm").per_px
0.012004801920768308
>>> s = scale_from_ruler("100,400,600,400:6mm")
>>> s.per_px, s.unit
(0.012, 'mm')
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from tissue_core.errors import InputError

__all__ = ["LENGTH_UNITS", "PixelScale", "parse_scale", "scale_from_file", "scale_from_ruler"]

#: accepted length units and their size in metres
LENGTH_UNITS = {"nm": 1e-9, "um": 1e-6, "µm": 1e-6, "mm": 1e-3, "cm": 1e-2, "m": 1.0}
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_UNIT = "|".join(sorted(LENGTH_UNITS, key=len, reverse=True))
_SCALE = re.compile(rf"^\s*({_NUMBER})\s*({_UNIT})\s*/\s*px\s*$")
_INVERSE = re.compile(rf"^\s*({_NUMBER})\s*px\s*/\s*({_UNIT})\s*$")
_LENGTH = re.compile(rf"^\s*({_NUMBER})\s*({_UNIT})\s*$")


@dataclass(frozen=True)
class PixelScale:
    """``per_px`` units of length per pixel; ``unit`` is one of :data:`LENGTH_UNITS`."""

    per_px: float
    unit: str
    source: str = "given"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.per_px) and 1e-300 < self.per_px < 1e300):
            raise InputError(f"the pixel size must be a positive number, got {self.per_px}")
        if self.unit not in LENGTH_UNITS:
            raise InputError(f"unknown length unit {self.unit!r}; use {', '.join(LENGTH_UNITS)}")
        if self.unit == "µm":
            object.__setattr__(self, "unit", "um")

    def to_json(self) -> dict:
        return {
            "length_per_px": self.per_px,
            "unit": self.unit,
            "px_per_unit": 1.0 / self.per_px,
            "source": self.source,
        }

    @classmethod
    def from_json(cls, data) -> PixelScale | None:
        """The scale recorded in a run's ``summary.json`` (``units.scale``), or None."""
        if not isinstance(data, dict) or data.get("length_per_px") is None:
            return None
        return cls(float(data["length_per_px"]), str(data["unit"]), str(data.get("source", "")))


def _number(text: str, what: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and 1e-300 < value < 1e300):
        raise InputError(f"{what} must be a positive number, got {text}")
    return value


def parse_scale(text: str) -> PixelScale:
    """``"0.012mm/px"``, ``"12 um/px"`` or ``"83.3px/mm"`` -> :class:`PixelScale`."""
    text = str(text)
    if m := _SCALE.match(text):
        size = _number(m.group(1), "--scale")
        unit = "um" if m.group(2) == "µm" else m.group(2)
        return PixelScale(size, unit, f"given: {size:g} {unit}/px")
    if m := _INVERSE.match(text):
        per_unit = _number(m.group(1), "--scale")
        unit = "um" if m.group(2) == "µm" else m.group(2)
        return PixelScale(1.0 / per_unit, unit, f"given: {per_unit:g} px/{unit}")
    raise InputError(
        f"--scale {text!r} is not a pixel size: write it as LENGTH_UNIT/px or px/UNIT, "
        f"e.g. 0.012mm/px or 83.3px/mm (units: nm, um, mm, cm, m)"
    )


def scale_from_ruler(text: str, image_shape: tuple[int, int] | None = None) -> PixelScale:
    """``"X0,Y0,X1,Y1:LENGTH"``: two points on the first frame a known ``LENGTH`` apart.

    The points are pixel positions (x = column, y = row), e.g. two marks of a
    ruler, the ends of a scale bar or two corners of a calibration target
    read off the first frame in any image viewer.  ``image_shape`` (H, W), when
    given, checks that both points are in the frame.
    """
    text = str(text)
    points, sep, length = text.rpartition(":")
    m = _LENGTH.match(length) if sep else None
    try:
        coords = [float(v) for v in points.split(",")]
    except ValueError:
        coords = []
    if m is None or len(coords) != 4 or not all(math.isfinite(c) for c in coords):
        raise InputError(
            f"--scale-ruler {text!r} is not X0,Y0,X1,Y1:LENGTH, e.g. 100,400,600,400:6mm "
            f"(two pixel positions on the first frame and the length between them)"
        )
    x0, y0, x1, y1 = coords
    if image_shape is not None:
        h, w = image_shape
        for x, y in ((x0, y0), (x1, y1)):
            if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
                raise InputError(
                    f"--scale-ruler point ({x:g}, {y:g}) is outside the {w}x{h} px frame"
                )
    px = math.hypot(x1 - x0, y1 - y0)
    if px < 10:
        raise InputError(
            f"--scale-ruler points are {px:.3g} px apart; pick points at least 10 px apart "
            f"(farther is more accurate)"
        )
    size = _number(m.group(1), "--scale-ruler's length")
    unit = "um" if m.group(2) == "µm" else m.group(2)
    return PixelScale(
        size / px,
        unit,
        f"ruler on the first frame: ({x0:g}, {y0:g}) to ({x1:g}, {y1:g}), "
        f"{px:.2f} px = {size:g} {unit}",
    )


def _in_length_unit(um: float) -> tuple[float, str]:
    """A size in micrometres in mm from 1 um up (12 um: 0.012 mm), else in um or nm."""
    if um >= 1:
        return um / 1000, "mm"
    return (um, "um") if um >= 0.001 else (um * 1000, "nm")


def scale_from_file(path) -> PixelScale:
    """The pixel size a TIFF records (``--scale auto``), or InputError saying why there is none.

    Read by :func:`tissue_core.tiff_units.lateral_pixel_size_um` (the reader
    mpm3d's stacks use): OME's ``PhysicalSizeX``, ImageJ/Fiji's calibration,
    or a resolution in cm, mm or um.  Square pixels are assumed; a file whose
    X and Y sizes differ is refused, and so is a resolution in inches (a
    print setting, 72 dpi and the like, not a pixel size).  A folder of
    frames is read from its first TIFF.
    """
    import os

    name = os.fspath(path)
    if os.path.isdir(name):  # a folder of frames: the first TIFF's
        tiffs = sorted(f for f in os.listdir(name) if f.lower().endswith((".tif", ".tiff")))
        name = os.path.join(name, tiffs[0]) if tiffs else name
    if not name.lower().endswith((".tif", ".tiff")):
        raise InputError(
            f"--scale auto reads the pixel size of a TIFF; {name} is not one: give --scale "
            f"0.012mm/px or --scale-ruler"
        )
    import tifffile

    from tissue_core.errors import SourceError
    from tissue_core.tiff_files import check_complete, tifffile_messages
    from tissue_core.tiff_units import lateral_pixel_size_um

    try:
        with tifffile_messages() as messages, tifffile.TiffFile(name) as tif:
            check_complete(tif, tif.series[0], name, messages)  # cut short: truncated, not unscaled
            found = lateral_pixel_size_um(tif)
    except SourceError:
        raise
    except Exception as exc:  # tifffile raises many types on damaged files
        raise InputError(f"{name}: cannot read its TIFF tags ({exc})") from None
    if isinstance(found, str):
        raise InputError(f"{name} records no pixel size ({found}): give --scale or --scale-ruler")
    dy, dx, source = found
    if abs(dy - dx) > 1e-6 * max(dy, dx):
        raise InputError(
            f"{name}: its pixels are not square ({dx:.6g} x {dy:.6g} um); give --scale"
        )
    size, unit = _in_length_unit(dx)
    return PixelScale(size, unit, f"{name}: {source}, {size:.6g} {unit}/px")
