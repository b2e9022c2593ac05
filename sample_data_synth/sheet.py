"""A full-HD video of a skeletal-muscle sheet twitching: strong texture, small strain.

Where the tissue suite asks whether a tracker keeps its points on weak
texture, this scene asks how fast it is where the texture is strong and the
strain small, as on a light-stimulated muscle sheet filmed in full HD:

* **texture** (:func:`muscle_texture`): wavy fibres along x, 8-24 px wide,
  each with its own brightness and cross-striations of irregular spacing
  (features of 3-6 px), dark membranes between fibres, fine granularity and
  slow shading;
* **motion**: a contraction along the fibres with a local one superposed
  (:class:`~sample_data_synth.deformations.Contraction`): at the peak, over
  the grid, ``Exx`` runs from ``-peak`` at the local centre to about
  ``-0.4 peak``, ``Eyy`` from ``-0.2 peak`` to about ``+0.4 peak``
  (``peak = 0.01``: strains of 0.002-0.01); a twitch in time
  (:class:`~sample_data_synth.deformations.Twitch`): rest for 2 frames, a
  smooth rise to the peak at 40 % of the video and a smooth relaxation to
  rest on the last frame;
* 1920 x 1080 px, 41 frames, a 29 x 15 grid over the middle 80 % (435 points).

Frames are rendered as in the tissue suite
(:func:`sample_data_synth.tissue.render_frames`), with exact truth.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy import ndimage

from sample_data_synth.cases import GroundTruth, SyntheticVideo
from sample_data_synth.deformations import Contraction, Field, Twitch
from sample_data_synth.tissue import render_frames

__all__ = ["SHEET_GRID", "make_muscle_sheet", "muscle_texture"]

#: the sheet's grid: points along x and y
SHEET_GRID = (29, 15)


def muscle_texture(shape: tuple[int, int] = (1080, 1920), *, rng=0) -> np.ndarray:
    """Skeletal-muscle-like texture ``(H, W)`` float, 25-225 gray levels.

    Parameters
    ----------
    shape : (H, W)
    rng : int or Generator, keyword-only
    """
    from sample_data_synth.tissue import _unit

    rng = np.random.default_rng(rng)
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    # fibres run along x and wave gently; y_f is the across-fibre coordinate
    wave = 6.0 * np.sin(2 * np.pi * xx / rng.uniform(500, 800) + rng.uniform(0, 2 * np.pi))
    yf = yy + wave + 3.0 * np.sin(2 * np.pi * xx / rng.uniform(150, 250))
    edges = np.cumsum(rng.uniform(8, 24, int(h / 8) + 8)) - 20.0
    fibre = np.clip(np.searchsorted(edges, yf), 0, len(edges) - 1)
    n = len(edges)
    brightness = rng.normal(0, 0.5, n)
    contrast = rng.uniform(0.3, 0.8, n)
    # cross-striations of irregular spacing: noise along each fibre, band-limited to 3-6 px
    # features (regular ones would let a subset match one striation over)
    striations = ndimage.gaussian_filter1d(rng.standard_normal((n, w)), 1.5, axis=1)
    striations /= striations.std()
    image = brightness[fibre] + contrast[fibre] * striations[fibre, xx.astype(int)]
    distance = np.minimum(
        np.abs(yf - edges[fibre]), np.abs(yf - np.concatenate([[-1e9], edges])[fibre])
    )
    image -= 1.2 * np.exp(-(distance**2) / (2 * 1.2**2))  # membranes between fibres
    image = ndimage.gaussian_filter(image, 0.7)
    grain = ndimage.gaussian_filter(rng.standard_normal(shape), 1.0)
    image += 0.35 * grain / grain.std()
    # slow shading over an eighth of the frame, drawn coarse (every 16 px) and enlarged
    coarse = rng.standard_normal((h // 16 + 2, w // 16 + 2))
    coarse = ndimage.gaussian_filter(coarse, min(h, w) / 8 / 16, mode="wrap")
    shading = ndimage.zoom(coarse, 16, order=3)[:h, :w]
    image += 0.6 * shading / shading.std()
    return _unit(image)


def render_sheet(
    shape: tuple[int, int],
    peak: float,
    times,
    *,
    spot: tuple[float, float, float],
    read_noise: float,
    shot_gain: float,
    rng,
    progress=None,
) -> tuple[np.ndarray, Contraction]:
    """Frames of the muscle sheet contracting by ``peak`` at ``t = 1`` over ``times``, and
    its deformation: stretches ``1 - 0.6 peak`` along the fibres and ``1 + 0.2 peak``
    across them (E ~ F - 1 for small strain), plus a local hot spot of ``0.4 peak`` at
    ``spot`` ``(x, y, width)`` as shares of the frame.  The texture and the noise come
    from two streams of ``rng``."""
    h, w = shape
    texture_rng, noise_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(rng).spawn(2)
    )
    texture = muscle_texture((h, w), rng=texture_rng)
    center = ((w - 1) / 2, (h - 1) / 2)
    sx, sy, width = spot
    local = Field("gaussian", (sx * (w - 1), sy * (h - 1)), a=0.4 * peak, s=width * w)
    deformation = Contraction(center, lx=1 - 0.6 * peak, ly=1 + 0.2 * peak, fields=[local])
    frames = render_frames(
        texture,
        deformation,
        times,
        read_noise=read_noise,
        shot_gain=shot_gain,
        rng=noise_rng,
        progress=progress,
    )
    return frames, deformation


def make_muscle_sheet(
    *,
    shape: tuple[int, int] = (1080, 1920),
    n_frames: int = 41,
    peak: float = 0.01,
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    rng: int | None = 0,
    progress: Callable[[int, int], None] | None = None,
) -> SyntheticVideo:
    """Render the twitching muscle sheet (see the module docstring).

    Parameters
    ----------
    shape : (H, W), keyword-only
        Frame size in px (>= 64 each).
    n_frames : int, keyword-only
        Frames (>= 6).
    peak : float, keyword-only
        Largest contraction ``-Exx`` at the twitch's peak (0 < peak < 0.2).
    read_noise, shot_gain : float, keyword-only
        See :func:`sample_data_synth.render.add_sensor_noise`.
    rng : int, keyword-only
        Seed of the texture and the noise.
    progress : callable(done, total), keyword-only

    Returns
    -------
    SyntheticVideo
        ``truth.params["grid"]`` is :data:`SHEET_GRID`; ``truth.time_profile``
        the twitch.
    """
    h, w = (int(v) for v in shape)
    if min(h, w) < 64:
        raise ValueError(f"shape must be at least 64 x 64 px, got {shape}")
    if n_frames < 6:
        raise ValueError(f"n_frames must be >= 6, got {n_frames}")
    if not 0 < peak < 0.2:
        raise ValueError(f"peak must be between 0 and 0.2, got {peak}")
    profile = Twitch(2, max(3, round(0.4 * (n_frames - 1))), n_frames - 1)
    frames, deformation = render_sheet(
        (h, w),
        peak,
        [profile(k) for k in range(n_frames)],
        spot=(0.35, 0.55, 0.15),
        read_noise=read_noise,
        shot_gain=shot_gain,
        rng=rng,
        progress=progress,
    )
    roi = (0.1 * (w - 1), 0.1 * (h - 1), 0.9 * (w - 1), 0.9 * (h - 1))
    params = {
        "description": f"twitching muscle sheet, {w}x{h} px, peak contraction {peak:g}",
        "suite": "muscle-sheet",
        "texture": "procedural skeletal muscle (wavy striated fibres)",
        "grid": list(SHEET_GRID),
        "peak": peak,
        "seed": rng,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
        "interpolation": "cubic B-spline",
    }
    truth = GroundTruth(
        "muscle-sheet", deformation, n_frames, (h, w), roi, params, time_profile=profile
    )
    return SyntheticVideo(frames, truth)
