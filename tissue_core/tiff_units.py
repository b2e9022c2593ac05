"""Physical pixel sizes that TIFF files record: the unit tables and tag readers, once.

``mpm3d`` reads a stack's voxel spacing with these (ImageJ, OME, the TIFF
resolution tags), and ``strain2d analyze --scale auto`` a video frame's pixel
size.  Sizes are exact :class:`~fractions.Fraction` micrometres until the end.
"""

from __future__ import annotations

import math
import re
from fractions import Fraction

__all__ = [
    "UM_PER_RESUNIT",
    "UM_PER_UNIT",
    "lateral_pixel_size_um",
    "resolution",
    "to_um",
    "um_per_unit",
]

#: micrometres per unit, exact, keyed by lower-case unit text as written by
#: ImageJ (including its escaped ``\\u00B5m``), OME and other software
UM_PER_UNIT: dict[str, Fraction] = {
    **dict.fromkeys(
        (
            "um",
            "µm",  # MICRO SIGN, U+00B5
            "μm",  # GREEK SMALL LETTER MU, U+03BC
            "\\u00b5m",  # ImageJ's escape for the micro sign
            "micron",
            "microns",
            "micrometer",
            "micrometre",
            "micrometers",
            "micrometres",
        ),
        Fraction(1),
    ),
    "nm": Fraction(1, 1000),
    "å": Fraction(1, 10_000),
    "mm": Fraction(1000),
    "cm": Fraction(10_000),
    "m": Fraction(1_000_000),
    "inch": Fraction(25_400),
    "in": Fraction(25_400),
}

#: micrometres per TIFF ``ResolutionUnit`` (2 INCH, 3 CENTIMETER, and
#: tifffile's non-standard 4 MILLIMETER and 5 MICROMETER); 1 NONE is absent
UM_PER_RESUNIT: dict[int, Fraction] = {
    2: Fraction(25_400),
    3: Fraction(10_000),
    4: Fraction(1000),
    5: Fraction(1),
}


def resolution(page) -> tuple[tuple[Fraction, Fraction] | None, Fraction | None]:
    """Pixel size ``(dy, dx)`` in resolution units, and micrometres per such unit."""
    try:
        pixel = tuple(
            Fraction(*page.tags[tag].value[::-1]) for tag in ("YResolution", "XResolution")
        )
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        pixel = None
    tag = page.tags.get("ResolutionUnit")
    resunit = UM_PER_RESUNIT.get(int(tag.value)) if tag is not None else None
    return pixel, resunit


def um_per_unit(unit) -> Fraction | None:
    """Micrometres per ``unit`` (text as TIFF writers spell it), or None if unknown."""
    if not isinstance(unit, str):
        return None
    return UM_PER_UNIT.get(unit.strip().lower())


def to_um(value, per_unit: Fraction | None) -> float | None:
    """``value`` (number or Fraction) in micrometres; None if unknown or not positive."""
    if per_unit is None or value is None:
        return None
    try:
        um = float(Fraction(value) * per_unit)
    except (TypeError, ValueError, OverflowError):
        return None
    return um if math.isfinite(um) and um > 0 else None


def lateral_pixel_size_um(tif) -> tuple[float, float, str] | str:
    """``(dy, dx, source)`` in micrometres that an open ``tifffile.TiffFile`` records.

    Read in order: OME's ``PhysicalSizeX`` (and ``Y``, else the same) with their units, ImageJ's
    ``unit`` with the resolution tags, the resolution tags in cm, mm or um.
    Returns a sentence saying why there is none instead (a resolution in
    inches is a print setting, 72 dpi and the like, not a size on a specimen).
    """
    if tif.is_ome and tif.ome_metadata:
        xml = tif.ome_metadata
        sizes = []
        for axis in ("Y", "X"):
            value = re.search(rf'PhysicalSize{axis}="([^"]+)"', xml)
            unit = re.search(rf'PhysicalSize{axis}Unit="([^"]+)"', xml)
            per = um_per_unit(unit.group(1) if unit else "µm")
            sizes.append(to_um(value.group(1), per) if value else None)
        if sizes[1] is not None:  # square pixels when only X is given
            return sizes[0] or sizes[1], sizes[1], "OME PhysicalSizeX"
    pixel, resunit = resolution(tif.pages[0])
    if pixel is None:
        return "no resolution tags"
    md = tif.imagej_metadata if tif.is_imagej else None
    if md and md.get("unit") is not None:
        per = um_per_unit(md.get("unit"))
        dy, dx = to_um(pixel[0], um_per_unit(md.get("yunit", md["unit"]))), to_um(pixel[1], per)
        if dy is not None and dx is not None:
            return dy, dx, f"ImageJ calibration (unit {md['unit']!r})"
        return f"an ImageJ unit {md['unit']!r} that is not a length"
    if resunit is not None and resunit != UM_PER_RESUNIT[2]:
        dy, dx = to_um(pixel[0], resunit), to_um(pixel[1], resunit)
        if dy is not None and dx is not None:
            return dy, dx, "TIFF resolution tags"
    if resunit == UM_PER_RESUNIT[2]:
        return "a resolution in pixels per inch, a print setting rather than a pixel size"
    return "no ImageJ calibration, OME PhysicalSizeX or resolution in cm"
