"""(Y, X) maps on disk: the height map's steps a band of rows or a strip of columns at a time.

A 4096 x 4096 px field of view holds 16.8 million columns; each float64 map
of it is 128 MiB, and finding the surface (:func:`mpm3d.heightmap.from_crossings`)
keeps some ten such maps and their filters' copies alive at once.  A
:class:`DiskMap` keeps a map in a file of a temporary folder
(:class:`MapFolder`) and hands out copies of bands of rows or strips of
columns, each mapped only while it is read or written, so the resident memory
is the bands' alone.

The steps are the in-memory ones, done a line at a time:

* a separable Gaussian (:func:`scipy.ndimage.gaussian_filter` filters along
  axis 0, then along axis 1) is :func:`scipy.ndimage.gaussian_filter1d` along
  axis 0 over strips of whole columns, written to a map, then along axis 1
  over bands of whole rows: every output value is the one the whole map's
  filter gives, bit for bit, whatever the strips' and bands' sizes;
* the 3 x 3 median is taken over bands of rows with a halo row each side;
* counts are integers, and the median of a map's values
  (:func:`exact_median`) is selected by a radix search over the values' bits:
  exact, in four passes.

:func:`from_crossings_on_disk` is :func:`mpm3d.heightmap.from_crossings` on
such maps: the same height map, bit for bit (tests compare the two).
"""

from __future__ import annotations

import errno
import math
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from mpm3d.errors import InputError, WorkFolderWarning
from mpm3d.tiled import format_bytes

__all__ = [
    "DiskMap",
    "MapFolder",
    "exact_median",
    "exact_percentiles",
    "fill_gaps_on_disk",
    "from_crossings_on_disk",
    "gaussian_on_disk",
    "smooth_on_disk",
]

#: bytes of one band (or strip) of a map that a step holds at once, per map it reads
BAND_BYTES = 16 * 2**20


class MapFolder:
    """A temporary folder for :class:`DiskMap` files, removed when closed.

    Parameters
    ----------
    need_bytes : int
        The disk space the maps will take: checked against the free space
        (``TMPDIR`` chooses the folder's place).
    """

    def __init__(self, need_bytes: int = 0, *, prefix: str = "mpm3d-maps-") -> None:
        base = tempfile.gettempdir()
        asked = os.environ.get("TMPDIR")
        if asked and os.path.realpath(asked) != os.path.realpath(base):
            warnings.warn(
                WorkFolderWarning(
                    f"TMPDIR {asked} is not a folder this process can write to: the height "
                    f"map's work maps go to {base}"
                ),
                stacklevel=3,
            )
        if need_bytes and _in_memory(base):
            warnings.warn(
                WorkFolderWarning(
                    f"{base} is held in memory (tmpfs): the height map's work maps "
                    f"({format_bytes(need_bytes)}) take memory there, not counted by "
                    "--memory-limit; set TMPDIR to a folder on disk"
                ),
                stacklevel=3,
            )
        free = shutil.disk_usage(base).free
        if need_bytes > free:
            raise InputError(
                f"the height map's work maps need {format_bytes(need_bytes)} of temporary "
                f"disk space, but {base} has {format_bytes(free)} free: set TMPDIR to a "
                "folder with more"
            )
        self.path = Path(tempfile.mkdtemp(prefix=prefix, dir=base))
        self._count = 0

    def new(self, shape: tuple[int, int], dtype, name: str = "map") -> DiskMap:
        """An empty (zero-filled) map in this folder."""
        self._count += 1
        return DiskMap(self.path / f"{self._count:03d}-{name}.bin", shape, dtype)

    def close(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)

    def __enter__(self) -> MapFolder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _in_memory(folder: str) -> bool:
    """Whether ``folder`` lies on a file system held in memory (tmpfs, ramfs), as the
    longest mount point over it in /proc/mounts says (False where that cannot be read)."""
    try:
        mounts = Path("/proc/mounts").read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError:
        return False
    path = os.path.realpath(folder)
    best, kind = "", ""
    for line in mounts:
        fields = line.split()
        if len(fields) < 3:
            continue
        point = fields[1].replace("\\040", " ")
        inside = path == point or path.startswith(point.rstrip("/") + "/")
        if inside and len(point) > len(best):
            best, kind = point, fields[2]
    return kind in ("tmpfs", "ramfs")


class DiskMap:
    """A ``(Y, X)`` array in a file, read and written a band of rows or a strip of
    columns at a time (each access maps the file only while it copies).

    Parameters
    ----------
    path : path
        The file; created (zero-filled, sparse) when it does not exist.
    shape : (Y, X)
    dtype : numpy dtype
    """

    def __init__(self, path, shape: tuple[int, int], dtype) -> None:
        self.path = Path(path)
        self.shape = (int(shape[0]), int(shape[1]))
        self.dtype = np.dtype(dtype)
        size = self.shape[0] * self.shape[1] * self.dtype.itemsize
        if not self.path.exists() or self.path.stat().st_size != size:
            # the blocks are reserved now: a disk that fills up fails here, with a clear
            # message, and never while a mapped page is written (which would end the
            # process with SIGBUS)
            reserve = getattr(os, "posix_fallocate", None)  # not on macOS nor Windows
            with open(self.path, "wb") as f:
                try:
                    if size and reserve is not None:
                        reserve(f.fileno(), 0, size)
                    elif size:
                        f.truncate(size)
                except OSError as err:
                    if err.errno in (errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
                        f.truncate(size)  # a file system that reserves nothing: sparse
                    elif err.errno != errno.ENOSPC:
                        raise
                    else:
                        free = shutil.disk_usage(self.path.parent).free
                        raise InputError(
                            f"no disk space left for the height map's work maps in "
                            f"{self.path.parent.parent}: a map of {format_bytes(size)} does "
                            f"not fit in the {format_bytes(free)} free; set TMPDIR to a "
                            "folder with more"
                        ) from None

    def _map(self, mode: str) -> np.memmap:
        return np.memmap(self.path, dtype=self.dtype, mode=mode, shape=self.shape)

    def rows(self, y0: int, y1: int) -> np.ndarray:
        """A copy of rows ``y0:y1``."""
        m = self._map("r")
        try:
            return np.array(m[y0:y1])
        finally:
            del m

    def write_rows(self, y0: int, values: np.ndarray) -> None:
        m = self._map("r+")
        try:
            m[y0 : y0 + len(values)] = values
        finally:
            del m

    def columns(self, x0: int, x1: int) -> np.ndarray:
        """A copy of columns ``x0:x1`` (every row)."""
        m = self._map("r")
        try:
            return np.array(m[:, x0:x1])
        finally:
            del m

    def write_columns(self, x0: int, values: np.ndarray) -> None:
        m = self._map("r+")
        try:
            m[:, x0 : x0 + values.shape[1]] = values
        finally:
            del m

    def to_array(self) -> np.ndarray:
        """The whole map in memory."""
        return self.rows(0, self.shape[0])

    @classmethod
    def of(cls, folder: MapFolder, values: np.ndarray, name: str = "map") -> DiskMap:
        """A map holding ``values`` (for tests and small maps)."""
        out = folder.new(values.shape, values.dtype, name)
        out.write_rows(0, values)
        return out


def band_rows(length: int, itemsize: int, budget: int = BAND_BYTES) -> int:
    """Lines of ``length`` items of ``itemsize`` bytes that fit ``budget`` bytes (>= 1)."""
    return max(1, budget // max(1, length * itemsize))


def _spans(n: int, step: int) -> Iterator[tuple[int, int]]:
    for a in range(0, n, step):
        yield a, min(n, a + step)


# ----------------------------------------------------------------------------- filters


def gaussian_on_disk(
    read_strip: Callable[[int, int], np.ndarray],
    shape: tuple[int, int],
    sigma: tuple[float, float],
    folder: MapFolder,
    *,
    mode: str,
    strip: int | None = None,
) -> DiskMap:
    """The first pass of :func:`scipy.ndimage.gaussian_filter`: along axis 0, over strips
    of whole columns (``read_strip(x0, x1)`` gives columns ``x0:x1`` of the input, float64);
    the second pass is the caller's, along axis 1 over bands of this map's rows
    (:func:`gaussian_rows`)."""
    from scipy import ndimage

    out = folder.new(shape, np.float64, "axis0")
    for x0, x1 in _spans(shape[1], strip or band_rows(shape[0], 8)):
        values = np.asarray(read_strip(x0, x1), np.float64)
        if sigma[0] > 1e-15:
            values = ndimage.gaussian_filter1d(values, sigma[0], axis=0, mode=mode)
        out.write_columns(x0, values)
    return out


def gaussian_rows(values: np.ndarray, sigma: float, *, mode: str) -> np.ndarray:
    """The second pass of :func:`scipy.ndimage.gaussian_filter` on a band of whole rows."""
    from scipy import ndimage

    if sigma <= 1e-15:
        return values
    return ndimage.gaussian_filter1d(values, sigma, axis=1, mode=mode)


def fill_gaps_on_disk(
    values: DiskMap,
    valid: DiskMap,
    folder: MapFolder,
    *,
    band: int | None = None,
    strip: int | None = None,
) -> DiskMap:
    """:func:`mpm3d.heightmap.fill_gaps` of two maps on disk: the same values, bit for bit.

    ``values`` may hold NaN where not ``valid``; returns a new float64 map.
    """
    ny, nx = values.shape
    out = folder.new(values.shape, np.float64, "filled")
    weight = folder.new(values.shape, np.float64, "weight")
    missing = 0
    for y0, y1 in _spans(ny, band or band_rows(nx, 8)):
        ok = valid.rows(y0, y1).astype(bool)
        out.write_rows(y0, np.where(ok, values.rows(y0, y1), 0.0).astype(np.float64))
        weight.write_rows(y0, ok.astype(np.float64))
        missing += int(ok.size - np.count_nonzero(ok))
    if missing == ny * nx:
        raise InputError("nothing to fill from: no valid values")
    sigma = 1.0
    # the missing columns are those of weight 0: filled ones take weight 1
    while missing:

        def product(x0: int, x1: int) -> np.ndarray:
            return out.columns(x0, x1) * weight.columns(x0, x1)

        num0 = gaussian_on_disk(product, values.shape, (sigma, sigma), folder, mode="nearest",
                                strip=strip)  # fmt: skip
        den0 = gaussian_on_disk(weight.columns, values.shape, (sigma, sigma), folder,
                                mode="nearest", strip=strip)  # fmt: skip
        for y0, y1 in _spans(ny, band or band_rows(nx, 8)):
            num = gaussian_rows(num0.rows(y0, y1), sigma, mode="nearest")
            den = gaussian_rows(den0.rows(y0, y1), sigma, mode="nearest")
            w = weight.rows(y0, y1)
            ok = (w == 0) & (den > 1e-6)
            if ok.any():
                o = out.rows(y0, y1)
                o[ok] = num[ok] / den[ok]
                w[ok] = 1.0
                out.write_rows(y0, o)
                weight.write_rows(y0, w)
                missing -= int(np.count_nonzero(ok))
        for m in (num0, den0):
            m.path.unlink()
        sigma *= 2.0
    weight.path.unlink()
    return out


def smooth_on_disk(
    values: DiskMap,
    sigma_px: tuple[float, float],
    folder: MapFolder,
    *,
    band: int | None = None,
    strip: int | None = None,
) -> DiskMap:
    """:func:`mpm3d.heightmap.smooth_map` of a map on disk: the same values, bit for bit.

    The map is extended point-symmetrically past its edges (NumPy's odd reflection,
    rows first, then columns, as :func:`numpy.pad` does) strip by strip, filtered
    along its columns, then along its rows; the extension is cut off."""
    ny, nx = values.shape
    py, px = (max(1, min(n - 1, math.ceil(4 * s))) for n, s in zip((ny, nx), sigma_px, strict=True))
    width = nx + 2 * px

    def padded(c0: int, c1: int) -> np.ndarray:
        """Columns ``c0:c1`` of the padded map, every row."""
        src = np.arange(c0, c1) - px
        left, right = src < 0, src > nx - 1
        mirror = np.where(left, -src, np.where(right, 2 * (nx - 1) - src, src))
        if nx == 1:  # NumPy extends a single column by itself
            mirror[:] = 0
        need = [mirror.min(), mirror.max(), *([0] if left.any() else []),
                *([nx - 1] if right.any() else [])]  # fmt: skip
        lo, hi = int(min(need)), int(max(need)) + 1
        block = values.columns(lo, hi).astype(np.float64)
        block = np.pad(block, [(py, py), (0, 0)], mode="reflect", reflect_type="odd")
        out = block[:, mirror - lo]
        if left.any():
            out[:, left] = 2 * block[:, [0 - lo]] - out[:, left]
        if right.any():
            out[:, right] = 2 * block[:, [nx - 1 - lo]] - out[:, right]
        return out

    first = gaussian_on_disk(padded, (ny + 2 * py, width), sigma_px, folder, mode="reflect",
                             strip=strip)  # fmt: skip
    out = folder.new(values.shape, np.float64, "smoothed")
    for y0, y1 in _spans(ny, band or band_rows(width, 8)):
        rows = gaussian_rows(first.rows(py + y0, py + y1), sigma_px[1], mode="reflect")
        out.write_rows(y0, rows[:, px : px + nx])
    first.path.unlink()
    return out


def median3_on_disk(
    values: DiskMap, *, band: int | None = None
) -> Iterator[tuple[int, int, np.ndarray]]:
    """``(y0, y1, rows)`` of :func:`scipy.ndimage.median_filter` (3 x 3, ``nearest``) of a
    map, a band of rows at a time (each read with a halo row each side)."""
    from scipy import ndimage

    ny, nx = values.shape
    for y0, y1 in _spans(ny, band or band_rows(nx, 8)):
        a, b = max(0, y0 - 1), min(ny, y1 + 1)
        med = ndimage.median_filter(values.rows(a, b), size=3, mode="nearest")
        yield y0, y1, med[y0 - a : y1 - a]


# ----------------------------------------------------------------------------- order statistics


def _keys(values: np.ndarray) -> np.ndarray:
    """float64 -> uint64 keys in the same order (negative values' bits flipped)."""
    bits = np.ascontiguousarray(values, np.float64).view(np.uint64)
    negative = (bits >> np.uint64(63)).astype(bool)
    return np.where(negative, ~bits, bits | np.uint64(1 << 63))


def _value(key: int) -> float:
    key = np.uint64(key)
    bits = key & ~np.uint64(1 << 63) if key >> np.uint64(63) else ~key
    return float(np.array([bits], np.uint64).view(np.float64)[0])


def _select(read: Callable[[], Iterator[np.ndarray]], ranks: list[int]) -> list[float]:
    """The ``ranks``-th smallest (0-based) of the values ``read()`` yields, band by band:
    a radix search over their keys, 16 bits a pass (four passes for any number of
    ranks)."""
    ranks = [int(r) for r in ranks]
    prefixes = [0] * len(ranks)
    shift = 48
    while shift >= 0:
        counts = np.zeros((len(ranks), 1 << 16), np.int64)
        for values in read():
            keys = _keys(values)
            high = keys >> np.uint64(shift + 16) if shift < 48 else None
            low = ((keys >> np.uint64(shift)) & np.uint64(0xFFFF)).astype(np.intp)
            for i, prefix in enumerate(prefixes):
                digits = low if high is None else low[high == np.uint64(prefix)]
                counts[i] += np.bincount(digits, minlength=1 << 16)
        for i in range(len(ranks)):
            total = np.cumsum(counts[i])
            b = int(np.searchsorted(total, ranks[i], side="right"))
            ranks[i] -= int(total[b - 1]) if b else 0
            prefixes[i] = (prefixes[i] << 16) | b
        shift -= 16
    return [_value(p) for p in prefixes]


def exact_median(read: Callable[[], Iterator[np.ndarray]], count: int) -> float:
    """What :func:`numpy.median` gives for the ``count`` float64 values ``read()`` yields
    (in bands, none of them NaN): the middle one, or the mean of the two middle ones."""
    if count <= 0:
        return float("nan")
    if count % 2:
        return _select(read, [count // 2])[0]
    lo, hi = _select(read, [count // 2 - 1, count // 2])
    return float(np.mean(np.array([lo, hi])))


def exact_percentiles(read: Callable[[], Iterator[np.ndarray]], count: int, q) -> np.ndarray:
    """What :func:`numpy.percentile` (linear) gives for the ``count`` float64 values
    ``read()`` yields (in bands, none of them NaN), ``q`` in percent: the two order
    statistics around each quantile, found exactly, and NumPy's interpolation between
    them."""
    q = np.asarray(q, np.float64)
    if count <= 0:
        return np.full(q.shape, np.nan)
    index = np.true_divide(q, 100) * (count - 1)
    below = np.floor(index).astype(np.int64)
    above = np.minimum(below + 1, count - 1)
    ranks = sorted({int(r) for r in (*below, *above)})
    value = dict(zip(ranks, _select(read, ranks), strict=True))
    a = np.array([value[int(r)] for r in below])
    b = np.array([value[int(r)] for r in above])
    t = index - below
    diff = b - a
    out = a + diff * t
    return np.where(t >= 0.5, b - diff * (1 - t), out)


# ----------------------------------------------------------------------------- the height map


def from_crossings_on_disk(
    depth: DiskMap,
    peak: DiskMap,
    folder: MapFolder,
    *,
    spacing,
    n_slices: int,
    levels: tuple[float, float, float],
    threshold_given: bool,
    separability: float,
    peak_window_um: float,
    smooth_um: float,
    min_cnr: float,
    outlier_um: float | None,
    min_coverage: float,
    band: int | None = None,
    strip: int | None = None,
):
    """:func:`mpm3d.heightmap.from_crossings` of crossing maps on disk: the same
    :class:`~mpm3d.heightmap.HeightMap`, bit for bit, its maps read into memory at the end
    (``depth_um`` float64, ``valid`` bool, ``cnr`` and ``peak`` float32: 17 bytes a column,
    where the in-memory steps hold some 80)."""
    from mpm3d.heightmap import HeightMap, check_coverage

    threshold, background, noise = levels
    dz, dy, dx = (float(s) for s in spacing)
    sigma_um = float(smooth_um)
    ny, nx = depth.shape
    size = ny * nx
    rows = band or band_rows(nx, 8)
    opts = {"band": band, "strip": strip}
    cnr_map = folder.new(depth.shape, np.float32, "cnr")
    valid = folder.new(depth.shape, np.bool_, "valid")
    depth_um = folder.new(depth.shape, np.float64, "depth_um")
    n_cut = n_none = n_found = n_valid = 0
    for y0, y1 in _spans(ny, rows):
        d, p = depth.rows(y0, y1), peak.rows(y0, y1)
        cut = d < 0
        found = np.isfinite(d) & ~cut
        with np.errstate(invalid="ignore"):
            cnr = np.where(found, (p - background) / max(noise, 1e-12), 0.0)
        cnr = np.nan_to_num(cnr, nan=0.0).astype(np.float32)
        ok = found & (cnr >= min_cnr)
        cnr_map.write_rows(y0, cnr)
        valid.write_rows(y0, ok)
        depth_um.write_rows(y0, np.where(found, d * dz, np.nan))
        n_cut += int(np.count_nonzero(cut))
        n_none += int(np.count_nonzero(~np.isfinite(d)))
        n_found += int(np.count_nonzero(found))
        n_valid += int(np.count_nonzero(ok))
    cut_fraction = n_cut / size
    faint = (n_found - n_valid) / size
    if outlier_um is None:
        outlier_um = 3.0 * dz
    if n_valid:
        filled = fill_gaps_on_disk(depth_um, valid, folder, **opts)
        before, n_valid = n_valid, 0
        for y0, y1, med in median3_on_disk(filled, band=band):
            ok = valid.rows(y0, y1) & (np.abs(filled.rows(y0, y1) - med) <= outlier_um)
            valid.write_rows(y0, ok)
            n_valid += int(np.count_nonzero(ok))
        filled.path.unlink()
        outliers = (before - n_valid) / size
    else:
        outliers = 0.0
    dropouts = {
        "no_crossing": n_none / size,
        "above_stack": cut_fraction,
        "faint": faint,
        "outlier": float(outliers),
    }
    check_coverage(n_valid / size, cut_fraction, threshold, min_coverage)
    final = fill_gaps_on_disk(depth_um, valid, folder, **opts)
    depth_um.path.unlink()
    if sigma_um > 0:
        smoothed = smooth_on_disk(final, (sigma_um / dy, sigma_um / dx), folder, **opts)
        final.path.unlink()
        final = smoothed

    def valid_peaks() -> Iterator[np.ndarray]:
        for a, b in _spans(ny, rows):
            yield peak.rows(a, b)[valid.rows(a, b)]

    level = background + 0.5 * (exact_median(valid_peaks, n_valid) - background)
    masked_peak = folder.new(depth.shape, np.float64, "peak")
    for a, b in _spans(ny, rows):
        masked_peak.write_rows(a, np.where(valid.rows(a, b), peak.rows(a, b), np.nan))
    peak_filled = fill_gaps_on_disk(masked_peak, valid, folder, **opts)
    masked_peak.path.unlink()
    peak_map = np.empty(depth.shape, np.float32)
    for a, b in _spans(ny, rows):
        peak_map[a:b] = peak_filled.rows(a, b).astype(np.float32)
    peak_filled.path.unlink()
    params = {
        "threshold": threshold,
        "threshold_given": threshold_given,
        "peak_window_um": peak_window_um,
        "smooth_um": sigma_um,
        "min_cnr": min_cnr,
        "outlier_um": outlier_um,
    }
    return HeightMap(
        depth_um=final.to_array(),
        valid=valid.to_array(),
        cnr=cnr_map.to_array(),
        spacing=(dz, dy, dx),
        n_slices=int(n_slices),
        threshold=threshold,
        background=background,
        level=float(level),
        peak=peak_map,
        cut_fraction=cut_fraction,
        noise=float(noise),
        separability=float(separability),
        dropouts=dropouts,
        params=params,
    )
