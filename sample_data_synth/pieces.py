"""Textured pieces on a blank background, turned about the frame's centre.

A tracker asked to follow a grid that lies mostly on nothing must say so:
the points on texture are measured, the others are not. This scene puts
three pieces with texture on a black background that holds nothing but
sensor noise, and turns the whole frame by ``angle_deg`` (20 degrees) per
frame about its centre, with exact truth.

======  ========================================  ==========================
piece   texture                                   grid points (of the 9x9)
======  ========================================  ==========================
centre  speckle (dots of 2 px radius)             columns 3-5, rows 3-5: 9
corner  photograph (scikit-image ``chelsea``)     columns 0-1, rows 0-2: 6
corner  photograph (``immunohistochemistry``)     columns 6-8, rows 6-7: 6
======  ========================================  ==========================

The 9 x 9 grid spans 20-80 % of the frame; 21 points lie on texture and 60
on the blank background. Each piece is a rectangle with rounded corners whose
edges run half-way between grid rows and columns, so every point lies at
least half a grid step (about 30 px at 800 px) from an edge, inside or out.
The pieces stay inside the circle the frame's corners cannot reach, so no
texture leaves the frame while it turns. Frames are rendered as in the
tissue suite (:func:`sample_data_synth.tissue.render_frames`): the reference
image inverse-mapped with cubic B-splines, then Poisson-Gaussian noise.
"""

from __future__ import annotations

import numpy as np
from scipy import special

from sample_data_synth.cases import GroundTruth, SyntheticVideo
from sample_data_synth.deformations import Homogeneous
from sample_data_synth.render import render_speckle
from sample_data_synth.speckle import speckle_pattern
from sample_data_synth.tissue import render_frames

__all__ = ["PIECES_GRID", "make_rotation_pieces", "texture_depth"]

#: the scene's grid, points along x and y
PIECES_GRID = (9, 9)

#: the grid's region, fractions of ``size - 1``
_ROI = (0.2, 0.2, 0.8, 0.8)

#: (texture, first column, first row, last column, last row) of each piece on the grid
_LAYOUT = (
    ("speckle", 3, 3, 5, 5),
    ("chelsea", 0, 0, 1, 2),
    ("immunohistochemistry", 6, 6, 8, 7),
)

#: width of a piece's anti-aliased edge (px, standard deviation of its blur)
_EDGE = 0.7


def _pieces(size: int) -> list[dict]:
    x0, y0, x1, y1 = (f * (size - 1) for f in _ROI)
    step_x, step_y = (x1 - x0) / (PIECES_GRID[0] - 1), (y1 - y0) / (PIECES_GRID[1] - 1)
    pieces = []
    for texture, c0, r0, c1, r1 in _LAYOUT:
        box = [
            x0 + (c0 - 0.5) * step_x,
            y0 + (r0 - 0.5) * step_y,
            x0 + (c1 + 0.5) * step_x,
            y0 + (r1 + 0.5) * step_y,
        ]
        pieces.append({"texture": texture, "box": box, "corner_radius": 0.25 * step_x})
    return pieces


def texture_depth(pieces: list[dict], points: np.ndarray) -> np.ndarray:
    """Signed distance (px) of reference points to the nearest piece's edge.

    Positive inside a piece (on texture), negative on the blank background.

    Parameters
    ----------
    pieces : list of dict
        ``truth.params["pieces"]`` of :func:`make_rotation_pieces`: each with
        ``box`` (x0, y0, x1, y1) in px and ``corner_radius`` in px.
    points : (..., 2) float
        x, y in reference px.

    Returns
    -------
    depth : (...) float
    """
    points = np.asarray(points, dtype=float)
    depth = np.full(points.shape[:-1], -np.inf)
    for piece in pieces:
        x0, y0, x1, y1 = piece["box"]
        r = piece["corner_radius"]
        center = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        half = np.array([(x1 - x0) / 2, (y1 - y0) / 2]) - r
        q = np.abs(points - center) - half
        outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
        inside = np.minimum(q.max(axis=-1), 0.0)
        depth = np.maximum(depth, r - outside - inside)
    return depth


def _texture(piece: dict, size: int, rng: np.random.Generator) -> np.ndarray:
    """The piece's texture over the whole frame (only its box matters)."""
    x0, y0, x1, y1 = piece["box"]
    if piece["texture"] == "speckle":
        pattern = speckle_pattern((x0 - 10, y0 - 10, x1 + 10, y1 + 10), radius=2.0, rng=rng)
        identity = Homogeneous("stretch", (0.0, 0.0), lx=1.0, ly=1.0)
        return render_speckle(pattern, identity, 0.0, (size, size))
    from sample_data_synth.tissue import _photograph, _unit

    i0, j0 = int(np.floor(y0)), int(np.floor(x0))
    i1, j1 = int(np.ceil(y1)) + 1, int(np.ceil(x1)) + 1
    patch = _photograph(piece["texture"], max(i1 - i0, j1 - j0), (0.2, 0.2, 0.8, 0.8))
    image = np.zeros((size, size))
    image[i0:i1, j0:j1] = _unit(patch, 40.0, 220.0)[: i1 - i0, : j1 - j0]
    return image


def make_rotation_pieces(
    *,
    size: int = 800,
    n_frames: int = 5,
    angle_deg: float = 20.0,
    background: float = 0.0,
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    rng: int | None = 0,
) -> SyntheticVideo:
    """Render the turning pieces (see the module docstring).

    Parameters
    ----------
    size : int, keyword-only
        Frame width and height in px (>= 200).
    n_frames : int, keyword-only
        Frames including the reference (>= 2); the last is turned by
        ``angle_deg * (n_frames - 1)``.
    angle_deg : float, keyword-only
        Turn per frame (clockwise on screen for positive angles).
    background : float, keyword-only
        Gray level of the blank background before noise (0: black).
    read_noise, shot_gain : float, keyword-only
        See :func:`sample_data_synth.render.add_sensor_noise`.
    rng : int, keyword-only
        Seed of the speckle and the noise.

    Returns
    -------
    SyntheticVideo
        ``truth.params`` holds ``pieces`` (for :func:`texture_depth`),
        ``grid`` ([9, 9]) and ``on_texture`` (one bool per grid point,
        row-major as :meth:`GroundTruth.grid`).
    """
    if size < 200:
        raise ValueError(f"size must be >= 200 px, got {size}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    speckle_rng, noise_rng = (
        np.random.default_rng(s) for s in np.random.SeedSequence(rng).spawn(2)
    )
    pieces = _pieces(size)
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    pixels = np.stack([xx, yy], axis=-1)
    image = np.full((size, size), float(background))
    for piece in pieces:
        depth = texture_depth([piece], pixels)
        mask = 0.5 * (1 + special.erf(depth / (_EDGE * np.sqrt(2))))
        image += mask * (_texture(piece, size, speckle_rng) - background)
    center = ((size - 1) / 2, (size - 1) / 2)
    deformation = Homogeneous("rotation", center, angle_deg=angle_deg * (n_frames - 1))
    frames = render_frames(
        image,
        deformation,
        np.arange(n_frames) / (n_frames - 1),
        read_noise=read_noise,
        shot_gain=shot_gain,
        rng=noise_rng,
    )
    roi = tuple(f * (size - 1) for f in _ROI)
    truth = GroundTruth("rotation-pieces", deformation, n_frames, (size, size), roi)
    on_texture = texture_depth(pieces, truth.grid(PIECES_GRID)) > 0
    truth.params = {
        "description": f"three textured pieces on a blank background turned by {angle_deg:g} "
        "degrees per frame",
        "suite": "rotation-pieces",
        "pieces": pieces,
        "grid": list(PIECES_GRID),
        "on_texture": on_texture.tolist(),
        "background": float(background),
        "angle_deg_per_frame": float(angle_deg),
        "seed": rng,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
        "interpolation": "cubic B-spline",
    }
    return SyntheticVideo(frames, truth)
