"""The lumen surface seen from the objective: a height map from a z-stack.

Geometry (the same as :mod:`mpm3d.io`): slice ``k`` lies at depth
``z = k * dz`` below the first slice (the objective side), pixel ``(row i,
column j)`` at ``(x, y) = (j * dx, i * dy)``.  The tissue lies below the
lumen, so the surface is where a column first turns bright.  The height map
holds the surface **depth** ``D(y, x)`` in micrometres; the **height**
(elevation above the deepest slice, larger on fold crests) is
``(Z - 1) * dz - D``.

The height datum, the plane of the stack's deepest slice, is the one datum
of every height the package writes (the height map, its figure, the 3D
rendering, the mesh's ``height_um`` array, metrics.json): it is fixed by the
stack's geometry alone, so it does not move with noise, smoothing or the
mesh's resolution, and the mesh and the map agree on it exactly.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mpm3d.errors import InputError, SurfaceOutsideWarning, warn_no_data

__all__ = [
    "HEIGHT_DATUM",
    "HeightMap",
    "fill_gaps",
    "height_map",
    "otsu_separability",
    "otsu_threshold",
    "smooth_map",
    "surface_intensity",
    "surface_levels",
]

log = logging.getLogger(__name__)

Spacing = tuple[float, float, float]

#: the datum of every height (um) the package writes: see the module's docstring
HEIGHT_DATUM = "the plane of the stack's deepest slice, (Z - 1) * dz below the first"


@dataclass(frozen=True, eq=False)
class HeightMap:
    """A lumen surface as a depth map, with where it was measured.

    Attributes
    ----------
    depth_um : (Y, X) float64
        Surface depth below slice 0 in micrometres, smoothed, gaps filled.
    valid : (Y, X) bool
        Columns where the surface was measured (not filled in): the
        confidence mask.
    cnr : (Y, X) float32
        Contrast-to-noise ratio of the surface layer in each column (0 where
        none was found).
    spacing : (dz, dy, dx) um
    n_slices : int
    threshold : float
        The detection level in the stack's grey values.
    background : float
        The lumen's grey level.
    level : float
        Half-way between ``background`` and the median surface peak: the
        grey level the measured depths correspond to on average.
    peak : (Y, X) float32
        The surface layer's peak grey value in each column (filled where
        not measured): with ``background`` it sets each column's own
        half-maximum level.
    cut_fraction : float
        Fraction of the columns bright from the first slice on (the surface
        lies above the stack there); they are not ``valid``.
    noise : float
        Robust standard deviation of the lumen's grey values.
    separability : float
        Otsu's separability of the grey values at ``threshold``: the
        between-class share of their variance, in [0, 1] (1: two distinct
        grey levels; NaN for a given threshold on a sample below it).
    dropouts : dict
        Fractions of the columns not measured, by reason: ``no_crossing``
        (never reaches the threshold), ``above_stack`` (bright from slice
        0), ``faint`` (contrast-to-noise below ``min_cnr``), ``outlier``
        (a spike off the neighbours' median).
    params : dict
        The options used, for the record.
    """

    depth_um: np.ndarray
    valid: np.ndarray
    cnr: np.ndarray
    spacing: Spacing
    n_slices: int
    threshold: float
    background: float
    level: float
    peak: np.ndarray
    cut_fraction: float = 0.0
    noise: float = float("nan")
    separability: float = float("nan")
    dropouts: dict = field(default_factory=dict)
    params: dict = field(default_factory=dict)

    @property
    def datum_depth_um(self) -> float:
        """Depth of the height datum (the deepest slice) below slice 0, um."""
        return (self.n_slices - 1) * self.spacing[0]

    @property
    def height_um(self) -> np.ndarray:
        """(Y, X) elevation above the deepest slice, um (crests high)."""
        return self.datum_depth_um - self.depth_um

    @property
    def coverage(self) -> float:
        """Fraction of the columns where the surface was measured."""
        return float(self.valid.mean())

    def __repr__(self) -> str:
        ny, nx = self.depth_um.shape
        return (
            f"<HeightMap {ny} x {nx} px, spacing {self.spacing} um, "
            f"depth {np.nanmin(self.depth_um):.1f}..{np.nanmax(self.depth_um):.1f} um, "
            f"{100 * self.coverage:.1f} % measured>"
        )


def surface_levels(
    volume: np.ndarray, *, threshold: float | None = None, sample: int = 2_000_000
) -> tuple[float, float, float]:
    """Detection threshold, lumen background and its noise from a subsample.

    Parameters
    ----------
    volume : (Z, Y, X) array
    threshold : float, optional
        A given detection level; by default Otsu's threshold (doi:10.1109/TSMC.1979.4310076)
        of a strided subsample of about ``sample`` voxels.

    Returns
    -------
    threshold, background, noise : float
        ``background`` is the median of the voxels below the threshold and
        ``noise`` their robust standard deviation (1.4826 x MAD).
    """
    step = sample_step(volume.size, sample)
    return levels_of_sample(volume[::step, ::step, ::step], threshold=threshold)


def sample_step(size: int, sample: int = 2_000_000) -> int:
    """The stride along each axis of the subsample :func:`surface_levels` takes."""
    return max(1, round((size / sample) ** (1 / 3)))


def levels_of_sample(
    sub: np.ndarray, *, threshold: float | None = None
) -> tuple[float, float, float]:
    """:func:`surface_levels` of a subsample already taken (``volume[::s, ::s, ::s]``)."""
    sub = np.asarray(sub, dtype=np.float32).ravel()
    finite = np.isfinite(sub)
    if not finite.any():
        raise InputError("every voxel is NaN or infinite: there is no surface to find")
    warn_no_data(float(np.isnan(sub).mean()))
    sub = sub[finite]
    if sub.min() == sub.max():
        raise InputError("the stack is uniform: there is no surface to find")
    if threshold is None:
        threshold = otsu_threshold(sub)
    low = sub[sub < threshold]
    if low.size == 0:
        raise InputError(
            f"no surface found: every voxel is at or above the threshold {threshold:g}; "
            "raise --threshold"
        )
    background = float(np.median(low))
    noise = 1.4826 * float(np.median(np.abs(low - background)))
    return float(threshold), background, noise


def otsu_threshold(values: np.ndarray, *, bins: int = 1024) -> float:
    """Otsu's threshold: the level that maximizes the between-class variance.

    N. Otsu, IEEE Trans. Syst. Man Cybern. 9 (1979) 62-66,
    doi:10.1109/TSMC.1979.4310076; :func:`skimage.filters.threshold_otsu` on a
    ``bins``-bin histogram of ``values`` over their range.

    Returns
    -------
    float
        The boundary between the classes: the upper edge of the darker
        class's last bin, so that values below it are the darker class
        (skimage reports that bin's centre, half a bin lower).

    Examples
    --------
    >>> v = np.r_[np.full(100, 10.0), np.full(50, 200.0)]
    >>> bool(10 < otsu_threshold(v) < 200)
    True
    """
    from skimage.filters import threshold_otsu

    v = np.asarray(values, np.float64).ravel()
    lo, hi = float(v.min()), float(v.max())
    if lo == hi:
        return lo
    counts, edges = np.histogram(v, bins=bins, range=(lo, hi))
    # each bin valued at its upper edge: the class means shift by half a bin
    # together, the split is the same, and the level returned is the boundary
    return float(threshold_otsu(hist=(counts, edges[1:])))


def otsu_separability(values: np.ndarray, threshold: float) -> float:
    """Between-class share of the variance of ``values`` split at ``threshold``.

    Otsu's separability measure eta = sigma_B^2 / sigma_T^2 (N. Otsu 1979,
    doi:10.1109/TSMC.1979.4310076, eq. 12): 1 for two distinct grey
    levels, about 0.64 for a Gaussian split at its mean; NaN when one class
    is empty or the values are constant.

    Examples
    --------
    >>> v = np.r_[np.full(100, 10.0), np.full(50, 200.0)]
    >>> round(otsu_separability(v, 100.0), 6)
    1.0
    """
    v = np.asarray(values, np.float64).ravel()
    v = v[np.isfinite(v)]
    high = v >= threshold
    w1 = float(high.mean()) if v.size else 0.0
    total = float(v.var()) if v.size else 0.0
    if not 0 < w1 < 1 or total <= 0:
        return float("nan")
    between = w1 * (1 - w1) * (float(v[high].mean()) - float(v[~high].mean())) ** 2
    return between / total


def height_map(
    volume: np.ndarray,
    *,
    spacing: Sequence[float],
    threshold: float | None = None,
    peak_window_um: float = 20.0,
    smooth_um: float | None = None,
    min_cnr: float = 5.0,
    outlier_um: float | None = None,
    min_coverage: float = 0.05,
) -> HeightMap:
    """Depth of the first bright layer below the lumen, per column, sub-voxel.

    Each column of ``volume`` (averaged over its 3 x 3 lateral neighbours) is
    scanned from the objective side to its first crossing of ``threshold``;
    the depth is then refined to where the rising edge crosses half its
    height (background to the surface layer's first peak within
    ``peak_window_um``), interpolated between slices.  Columns whose layer
    is faint (contrast-to-noise below ``min_cnr``) or that jump away from
    their neighbours by more than ``outlier_um`` (spikes from debris or noise)
    are drop-outs; they are filled from their neighbours by normalized
    convolution and the whole map is smoothed with a Gaussian of
    ``smooth_um`` (by default one pixel).

    Parameters
    ----------
    volume : (Z, Y, X) array
        One channel (or a combination) of the stack; read in place.
    spacing : (dz, dy, dx) um
    threshold : float, optional
        Detection level in grey values; Otsu's by default.
    peak_window_um : float
        How far below the first crossing to look for the layer's peak.
    smooth_um : float, optional
        Gaussian sigma of the final smoothing; 0 turns it off.  At most the
        field of view's longer side.
    min_cnr : float
        Least contrast-to-noise ratio of a measured column.
    outlier_um : float, optional
        Largest difference from the 3 x 3 median; by default 3 z-steps.
    min_coverage : float
        Least fraction of measured columns; fewer raise :class:`InputError`.

    Returns
    -------
    HeightMap

    Examples
    --------
    A tilted bright slab below a dark lumen, found to a few hundredths of
    its 2 um z-step:

    >>> import numpy as np
    >>> z = np.arange(40.0)[:, None, None]
    >>> true_depth = 10.0 + 0.05 * np.arange(32.0)[None, None, :]  # slices
    >>> vol = 100 + 1000 / (1 + np.exp(-(z - true_depth) / 0.8))
    >>> hm = height_map(vol, spacing=(2.0, 1.0, 1.0), smooth_um=0)
    >>> bool(np.abs(hm.depth_um - 2.0 * true_depth[0]).max() < 0.1)
    True
    """
    from mpm3d._kernels import first_crossing

    volume = np.asarray(volume) if not isinstance(volume, np.memmap) else volume
    if volume.ndim != 3:
        raise InputError(f"volume must be (Z, Y, X), got shape {volume.shape}")
    nz, ny, nx = volume.shape
    window, sigma_um = check_options(
        volume.shape,
        spacing=spacing,
        peak_window_um=peak_window_um,
        smooth_um=smooth_um,
        min_cnr=min_cnr,
    )
    threshold_given = threshold is not None
    threshold, background, noise = surface_levels(volume, threshold=threshold)
    step = sample_step(volume.size)  # surface_levels' sample
    separability = otsu_separability(volume[::step, ::step, ::step], threshold)
    depth = np.empty((ny, nx), np.float64)
    peak = np.empty((ny, nx), np.float64)
    log.info("height map: threshold %g, background %g, noise %g", threshold, background, noise)
    first_crossing(volume, float(threshold), float(background), int(window), depth, peak)
    return from_crossings(
        depth,
        peak,
        spacing=spacing,
        n_slices=nz,
        levels=(threshold, background, noise),
        threshold_given=threshold_given,
        separability=separability,
        peak_window_um=peak_window_um,
        smooth_um=sigma_um,
        min_cnr=min_cnr,
        outlier_um=outlier_um,
        min_coverage=min_coverage,
    )


def check_options(
    shape: Sequence[int],
    *,
    spacing: Sequence[float],
    peak_window_um: float,
    smooth_um: float | None,
    min_cnr: float,
) -> tuple[int, float]:
    """Check :func:`height_map`'s options for a ``(Z, Y, X)`` stack of ``shape``.

    Returns
    -------
    window : int
        ``peak_window_um`` in slices (at least 1, at most the stack).
    sigma_um : float
        The smoothing to apply (``smooth_um``, by default one pixel).
    """
    dz, dy, dx = (float(s) for s in spacing)
    nz, ny, nx = shape
    if nz < 3:
        raise InputError(f"a z-stack needs at least 3 slices, got {nz}")
    for name, value in (("peak_window_um", peak_window_um), ("min_cnr", min_cnr)):
        if not (math.isfinite(value) and value >= 0):
            raise InputError(f"{name} must be a number >= 0, got {value}")
    sigma_um = max(dx, dy) if smooth_um is None else float(smooth_um)
    if not (math.isfinite(sigma_um) and sigma_um >= 0):
        raise InputError(f"smooth_um must be a number >= 0, got {smooth_um}")
    if sigma_um > max(ny * dy, nx * dx):
        raise InputError(
            f"a smoothing of {sigma_um:g} um (--smooth) is wider than the field of view "
            f"({ny * dy:g} x {nx * dx:g} um)"
        )
    window = max(1, math.ceil(min(peak_window_um / dz, nz)))  # slices, at most the stack
    return window, sigma_um


def from_crossings(
    depth: np.ndarray,
    peak: np.ndarray,
    *,
    spacing: Sequence[float],
    n_slices: int,
    levels: tuple[float, float, float],
    threshold_given: bool,
    separability: float,
    peak_window_um: float,
    smooth_um: float,
    min_cnr: float,
    outlier_um: float | None,
    min_coverage: float,
) -> HeightMap:
    """The height map from each column's first crossing: drop-outs, gap filling, smoothing.

    Everything after :func:`mpm3d._kernels.first_crossing` in :func:`height_map`,
    on ``(Y, X)`` maps only, so a stack read in tiles
    (:func:`mpm3d.tiled.tiled_height_map`) ends in the same map.

    Parameters
    ----------
    depth, peak : (Y, X) float64
        The crossing depth in slices and the layer's peak grey value (see
        :func:`mpm3d._kernels.first_crossing`).
    levels : (threshold, background, noise)
        From :func:`surface_levels`.
    smooth_um : float
        The smoothing sigma to apply (from :func:`check_options`).
    """
    from scipy import ndimage

    threshold, background, noise = levels
    dz, dy, dx = (float(s) for s in spacing)
    sigma_um = float(smooth_um)
    cut = depth < 0  # bright from slice 0 on: the surface lies above the stack
    found = np.isfinite(depth) & ~cut
    cut_fraction = float(cut.mean())
    # the peak is one voxel's value: compare it with one voxel's noise
    with np.errstate(invalid="ignore"):
        cnr = np.where(found, (peak - background) / max(noise, 1e-12), 0.0)
    cnr = np.nan_to_num(cnr, nan=0.0).astype(np.float32)
    valid = found & (cnr >= min_cnr)
    faint = float((found & ~valid).mean())
    depth_um = np.where(found, depth * dz, np.nan)
    if outlier_um is None:
        outlier_um = 3.0 * dz
    if valid.any():
        filled = fill_gaps(depth_um, valid)
        med = ndimage.median_filter(filled, size=3, mode="nearest")
        before = int(valid.sum())
        valid &= np.abs(filled - med) <= outlier_um
        outliers = (before - int(valid.sum())) / valid.size
    else:
        outliers = 0.0
    dropouts = {
        "no_crossing": float((~np.isfinite(depth)).mean()),
        "above_stack": cut_fraction,
        "faint": faint,
        "outlier": float(outliers),
    }
    check_coverage(float(valid.mean()), cut_fraction, threshold, min_coverage)
    depth_um = fill_gaps(depth_um, valid)
    if sigma_um > 0:
        depth_um = smooth_map(depth_um, (sigma_um / dy, sigma_um / dx))
    peaks = peak[valid]
    level = background + 0.5 * (float(np.median(peaks)) - background)
    peak_map = fill_gaps(np.where(valid, peak, np.nan), valid).astype(np.float32)
    params = {
        "threshold": threshold,
        "threshold_given": threshold_given,
        "peak_window_um": peak_window_um,
        "smooth_um": sigma_um,
        "min_cnr": min_cnr,
        "outlier_um": outlier_um,
    }
    return HeightMap(
        depth_um=depth_um,
        valid=valid,
        cnr=cnr,
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


def check_coverage(
    coverage: float, cut_fraction: float, threshold: float, min_coverage: float
) -> None:
    """Refuse a height map measured in too few columns; warn where the surface is cut off
    above the stack (:func:`from_crossings` and its banded twin,
    :func:`mpm3d.diskmaps.from_crossings_on_disk`)."""
    if coverage < min_coverage:
        raise InputError(
            f"no surface found: only {100 * coverage:.1f} % of the columns rise above the "
            f"threshold {threshold:g} with contrast; change --threshold or --channel"
        )
    if cut_fraction > 0.01:
        warnings.warn(
            SurfaceOutsideWarning(
                f"the surface lies above the first slice in {100 * cut_fraction:.1f} % of the "
                "columns (cut off by the stack); they are left out and filled in"
            ),
            stacklevel=4,
        )


def smooth_map(values: np.ndarray, sigma_px: tuple[float, float]) -> np.ndarray:
    """Gaussian smoothing that leaves planes (and ramps up to the edges) unchanged.

    The map is extended past its edges point-symmetrically
    (``h(-k) = 2 h(0) - h(k)``) before filtering, so a sloping surface keeps
    its height at the edges, where constant or mirror padding would bend it.

    Examples
    --------
    >>> ramp = np.tile(np.arange(8.0), (5, 1))
    >>> bool(np.abs(smooth_map(ramp, (1.5, 1.5)) - ramp).max() < 1e-9)
    True
    """
    from scipy import ndimage

    pad = [
        max(1, min(n - 1, math.ceil(4 * s))) for n, s in zip(values.shape, sigma_px, strict=True)
    ]
    ext = np.pad(values, [(p, p) for p in pad], mode="reflect", reflect_type="odd")
    out = ndimage.gaussian_filter(ext, sigma_px, mode="reflect")
    return out[pad[0] : pad[0] + values.shape[0], pad[1] : pad[1] + values.shape[1]]


def fill_gaps(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Fill ``values`` where not ``valid`` by normalized Gaussian convolution.

    The kernel grows until every gap is filled, so small drop-outs take
    their close neighbours' values and large ones a smooth blend.

    Parameters
    ----------
    values : (Y, X) float
    valid : (Y, X) bool
        At least one True.

    Returns
    -------
    (Y, X) float64, equal to ``values`` where ``valid``.

    Examples
    --------
    >>> v = np.array([[1.0, np.nan, 3.0]])
    >>> fill_gaps(v, np.isfinite(v)).round(3).tolist()
    [[1.0, 2.0, 3.0]]
    """
    from scipy import ndimage

    valid = np.asarray(valid, bool)
    if not valid.any():
        raise InputError("nothing to fill from: no valid values")
    out = np.where(valid, values, 0.0).astype(np.float64)
    if valid.all():
        return out
    weight = valid.astype(np.float64)
    missing = ~valid
    sigma = 1.0
    while missing.any():
        num = ndimage.gaussian_filter(out * weight, sigma, mode="nearest")
        den = ndimage.gaussian_filter(weight, sigma, mode="nearest")
        ok = missing & (den > 1e-6)
        out[ok] = num[ok] / den[ok]
        weight[ok] = 1.0
        missing &= ~ok
        sigma *= 2.0
    return out


#: how deep below the surface the surface-intensity projection averages (um)
SURFACE_LAYER_UM = 6.0


def surface_intensity(
    volume, depth_um: np.ndarray, dz: float, *, layer_um: float = SURFACE_LAYER_UM,
    rows: int | None = None,
) -> np.ndarray:  # fmt: skip
    """The tissue's surface as seen from above: per column, the mean intensity over the
    ``layer_um`` below the surface (the slices from the surface's depth on).

    Parameters
    ----------
    volume : (Z, Y, X) array, or anything with ``shape`` and ``rows(y0, y1, z0, z1)``
        giving ``volume[z0:z1, y0:y1, :]`` (a stack read a band of rows at a time: only
        the slices the band's surface lies in are read)
    depth_um : (Y, X) float
        The surface's depth below slice 0.
    dz : float
        Slice spacing (um).
    rows : int, optional
        Rows read at a time (all at once by default).

    Returns
    -------
    (Y, X) float32
        NaN where the surface's depth is not finite.
    """
    nz, ny, nx = volume.shape
    count = max(1, round(layer_um / dz))
    out = np.empty((ny, nx), np.float32)
    step = ny if rows is None else max(1, int(rows))
    for y0 in range(0, ny, step):
        y1 = min(ny, y0 + step)
        depth = np.asarray(depth_um[y0:y1], dtype=float)
        first = np.clip(np.ceil(np.nan_to_num(depth, nan=0.0) / dz), 0, nz - 1).astype(np.intp)
        z0 = int(first.min())
        z1 = min(nz, int(first.max()) + count)
        if hasattr(volume, "rows"):
            band = volume.rows(y0, y1, z0, z1)
        else:
            band = volume[z0:z1, y0:y1, :]
        total = np.zeros((y1 - y0, nx), np.float64)
        for k in range(count):
            index = (np.minimum(first + k, nz - 1) - z0)[None]
            total += np.take_along_axis(band, index, axis=0)[0]
        total /= count
        total[~np.isfinite(depth)] = np.nan
        out[y0:y1] = total
    return out
