"""Still videos of real texture: one photograph, fresh sensor noise on every frame.

Nothing moves, so every tracked position's deviation from the reference is
measurement error: the scatter a tracker's reported uncertainty must match
(:func:`sample_data_synth.measures.sigma_against_scatter`). The photographs
ship with scikit-image; each is converted to gray, resized and scaled to
25-225 gray levels as in the tissue suite, and every frame is that image
plus Poisson-Gaussian noise of one of :data:`NOISE_LEVELS`, in 8 bits.
"""

from __future__ import annotations

import numpy as np

from sample_data_synth.cases import GroundTruth, SyntheticVideo
from sample_data_synth.deformations import Homogeneous
from sample_data_synth.tissue import render_frames

__all__ = ["NOISE_LEVELS", "STILL_GRID", "STILL_PHOTOGRAPHS", "make_still_video", "still_texture"]

#: sensor noise levels: (read noise in gray levels, shot-noise variance per gray level)
NOISE_LEVELS = {"low": (0.5, 0.005), "camera": (1.0, 0.02), "high": (3.0, 0.06)}

#: photographs of scikit-image and the part of each that is used (x0, y0, x1, y1 fractions)
STILL_PHOTOGRAPHS = {
    "immunohistochemistry": (0.0, 0.0, 1.0, 1.0),  # a stained tissue section
    "chelsea": (0.05, 0.0, 0.65, 1.0),  # fur
    "retina": (0.3, 0.3, 0.7, 0.7),  # a fundus: vessels on smooth background
}

#: the grid of a still video (points along x and y) over the middle 60 % of the frame
STILL_GRID = (11, 11)


def still_texture(photograph: str, size: int = 400) -> np.ndarray:
    """The gray photograph of a still video, ``(size, size)`` float, 25-225 gray levels."""
    from sample_data_synth.tissue import _photograph, _unit

    if photograph not in STILL_PHOTOGRAPHS:
        raise ValueError(
            f"unknown photograph {photograph!r}; choose from {', '.join(STILL_PHOTOGRAPHS)}"
        )
    return _unit(_photograph(photograph, size, STILL_PHOTOGRAPHS[photograph]))


def make_still_video(
    photograph: str = "immunohistochemistry",
    *,
    noise: str = "camera",
    size: int = 400,
    n_frames: int = 21,
    rng: int | None = 0,
) -> SyntheticVideo:
    """A photograph copied to ``n_frames`` frames with fresh sensor noise on each.

    Parameters
    ----------
    photograph : str
        A key of :data:`STILL_PHOTOGRAPHS`.
    noise : str, keyword-only
        A key of :data:`NOISE_LEVELS`.
    size : int, keyword-only
        Frame width and height in px (>= 64).
    n_frames : int, keyword-only
        Frames (>= 2).
    rng : int, keyword-only
        Seed of the noise.

    Returns
    -------
    SyntheticVideo
        The truth is the identity (every point stays where it is);
        ``truth.params["grid"]`` is :data:`STILL_GRID`.
    """
    if noise not in NOISE_LEVELS:
        raise ValueError(f"unknown noise level {noise!r}; choose from {', '.join(NOISE_LEVELS)}")
    if size < 64:
        raise ValueError(f"size must be >= 64 px, got {size}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    texture = still_texture(photograph, size)
    read_noise, shot_gain = NOISE_LEVELS[noise]
    center = ((size - 1) / 2, (size - 1) / 2)
    still = Homogeneous("stretch", center, lx=1.0, ly=1.0)
    frames = render_frames(
        texture, still, np.zeros(n_frames), read_noise=read_noise, shot_gain=shot_gain, rng=rng
    )
    roi = tuple(f * (size - 1) for f in (0.2, 0.2, 0.8, 0.8))
    params = {
        "description": f"still video of {photograph} with {noise} sensor noise",
        "suite": "still",
        "photograph": photograph,
        "crop": list(STILL_PHOTOGRAPHS[photograph]),
        "noise": noise,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
        "grid": list(STILL_GRID),
        "seed": rng,
    }
    truth = GroundTruth(f"still-{photograph}-{noise}", still, n_frames, (size, size), roi, params)
    return SyntheticVideo(frames, truth)
