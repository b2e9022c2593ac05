"""Z-stacks read a band of rows at a time: for stacks larger than memory.

:func:`open_stack_lazily` reads a TIFF stack's metadata as
:func:`mpm3d.io.read_stack` does (the same checks, spacing, channel names and
errors) but no pixels: its :class:`~mpm3d.io.Stack` holds a
:class:`TiffRows`, a ``(Z, C, Y, X)`` view that reads from the file only
what is indexed, e.g. ``data[:, 1, 200:264, :]`` (a band of rows of one
channel, every slice) or ``data[::9, :, ::9, ::9]`` (a strided subsample).

How the rows are read:

* uncompressed, contiguous files (what ImageJ, Fiji and tifffile write by
  default, in either byte order) by one positioned read (``os.preadv``) per
  plane and band, straight into the array returned: each plane's rows lie
  one after the other, so a band of rows is one run of bytes and every byte
  of the file is read once per pass over it.  No memory map: pages read stay
  out of the process's resident memory.
* any other file (compressed, fragmented, 1-bit) page by page with
  tifffile, a whole page decoded for each band it contributes to: bounded
  memory, but each pass over the stack decodes every page once per band.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Sequence

import numpy as np

from mpm3d.errors import InputError, SourceError
from mpm3d.io import (
    Stack,
    _check_complete,
    _check_dtype,
    _check_spacing,
    _metadata,
    _reason,
    _resolve_spacing,
    _stack_file,
    _tifffile_messages,
    _zcyx_order,
)

__all__ = ["TiffRows", "index_ranges", "open_stack_lazily"]


def index_ranges(key, shape: Sequence[int], what: str) -> tuple[list[range], list[bool]]:
    """A ``(Z, C, Y, X)`` view's index ``key`` (integers and slices) as one ``range`` per
    axis, and whether each axis was an integer (dropped from the result)."""
    if not isinstance(key, tuple):
        key = (key,)
    if len(key) > 4:
        raise IndexError(f"too many indices for a (Z, C, Y, X) stack: {len(key)}")
    key = key + (slice(None),) * (4 - len(key))
    ranges, drop = [], []
    for k, n in zip(key, shape, strict=True):
        if isinstance(k, int | np.integer) and not isinstance(k, bool):
            i = int(k) + n if k < 0 else int(k)
            if not 0 <= i < n:
                raise IndexError(f"index {k} out of range for an axis of {n}")
            ranges.append(range(i, i + 1))
            drop.append(True)
        elif isinstance(k, slice):
            ranges.append(range(*k.indices(n)))
            drop.append(False)
        else:
            raise TypeError(f"{what} takes integers and slices, got {k!r}")
    return ranges, drop


class TiffRows:
    """A ``(Z, C, Y, X)`` view of a TIFF series that reads only what is indexed.

    Indexing takes integers and slices (any steps) on the four axes and
    returns a new in-memory array in the kernels' types (``float16`` as
    ``float32``, 1-bit ``bool`` as ``uint8``) and the machine's byte order,
    as :func:`mpm3d.io.read_stack` gives them.  Use it as a context manager,
    or call :meth:`close`.

    Attributes
    ----------
    shape : (Z, C, Y, X)
    dtype : numpy.dtype
        The type of the arrays returned.
    contiguous : bool
        True when rows are read by positioned reads (uncompressed,
        contiguous data), False when pages are decoded by tifffile.
    """

    def __init__(self, tif, series, shape_zcyx: tuple[int, int, int, int], order: dict[str, str]):
        self._tif = tif
        self._series = series
        self.shape = tuple(int(n) for n in shape_zcyx)
        file_dtype = np.dtype(series.dtype)
        order_char = tif.byteorder if file_dtype.itemsize > 1 else "|"
        self._file_dtype = file_dtype.newbyteorder(order_char)
        if file_dtype == np.bool_:
            self.dtype = np.dtype(np.uint8)
        elif file_dtype == np.float16:
            self.dtype = np.dtype(np.float32)
        else:
            self.dtype = file_dtype.newbyteorder("=")
        axes, sizes = series.axes, tuple(series.shape)
        while axes and axes[-1] == "S" and sizes[-1] == 1:  # a singleton sample axis
            axes, sizes = axes[:-1], sizes[:-1]
        self._unreadable = None
        if not axes.endswith("YX"):  # said when rows are read: the metadata are fine
            self._unreadable = (
                f"{tif.filehandle.path}: cannot read axes {series.axes!r} a band of rows at a time"
            )
        self._plane_axes = axes[:-2]
        self._plane_sizes = sizes[:-2]
        self._z_axis = order["Z"]
        self._c_axis = order.get("C")
        self._plane_bytes = sizes[-2] * sizes[-1] * file_dtype.itemsize
        self.contiguous = series.dataoffset is not None and file_dtype != np.bool_
        self._offset = series.dataoffset
        self._fd = os.open(tif.filehandle.path, os.O_RDONLY) if self.contiguous else None
        self._lock = threading.Lock()

    @property
    def ndim(self) -> int:
        return 4

    @property
    def size(self) -> int:
        return math.prod(self.shape)

    @property
    def nbytes(self) -> int:
        """Bytes of the whole stack in :attr:`dtype` (what reading it whole would take)."""
        return self.size * self.dtype.itemsize

    def __repr__(self) -> str:
        how = "positioned reads" if self.contiguous else "pages decoded"
        return f"<TiffRows {self.shape} {self.dtype} ({how})>"

    def __enter__(self) -> TiffRows:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        if self._tif is not None:
            self._tif.close()
            self._tif = None

    def _plane(self, z: int, c: int) -> int:
        index = []
        for axis in self._plane_axes:
            if axis == self._z_axis:
                index.append(z)
            elif axis == self._c_axis:
                index.append(c)
            else:
                index.append(0)  # a singleton axis
        return int(np.ravel_multi_index(index, self._plane_sizes)) if index else 0

    def __getitem__(self, key) -> np.ndarray:
        ranges, drop = index_ranges(key, self.shape, "TiffRows")
        if self._unreadable:
            raise InputError(self._unreadable)
        zs, cs, ys, xs = ranges
        out = np.empty((len(zs), len(cs), len(ys), len(xs)), self.dtype)
        if out.size:
            lo, hi = min(ys), max(ys) + 1
            rows = np.asarray(ys) - lo
            direct = ys.step == 1 and xs == range(self.shape[3]) and self.contiguous
            for i, z in enumerate(zs):
                for j, c in enumerate(cs):
                    plane = self._plane(z, c)
                    if direct:
                        self._read_into(plane, lo, hi, out[i, j])
                    else:
                        out[i, j] = self._rows(plane, lo, hi)[rows][:, xs.start : xs.stop : xs.step]
        return out[tuple(0 if d else slice(None) for d in drop)]

    def _read_into(self, plane: int, lo: int, hi: int, dest: np.ndarray) -> None:
        """Rows ``lo:hi`` of ``plane`` into ``dest`` ((hi - lo, X), C-contiguous), converted."""
        if self._file_dtype.itemsize != self.dtype.itemsize:  # float16: through a buffer
            dest[...] = self._rows(plane, lo, hi)
            return
        raw = dest.view(self._file_dtype)
        width = self.shape[3]
        start = self._offset + plane * self._plane_bytes + lo * width * raw.itemsize
        view = memoryview(raw.reshape(-1).view(np.uint8))
        done = 0
        while done < len(view):
            n = os.preadv(self._fd, [view[done:]], start + done)
            if n == 0:
                raise SourceError(f"{self._tif.filehandle.path} is truncated: a plane ends early")
            done += n
        if not raw.dtype.isnative:
            raw.byteswap(inplace=True)

    def _rows(self, plane: int, lo: int, hi: int) -> np.ndarray:
        """Rows ``lo:hi`` of ``plane`` ((hi - lo, X) in :attr:`dtype`)."""
        if self.contiguous:
            width = self.shape[3]
            raw = np.empty((hi - lo, width), self._file_dtype)
            view = memoryview(raw.reshape(-1).view(np.uint8))
            start = self._offset + plane * self._plane_bytes + lo * width * raw.itemsize
            done = 0
            while done < len(view):
                n = os.preadv(self._fd, [view[done:]], start + done)
                if n == 0:
                    raise SourceError(
                        f"{self._tif.filehandle.path} is truncated: a plane ends early"
                    )
                done += n
            return raw.astype(self.dtype)
        with self._lock:  # tifffile reads through one file handle
            page = self._series.pages[plane]
            if page is None:
                raise SourceError(
                    f"{self._tif.filehandle.path} is truncated or damaged: a page is missing"
                )
            data = page.asarray()
        data = data.reshape(data.shape[-2:] if data.ndim > 2 else data.shape)[lo:hi]
        if data.dtype == np.bool_:
            return data.view(np.uint8).copy()
        return data.astype(self.dtype)


def open_stack_lazily(path: str | os.PathLike, *, spacing: Sequence[float] | None = None) -> Stack:
    """A :class:`~mpm3d.io.Stack` whose ``data`` is a :class:`TiffRows`: no pixels read yet.

    Checks the file, and finds its spacing and channel names, exactly as
    :func:`mpm3d.io.read_stack` does, with the same errors and warnings.
    Close ``stack.data`` when done (it holds the file open).
    """
    user_spacing = None if spacing is None else _check_spacing(spacing, "spacing")
    name = _stack_file(path)

    import tifffile

    tif = None
    try:
        with _tifffile_messages() as messages:
            tif = tifffile.TiffFile(name)
            series = tif.series[0]
            axes, shape = series.axes, tuple(series.shape)
            _check_complete(tif, series, name, messages)
            _check_dtype(series.dtype, name)
            order = _zcyx_order(axes, shape, name)
            meta_spacing, source, names, found = _metadata(tif, axes, shape)
        sizes = dict(zip(axes, shape, strict=True))
        zcyx = (sizes[order["Z"]], sizes.get("C", 1) if "C" in order else 1, sizes["Y"], sizes["X"])
        data = TiffRows(tif, series, zcyx, order)
    except (InputError, SourceError):
        if tif is not None:
            tif.close()
        raise
    except Exception as exc:  # a damaged file can make tifffile raise almost anything
        if tif is not None:
            tif.close()
        raise SourceError(f"cannot read {name} as a TIFF stack: {_reason(exc)}") from None
    if names is None or len(names) != zcyx[1]:
        names = tuple(str(i) for i in range(zcyx[1]))
    try:
        meta_spacing, source = _resolve_spacing(name, user_spacing, meta_spacing, source, found)
        return Stack(
            data=data,
            spacing=meta_spacing,
            spacing_source=source,
            channel_names=names,
            path=name,
            axes=axes,
        )
    except BaseException:
        data.close()
        raise
