"""Read multiphoton z-stacks from TIFF files with their voxel spacing.

A stack is returned as a ``(Z, C, Y, X)`` array with its spacing
``(dz, dy, dx)`` in micrometres; slice 0 is the slice nearest the objective,
as acquired.  Three kinds of file are understood, through tifffile_:

* ImageJ hyperstacks: axes from the hyperstack layout, the Z step from the
  ``spacing`` entry of the ImageJ description, the pixel size from the
  ``XResolution`` / ``YResolution`` tags, all in the description's ``unit``
  (or, without one, in the TIFF ``ResolutionUnit``); channel names from the
  slice ``Labels`` when they name the channels consistently.
* OME-TIFF: axes from the OME ``DimensionOrder``, ``PhysicalSizeX/Y/Z`` with
  their units (micrometres when no unit is given) and the ``Name`` of each
  ``Channel``.
* Plain multi-page TIFF: pages are Z slices; the pixel size comes from the
  resolution tags when ``ResolutionUnit`` is physical, but such files carry
  no Z step, so their spacing must be passed by the caller.

Pixels may be of any real type a microscope, ImageJ/Fiji or tifffile writes
(``uint8`` to ``uint64``, ``int8`` to ``int64``, ``float16`` to ``float64``,
NaN voxels included, and 1-bit ``bool``), in either byte order.  Memory:

* uncompressed, contiguous files in the machine's byte order (what ImageJ and
  tifffile write by default on x86 and ARM) are memory-mapped read-only: no
  copy is made, pages are read as the analysis touches them;
* big-endian files (ImageJ's default), compressed or fragmented files are
  decoded into memory once, in the machine's byte order and the file's type:
  one copy of the pixel data;
* ``float16`` stacks become ``float32`` (twice the file's pixel bytes) and
  1-bit ``bool`` stacks ``uint8`` (one byte a voxel), the narrowest types the
  compiled kernels take.

Complex stacks are refused with one :class:`~mpm3d.errors.InputError`, and
files that are cut short or damaged (an ImageJ hyperstack with fewer planes
than its metadata announces, a page beyond the end of the file) with one
:class:`~mpm3d.errors.SourceError` that says so.

.. _tifffile: https://github.com/cgohlke/tifffile
"""

from __future__ import annotations

import logging
import math
import os
import re
import sys
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np

from mpm3d.errors import InputError, MissingSpacingWarning, SourceError, warn_no_data
from tissue_core.tiff_files import check_complete as _check_complete
from tissue_core.tiff_files import tifffile_messages as _tifffile_messages
from tissue_core.tiff_units import resolution, to_um, um_per_unit

__all__ = ["SpacingSource", "Stack", "parse_spacing", "read_stack", "select_channel"]

logger = logging.getLogger(__name__)

#: where :attr:`Stack.spacing` came from
SpacingSource = Literal["imagej", "ome", "tiff-resolution", "user", "none"]

Spacing = tuple[float, float, float]

#: axes tifffile gives to a run of pages it knows nothing more about
_PAGE_AXES = ("Q", "I")

#: voxels sampled per channel to estimate its intensity range
_RANGE_SAMPLE_VOXELS = 1_000_000
#: percentiles of a channel's intensity that map to 0 and 65535 in a combination
_RANGE_PERCENTILES = (0.1, 99.9)
#: the voxel sizes a command line accepts, um: anything outside is in other units
_SPACING_RANGE_UM = (1e-3, 1e4)
#: the TIFF byte order that needs no conversion on this machine
_NATIVE_ORDER = "<" if sys.byteorder == "little" else ">"


@dataclass(frozen=True, eq=False, repr=False)
class Stack:
    """A z-stack in ``(Z, C, Y, X)`` order with its voxel spacing.

    A thin container: it checks that its fields agree and prints a summary.
    Build one with :func:`read_stack`.

    Attributes
    ----------
    data : (Z, C, Y, X) ndarray
        Intensities in the file's own units and type, in the machine's byte
        order (``float16`` read as ``float32``, 1-bit ``bool`` as ``uint8``
        0 and 1).  Read-only: a view of a :class:`numpy.memmap` when
        ``memmapped``, else an in-memory array; either way possibly a
        transposed view of the file's axis order.
    spacing : (3,) tuple of float
        Voxel size ``(dz, dy, dx)`` in micrometres.  ``(1.0, 1.0, 1.0)``
        when the spacing is unknown (``spacing_source == "none"``).
    spacing_source : {"imagej", "ome", "tiff-resolution", "user", "none"}
        Where ``spacing`` came from.  ``"tiff-resolution"`` means an ImageJ
        file whose units came from the TIFF ``ResolutionUnit`` tag because
        its description gives none.
    channel_names : tuple of str
        One name per channel, from the metadata, else ``("0", "1", ...)``.
    path : str
        The file read.
    axes : str
        The file's axes as tifffile reports them, singleton axes dropped,
        e.g. ``"ZCYX"`` (ImageJ), ``"CZYX"`` (OME), ``"ZYX"``, ``"IYX"``.
    memmapped : bool
        True when ``data`` is memory-mapped from the file, False when the
        file had to be decoded (compressed or fragmented data, the other
        byte order, ``float16`` or ``bool`` pixels).
    """

    data: np.ndarray
    spacing: Spacing
    spacing_source: SpacingSource
    channel_names: tuple[str, ...]
    path: str
    axes: str
    memmapped: bool = False

    def __post_init__(self) -> None:
        if self.data.ndim != 4:
            raise InputError(f"Stack data must be (Z, C, Y, X), got shape {self.data.shape}")
        object.__setattr__(self, "spacing", _check_spacing(self.spacing, "spacing"))
        if self.spacing_source not in get_args(SpacingSource):
            raise InputError(
                f"spacing_source must be one of {get_args(SpacingSource)}, "
                f"got {self.spacing_source!r}"
            )
        names = tuple(str(name) for name in self.channel_names)
        if len(names) != self.data.shape[1]:
            raise InputError(
                f"channel_names has {len(names)} names for {self.data.shape[1]} channels"
            )
        object.__setattr__(self, "channel_names", names)

    @property
    def shape(self) -> tuple[int, int, int, int]:
        """``(Z, C, Y, X)``."""
        return self.data.shape

    def __repr__(self) -> str:
        z, c, y, x = self.data.shape
        dz, dy, dx = self.spacing
        how = "memory-mapped" if self.memmapped else "in memory"
        if not isinstance(self.data, np.ndarray):
            how = "read lazily"
        return "\n".join(
            (
                "<mpm3d Stack>",
                f"  Path: {self.path}",
                f"  Shape (Z, C, Y, X): ({z}, {c}, {y}, {x}) {self.data.dtype}, {how}",
                f"  File axes: {self.axes}",
                f"  Spacing (dz, dy, dx): ({dz:g}, {dy:g}, {dx:g}) um from {self.spacing_source}",
                f"  Channels: {', '.join(self.channel_names)}",
            )
        )


def parse_spacing(text: str) -> Spacing:
    """Parse ``"Z,Y,X"`` voxel spacing in micrometres, as given on a command line.

    Parameters
    ----------
    text : str
        Three comma-separated numbers ``dz,dy,dx`` in micrometres, each
        between 0.001 and 10000 (a value outside is in other units).

    Returns
    -------
    spacing : (3,) tuple of float
        ``(dz, dy, dx)`` in micrometres.

    Raises
    ------
    InputError
        When ``text`` is not three numbers in that range.

    Examples
    --------
    >>> parse_spacing("4,1.24,1.24")
    (4.0, 1.24, 1.24)
    >>> parse_spacing(" 2, 0.5 ,0.5")
    (2.0, 0.5, 0.5)
    """
    message = f"--spacing must be Z,Y,X in micrometres, got {text!r}"
    parts = str(text).split(",")
    if len(parts) != 3:
        raise InputError(message)
    try:
        values = tuple(float(part) for part in parts)
    except ValueError:
        raise InputError(message) from None
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise InputError(message)
    lo, hi = _SPACING_RANGE_UM
    if not all(lo <= v <= hi for v in values):
        raise InputError(f"{message}: each must lie between {lo:g} and {hi:g} um")
    return values


def read_stack(path: str | os.PathLike, *, spacing: Sequence[float] | None = None) -> Stack:
    """Read a z-stack from a TIFF, ImageJ hyperstack or OME-TIFF file.

    Parameters
    ----------
    path : str or path-like
        The TIFF file.  Its first image series is read.
    spacing : (3,) sequence of float, optional
        Voxel size ``(dz, dy, dx)`` in micrometres.  Overrides the file's
        metadata (``spacing_source == "user"``).

    Returns
    -------
    Stack
        ``data`` is ``(Z, C, Y, X)``: a view of the file's axes in their
        stored order, memory-mapped when the file is uncompressed,
        contiguous and in the machine's byte order, else decoded into memory
        once (see the module's notes on memory).

    Raises
    ------
    SourceError
        When the file is missing, a folder, empty, not a readable TIFF, or
        truncated or damaged.
    InputError
        When ``spacing`` is not three finite positive numbers, the pixels
        are complex or not numbers, or the file is not a single z-stack: a
        2D image, a time series (``T > 1``), RGB samples, or axes that
        cannot be told apart.

    Warns
    -----
    MissingSpacingWarning
        When neither the metadata nor ``spacing`` gives the full voxel size;
        the stack then has ``spacing == (1.0, 1.0, 1.0)`` and
        ``spacing_source == "none"``.

    Notes
    -----
    Axes are identified from tifffile's ``series.axes``.  Singleton axes are
    dropped.  Pages without further metadata (axes ``"IYX"`` or ``"QYX"``)
    are taken as Z slices; a stack without a channel axis gets ``C == 1``.
    """
    user_spacing = None if spacing is None else _check_spacing(spacing, "spacing")
    name = _stack_file(path)

    import tifffile

    try:
        with _tifffile_messages() as messages:
            with tifffile.TiffFile(name) as tif:
                series = tif.series[0]
                axes, shape = series.axes, tuple(series.shape)
                _check_complete(tif, series, name, messages)
                _check_dtype(series.dtype, name)
                order = _zcyx_order(axes, shape, name)
                meta_spacing, source, names, found = _metadata(tif, axes, shape)
                native = series.dtype.itemsize == 1 or tif.byteorder == _NATIVE_ORDER
                memmapped = series.dataoffset is not None and native and series.dtype != np.float16
                if not memmapped:
                    array = _kernel_dtype(series.asarray())
                    array.flags.writeable = False  # as a memory map is
            if memmapped:
                array = tifffile.memmap(name, series=0, mode="r")
        if array.size != math.prod(shape):
            raise SourceError(
                f"{name} is damaged: it holds {array.size} values for a stack of shape {shape}"
            )
        array = array.reshape(shape)
    except (InputError, SourceError):
        raise
    except MemoryError as exc:
        raise SourceError(f"cannot read {name}: not enough memory to decode it ({exc})") from None
    except Exception as exc:  # a damaged file can make tifffile raise almost anything
        raise SourceError(f"cannot read {name} as a TIFF stack: {_reason(exc)}") from None

    data = _to_zcyx(array, axes, order)
    if names is None or len(names) != data.shape[1]:
        names = tuple(str(i) for i in range(data.shape[1]))

    meta_spacing, source = _resolve_spacing(name, user_spacing, meta_spacing, source, found)
    return Stack(
        data=data,
        spacing=meta_spacing,
        spacing_source=source,
        channel_names=names,
        path=name,
        axes=axes,
        memmapped=memmapped,
    )


def _resolve_spacing(name: str, user_spacing, meta_spacing, source: str, found: str):
    """The spacing and its source: the user's, else the metadata's, else 1 um with a warning."""
    if user_spacing is not None:
        if meta_spacing is not None and not np.allclose(meta_spacing, user_spacing):
            logger.info(
                "%s: spacing %s um from %s metadata overridden by %s um",
                name,
                meta_spacing,
                source,
                user_spacing,
            )
        return user_spacing, "user"
    if meta_spacing is None:
        detail = f" (found {found})" if found else ""
        warnings.warn(
            MissingSpacingWarning(
                f"{name}: no voxel spacing in metadata{detail}; assuming 1 um voxels; "
                "pass --spacing Z,Y,X"
            ),
            stacklevel=3,
        )
        return (1.0, 1.0, 1.0), "none"
    return meta_spacing, source


def _stack_file(path: str | os.PathLike) -> str:
    """The stack's file name, refused in one line if it is missing, a folder or empty."""
    name = os.fspath(path)
    if not os.path.exists(name):
        raise SourceError(f"stack file not found: {name}")
    if os.path.isdir(name):
        raise SourceError(f"stack path is a folder, not a TIFF file: {name}")
    if os.path.getsize(name) == 0:
        raise SourceError(f"{name} is empty (0 bytes), not a TIFF stack")
    return name


def select_channel(stack: Stack, channel: int | str | None = None) -> tuple[np.ndarray, str]:
    """One channel of a stack, or all of them combined.

    Parameters
    ----------
    stack : Stack
        The stack, ``data`` of shape ``(Z, C, Y, X)``.
    channel : int or str, optional
        A channel index ``0 .. C-1``, a channel name (case-insensitive) or
        an index written as text (``"1"``).  ``None`` takes the only channel
        of a one-channel stack and combines the channels of a multi-channel
        stack.

    Returns
    -------
    volume : (Z, Y, X) ndarray
        For one channel, a view ``stack.data[:, c]`` (no copy, file dtype).
        For a combination, a new uint16 array: each channel scaled so its
        0.1th..99.9th percentiles (estimated on a strided subsample) span
        0..65535, clipped, then the voxelwise maximum over channels.  A
        channel with no intensity range contributes zeros.
    label : str
        The channel's name, or ``"max of NAME, NAME, ..."``.

    Raises
    ------
    InputError
        When the channel does not exist.

    Examples
    --------
    >>> data = np.zeros((2, 2, 3, 3), np.uint8)
    >>> stack = Stack(data, (4.0, 1.0, 1.0), "user", ("collagen", "urothelium"), "s.tif", "ZCYX")
    >>> volume, label = select_channel(stack, "Urothelium")
    >>> volume.shape, label
    ((2, 3, 3), 'urothelium')
    >>> select_channel(stack)[1]
    'max of collagen, urothelium'
    """
    names = stack.channel_names
    if channel is None:
        if len(names) == 1:
            return stack.data[:, 0], names[0]
        return _combine_channels(stack.data), "max of " + ", ".join(names)
    index = _channel_index(channel, names)
    return stack.data[:, index], names[index]


def _channel_index(channel: int | str, names: tuple[str, ...]) -> int:
    listing = ", ".join(names)
    if isinstance(channel, str):
        key = channel.strip().casefold()
        matches = [i for i, name in enumerate(names) if name.casefold() == key]
        if len(matches) > 1:
            raise InputError(
                f"channel {channel!r} is ambiguous: channels {matches} all have that name"
            )
        if matches:
            return matches[0]
        if key.isdecimal():
            channel = int(key)
        else:
            raise InputError(f"channel {channel!r} not found; the stack has channels: {listing}")
    if isinstance(channel, bool) or not isinstance(channel, int | np.integer):
        raise InputError(f"channel must be an index or a name, got {channel!r}")
    if not 0 <= channel < len(names):
        raise InputError(
            f"channel {channel} out of range: the stack has {len(names)} "
            f"channel{'s' if len(names) != 1 else ''} ({listing})"
        )
    return int(channel)


def _combine_channels(data: np.ndarray) -> np.ndarray:
    """Voxelwise maximum of robustly normalised channels, ``(Z, C, Y, X)`` -> uint16."""
    z, _, y, x = data.shape
    lo, hi = channel_ranges(data)

    from mpm3d._kernels import combine_channels

    out = np.empty((z, y, x), dtype=np.uint16)
    combine_channels(data, lo, hi, out)  # compiled, parallel over slices
    return out


def channel_ranges(data) -> tuple[np.ndarray, np.ndarray]:
    """Each channel's 0.1th and 99.9th percentile, on a strided subsample of ``data``.

    ``data`` is ``(Z, C, Y, X)``: an array, or any object indexed like one
    (a stack read lazily, :class:`mpm3d.lazyio.TiffRows`).  Returns ``(lo,
    hi)``, (C,) float64 each, for :func:`mpm3d._kernels.combine_channels`.
    """
    z, c, y, x = data.shape
    step = max(1, math.ceil((z * y * x / _RANGE_SAMPLE_VOXELS) ** (1 / 3)))
    ranges = []
    missing = 0.0
    for k in range(c):
        sample = np.asarray(data[::step, k, ::step, ::step], dtype=np.float64).ravel()
        missing = max(missing, float(np.isnan(sample).mean()))
        sample = sample[np.isfinite(sample)]
        if sample.size == 0:
            ranges.append(None)
            continue
        lo, hi = np.percentile(sample, _RANGE_PERCENTILES)
        ranges.append((float(lo), float(hi)))

    if all(r is None for r in ranges):
        raise InputError("every voxel is NaN or infinite: there is no surface to find")
    warn_no_data(missing)  # the channels are combined into integers: NaN is seen only here
    ranges = [(0.0, 0.0) if r is None else r for r in ranges]
    lo = np.array([r[0] for r in ranges], np.float64)
    hi = np.array([r[1] for r in ranges], np.float64)
    return lo, hi


def _check_spacing(spacing: Sequence[float], argument: str) -> Spacing:
    message = (
        f"{argument} must be three finite positive numbers (dz, dy, dx) in micrometres, "
        f"got {spacing!r}"
    )
    if isinstance(spacing, str | bytes):
        raise InputError(message)
    try:
        values = tuple(float(v) for v in spacing)
    except (TypeError, ValueError):
        raise InputError(message) from None
    if len(values) != 3 or not all(math.isfinite(v) and v > 0 for v in values):
        raise InputError(message)
    return values


def _reason(exc: Exception) -> str:
    """Why tifffile could not read a file, in words (its exception's type when it says nothing)."""
    text = "".join(c if c.isprintable() else "?" for c in str(exc).strip("'\" "))[:200]
    match = re.search(r"<COMPRESSION\.(\w+): \d+> requires the 'imagecodecs' package", text)
    if match:
        return (
            f"its pixels are {match.group(1)}-compressed, which needs the imagecodecs "
            "package: pip install imagecodecs"
        )
    import tifffile

    if isinstance(exc, tifffile.TiffFileError | OSError | ValueError) and text:
        return text
    return f"{type(exc).__name__}: {text}" if text else f"{type(exc).__name__} in tifffile"


def _check_dtype(dtype: np.dtype, path: str) -> None:
    """Refuse pixels that are not real numbers."""
    if dtype.kind == "c":
        raise InputError(
            f"{path} holds complex pixels ({dtype}); save the magnitude or the real part "
            "as a real-valued stack"
        )
    if dtype.kind not in "biuf":
        raise InputError(f"{path} has pixels of type {dtype}, not intensities mpm3d can read")


def _kernel_dtype(array: np.ndarray) -> np.ndarray:
    """``array`` in a type the compiled kernels take: bool as uint8, float16 as float32."""
    if array.dtype == np.bool_:
        return array.view(np.uint8)
    if array.dtype == np.float16:
        return array.astype(np.float32)
    return array


def _zcyx_order(axes: str, shape: tuple[int, ...], path: str) -> dict[str, str]:
    """Map each of ``Z, C, Y, X`` to the file axis holding it, checking the stack is 3D.

    Raises InputError for time series, RGB samples, 2D images and unknown axes.
    """
    sizes = dict(zip(axes, shape, strict=True))
    described = f"axes {axes!r}, shape {shape}"
    if sizes.get("T", 1) > 1:
        raise InputError(
            f"{path} has a time axis (T={sizes['T']}); pass one time point as a z-stack"
        )
    if sizes.get("S", 1) > 1:
        raise InputError(
            f"{path} stores RGB colour samples ({described}), not channels; "
            "save the channels as a separate C axis (ImageJ: Image > Color > Make Composite)"
        )
    if "Y" not in sizes or "X" not in sizes:
        raise InputError(f"{path} has no Y and X image axes ({described})")
    order = {"Y": "Y", "X": "X"}
    if sizes.get("C", 1) > 1:
        order["C"] = "C"
    others = [a for a in axes if a not in "CYX" and sizes[a] > 1]
    if others == ["Z"] or (len(others) == 1 and others[0] in _PAGE_AXES):
        order["Z"] = others[0]
    elif others:
        raise InputError(
            f"{path}: cannot tell the Z axis apart in {described}; "
            "save it with ImageJ hyperstack or OME axes"
        )
    else:
        raise InputError(f"{path} is a 2D image ({described}), not a z-stack")
    return order


def _to_zcyx(array: np.ndarray, axes: str, order: dict[str, str]) -> np.ndarray:
    """View ``array`` (axes ``axes``) as ``(Z, C, Y, X)``: drop singletons, move axes."""
    keep = set(order.values())
    array = array[tuple(slice(None) if a in keep else 0 for a in axes)]
    axes = "".join(a for a in axes if a in keep)
    if "C" not in order:  # one channel: add a C axis in front, moved into place below
        array, axes, order = array[np.newaxis], "C" + axes, {**order, "C": "C"}
    source = [axes.index(order[a]) for a in "ZCYX"]
    return np.moveaxis(array, source, [0, 1, 2, 3])


def _metadata(tif, axes: str, shape: tuple[int, ...]):
    """Spacing, its source, channel names and a note on partial spacing, from metadata.

    Never raises on malformed metadata: what cannot be read counts as absent.
    Returns ``(spacing or None, source, names or None, found)``, where
    ``found`` describes a partial spacing for the warning ("" if none).
    """
    if tif.is_ome and tif.ome_metadata:
        spacing, names, found = _ome_metadata(tif.ome_metadata)
        return spacing, "ome", names, found
    page = tif.pages[0]
    pixel, resunit = resolution(page)
    if tif.is_imagej and tif.imagej_metadata is not None:
        return _imagej_metadata(tif.imagej_metadata, pixel, resunit, axes, shape)
    if pixel is not None and resunit is not None:
        dy, dx = (float(p * resunit) for p in pixel)
        return None, "none", None, f"a pixel size of {dy:g} x {dx:g} um but no Z step"
    return None, "none", None, ""


def _imagej_metadata(md: Mapping, pixel, resunit, axes: str, shape: tuple[int, ...]):
    unit = md.get("unit")
    source = "imagej"
    if unit is None and resunit is not None:
        per_x = per_y = per_z = resunit
        source = "tiff-resolution"
    else:
        per_x = um_per_unit(unit)
        per_y = um_per_unit(md.get("yunit", unit))
        per_z = um_per_unit(md.get("zunit", unit))
    dz = to_um(md.get("spacing"), per_z)
    dy, dx = (None, None) if pixel is None else (to_um(pixel[0], per_y), to_um(pixel[1], per_x))
    names = _imagej_channel_names(md.get("Labels"), axes, shape)
    if None in (dz, dy, dx):
        found = ""
        if dy is not None and dx is not None:
            found = f"a pixel size of {dy:g} x {dx:g} um but no Z step"
        elif md.get("spacing") is not None or unit is not None:
            found = f"ImageJ spacing={md.get('spacing')!r} unit={unit!r}, not usable"
        return None, "none", names, found
    return (dz, dy, dx), source, names, ""


def _imagej_channel_names(labels, axes: str, shape: tuple[int, ...]) -> tuple[str, ...] | None:
    """Channel names from ImageJ slice labels, if every slice of a channel has the same one.

    ImageJ stores planes with C varying fastest, then Z, then T.
    """
    if not isinstance(labels, list | tuple):
        return None
    channels = dict(zip(axes, shape, strict=True)).get("C", 1)
    planes = math.prod(n for a, n in zip(axes, shape, strict=True) if a not in "YXS")
    if len(labels) != planes or planes % channels:
        return None
    table = np.asarray([str(label).strip() for label in labels], dtype=object)
    table = table.reshape(-1, channels)
    if not (table == table[0]).all() or not all(table[0]):
        return None
    return tuple(table[0])


def _ome_metadata(xml: str):
    """Spacing, channel names and a partial-spacing note from OME-XML (first image)."""
    from xml.etree import ElementTree

    try:
        root = ElementTree.fromstring(xml)
    except ElementTree.ParseError:
        logger.debug("unparseable OME-XML ignored")
        return None, None, ""
    pixels = root.find("{*}Image/{*}Pixels")
    if pixels is None:
        return None, None, ""
    sizes = []
    for axis in "ZYX":
        value = pixels.get(f"PhysicalSize{axis}")
        per_unit = um_per_unit(pixels.get(f"PhysicalSize{axis}Unit", "µm"))
        try:
            sizes.append(to_um(None if value is None else float(value), per_unit))
        except ValueError:
            sizes.append(None)
    names = tuple(
        channel.get("Name") or str(i) for i, channel in enumerate(pixels.findall("{*}Channel"))
    )
    dz, dy, dx = sizes
    if None in sizes:
        found = ""
        if dy is not None and dx is not None:
            found = f"a pixel size of {dy:g} x {dx:g} um but no Z step"
        elif any(pixels.get(f"PhysicalSize{a}") for a in "ZYX"):
            found = "OME PhysicalSize with missing or unknown units"
        return None, names or None, found
    return (dz, dy, dx), names or None, ""
