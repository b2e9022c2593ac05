"""Synthetic multiphoton (MPM) z-stacks of a folded bladder lumen, with exact ground truth.

Geometry (a contract: the analysis is written against it)
---------------------------------------------------------
* A stack is ``(Z, C, Y, X)`` uint16 with ``spacing = (dz, dy, dx)`` in
  micrometres.  Slice ``k`` lies at depth ``z = k * dz`` (slice 0 is nearest
  the objective); pixel (row ``i``, column ``j``) has its centre at
  ``y = i * dy``, ``x = j * dx``.
* The lumen (empty, dark) lies above the tissue: the tissue fills
  ``z >= D(y, x)``, where ``depth_um = D`` (Y, X) is the surface depth.  The
  surface height ``height_um = (Z - 1) * dz - depth_um`` is the elevation
  above the deepest slice centre, so fold crests have large heights (small
  depths).
* A direction at angle ``theta`` (degrees) is the vector
  ``(cos theta, sin theta)`` in ``(x, y)`` = (column, row) coordinates.  A fold
  orientation is the direction of its crests, in [0, 180).

Channel 0 is collagen (second-harmonic generation: a fibrous texture below the
urothelium, fading with depth into the tissue), channel 1 the urothelium
(autofluorescence: a thin bright layer starting at the surface).

The pipeline is a chain of small seeded steps: fold height field
(:func:`fold_height_field`) -> surface depth -> per-slice intensities whose
axial blur is analytic -> lateral blur -> attenuation with depth ->
Poisson-Gaussian noise (:func:`render_stack`).  :func:`make_stack_case`
chains them for two cases:

======  ==========================  ==========  ===========  =========
case    folds                       wavelength  fold height  roughness
======  ==========================  ==========  ===========  =========
before  small longitudinal rugae    200 um      80-120 um    4 um RMS
after   contracted: large folds     450 um      650-900 um   8 um RMS
======  ==========================  ==========  ===========  =========

:func:`write_stack` writes ImageJ hyperstacks or OME-TIFF, and
:func:`save_stack_truth` the ground truth beside them.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from scipy import fft, ndimage, special

from sample_data_synth._common import Rng
from sample_data_synth._common import non_negative as _non_negative
from sample_data_synth._common import positive as _positive
from sample_data_synth._common import spawn as _spawn
from sample_data_synth._common import version as _version
from tissue_core.jsonio import write_json
from tissue_core.outputs import replaced_on_success

__all__ = [
    "STACK_CASES",
    "SyntheticStack",
    "fold_height_field",
    "make_stack_case",
    "render_stack",
    "save_stack_truth",
    "write_stack",
    "write_stack_tiles",
]

#: channel names of every rendered stack, in channel order
CHANNEL_NAMES: tuple[str, str] = ("collagen", "urothelium")

StackFormat = Literal["imagej", "ome"]

CONVENTIONS = {
    "array": "stack is (Z, C, Y, X) uint16; spacing is (dz, dy, dx) in um",
    "depth": "slice k lies at depth z = k * dz; slice 0 is nearest the objective",
    "pixels": "pixel (row i, column j) has its centre at y = i * dy, x = j * dx",
    "surface": "tissue fills z >= depth_um(y, x); the lumen above it is empty",
    "height": "height_um = (Z - 1) * dz - depth_um (elevation above the deepest slice)",
    "angles": "angle theta is the direction (cos theta, sin theta) in (x, y) = (column, row)",
    "orientation": "fold orientation is the direction of the crests, in [0, 180) degrees",
    "fold_height": "crest-to-trough height of a fold, roughness excluded",
}


def _spacing(spacing: Sequence[float], n: int, name: str) -> tuple[float, ...]:
    values = tuple(float(s) for s in np.atleast_1d(np.asarray(spacing, dtype=float)))
    if len(values) != n or not all(math.isfinite(s) and s > 0 for s in values):
        raise ValueError(f"{name} must be {n} finite numbers > 0 (um), got {spacing!r}")
    return values


# --------------------------------------------------------------------------- height field


def fold_height_field(
    shape_yx: tuple[int, int],
    spacing_yx: tuple[float, float],
    *,
    wavelength_um: float,
    orientation_deg: float,
    fold_heights_um: float | Sequence[float] | None = None,
    fold_height_range_um: tuple[float, float] | None = None,
    phase_um: float = 0.0,
    roughness_um: float = 0.0,
    roughness_wavelength_um: float = 30.0,
    rng: Rng = None,
) -> tuple[np.ndarray, dict]:
    """Height of a folded surface: parallel folds of individual heights plus roughness.

    Let ``n = (-sin theta, cos theta)`` be the normal to the crests and
    ``u = (x - xc, y - yc) . n`` the distance across the folds from the image
    centre ``(xc, yc) = ((X - 1) dx / 2, (Y - 1) dy / 2)``.  Fold ``k`` (any
    integer) has its crest at ``u_k = phase_um + k * wavelength_um`` with
    height ``c_k`` and its troughs at ``u_k +- wavelength_um / 2`` with height
    0; every point belongs to its nearest crest and lies on the half-cosine

        h = c_k (1 + cos(pi s)) / 2,   s = |u - u_k| / (wavelength_um / 2) in [0, 1],

    so the surface is C1, every trough is exactly 0 and fold ``k``'s
    crest-to-trough height is exactly ``c_k``.  With equal heights this is the
    sinusoid ``c (1 + cos(2 pi (u - phase_um) / wavelength_um)) / 2``.

    Parameters
    ----------
    shape_yx : (Y, X) int
        Grid shape, at least 2 x 2.
    spacing_yx : (dy, dx) float
        Pixel spacing in um.
    wavelength_um : float, keyword-only
        Distance between neighbouring crests.
    orientation_deg : float, keyword-only
        Direction of the crests in degrees (see the module docstring); reduced
        modulo 180.
    fold_heights_um : float or sequence of float, keyword-only
        Crest heights ``c_k`` given explicitly, cycled: fold ``k`` gets
        ``fold_heights_um[k % len(fold_heights_um)]``, so fold 0 (the crest at
        ``u = phase_um``, the one through the image centre when ``phase_um``
        is 0) gets the first value, fold 1 (one wavelength along ``n``) the
        second and fold -1 the last.  A single number gives equal folds.
    fold_height_range_um : (lo, hi) float, keyword-only
        Instead of ``fold_heights_um``: each fold's ``c_k`` is drawn
        uniformly from [lo, hi) from a stream of its own derived from ``rng``
        and ``k``, so a fold keeps its height when the grid changes size.
        Give exactly one of the two.
    phase_um : float, keyword-only
        Offset ``u_0`` of crest 0 from the image centre along ``n``.
    roughness_um : float, keyword-only
        RMS of added isotropic roughness (random rugae, small bumps): white
        noise low-pass filtered by a Gaussian of standard deviation
        ``roughness_wavelength_um / 2`` (periodic boundaries), so its
        autocorrelation is ``exp(-r^2 / roughness_wavelength_um^2)``; then
        shifted and scaled to mean 0 and RMS exactly ``roughness_um`` over the
        grid.  0 gives the exact fold profile.
    roughness_wavelength_um : float, keyword-only
        Correlation length of the roughness.
    rng : int, Generator or None, keyword-only
        Seed for the fold heights and the roughness.

    Returns
    -------
    height : (Y, X) float64
        Surface height in um (troughs at 0 before roughness is added).
    info : dict
        JSON-serializable: ``wavelength_um``, ``orientation_deg``, ``phase_um``,
        ``normal_xy`` (n), ``center_xy_um`` (xc, yc), ``fold_heights`` (how
        they were chosen), ``folds`` (one dict per fold reaching the grid:
        ``index`` k, ``crest_offset_um`` u_k, ``crest_height_um`` c_k,
        ``in_view``: whether the crest line crosses the grid's rectangle of
        pixel centres), ``n_folds_in_view``, ``median_fold_height_um`` and
        ``max_fold_height_um`` (of c_k over the folds in view; None when no
        crest crosses the grid), ``roughness_um`` and
        ``roughness_wavelength_um``.

    Examples
    --------
    >>> h, info = fold_height_field(
    ...     (5, 9), (1.0, 1.0), wavelength_um=4.0, orientation_deg=90.0, fold_heights_um=[2.0]
    ... )
    >>> np.round(h[0], 6).tolist()
    [2.0, 1.0, 0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0]
    >>> info["median_fold_height_um"], info["n_folds_in_view"]
    (2.0, 3)
    """
    shape = tuple(int(s) for s in shape_yx)
    if len(shape) != 2 or min(shape) < 2:
        raise ValueError(f"shape_yx must be two integers >= 2, got {shape_yx!r}")
    ny, nx = shape
    dy, dx = _spacing(spacing_yx, 2, "spacing_yx")
    wavelength = _positive(wavelength_um, "wavelength_um")
    theta = float(orientation_deg)
    if not math.isfinite(theta):
        raise ValueError(f"orientation_deg must be finite, got {orientation_deg}")
    theta %= 180.0
    phase = float(phase_um)
    if not math.isfinite(phase):
        raise ValueError(f"phase_um must be finite, got {phase_um}")
    roughness = _non_negative(roughness_um, "roughness_um")
    corr = _positive(roughness_wavelength_um, "roughness_wavelength_um")
    if (fold_heights_um is None) == (fold_height_range_um is None):
        raise ValueError("give exactly one of fold_heights_um and fold_height_range_um")
    fold_rng, rough_rng = _spawn(rng, 2)

    rad = math.radians(theta)
    normal = (-math.sin(rad), math.cos(rad))
    center = ((nx - 1) * dx / 2, (ny - 1) * dy / 2)
    x = np.arange(nx) * dx - center[0]
    y = np.arange(ny) * dy - center[1]
    u = x[None, :] * normal[0] + y[:, None] * normal[1]
    u_min, u_max = float(u.min()), float(u.max())
    k = np.rint((u - phase) / wavelength).astype(np.int64)
    k_lo, k_hi = int(k.min()), int(k.max())
    ks = np.arange(k_lo, k_hi + 1)

    if fold_heights_um is not None:
        values = np.atleast_1d(np.asarray(fold_heights_um, dtype=float))
        if values.ndim != 1 or values.size == 0 or not np.all(np.isfinite(values) & (values >= 0)):
            raise ValueError(
                f"fold_heights_um must be a number or a sequence of numbers >= 0, "
                f"got {fold_heights_um!r}"
            )
        crest = values[ks % values.size]
        how = {"mode": "cycled", "values_um": values.tolist()}
    else:
        lo, hi = _fold_range(fold_height_range_um, "fold_height_range_um")
        base = int(fold_rng.integers(2**63))
        crest = np.array(  # fold k's own stream (k >= 0 -> 2k, k < 0 -> -2k - 1)
            [
                np.random.default_rng([base, 2 * k if k >= 0 else -2 * k - 1]).uniform(lo, hi)
                for k in ks
            ]
        )
        how = {"mode": "uniform", "range_um": [lo, hi]}

    s = np.minimum(np.abs(u - phase - k * wavelength) / (wavelength / 2), 1.0)
    height = crest[k - k_lo] * (0.5 + 0.5 * np.cos(np.pi * s))

    if roughness > 0:
        noise = rough_rng.standard_normal(shape)
        noise = ndimage.gaussian_filter(noise, (corr / 2 / dy, corr / 2 / dx), mode="wrap")
        noise -= noise.mean()
        rms = float(np.sqrt(np.mean(noise**2)))
        if rms > 0:
            height += noise * (roughness / rms)

    offsets = phase + ks * wavelength
    in_view = (offsets >= u_min) & (offsets <= u_max)
    folds = [
        {
            "index": int(kk),
            "crest_offset_um": float(off),
            "crest_height_um": float(c),
            "in_view": bool(v),
        }
        for kk, off, c, v in zip(ks, offsets, crest, in_view, strict=True)
    ]
    seen = crest[in_view]
    info = {
        "wavelength_um": wavelength,
        "orientation_deg": theta,
        "phase_um": phase,
        "normal_xy": list(normal),
        "center_xy_um": list(center),
        "fold_heights": how,
        "folds": folds,
        "n_folds_in_view": int(seen.size),
        "median_fold_height_um": float(np.median(seen)) if seen.size else None,
        "max_fold_height_um": float(seen.max()) if seen.size else None,
        "roughness_um": roughness,
        "roughness_wavelength_um": corr,
    }
    return height, info


def _fold_range(value, name: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (lo, hi) of numbers, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo <= hi):
        raise ValueError(f"{name} must satisfy 0 <= lo <= hi, got {value!r}")
    return lo, hi


# --------------------------------------------------------------------------- rendering


def _fibre_layer(
    rng: np.random.Generator,
    shape: tuple[int, int],
    ky: np.ndarray,
    kx: np.ndarray,
    sigma_along: float,
    sigma_across: float,
    n_families: int = 3,
) -> np.ndarray:
    """One plane of fibre texture: Gaussian noise, zero mean and unit variance, whose
    power spectrum is the sum of ``n_families`` elongated Gaussians of random
    directions (independent fibre families crossing), ``(Y, X)`` float32."""
    power = np.zeros((ky.size, kx.size), dtype=np.float32)
    for angle in rng.uniform(0, np.pi, n_families):
        c, s = np.float32(np.cos(angle)), np.float32(np.sin(angle))
        k_along = kx * c + ky * s
        k_across = ky * c - kx * s
        power += np.exp(
            np.float32(-4 * np.pi**2)
            * (sigma_along**2 * k_along**2 + sigma_across**2 * k_across**2)
        )
    white = rng.standard_normal(shape, dtype=np.float32)
    g = fft.irfft2(fft.rfft2(white) * np.sqrt(power), s=shape)
    g -= g.mean()
    std = g.std()
    return g / std if std > 0 else g


def _cell_texture(
    rng: np.random.Generator, shape: tuple[int, int], spacing_yx: tuple[float, float], size: float
) -> np.ndarray:
    """Isotropic Gaussian noise of correlation length ``size`` um, unit variance."""
    g = rng.standard_normal(shape, dtype=np.float32)
    g = ndimage.gaussian_filter(
        g, (size / 2 / spacing_yx[0], size / 2 / spacing_yx[1]), mode="wrap"
    )
    g -= g.mean()
    std = g.std()
    return g / std if std > 0 else g


def render_stack(
    depth_um: np.ndarray,
    *,
    n_slices: int,
    spacing: tuple[float, float, float],
    urothelium_thickness_um: float = 15.0,
    urothelium_intensity: float = 2500.0,
    urothelium_contrast: float = 0.15,
    cell_size_um: float = 10.0,
    collagen_intensity: float = 2000.0,
    collagen_decay_um: float = 150.0,
    fibre_length_um: float = 30.0,
    fibre_width_um: float = 3.0,
    fibre_layer_um: float = 6.0,
    axial_sigma_um: float = 3.0,
    lateral_sigma_um: float = 1.0,
    attenuation_um: float = 3000.0,
    background: float = 100.0,
    shot_gain: float = 8.0,
    read_noise: float = 4.0,
    rng: Rng = None,
    out: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
    cell_texture: np.ndarray | None = None,
) -> np.ndarray:
    """Render a two-channel MPM z-stack of tissue below a surface of known depth.

    With ``d = z - D(y, x)`` the depth below the surface of a voxel at depth
    ``z`` and ``t(y, x) = urothelium_thickness_um * sqrt(1 + |grad D|^2)`` the
    layer's vertical thickness (its thickness normal to the surface is
    constant), the noise-free signals before the lateral blur are

    * urothelium (channel 1):
      ``I_u (1 + urothelium_contrast * q(y, x)) [Phi(d / sz) - Phi((d - t) / sz)]``,
      a layer from the surface to ``t`` below it convolved exactly with the
      Gaussian axial point-spread function of standard deviation ``sz``:
      ``Phi`` is the normal CDF, so the layer's top edge reaches 50 % of its
      plateau on the true surface.  ``q`` is a unit-variance cell-sized texture
      constant along z.
    * collagen (channel 0): ``I_c f(x, y, z) E(d - t)``, fibres ``f`` filling
      the tissue below the urothelium with the envelope ``exp(-e / L)`` for
      ``e >= 0`` (``L = collagen_decay_um``) convolved exactly along z with the
      same PSF: ``E(e) = exp(-e / L + sz^2 / (2 L^2)) Phi(e / sz - sz / L)``.
      ``f = max(g, 0) / 2`` with ``g`` unit-variance Gaussian noise filtered
      anisotropically (three crossing fibre families per plane, random
      directions); planes of independent ``g`` every ``fibre_layer_um`` in z are
      blended with variance-preserving weights ``cos``, ``sin`` of
      ``pi w / 2``, so ``f = 1`` (``I_c``) is a fibre at two standard
      deviations of the texture and the brightest fibres reach about ``2.5 I_c``.

    Both are multiplied by ``exp(-z / attenuation_um)`` (absolute depth),
    blurred laterally by a Gaussian of ``lateral_sigma_um``, then photon
    (shot) noise ``shot_gain * Poisson(S / shot_gain)``, the ``background``
    offset and Gaussian read noise are added, and the result is rounded and
    clipped to uint16.  The stack is computed slice by slice in float32 into
    the preallocated output.

    Parameters
    ----------
    depth_um : (Y, X) float
        Surface depth ``D`` in um (see the module docstring), Y, X >= 2.
    n_slices : int, keyword-only
        Number of slices Z.
    spacing : (dz, dy, dx) float, keyword-only
        Voxel spacing in um.
    urothelium_thickness_um : float, keyword-only
        Layer thickness normal to the surface.
    urothelium_intensity, collagen_intensity : float, keyword-only
        ``I_u`` and ``I_c`` in counts above the background.
    urothelium_contrast : float, keyword-only
        Relative standard deviation of the urothelium's cell texture, < 1.
    cell_size_um : float, keyword-only
        Correlation length of the cell texture.
    collagen_decay_um : float, keyword-only
        ``L``: the collagen signal's decay length below the urothelium.
    fibre_length_um, fibre_width_um : float, keyword-only
        Full widths at half maximum of the fibre texture's autocorrelation
        along and across the fibres.
    fibre_layer_um : float, keyword-only
        Distance in z between independent texture planes.
    axial_sigma_um, lateral_sigma_um : float, keyword-only
        Standard deviations of the Gaussian point-spread function (``sz``
        along z; laterally 0 gives no lateral blur).
    attenuation_um : float, keyword-only
        Decay length of both signals with absolute depth ``z``.
    background : float, keyword-only
        Offset in counts added to every voxel.
    shot_gain : float, keyword-only
        Counts per detected photon; 0 gives no shot noise.
    read_noise : float, keyword-only
        Standard deviation of Gaussian read noise in counts; 0 gives none.
        ``shot_gain=0, read_noise=0`` render the noise-free stack (only
        rounded).
    rng : int, Generator or None, keyword-only
        Seed.  The texture and the noise use separate streams, so the noisy and
        the noise-free renders of one seed show the same tissue.
    out : (Z, 2, Y, X) uint16 array, keyword-only
        Write into this array (e.g. a memory map) instead of a new one.
    progress : callable(done, total), keyword-only
        Called after every slice.
    cell_texture : (Y, X) array, keyword-only
        The urothelium's texture ``q`` itself (scaled here to zero mean and
        unit variance) in place of the random cells: a pattern the tissue's
        surface also shows to a camera.  The other streams of ``rng`` are
        drawn as without it.

    Returns
    -------
    stack : (Z, 2, Y, X) uint16
        Channel 0 collagen, channel 1 urothelium.
    """
    depth = np.asarray(depth_um, dtype=np.float64)
    if depth.ndim != 2 or min(depth.shape) < 2 or not np.all(np.isfinite(depth)):
        raise ValueError(f"depth_um must be a finite (Y, X) array, Y, X >= 2; got {depth.shape}")
    n_z = int(n_slices)
    if n_z < 1 or n_z != n_slices:
        raise ValueError(f"n_slices must be an integer >= 1, got {n_slices}")
    dz, dy, dx = _spacing(spacing, 3, "spacing")
    thickness = _positive(urothelium_thickness_um, "urothelium_thickness_um")
    i_u = _non_negative(urothelium_intensity, "urothelium_intensity")
    i_c = _non_negative(collagen_intensity, "collagen_intensity")
    contrast = _non_negative(urothelium_contrast, "urothelium_contrast")
    if contrast >= 1:
        raise ValueError(f"urothelium_contrast must be < 1, got {contrast}")
    cell = _positive(cell_size_um, "cell_size_um")
    decay = _positive(collagen_decay_um, "collagen_decay_um")
    fibre_len = _positive(fibre_length_um, "fibre_length_um")
    fibre_wid = _positive(fibre_width_um, "fibre_width_um")
    layer = _positive(fibre_layer_um, "fibre_layer_um")
    sz = _positive(axial_sigma_um, "axial_sigma_um")
    sl = _non_negative(lateral_sigma_um, "lateral_sigma_um")
    att_len = _positive(attenuation_um, "attenuation_um")
    offset = _non_negative(background, "background")
    gain = _non_negative(shot_gain, "shot_gain")
    read = _non_negative(read_noise, "read_noise")
    shape = depth.shape
    if out is None:
        out = np.empty((n_z, 2, *shape), dtype=np.uint16)
    elif out.shape != (n_z, 2, *shape) or out.dtype != np.uint16:
        raise ValueError(f"out must be a uint16 array of shape {(n_z, 2, *shape)}")

    texture_rng, noise_rng = _spawn(rng, 2)
    cell_rng, fibre_rng = texture_rng.spawn(2)
    fibre_seed = int(fibre_rng.integers(2**63))

    gy, gx = np.gradient(depth, dy, dx)
    depth32 = depth.astype(np.float32)
    t_vert = (thickness * np.sqrt(1 + gx**2 + gy**2)).astype(np.float32)
    del gy, gx
    if cell_texture is None:
        cells = _cell_texture(cell_rng, shape, (dy, dx), cell)
    else:
        given = np.asarray(cell_texture, dtype=np.float64)
        if given.shape != shape or not np.isfinite(given).all() or not given.std() > 0:
            raise ValueError(f"cell_texture must be a finite, non-uniform {shape} array")
        cells = ((given - given.mean()) / given.std()).astype(np.float32)
    uro_amp = np.float32(i_u) * np.maximum(1 + np.float32(contrast) * cells, 0)
    del cells
    collagen_top = depth32 + t_vert  # where the collagen envelope starts
    reach = 8 * sz  # Phi(-8) ~ 6e-16: no signal further above an edge
    first_uro = float(depth32.min()) - reach
    first_col = float(collagen_top.min()) - reach

    fwhm = 4 * math.sqrt(math.log(2))  # autocorrelation FWHM of Gaussian-filtered noise / sigma
    ky = fft.fftfreq(shape[0], dy).astype(np.float32)[:, None]
    kx = fft.rfftfreq(shape[1], dx).astype(np.float32)[None, :]
    layers: dict[int, np.ndarray] = {}

    def fibre_plane(j: int) -> np.ndarray:
        if j not in layers:
            for old in [i for i in layers if i < j - 1]:
                del layers[old]
            layers[j] = _fibre_layer(
                np.random.default_rng([fibre_seed, j]),
                shape,
                ky,
                kx,
                fibre_len / fwhm,
                fibre_wid / fwhm,
            )
        return layers[j]

    lateral = (sl / dy, sl / dx)
    inv_sz = np.float32(1 / sz)
    sz_over_l = np.float32(sz / decay)
    e_shift = np.float32(sz**2 / (2 * decay**2))
    for z_index in range(n_z):
        z = z_index * dz
        attenuation = np.float32(math.exp(-z / att_len))
        for channel, first in ((1, first_uro), (0, first_col)):
            if z < first or (i_u if channel == 1 else i_c) == 0:
                signal = np.zeros(shape, dtype=np.float32)
            elif channel == 1:
                d = np.float32(z) - depth32
                signal = special.ndtr(d * inv_sz)
                d -= t_vert
                signal -= special.ndtr(d * inv_sz)
                signal *= uro_amp
            else:
                e = np.maximum(np.float32(z) - collagen_top, np.float32(-reach))
                signal = special.ndtr(e * inv_sz - sz_over_l)
                e *= np.float32(-1 / decay)
                e += e_shift
                signal *= np.exp(e)
                w = (z / layer) % 1.0
                j = int(z // layer)
                g = fibre_plane(j) * np.float32(math.cos(np.pi * w / 2))
                g += fibre_plane(j + 1) * np.float32(math.sin(np.pi * w / 2))
                np.maximum(g, 0, out=g)
                signal *= g
                signal *= np.float32(i_c / 2)
            if signal.any():
                signal *= attenuation
                if sl > 0:
                    signal = ndimage.gaussian_filter(signal, lateral, mode="nearest")
            _add_noise(signal, gain, read, offset, noise_rng)
            out[z_index, channel] = signal
        if progress:
            progress(z_index + 1, n_z)
    return out


def _add_noise(
    signal: np.ndarray, gain: float, read: float, offset: float, rng: np.random.Generator
) -> None:
    """Shot noise, offset and read noise in place, then round and clip to uint16 range."""
    if gain > 0:
        np.maximum(signal, 0, out=signal)
        signal[...] = rng.poisson(signal / np.float32(gain))
        signal *= np.float32(gain)
    signal += np.float32(offset)
    if read > 0:
        signal += np.float32(read) * rng.standard_normal(signal.shape, dtype=np.float32)
    np.rint(signal, out=signal)
    np.clip(signal, 0, 65535, out=signal)


# --------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class _StackSpec:
    description: str
    wavelength_um: float
    fold_height_range_um: tuple[float, float]
    orientation_deg: float
    roughness_um: float
    roughness_wavelength_um: float


STACK_CASES: dict[str, _StackSpec] = {
    "before": _StackSpec(
        "MPM z-stack, relaxed bladder: small longitudinal rugae (wavelength 200 um, "
        "folds 80-120 um high, crests at 85 deg, roughness 4 um RMS)",
        200.0,
        (80.0, 120.0),
        85.0,
        4.0,
        30.0,
    ),
    "after": _StackSpec(
        "MPM z-stack, contracted bladder: large folds (wavelength 450 um, "
        "folds 650-900 um high, crests at 80 deg, roughness 8 um RMS)",
        450.0,
        (650.0, 900.0),
        80.0,
        8.0,
        50.0,
    ),
}


@dataclass(repr=False)
class SyntheticStack:
    """A rendered z-stack and the exact surface it images.

    Attributes
    ----------
    name : str
        Case name.
    stack : (Z, 2, Y, X) uint16
        Channel 0 collagen, channel 1 urothelium.
    spacing : (dz, dy, dx) float
        Voxel spacing in um.
    depth_um : (Y, X) float64
        True surface depth ``D``: tissue fills ``z >= D``.
    height_um : (Y, X) float64
        ``(Z - 1) * dz - depth_um``.
    info : dict
        The fold geometry (see :func:`fold_height_field`) plus the surface
        placement (``crest_depth_um``, ``tissue_below_um``,
        ``surface_offset_um``: ``depth_um = surface_offset_um - h``).
    params : dict
        Case and rendering parameters.
    channel_names : (str, str)
    """

    name: str
    stack: np.ndarray
    spacing: tuple[float, float, float]
    depth_um: np.ndarray
    height_um: np.ndarray
    info: dict
    params: dict = field(default_factory=dict)
    channel_names: tuple[str, str] = CHANNEL_NAMES

    def __post_init__(self) -> None:
        self.spacing = _spacing(self.spacing, 3, "spacing")
        if self.stack.ndim != 4 or self.stack.shape[1] != len(self.channel_names):
            raise ValueError(
                f"stack must be (Z, {len(self.channel_names)}, Y, X), got {self.stack.shape}"
            )
        for name in ("depth_um", "height_um"):
            if getattr(self, name).shape != self.stack.shape[2:]:
                raise ValueError(
                    f"{name} must have shape {self.stack.shape[2:]}, "
                    f"got {getattr(self, name).shape}"
                )

    def __repr__(self) -> str:
        median = self.info.get("median_fold_height_um")
        folds = f"{self.info.get('n_folds_in_view', 0)} folds in view" + (
            f", median height {median:.1f} um" if median is not None else ""
        )
        return (
            f"SyntheticStack({self.name!r}, stack {self.stack.shape} {self.stack.dtype}, "
            f"spacing {self.spacing} um, {folds})"
        )


def make_stack_case(
    name: Literal["before", "after"],
    *,
    size: int | tuple[int, int] = 512,
    spacing: tuple[float, float, float] = (4.0, 2.5, 2.5),
    n_slices: int | None = None,
    wavelength_um: float | None = None,
    fold_height_range_um: tuple[float, float] | None = None,
    fold_heights_um: float | Sequence[float] | None = None,
    orientation_deg: float | None = None,
    phase_um: float = 0.0,
    roughness_um: float | None = None,
    roughness_wavelength_um: float | None = None,
    crest_depth_um: float = 40.0,
    tissue_below_um: float = 60.0,
    shot_gain: float = 8.0,
    read_noise: float = 4.0,
    rng: Rng = 0,
    progress: Callable[[int, int], None] | None = None,
) -> SyntheticStack:
    """Render the "before" (relaxed) or "after" (contracted) folded lumen.

    The surface is the case's fold field (:func:`fold_height_field`) placed so
    its highest point lies ``crest_depth_um`` below slice 0; the stack reaches
    at least ``tissue_below_um`` below its deepest point.

    Parameters
    ----------
    name : {"before", "after"}
        See :data:`STACK_CASES` and the module docstring.
    size : int or (Y, X), keyword-only
        Lateral size in pixels, at least 16.
    spacing : (dz, dy, dx), keyword-only
        Voxel spacing in um.
    n_slices : int, keyword-only
        Number of slices; None gives the fewest that fit.  A ValueError names
        the depth needed when the given number does not fit the folds.
    wavelength_um, fold_height_range_um, orientation_deg, roughness_um, roughness_wavelength_um
        Keyword-only overrides of the case's values (None keeps them).
    fold_heights_um : keyword-only
        Explicit, cycled crest heights instead of the case's range.
    phase_um : keyword-only
        See :func:`fold_height_field`.
    crest_depth_um, tissue_below_um : float, keyword-only
        Surface placement in the stack.
    shot_gain, read_noise : float, keyword-only
        See :func:`render_stack`; 0 and 0 give the noise-free stack.
    rng : int, Generator or None, keyword-only
        Seed for the fold heights, roughness, texture and noise.
    progress : callable(done, total), keyword-only
        Called after every slice.

    Returns
    -------
    SyntheticStack

    Examples
    --------
    >>> case = make_stack_case(
    ...     "before", size=16, spacing=(4.0, 5.0, 5.0), fold_heights_um=20.0, roughness_um=0.0
    ... )
    >>> case.stack.shape, case.stack.dtype.name
    ((28, 2, 16, 16), 'uint16')
    >>> round(float(case.depth_um.min()), 6), case.info["crest_depth_um"]
    (40.0, 40.0)
    """
    if name not in STACK_CASES:
        raise ValueError(f"unknown stack case {name!r}; choose from {', '.join(STACK_CASES)}")
    spec = STACK_CASES[name]
    sizes = (size, size) if np.ndim(size) == 0 else tuple(size)
    if len(sizes) != 2 or any(int(s) != s or s < 16 for s in sizes):
        raise ValueError(f"size must be an integer or (Y, X) integers >= 16, got {size!r}")
    shape = (int(sizes[0]), int(sizes[1]))
    dz, dy, dx = _spacing(spacing, 3, "spacing")
    crest_depth = _non_negative(crest_depth_um, "crest_depth_um")
    below = _non_negative(tissue_below_um, "tissue_below_um")
    if fold_heights_um is None and fold_height_range_um is None:
        fold_height_range_um = spec.fold_height_range_um
    if roughness_um is None:
        roughness_um = spec.roughness_um
    if roughness_wavelength_um is None:
        roughness_wavelength_um = spec.roughness_wavelength_um
    fold_rng, render_rng = _spawn(rng, 2)
    h, info = fold_height_field(
        shape,
        (dy, dx),
        wavelength_um=spec.wavelength_um if wavelength_um is None else wavelength_um,
        orientation_deg=spec.orientation_deg if orientation_deg is None else orientation_deg,
        fold_heights_um=fold_heights_um,
        fold_height_range_um=fold_height_range_um,
        phase_um=phase_um,
        roughness_um=roughness_um,
        roughness_wavelength_um=roughness_wavelength_um,
        rng=fold_rng,
    )
    surface_offset = crest_depth + float(h.max())
    depth = surface_offset - h
    needed = float(depth.max()) + below
    fit = math.ceil(needed / dz - 1e-9) + 1
    if n_slices is None:
        n_slices = fit
    elif int(n_slices) != n_slices or (n_slices - 1) * dz < needed - 1e-9:
        raise ValueError(
            f"n_slices={n_slices} at dz={dz} um reaches {(n_slices - 1) * dz:g} um, but the "
            f"folds need {needed:.1f} um (crests {crest_depth:g} um below slice 0, deepest "
            f"point {float(depth.max()):.1f} um, {below:g} um of tissue below it): "
            f"use n_slices >= {fit}"
        )
    n_slices = int(n_slices)
    info.update(
        crest_depth_um=crest_depth,
        tissue_below_um=below,
        surface_offset_um=surface_offset,
        deepest_surface_depth_um=float(depth.max()),
    )
    stack = render_stack(
        depth,
        n_slices=n_slices,
        spacing=(dz, dy, dx),
        shot_gain=shot_gain,
        read_noise=read_noise,
        rng=render_rng,
        progress=progress,
    )
    params = {
        "description": spec.description,
        "size_yx": list(shape),
        "n_slices": n_slices,
        "spacing_um": [dz, dy, dx],
        "seed": rng if isinstance(rng, int) else None,
        "shot_gain": float(shot_gain),
        "read_noise": float(read_noise),
        "render": "render_stack defaults otherwise",
    }
    return SyntheticStack(
        name=name,
        stack=stack,
        spacing=(dz, dy, dx),
        depth_um=depth,
        height_um=(n_slices - 1) * dz - depth,
        info=info,
        params=params,
    )


# --------------------------------------------------------------------------- files


def write_stack(
    path: str | os.PathLike, case: SyntheticStack, *, format: StackFormat = "imagej"
) -> None:
    """Write a stack as an ImageJ hyperstack or an OME-TIFF.

    Parameters
    ----------
    path : str or path
        Output file (conventionally ``.tif``, or ``.ome.tif`` for OME); it is
        replaced atomically.
    case : SyntheticStack
    format : {"imagej", "ome"}, keyword-only
        ``"imagej"``: axes ZCYX, ``spacing`` (dz) and ``unit`` "um" in the
        ImageJ description, pixels per um in the X/YResolution tags, composite
        display mode and each plane labelled with its channel name.
        ``"ome"``: OME-XML with ``PhysicalSizeX/Y/Z`` in um and the channel
        names.
    """
    import tifffile

    if format not in ("imagej", "ome"):
        raise ValueError(f"format must be 'imagej' or 'ome', got {format!r}")
    path = Path(path)
    dz, dy, dx = case.spacing
    names = list(case.channel_names)
    with replaced_on_success(path) as tmp:
        if format == "imagej":
            tifffile.imwrite(
                tmp,
                case.stack,
                imagej=True,
                resolution=(1 / dx, 1 / dy),
                metadata={
                    "axes": "ZCYX",
                    "spacing": dz,
                    "unit": "um",
                    "mode": "composite",
                    "Labels": names * case.stack.shape[0],
                },
            )
        else:
            tifffile.imwrite(
                tmp,
                case.stack,
                ome=True,
                photometric="minisblack",
                metadata={
                    "axes": "ZCYX",
                    "PhysicalSizeX": dx,
                    "PhysicalSizeXUnit": "µm",
                    "PhysicalSizeY": dy,
                    "PhysicalSizeYUnit": "µm",
                    "PhysicalSizeZ": dz,
                    "PhysicalSizeZUnit": "µm",
                    "Channel": {"Name": names},
                },
            )


def save_stack_truth(prefix: str | os.PathLike, case: SyntheticStack) -> None:
    """Write ``PREFIX_truth.json`` and ``PREFIX_truth.npz`` beside a stack.

    The JSON holds the geometry conventions, shape, spacing, channel names,
    wavelength, orientation, the per-fold table, the median and max fold
    height over the folds in view, the case parameters and the software
    version; the npz holds ``depth_um`` and ``height_um`` ((Y, X) float32).
    """
    prefix = Path(prefix)
    info = case.info
    truth = {
        "case": case.name,
        "description": case.params.get("description", ""),
        "shape_zcyx": list(case.stack.shape),
        "spacing_um": list(case.spacing),
        "spacing_order": "dz, dy, dx",
        "channel_names": list(case.channel_names),
        "wavelength_um": info["wavelength_um"],
        "orientation_deg": info["orientation_deg"],
        "n_folds_in_view": info["n_folds_in_view"],
        "median_fold_height_um": info["median_fold_height_um"],
        "max_fold_height_um": info["max_fold_height_um"],
        "folds": info["folds"],
        "surface": info,
        "conventions": CONVENTIONS,
        "params": case.params,
        "software": {"sample_data_synth": _version()},
    }
    json_path = prefix.with_name(prefix.name + "_truth.json")
    with replaced_on_success(json_path) as tmp:
        write_json(tmp, truth)
    with replaced_on_success(prefix.with_name(prefix.name + "_truth.npz")) as tmp:
        with open(tmp, "wb") as f:
            np.savez_compressed(
                f,
                depth_um=case.depth_um.astype(np.float32),
                height_um=case.height_um.astype(np.float32),
            )


def write_stack_tiles(
    folder: str | os.PathLike,
    case: SyntheticStack,
    *,
    tiles: tuple[int, int] = (3, 3),
    overlap: float = 0.1,
    stage_error_px: float = 0.2,
    format: StackFormat = "imagej",
    rng: int | np.random.Generator | None = 0,
) -> Path:
    """Cut a stack into a microscope mosaic: overlapping tiles and their tile list.

    The stack is cut into ``tiles`` (rows, columns) tiles of equal size that
    overlap their neighbours by ``overlap`` of a tile's side; each is written
    as ``tile_rR_cC.tif`` (see :func:`write_stack`) into ``folder`` (which
    must exist), with ``tiles.csv`` (``file,x_um,y_um``: the stage position
    of each tile's pixel (0, 0)).  The positions carry a stage error, uniform
    within ``stage_error_px`` px per axis (below a quarter of a pixel, so the
    difference of two positions rounds to the tiles' true offset): the
    mosaic read from the tiles is the stack, pixel for pixel.

    Returns
    -------
    Path
        The tile list.
    """
    from tissue_core.csvtext import csv_writer

    ny_t, nx_t = (int(n) for n in tiles)
    if ny_t < 1 or nx_t < 1:
        raise ValueError(f"tiles must be at least 1 x 1, got {tiles}")
    if not 0 <= overlap < 0.5:
        raise ValueError(f"overlap must be in [0, 0.5), got {overlap}")
    if not 0 <= stage_error_px < 0.25:
        raise ValueError(f"stage_error_px must be in [0, 0.25), got {stage_error_px}")
    folder = Path(folder)
    rng = np.random.default_rng(rng)
    _, _, ny, nx = case.stack.shape
    _, dy, dx = case.spacing

    def cuts(n: int, k: int) -> list[tuple[int, int]]:
        # k tiles of one size covering n pixels, each overlapping the next by ~overlap
        size = min(n, math.ceil(n / (k - (k - 1) * overlap))) if k > 1 else n
        starts = np.linspace(0, n - size, k).round().astype(int) if k > 1 else [0]
        return [(int(a), int(a) + size) for a in starts]

    suffix = ".tif" if format == "imagej" else ".ome.tif"
    rows = []
    for r, (y0, y1) in enumerate(cuts(ny, ny_t)):
        for c, (x0, x1) in enumerate(cuts(nx, nx_t)):
            name = f"tile_r{r}_c{c}{suffix}"
            part = dataclasses.replace(
                case,
                stack=np.ascontiguousarray(case.stack[..., y0:y1, x0:x1]),
                depth_um=case.depth_um[y0:y1, x0:x1],
                height_um=case.height_um[y0:y1, x0:x1],
            )
            write_stack(folder / name, part, format=format)
            ex, ey = rng.uniform(-stage_error_px, stage_error_px, 2)
            rows.append((name, f"{(x0 + ex) * dx:.4f}", f"{(y0 + ey) * dy:.4f}"))
    listing = folder / "tiles.csv"
    with replaced_on_success(listing) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        w = csv_writer(f)
        w.writerow(["file", "x_um", "y_um"])
        w.writerows(rows)
    return listing
