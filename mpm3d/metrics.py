"""Fold and roughness metrics of a lumen height map.

All functions take a height map ``(Y, X)`` in micrometres (elevation: fold
crests are high, see :class:`mpm3d.heightmap.HeightMap.height_um`) and its
lateral ``spacing=(dy, dx)`` in micrometres.  Directions are angles in
degrees from the image x axis (columns) towards the y axis (rows): angle
``a`` is the vector ``(cos a, sin a)`` in ``(x, y)``.  A fold's
**orientation** is the direction of its crests, in [0, 180).

References
----------
* ISO 25178-2:2021, Geometrical product specifications (GPS) - Surface
  texture: Areal - Part 2: Terms, definitions and surface texture parameters
  (Sa, Sq, Ssk, Sku, Sp, Sv, Sz, Sdr).
* R. Leach (ed.), Characterisation of Areal Surface Texture, Springer 2013,
  doi:10.1007/978-3-642-36458-7 (the discrete formulas, chapters 2-3).
* J. Bigun, G. Granlund, Optimal orientation detection of linear symmetry,
  ICCV 1987; R. Rezakhaniha et al., Biomech. Model. Mechanobiol. 11 (2012)
  461-473, doi:10.1007/s10237-011-0325-z (structure tensor orientation and
  coherency).
* D. Rife, R. Boorstyn, Single-tone parameter estimation from discrete-time
  observations, IEEE Trans. Inf. Theory 20 (1974) 591-598,
  doi:10.1109/TIT.1974.1055282 (the periodogram maximum as the frequency
  estimate).
"""

from __future__ import annotations

import functools
import heapq
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from mpm3d.errors import InputError

__all__ = [
    "FoldSpectrum",
    "FoldTable",
    "detrend",
    "fold_metrics",
    "fold_orientation",
    "fold_profiles",
    "fold_spectrum",
    "roughness",
]


def _lateral(spacing: Sequence[float]) -> tuple[float, float]:
    spacing = tuple(float(s) for s in spacing)
    if len(spacing) == 3:
        spacing = spacing[1:]
    if len(spacing) != 2 or not all(math.isfinite(s) and s > 0 for s in spacing):
        raise InputError(f"spacing must be (dy, dx) or (dz, dy, dx) > 0 in um, got {spacing}")
    return spacing  # type: ignore[return-value]


def _coords(shape: tuple[int, int], spacing: tuple[float, float]):
    dy, dx = spacing
    y = np.arange(shape[0]) * dy
    x = np.arange(shape[1]) * dx
    return y - y.mean(), x - x.mean()


#: rows of a map that the metrics take at a time: a map's work copies are a band's, not the
#: whole map's (a 4096 x 4096 px map is 128 MiB a copy); the bands are fixed, so a metric
#: does not depend on how the map was made
BAND_ROWS = 256


def _bands(n: int, rows: int | None = None):
    rows = rows or BAND_ROWS
    for a in range(0, n, rows):
        yield a, min(n, a + rows)


def _mask_rows(mask, h: np.ndarray, a: int, b: int) -> np.ndarray:
    """Rows ``a:b`` of ``mask`` (all True when None) and of the finite heights."""
    m = np.isfinite(h[a:b])
    if mask is not None:
        m &= np.asarray(mask[a:b], bool)
    return m


def _least_squares(columns, h: np.ndarray, mask, n_terms: int) -> np.ndarray:
    """Coefficients of the least-squares fit of ``h`` (over ``mask`` and its finite values)
    by the basis ``columns(a, b)`` gives for rows ``a:b`` (``(rows * X, n_terms)``): the
    normal equations summed over bands of rows, solved in the least-squares sense."""
    ata = np.zeros((n_terms, n_terms))
    atb = np.zeros(n_terms)
    count = 0
    for a, b in _bands(h.shape[0]):
        use = _mask_rows(mask, h, a, b).ravel()
        if not use.any():
            continue
        basis = columns(a, b)[use]
        ata += basis.T @ basis
        atb += basis.T @ h[a:b].ravel()[use]
        count += int(use.sum())
    if count < n_terms:
        raise InputError("too few valid heights to remove the form")
    coef, *_ = np.linalg.lstsq(ata, atb, rcond=None)
    return coef


def _quantiles(h: np.ndarray, q: Sequence[float], mask=None) -> np.ndarray:
    """:func:`numpy.percentile` of the finite heights (over ``mask``), ``q`` in percent,
    without a copy of the map: the order statistics found exactly, band by band
    (:func:`mpm3d.diskmaps.exact_percentiles`)."""
    from mpm3d.diskmaps import exact_percentiles

    def read():
        for a, b in _bands(h.shape[0]):
            yield h[a:b][_mask_rows(mask, h, a, b)]

    count = sum(int(_mask_rows(mask, h, a, b).sum()) for a, b in _bands(h.shape[0]))
    return exact_percentiles(read, count, q)


def _block_mean(h: np.ndarray, f: int) -> np.ndarray:
    """``h`` averaged over blocks of ``f x f`` pixels (the last partial row and column of
    blocks dropped), a band of block rows at a time."""
    ny, nx = h.shape[0] // f, h.shape[1] // f
    out = np.empty((ny, nx))
    step = max(1, BAND_ROWS // f)
    for a, b in _bands(ny, step):
        block = np.asarray(h[a * f : b * f, : nx * f], np.float64)
        out[a:b] = block.reshape(b - a, f, nx, f).mean(axis=(1, 3))
    return out


def detrend(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    mask: np.ndarray | None = None,
    order: int = 1,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Remove the least-squares plane (``order=1``) or quadric (``order=2``).

    This is the form removal (F-operator) of ISO 25178-2 before the
    areal parameters are computed.  The fit uses the ``mask`` columns only.

    Parameters
    ----------
    height : (Y, X) float, um
    spacing : (dy, dx) um
    mask : (Y, X) bool, optional
    order : {0, 1, 2}
    out : (Y, X) float64, optional
        Where to write the result (may be ``height`` itself).

    Returns
    -------
    (Y, X) float64 residual heights, um; zero mean over ``mask``.

    Examples
    --------
    >>> y, x = np.mgrid[0:20, 0:30] * 2.0
    >>> bool(np.abs(detrend(5 + 0.3 * x - 0.1 * y, spacing=(2, 2))).max() < 1e-9)
    True
    """
    if order not in (0, 1, 2):
        raise InputError(f"order must be 0, 1 or 2, got {order}")
    spacing = _lateral(spacing)
    h = np.asarray(height, np.float64)
    y, x = _coords(h.shape, spacing)
    # coordinates scaled to about [-1, 1]: well-conditioned normal equations
    y, x = y / max(np.abs(y).max(), 1e-300), x / max(np.abs(x).max(), 1e-300)

    def columns(a: int, b: int) -> np.ndarray:
        yy, xx = np.meshgrid(y[a:b], x, indexing="ij")
        terms = [np.ones_like(xx)]
        if order >= 1:
            terms += [xx, yy]
        if order >= 2:
            terms += [xx * xx, xx * yy, yy * yy]
        return np.stack([t.ravel() for t in terms], axis=1)

    n_terms = (1, 3, 6)[order]
    coef = _least_squares(columns, h, mask, n_terms)
    res = out if out is not None else np.empty(h.shape)
    for a, b in _bands(h.shape[0]):
        res[a:b] = h[a:b] - (columns(a, b) @ coef).reshape(b - a, h.shape[1])
    return res


def roughness(
    height: np.ndarray, *, spacing: Sequence[float], mask: np.ndarray | None = None
) -> dict[str, float]:
    """ISO 25178-2 areal parameters of a (detrended) height map.

    ``Sa`` (arithmetic mean height), ``Sq`` (root mean square height),
    ``Ssk`` (skewness), ``Sku`` (kurtosis), ``Sp`` (maximum peak height),
    ``Sv`` (maximum pit depth), ``Sz = Sp + Sv`` (maximum height), all about
    the mean plane over ``mask``; and ``Sdr``, the developed interfacial area
    ratio in percent: the surface's area over its projected area, minus one.
    Each grid cell's area is ``dx dy sqrt(1 + zx^2 + zy^2)`` with the slopes
    averaged over the cell's edges (exact for planes).

    Parameters
    ----------
    height : (Y, X) float, um, with its form already removed
    spacing : (dy, dx) um
    mask : (Y, X) bool, optional
        Columns to include (Sdr uses the cells whose four corners are in).

    Returns
    -------
    dict with keys ``Sa_um, Sq_um, Ssk, Sku, Sp_um, Sv_um, Sz_um, Sdr_percent``.

    Examples
    --------
    A 45 degree roof has Sdr = sqrt(2) - 1:

    >>> x = np.arange(50.0)
    >>> r = roughness(np.tile(np.abs(x - 24), (40, 1)), spacing=(1, 1))
    >>> round(r["Sdr_percent"], 2)
    41.42
    """
    dy, dx = _lateral(spacing)
    h = np.asarray(height, np.float64)
    ny = h.shape[0]
    count, total = 0, 0.0
    for a, b in _bands(ny):
        z = h[a:b][_mask_rows(mask, h, a, b)]
        count += z.size
        total += float(z.sum())
    if count < 4:
        raise InputError("too few valid heights for roughness parameters")
    mean = total / count
    s1 = s2 = s3 = s4 = 0.0
    top, bottom = -np.inf, np.inf
    area, cells = 0.0, 0
    for a, b in _bands(ny):
        z = h[a:b][_mask_rows(mask, h, a, b)] - mean
        if z.size:
            z2 = z * z
            s1 += float(np.abs(z).sum())
            s2 += float(z2.sum())
            s3 += float((z2 * z).sum())
            s4 += float((z2 * z2).sum())
            top, bottom = max(top, float(z.max())), min(bottom, float(z.min()))
        # the cells whose top-left corner lies in rows a:b (and the row below them)
        c1 = min(b, ny - 1)
        if c1 <= a:
            continue
        hh = h[a : c1 + 1]
        m = _mask_rows(mask, h, a, c1 + 1)
        zx = ((hh[:-1, 1:] - hh[:-1, :-1]) + (hh[1:, 1:] - hh[1:, :-1])) / (2 * dx)
        zy = ((hh[1:, :-1] - hh[:-1, :-1]) + (hh[1:, 1:] - hh[:-1, 1:])) / (2 * dy)
        inside = m[:-1, :-1] & m[1:, :-1] & m[:-1, 1:] & m[1:, 1:]
        area += float(np.sqrt(1 + zx[inside] ** 2 + zy[inside] ** 2).sum())
        cells += int(inside.sum())
    sq = math.sqrt(s2 / count)
    sa = s1 / count
    ssk = s3 / count / sq**3 if sq > 0 else 0.0
    sku = s4 / count / sq**4 if sq > 0 else 0.0
    sp, sv = top, -bottom
    sdr = 100 * (area / cells - 1) if cells else float("nan")
    return {
        "Sa_um": sa,
        "Sq_um": sq,
        "Ssk": ssk,
        "Sku": sku,
        "Sp_um": sp,
        "Sv_um": sv,
        "Sz_um": sp + sv,
        "Sdr_percent": sdr,
    }


@dataclass(frozen=True, eq=False)
class FoldSpectrum:
    """The dominant spatial frequency of a height map.

    Attributes
    ----------
    wavelength_um : float
        1 / |k| of the refined spectral peak.
    wavevector : (2,) float
        ``(kx, ky)`` in cycles per um, pointing across the folds.
    orientation_deg : float
        Direction of the crests (perpendicular to the wavevector), [0, 180).
    freq_x, freq_y : (X2,), (Y2,) float
        Frequency axes (cycles/um) of ``power`` (zero-padded, fftshifted).
    power : (Y2, X2) float
        Windowed power spectrum, um^2 (arbitrary scale).
    peak_fraction : float
        Share of the searched band's power within the peak's main lobe (and
        its mirror): near 1 for one clean fold period, small for an
        isotropic or multi-scale surface.
    """

    wavelength_um: float
    wavevector: np.ndarray
    orientation_deg: float
    freq_x: np.ndarray
    freq_y: np.ndarray
    power: np.ndarray
    peak_fraction: float


def fold_spectrum(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    max_wavelength_um: float | None = None,
    min_wavelength_um: float | None = None,
    max_size: int = 512,
) -> FoldSpectrum:
    """Dominant fold wavelength and direction from the spectral peak.

    The detrended, Hann-windowed height map's power spectrum (zero-padded
    two-fold) is searched for its highest peak between ``min_wavelength_um``
    (default 4 pixels) and ``max_wavelength_um`` (default the field's
    shorter side); the peak is then refined off the grid by maximizing the
    windowed discrete-time Fourier transform's magnitude (compass search), the
    single-tone maximum-likelihood estimate (Rife & Boorstyn 1974).

    Maps larger than ``max_size`` pixels on a side are first averaged over
    blocks to at most that size: folds are many pixels wide, and the
    estimate does not need the fine sampling.

    Parameters
    ----------
    height : (Y, X) float, um
    spacing : (dy, dx) um

    Returns
    -------
    FoldSpectrum

    Examples
    --------
    >>> y, x = np.mgrid[0:128, 0:128] * 2.0
    >>> crest = np.deg2rad(60)  # crests along 60 deg: the wave runs along 150 deg
    >>> u = -x * np.sin(crest) + y * np.cos(crest)
    >>> s = fold_spectrum(np.cos(2 * np.pi * u / 37.0), spacing=(2, 2))
    >>> round(s.wavelength_um, 2), round(s.orientation_deg, 2)
    (37.0, 60.0)
    """
    dy, dx = _lateral(spacing)
    h = np.asarray(height)
    finite = h.ndim == 2 and all(np.isfinite(h[a:b]).all() for a, b in _bands(h.shape[0]))
    if h.ndim != 2 or min(h.shape) < 8 or not finite:
        raise InputError("the height map must be 2D, finite and at least 8 x 8")
    factor = max(1, math.ceil(max(h.shape) / max_size))
    h = _block_mean(h, factor) if factor > 1 else np.asarray(h, np.float64)
    dy, dx = dy * factor, dx * factor
    ny, nx = h.shape
    z = detrend(h, spacing=(dy, dx))
    window = np.hanning(ny)[:, None] * np.hanning(nx)[None, :]
    zw = z * window
    py, px = 2 * ny, 2 * nx
    spec = np.fft.fftshift(np.abs(np.fft.fft2(zw, s=(py, px))) ** 2)
    fy = np.fft.fftshift(np.fft.fftfreq(py, dy))
    fx = np.fft.fftshift(np.fft.fftfreq(px, dx))
    kk = np.hypot(fx[None, :], fy[:, None])
    longest = min(ny * dy, nx * dx) if max_wavelength_um is None else float(max_wavelength_um)
    shortest = 4 * max(dx, dy) if min_wavelength_um is None else float(min_wavelength_um)
    band = (kk >= 1 / longest) & (kk <= 1 / shortest)
    if not band.any():
        raise InputError("no frequencies between the shortest and longest wavelength asked for")
    masked = np.where(band, spec, -1.0)
    iy, ix = np.unravel_index(int(np.argmax(masked)), spec.shape)
    k0 = np.array([fx[ix], fy[iy]])
    ys, xs = _coords((ny, nx), (dy, dx))

    def power(k: np.ndarray) -> float:
        ex = np.exp(-2j * np.pi * k[0] * xs)
        ey = np.exp(-2j * np.pi * k[1] * ys)
        return float(abs(ey @ (zw @ ex)) ** 2)

    # compass search: try the eight neighbours at the current step, move to
    # the best, halve the step when none is better, down to 1e-4 of a bin
    k, best = k0, power(k0)
    step = np.array([0.5 / (px * dx), 0.5 / (py * dy)])
    moves = np.array([(i, j) for i in (-1, 0, 1) for j in (-1, 0, 1) if i or j], np.float64)
    while step.max() > 1e-4 / (px * dx):
        trials = k + moves * step
        radius = np.hypot(trials[:, 0], trials[:, 1])
        trials = trials[(radius >= 1 / longest) & (radius <= 1 / shortest)]  # stay in the band
        if len(trials) == 0:
            break
        values = [power(t) for t in trials]
        i = int(np.argmax(values))
        if values[i] > best:
            k, best = trials[i], values[i]
        else:
            step = step / 2
    if k[1] < 0 or (k[1] == 0 and k[0] < 0):
        k = -k
    wave_dir = math.degrees(math.atan2(k[1], k[0]))
    orientation = (wave_dir + 90.0) % 180.0
    lobe = 2.0 / min(nx * dx, ny * dy)  # the Hann window's main-lobe half width
    near = (np.hypot(fx[None, :] - k[0], fy[:, None] - k[1]) <= lobe) | (
        np.hypot(fx[None, :] + k[0], fy[:, None] + k[1]) <= lobe
    )
    fraction = float(spec[near & band].sum() / max(spec[band].sum(), 1e-300))
    return FoldSpectrum(
        wavelength_um=float(1 / np.hypot(*k)),
        wavevector=np.asarray(k, np.float64),
        orientation_deg=float(orientation),
        freq_x=fx,
        freq_y=fy,
        power=spec,
        peak_fraction=fraction,
    )


def fold_orientation(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    mask: np.ndarray | None = None,
    sigma_um: float | None = None,
) -> tuple[float, float]:
    """Crest direction and coherency from the height map's structure tensor.

    The gradient structure tensor ``J = <grad h grad h^T>`` averaged over the
    map (Bigun & Granlund 1987) has its leading eigenvector across the folds;
    the crests run perpendicular to it.  Coherency
    ``(l1 - l2) / (l1 + l2)`` is 1 for perfectly parallel folds and 0 for an
    isotropic surface.

    Parameters
    ----------
    height : (Y, X) float, um
    spacing : (dy, dx) um
    mask : (Y, X) bool, optional
        Columns included in the average.
    sigma_um : float, optional
        Gaussian pre-smoothing; by default 2 pixels.

    Returns
    -------
    orientation_deg : float in [0, 180)
    coherency : float in [0, 1]

    Examples
    --------
    >>> y, x = np.mgrid[0:64, 0:64] * 1.0
    >>> o, c = fold_orientation(np.sin(2 * np.pi * x / 16), spacing=(1, 1))
    >>> round(o, 3), round(c, 3)  # crests run along y
    (90.0, 1.0)
    """
    from scipy import ndimage

    dy, dx = _lateral(spacing)
    h = np.asarray(height, np.float64)
    ny = h.shape[0]
    sigma = 2 * max(dx, dy) if sigma_um is None else float(sigma_um)
    # a band of rows with the filter's reach and the gradient's row on each side: its
    # inner rows are the whole map's
    halo = (int(4.0 * sigma / dy + 0.5) if sigma > 0 else 0) + 1
    sums = np.zeros(3)
    count = 0
    for a, b in _bands(ny):
        lo, hi = max(0, a - halo), min(ny, b + halo)
        band = h[lo:hi]
        if sigma > 0:
            band = ndimage.gaussian_filter(band, (sigma / dy, sigma / dx), mode="nearest")
        if hi - lo < 2:
            gy, gx = np.zeros_like(band), np.gradient(band, dx, axis=1)
        else:
            gy, gx = np.gradient(band, dy, dx)
        gy, gx = gy[a - lo : b - lo], gx[a - lo : b - lo]
        m = np.ones(gx.shape, bool) if mask is None else np.asarray(mask[a:b], bool)
        gx, gy = gx[m], gy[m]
        sums += (float((gx * gx).sum()), float((gy * gy).sum()), float((gx * gy).sum()))
        count += gx.size
    if count == 0:
        return float("nan"), 0.0
    jxx, jyy, jxy = (float(v) / count for v in sums)
    trace = jxx + jyy
    if trace <= 0:
        return float("nan"), 0.0
    wave_dir = 0.5 * math.degrees(math.atan2(2 * jxy, jxx - jyy))
    coherency = math.hypot(jxx - jyy, 2 * jxy) / trace
    return float((wave_dir + 90.0) % 180.0), float(coherency)


#: profiles whose samples a :class:`FoldTable` keeps (the longest)
KEPT_PROFILES = 32


@dataclass(frozen=True, eq=False)
class FoldTable:
    """Folds found along profiles across the crests.

    Attributes
    ----------
    crests : dict of (P,) arrays
        One entry per crest found on a profile: ``profile`` (index),
        ``x_um``, ``y_um`` (crest position), ``offset_um`` (position across
        the folds, along the wavevector from the map centre), ``height_um``
        (crest minus the mean of the neighbouring troughs), ``sides`` (2, or
        1 where the profile leaves the map before the other trough) and
        ``width_um`` (trough to trough; NaN when one-sided).
    folds : dict of (F,) arrays
        One entry per fold (crests grouped by offset): ``fold``,
        ``offset_um``, ``x_um``, ``y_um`` (mean crest position),
        ``n_profiles``, ``height_um`` (median over profiles),
        ``height_max_um``, ``width_um`` (median).
    profiles : list of dict
        The :data:`KEPT_PROFILES` longest profiles' samples, for figures: each
        one's ``profile`` (index, as in ``crests``), ``s_um`` (distance along
        it), ``x_um``, ``y_um`` and ``height_um``.
    normal : (2,) float
        Unit vector across the folds (x, y).
    troughs : dict of (T,) arrays
        One entry per trough found on a profile: ``profile``, ``x_um``,
        ``y_um``, ``offset_um`` and ``height_um`` (from the quadratic fit).
    """

    crests: dict
    folds: dict
    profiles: list
    normal: np.ndarray
    troughs: dict = field(default_factory=dict)

    @property
    def n_folds(self) -> int:
        return len(self.folds["fold"])


def _prominent_peaks(
    profile: np.ndarray, *, distance: int, prominence: float, sigma: float
) -> np.ndarray:
    """Indices of the peaks of ``profile`` that stand out, in increasing order.

    The profile is first smoothed (Gaussian, ``sigma`` samples) so small
    roughness does not split a crest.  A peak's prominence is its height
    above the higher of the two lowest points between it and the nearest
    higher sample on either side, as in topography.  A side that reaches the
    profile's end without a higher sample is open: the fold goes on outside
    the map, so only the other side counts (a crest near the edge of the
    field stands out from its one trough in view).  Peaks under
    ``prominence`` are dropped, then of peaks closer than ``distance``
    samples only the highest is kept.
    """
    from scipy import ndimage

    sm = ndimage.gaussian_filter1d(profile, sigma, mode="nearest") if sigma > 0 else profile
    n = sm.size
    if n < 3:
        return np.zeros(0, np.int64)
    candidates = np.flatnonzero((sm[1:-1] > sm[:-2]) & (sm[1:-1] >= sm[2:])) + 1
    kept = []
    for i in candidates:
        higher = np.flatnonzero(sm[:i] > sm[i])
        left = sm[higher[-1] if higher.size else 0 : i].min()
        left_open = higher.size == 0
        higher = np.flatnonzero(sm[i + 1 :] > sm[i])
        right = sm[i + 1 : i + 1 + higher[0] if higher.size else n].min()
        right_open = higher.size == 0
        if left_open != right_open:  # one side runs off the map: the other one counts
            base = right if left_open else left
        else:
            base = max(left, right)
        if sm[i] - base >= prominence:
            kept.append(i)
    chosen: list[int] = []
    for i in sorted(kept, key=lambda j: -sm[j]):
        if all(abs(i - j) >= distance for j in chosen):
            chosen.append(int(i))
    return np.asarray(sorted(chosen), np.int64)


@functools.lru_cache(maxsize=256)
def _quadratic_fit(before: int, after: int) -> np.ndarray:
    """(3, before + after + 1) least-squares map from samples at ``-before..after`` to
    ``(c2, c1, c0)`` of ``c2 t^2 + c1 t + c0``."""
    t = np.arange(-before, after + 1, dtype=np.float64)
    return np.linalg.pinv(np.vander(t, 3))


def _extremum(profile: np.ndarray, i: int, half: int) -> float:
    """Height of the extremum near sample ``i`` from a local quadratic fit."""
    lo, hi = max(0, i - half), min(len(profile), i + half + 1)
    if hi - lo < 3:
        return float(profile[i])
    c2, c1, c0 = _quadratic_fit(i - lo, hi - 1 - i) @ profile[lo:hi]
    if c2 == 0:
        return float(profile[i])
    tv = -c1 / (2 * c2)
    if abs(tv) > half:
        return float(profile[i])
    return float(c0 + c1 * tv + c2 * tv * tv)


def fold_profiles(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    orientation_deg: float,
    wavelength_um: float,
    profile_spacing_um: float | None = None,
    min_fold_height_um: float | None = None,
    min_profiles: int = 3,
    fit_fraction: float = 0.1,
) -> FoldTable:
    """Per-fold crest-to-trough heights along profiles across the crests.

    Straight profiles run across the folds (along the wavevector, at
    ``orientation_deg + 90``) every ``profile_spacing_um`` along the crests
    (default a sixteenth of a wavelength: many profiles, so that the median
    over them averages out roughness even where a field of view holds a
    short stretch of few folds).  On each profile, crests and troughs are
    the peaks and valleys at least half a wavelength apart whose prominence
    is at least ``min_fold_height_um`` (default a fifth of the map's 1-99 %
    height range); their heights come from a quadratic fit over a tenth of a
    wavelength on either side, which averages out small roughness.  A crest
    gives a fold height: crest minus the mean of its two neighbouring
    troughs, or of the one trough inside the map where the profile leaves
    the map first (such one-sided heights are used for a fold only when it
    has too few two-sided ones).  Crests are grouped into folds by their offset across
    the folds (gaps over a third of a wavelength separate folds); folds seen
    on fewer than ``min_profiles`` profiles are dropped.

    Parameters
    ----------
    height : (Y, X) float, um
    spacing : (dy, dx) um
    orientation_deg : float
        Crest direction (see :func:`fold_orientation`).
    wavelength_um : float
        Fold wavelength (see :func:`fold_spectrum`).

    Returns
    -------
    FoldTable
    """
    from scipy import ndimage

    dy, dx = _lateral(spacing)
    h = np.asarray(height, np.float64)
    if not (math.isfinite(wavelength_um) and wavelength_um > 0):
        raise InputError(f"wavelength_um must be > 0, got {wavelength_um}")
    ny, nx = h.shape
    theta = math.radians(orientation_deg)
    crest = np.array([math.cos(theta), math.sin(theta)])
    normal = np.array([-math.sin(theta), math.cos(theta)])
    centre = np.array([(nx - 1) * dx / 2, (ny - 1) * dy / 2])
    step = min(dx, dy)
    radius = math.hypot(nx * dx, ny * dy) / 2
    s = np.arange(-radius, radius + step, step)
    gap = profile_spacing_um if profile_spacing_um is not None else wavelength_um / 16
    offsets = np.arange(-radius, radius + gap, gap)
    if min_fold_height_um is None:
        lo, hi = _quantiles(h, [1, 99])
        min_prom = 0.2 * (hi - lo)
    else:
        min_prom = float(min_fold_height_um)
    distance = max(1, int(0.5 * wavelength_um / step))
    half = max(1, round(fit_fraction * wavelength_um / step))
    rec: dict[str, list] = {k: [] for k in ("profile", "x_um", "y_um", "offset_um", "height_um")}
    rec["width_um"] = []
    rec["sides"] = []
    low: dict[str, list] = {k: [] for k in ("profile", "x_um", "y_um", "offset_um", "height_um")}
    profiles = []
    for p, v in enumerate(offsets):
        pts = centre + v * crest + s[:, None] * normal
        inside = (
            (pts[:, 0] >= 0)
            & (pts[:, 0] <= (nx - 1) * dx)
            & (pts[:, 1] >= 0)
            & (pts[:, 1] <= (ny - 1) * dy)
        )
        if inside.sum() < 2 * distance:
            continue
        idx = np.flatnonzero(inside)
        pts = pts[idx[0] : idx[-1] + 1]
        prof = ndimage.map_coordinates(h, [pts[:, 1] / dy, pts[:, 0] / dx], order=1)
        sp = s[idx[0] : idx[-1] + 1]
        # the KEPT_PROFILES longest profiles' samples are kept as they come (the first of
        # equal length), for figures: a 4096 px map has some 800 profiles of 4000 samples
        entry = {"profile": p, "s_um": sp, "x_um": pts[:, 0], "y_um": pts[:, 1], "height_um": prof}
        heapq.heappush(profiles, (len(sp), -p, entry))
        if len(profiles) > KEPT_PROFILES:
            heapq.heappop(profiles)
        peaks = _prominent_peaks(prof, distance=distance, prominence=min_prom, sigma=half / 2)
        troughs = _prominent_peaks(-prof, distance=distance, prominence=min_prom, sigma=half / 2)
        for t in troughs:
            low["profile"].append(p)
            low["x_um"].append(pts[t, 0])
            low["y_um"].append(pts[t, 1])
            low["offset_um"].append(float(sp[t]))
            low["height_um"].append(_extremum(prof, int(t), half))
        if peaks.size == 0 or troughs.size == 0:
            continue
        for i in peaks:
            left = troughs[troughs < i]
            right = troughs[troughs > i]
            sides = [t for t in (left[-1:], right[:1]) if t.size]
            if not sides:
                continue
            a, b = int(sides[0][0]), int(sides[-1][0])
            top = _extremum(prof, int(i), half)
            base = float(np.mean([_extremum(prof, t, half) for t in (a, b)]))
            rec["sides"].append(len(sides))
            rec["profile"].append(p)
            rec["x_um"].append(pts[i, 0])
            rec["y_um"].append(pts[i, 1])
            rec["offset_um"].append(float(sp[i]))
            rec["height_um"].append(top - base)
            rec["width_um"].append(float(sp[b] - sp[a]) if len(sides) == 2 else float("nan"))
    crests = {
        k: np.asarray(v, np.int64 if k in ("profile", "sides") else np.float64)
        for k, v in rec.items()
    }
    troughs = {k: np.asarray(v, np.int64 if k == "profile" else np.float64) for k, v in low.items()}
    folds = _group_folds(crests, wavelength_um, min_profiles)
    profiles = [entry for _, _, entry in sorted(profiles, key=lambda e: -e[1])]
    return FoldTable(crests=crests, folds=folds, profiles=profiles, normal=normal, troughs=troughs)


def _group_folds(crests: dict, wavelength_um: float, min_profiles: int) -> dict:
    keys = ("fold", "offset_um", "x_um", "y_um", "n_profiles", "height_um")
    out: dict[str, list] = {k: [] for k in (*keys, "height_max_um", "width_um")}
    u = crests["offset_um"]
    if u.size:
        order = np.argsort(u)
        breaks = np.flatnonzero(np.diff(u[order]) > wavelength_um / 3) + 1
        for group in np.split(order, breaks):
            n = len(np.unique(crests["profile"][group]))
            if n < min_profiles:
                continue
            two = group[crests["sides"][group] == 2]
            if len(np.unique(crests["profile"][two])) >= min_profiles:
                group = two  # prefer crests with a trough on both sides
            hgt = crests["height_um"][group]
            out["fold"].append(len(out["fold"]))
            out["offset_um"].append(float(np.mean(u[group])))
            out["x_um"].append(float(np.mean(crests["x_um"][group])))
            out["y_um"].append(float(np.mean(crests["y_um"][group])))
            out["n_profiles"].append(n)
            out["height_um"].append(float(np.median(hgt)))
            out["height_max_um"].append(float(np.max(hgt)))
            widths = crests["width_um"][group]
            widths = widths[np.isfinite(widths)]
            out["width_um"].append(float(np.median(widths)) if widths.size else float("nan"))
    return {
        k: np.asarray(v, np.int64 if k in ("fold", "n_profiles") else np.float64)
        for k, v in out.items()
    }


def _fold_form(
    height: np.ndarray,
    *,
    spacing: tuple[float, float],
    mask: np.ndarray | None,
    wavevector: np.ndarray,
    max_size: int = 128,
) -> tuple[Callable[[int, int], np.ndarray], float]:
    """The plane of a joint least-squares fit of a plane and the dominant fold wave.

    A plane fitted alone to a field of view holding a fraction of a fold
    period takes up part of the folds (a crest on one side tilts it), which
    biases the height of a fold seen from one side.  Fitting it together
    with ``cos`` and ``sin`` of ``2 pi k . r`` leaves the folds to the wave;
    the wave's length is refined from ``1 / |wavevector|`` by minimizing the
    fit's residual over 0.7..1.4 times ``|k|`` (on the map averaged to at
    most ``max_size`` pixels a side), which also corrects the periodogram's
    bias when few periods are in view.

    Returns
    -------
    plane : callable
        ``plane(a, b)``: rows ``a:b`` of the fitted plane alone (um), to subtract.
    wavelength_um : float
        The refined wavelength.
    """
    from scipy.optimize import minimize_scalar

    h = np.asarray(height, np.float64)
    k0 = np.asarray(wavevector, np.float64)

    def design(y: np.ndarray, x: np.ndarray, k: np.ndarray) -> np.ndarray:
        yy, xx = np.meshgrid(y, x, indexing="ij")
        phase = 2 * np.pi * (k[0] * xx + k[1] * yy)
        return np.stack([np.ones_like(xx), xx, yy, np.cos(phase), np.sin(phase)], -1).reshape(-1, 5)

    f = max(1, math.ceil(max(h.shape) / max_size))
    ny, nx = h.shape[0] // f, h.shape[1] // f
    small = np.empty((ny, nx))
    kept = np.empty((ny, nx), bool)
    step = max(1, BAND_ROWS // f)
    for a, b in _bands(ny, step):
        rows = slice(a * f, b * f)
        use = _mask_rows(mask, h, a * f, b * f)[:, : nx * f]
        values = np.where(use, h[rows, : nx * f], 0.0)
        small[a:b] = values.reshape(b - a, f, nx, f).mean(axis=(1, 3))
        kept[a:b] = use.reshape(b - a, f, nx, f).all(axis=(1, 3))
    keep = kept.ravel()
    if keep.sum() < 5:
        keep = np.ones(ny * nx, bool)
    values = small.ravel()[keep]
    ys, xs = _coords((ny, nx), (spacing[0] * f, spacing[1] * f))

    def residual(scale: float) -> float:
        basis = design(ys, xs, k0 * scale)[keep]
        coef, *_ = np.linalg.lstsq(basis, values, rcond=None)
        r = values - basis @ coef
        return float(r @ r)

    grid = np.linspace(0.7, 1.4, 29)
    i = int(np.argmin([residual(g) for g in grid]))
    lo, hi = grid[max(0, i - 1)], grid[min(grid.size - 1, i + 1)]
    scale = float(minimize_scalar(residual, bounds=(lo, hi), method="bounded").x)
    y, x = _coords(h.shape, spacing)
    # the fit on the whole map, in coordinates scaled to about [-1, 1] (the wave's phase
    # from the unscaled ones)
    ry, rx = max(np.abs(y).max(), 1e-300), max(np.abs(x).max(), 1e-300)
    k = k0 * scale

    def columns(a: int, b: int) -> np.ndarray:
        basis = design(y[a:b], x, k)
        basis[:, 1] /= rx
        basis[:, 2] /= ry
        return basis

    coef = _least_squares(columns, h, mask, 5)

    def plane(a: int, b: int) -> np.ndarray:
        return coef[0] + coef[1] * (x / rx)[None, :] + coef[2] * (y[a:b] / ry)[:, None]

    return plane, float(1.0 / np.hypot(*k))


def _trough_plane(
    troughs: dict,
    *,
    shape: tuple[int, int],
    spacing: tuple[float, float],
    normal: np.ndarray,
    wavelength_um: float,
) -> Callable[[int, int], np.ndarray | float]:
    """The plane through the fold troughs: the base the folds rise from.

    With troughs on lines at least half a wavelength apart across the folds
    the plane is fitted in full; with one trough line only its tilt along the
    crests is fitted (the tilt across the folds cannot be told from the
    height differences between folds), and with fewer than three troughs
    there is no plane (zeros).

    Returns ``plane(r0, r1)``: rows ``r0:r1`` of the plane (um).
    """
    ny, nx = shape
    dy, dx = spacing
    x, y, hgt = (np.asarray(troughs.get(k, ()), np.float64) for k in ("x_um", "y_um", "height_um"))
    if hgt.size < 3:
        return lambda r0, r1: 0.0
    centre = np.array([(nx - 1) * dx / 2, (ny - 1) * dy / 2])
    along = np.array([normal[1], -normal[0]])

    def coords(px: np.ndarray, py: np.ndarray):
        return (px - centre[0]) * along[0] + (py - centre[1]) * along[1], (
            (px - centre[0]) * normal[0] + (py - centre[1]) * normal[1]
        )

    a, u = coords(x, y)
    terms = [np.ones_like(a), a]
    if np.ptp(u) >= wavelength_um / 2:
        terms.append(u)
    coef, *_ = np.linalg.lstsq(np.stack(terms, 1), hgt, rcond=None)
    xs = np.arange(nx) * dx

    def plane(r0: int, r1: int) -> np.ndarray:
        yy, xx = np.meshgrid(np.arange(r0, r1) * dy, xs, indexing="ij")
        ga, gu = coords(xx, yy)
        return coef[0] + coef[1] * ga + (coef[2] * gu if len(coef) > 2 else 0.0)

    return plane


def fold_metrics(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    mask: np.ndarray | None = None,
    min_fold_height_um: float | None = None,
    resolution_um: float = 0.0,
    min_folds_in_view: float = 2.0,
    profile_spacing_um: float | None = None,
    fit_fraction: float = 0.1,
    overwrite: bool = False,
) -> tuple[dict, FoldSpectrum, FoldTable]:
    """Every fold and roughness metric of a height map, in one dictionary.

    Form removal (least-squares plane), then :func:`roughness`,
    :func:`fold_spectrum`, :func:`fold_orientation` and
    :func:`fold_profiles`.

    Folds must stand out: by default at least a fifth of the map's height
    range and at least three times ``resolution_um`` (pass the z-step), so
    a flat or tilted surface, whose height map holds only noise and the
    z-step staircase, has no folds.  When no fold is found the fold
    wavelength and heights are None; the roughness parameters are always
    given.

    Fold heights are measured however few folds are in view.  A field that
    holds part of a fold period tilts a least-squares plane (a crest on one
    side lifts it), which would bias the height of a fold seen from one side
    only, so before the profiles the form is removed twice: the plane of a
    joint fit of a plane and the dominant fold wave, then the plane through
    the troughs the profiles find (its tilt across the folds only when
    troughs lie on two lines or more).  The wavelength needs at least
    ``min_folds_in_view`` periods across the field (the periodogram's peak
    of fewer periods is biased long); with fewer it is None and
    ``fold_wavelength_note`` says how many periods were in view.

    ``overwrite=True`` lets the form-removed map take the place of ``height``
    (float64): the work is then done in the caller's array, with no map-sized copy.

    Returns
    -------
    metrics : dict
        ``fold_wavelength_um`` (None with fewer than ``min_folds_in_view``
        periods in view), ``fold_wavelength_note`` (why it is None, else
        None), ``fold_periods_in_view`` (the field's extent across the
        folds over the fitted fold wave's length), ``fold_height_um``
        (median over folds of their median crest-to-trough height),
        ``max_fold_height_um`` (the highest fold's median height),
        ``n_folds``, ``fold_orientation_deg`` (structure tensor),
        ``fold_coherency``, ``spectral_orientation_deg``,
        ``spectral_peak_fraction`` and the ISO 25178 parameters of
        :func:`roughness`.
    spectrum : FoldSpectrum
    folds : FoldTable
    """
    # one work map: the height with its form removed, in place of the height when the caller
    # gives it up (``overwrite``); the steps' other copies are a band's (see BAND_ROWS)
    h = np.asarray(height)
    own = overwrite and h.dtype == np.float64 and h.flags.writeable
    z = detrend(h, spacing=spacing, mask=mask, out=h if own else None)
    dy, dx = _lateral(spacing)
    metrics: dict[str, float | int | str | None] = {}
    rough = roughness(z, spacing=spacing, mask=mask)
    spectrum = fold_spectrum(z, spacing=spacing)
    orientation, coherency = fold_orientation(z, spacing=spacing, mask=mask)
    if min_fold_height_um is None:
        lo, hi = _quantiles(z, [1, 99])
        min_fold_height_um = max(0.2 * (hi - lo), 3.0 * float(resolution_um))
    form, wavelength = _fold_form(z, spacing=(dy, dx), mask=mask, wavevector=spectrum.wavevector)
    zf = z  # the form is removed in place: z is not needed after this
    for a, b in _bands(z.shape[0]):
        zf[a:b] -= form(a, b)
    options = {
        "spacing": spacing,
        "orientation_deg": orientation,
        "wavelength_um": wavelength,
        "min_fold_height_um": min_fold_height_um,
        "profile_spacing_um": profile_spacing_um,
        "fit_fraction": fit_fraction,
    }
    # the troughs that set the base plane: a coarser set of profiles finds them
    first = fold_profiles(zf, **{**options, "profile_spacing_um": wavelength / 4})
    base = _trough_plane(
        first.troughs,
        shape=z.shape,
        spacing=(dy, dx),
        normal=first.normal,
        wavelength_um=wavelength,
    )
    for a, b in _bands(zf.shape[0]):
        zf[a:b] -= base(a, b)
    table = fold_profiles(zf, **options)
    heights = table.folds["height_um"]
    theta = math.radians(orientation)
    across = abs(z.shape[1] * dx * math.sin(theta)) + abs(z.shape[0] * dy * math.cos(theta))
    periods = across / wavelength
    enough = periods >= min_folds_in_view
    metrics["fold_wavelength_um"] = spectrum.wavelength_um if enough and heights.size else None
    metrics["fold_wavelength_note"] = (
        None
        if metrics["fold_wavelength_um"] is not None
        else "no folds found"
        if not heights.size
        else f"not measured: about {periods:.1f} fold periods in view, "
        f"at least {min_folds_in_view:g} needed"
    )
    metrics["fold_periods_in_view"] = float(periods)
    metrics["fold_height_um"] = float(np.median(heights)) if heights.size else None
    metrics["max_fold_height_um"] = float(np.max(heights)) if heights.size else None
    metrics["n_folds"] = int(heights.size)
    metrics["min_fold_height_um"] = float(min_fold_height_um)
    metrics["fold_orientation_deg"] = orientation
    metrics["fold_coherency"] = coherency
    metrics["spectral_orientation_deg"] = spectrum.orientation_deg
    metrics["spectral_peak_fraction"] = spectrum.peak_fraction
    metrics.update(rough)
    return metrics, spectrum, table
