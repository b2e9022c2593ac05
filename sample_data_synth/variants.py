"""Randomised variants of the tissue suite, held out from its cases.

Each variant draws, from its own seed, everything the tissue suite fixes
(:mod:`sample_data_synth.tissue`):

* **texture**: a square crop of a photograph shipped with scikit-image
  (``astronaut``, ``brick``, ``camera``, ``cell``, ``chelsea``, ``coffee``,
  ``coins``, ``grass``, ``gravel``, ``immunohistochemistry``, ``moon``,
  ``retina``, ``rocket``), 30-90 % of the photograph's short side, so that it
  is enlarged 1-4 times (small crops are blurry, weak texture), or a
  procedural one (``vessels``, ``fibres``), with a random contrast that the
  light never saturates;
* **field** with a random centre inside the grid region and a random
  amplitude: ``stretch`` (uniform contraction or stretch, 0.75-1.25 per
  axis), ``gaussian`` (local contraction or dilation, ``a`` in [-0.25, 0.35],
  ``s`` 6-12 % of the frame), ``bump`` (a local shift of up to half its width
  ``s``, 8-15 % of the frame), ``shear`` (0.1-0.35 either way), ``sinusoid``
  (wavelength 30-60 % of the frame, peak strain 0.05-0.2);
* **light**: a fade over the video of 0-40 % (dimming, or brightening by up to
  25 %), deeper towards a random side, a fixed light gradient of up to 35 %
  across the frame in a random direction, and specular spots in a quarter of
  the variants;
* **optics and sensor**: Gaussian blur of 0-2 px, read noise 0.5-3 gray
  levels and shot-noise gain 0.005-0.06;
* **video and grid**: 400-600 px square frames, 11-21 frames, a grid of 7-15
  by 7-15 points over a random region.

The textures take turns (every one once before any twice), and so do the
fields, shifted by one each round of textures. Two draws are refused and
drawn again: a grid point that comes within 45 px of the frame's edge on any
frame (so every point stays in view with room for a 81 px subset), and a
grid point whose texture is weaker against the noise than the suite's
weakest (see :func:`texture_strength` and :data:`MIN_TEXTURE_TO_NOISE`):
the variants are as hard as the suite, not blank. Variant ``i`` of a seed is
the same whatever ``n`` is, so the first few of the bench's variants are the
tests' variants.

Examples
--------
>>> variants = tissue_variants(2, rng=0)  # doctest: +SKIP
>>> video = make_variant(variants[0])  # doctest: +SKIP
>>> points = video.truth.grid(variants[0].grid)  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from sample_data_synth.cases import GroundTruth, SyntheticVideo
from sample_data_synth.deformations import Field, Homogeneous, deformation_from_dict
from sample_data_synth.tissue import Light, render_frames

__all__ = [
    "MIN_TEXTURE_TO_NOISE",
    "PHOTOGRAPHS",
    "Variant",
    "make_variant",
    "texture_strength",
    "tissue_variants",
    "variant_reference",
    "variant_truth",
    "weakest_texture_to_noise",
]

#: photographs of scikit-image (``skimage.data`` function names) the variants crop
PHOTOGRAPHS = (
    "astronaut",
    "brick",
    "camera",
    "cell",
    "chelsea",
    "coffee",
    "coins",
    "grass",
    "gravel",
    "immunohistochemistry",
    "moon",
    "retina",
    "rocket",
)

#: procedural textures of :func:`sample_data_synth.tissue.tissue_texture`
_PROCEDURAL = ("vessels", "fibres")

_FIELDS = ("stretch", "gaussian", "bump", "shear", "sinusoid")

#: weakest texture a grid point may have, against the noise on the last frame: the
#: suite's weakest point (closeup-gaussian, 800 px) has 3.6 (:func:`texture_strength`
#: over 31 px, faded by 30 %, divided by the noise's standard deviation)
MIN_TEXTURE_TO_NOISE = 3.0

#: distance (px) every grid point keeps from the frame's edges on every frame
_EDGE_MARGIN = 45.0

#: side of the window of :func:`texture_strength` (px)
_WINDOW = 31


@dataclass(frozen=True)
class Variant:
    """One randomised variant of the tissue suite (all it takes to render it).

    Attributes
    ----------
    name : str
        ``variant-II-TEXTURE-FIELD``.
    texture : str
        A name of :data:`PHOTOGRAPHS`, or ``vessels`` or ``fibres``.
    crop : (x0, y0, x1, y1)
        Fractions of the photograph's width and height (procedural: the whole).
    contrast : (lo, hi)
        Gray levels the texture spans (its 0.5 and 99.5 percentiles).
    size : int
        Frame width and height in px.
    n_frames : int
    deformation : dict
        The field's ``to_dict()`` (:func:`~sample_data_synth.deformations.deformation_from_dict`).
    light : Light
    blur : float
        Standard deviation of the optics' Gaussian blur in px.
    read_noise, shot_gain : float
        See :func:`sample_data_synth.render.add_sensor_noise`.
    grid : (nx, ny)
        Points along x and y (:meth:`GroundTruth.grid`).
    roi : (x0, y0, x1, y1)
        The grid's region in px.
    seed : int
        Seed of the procedural texture and of the noise.
    """

    name: str
    texture: str
    crop: tuple[float, float, float, float]
    contrast: tuple[float, float]
    size: int
    n_frames: int
    deformation: dict
    light: Light
    blur: float
    read_noise: float
    shot_gain: float
    grid: tuple[int, int]
    roi: tuple[float, float, float, float]
    seed: int

    @property
    def field(self) -> str:
        """The field's kind: stretch, gaussian, bump, shear or sinusoid."""
        return self.deformation["kind"]

    def describe(self) -> str:
        """One line: texture, field, light, blur and noise."""
        fade = self.light.fade
        return (
            f"{self.texture} {_crop_words(self)}, {self.field} field, "
            f"{'fade' if fade >= 0 else 'brightening'} {abs(fade):.0%}, blur {self.blur:.1f} px, "
            f"noise {self.read_noise:.1f} + {self.shot_gain:.3f} I, "
            f"{self.grid[0]}x{self.grid[1]} grid, {self.size} px, {self.n_frames} frames"
        )

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "texture": self.texture,
            "crop": list(self.crop),
            "contrast": list(self.contrast),
            "size": self.size,
            "n_frames": self.n_frames,
            "deformation": self.deformation,
            "light": self.light.to_dict(),
            "blur": self.blur,
            "read_noise": self.read_noise,
            "shot_gain": self.shot_gain,
            "grid": list(self.grid),
            "roi": list(self.roi),
            "seed": self.seed,
        }


def _crop_words(variant: Variant) -> str:
    if variant.texture in _PROCEDURAL:
        return "(procedural)"
    x0, y0, x1, y1 = variant.crop
    return f"crop ({x0:.2f}, {y0:.2f})-({x1:.2f}, {y1:.2f})"


# ----------------------------------------------------------------------------- texture


def texture_strength(image: np.ndarray, *, window: int = _WINDOW) -> np.ndarray:
    """Texture of an image around each pixel, along its weakest direction.

    The square root of the smaller eigenvalue of the structure tensor
    ``sum (grad I)(grad I)^T`` over a ``window`` x ``window`` square centred
    on the pixel (central differences), in gray levels: a subset of that side
    matched on noise of standard deviation ``s`` in both images locates its
    point to about ``s sqrt(2) / strength`` px along that direction.

    Parameters
    ----------
    image : (H, W) float
    window : int, keyword-only

    Returns
    -------
    strength : (H, W) float
    """
    image = np.asarray(image, dtype=float)
    gy, gx = np.gradient(image)
    area = window * window
    a, b, c = (ndimage.uniform_filter(g, window) * area for g in (gx * gx, gx * gy, gy * gy))
    weakest = (a + c) / 2 - np.sqrt(((a - c) / 2) ** 2 + b * b)
    return np.sqrt(np.clip(weakest, 0, None))


def _variant_texture(
    name: str, crop: tuple[float, ...], contrast: tuple[float, float], size: int, seed: int
) -> np.ndarray:
    from sample_data_synth.tissue import _fibres, _photograph, _unit, _vessels

    rng = np.random.default_rng(seed)
    if name == "vessels":
        image = _vessels(rng, size)
    elif name == "fibres":
        image = _fibres(rng, size)
    else:
        image = _photograph(name, size, crop)
    return _unit(image, *contrast)


# ----------------------------------------------------------------------------- draws


def _draw_deformation(rng: np.random.Generator, kind: str, center, size: int) -> dict:
    if kind == "stretch":
        lx, ly = rng.uniform(0.75, 1.25, 2)
        return Homogeneous("stretch", center, lx=lx, ly=ly).to_dict()
    if kind == "shear":
        gamma = rng.choice([-1.0, 1.0]) * rng.uniform(0.1, 0.35)
        return Homogeneous("shear", center, gamma=gamma).to_dict()
    if kind == "gaussian":
        a = rng.uniform(-0.25, 0.35)
        return Field("gaussian", center, a=a, s=rng.uniform(0.06, 0.12) * size).to_dict()
    if kind == "bump":
        s = rng.uniform(0.08, 0.15) * size
        length, angle = rng.uniform(0.15, 0.5) * s, rng.uniform(0, 2 * np.pi)
        return Field(
            "bump", center, ax=length * np.cos(angle), ay=length * np.sin(angle), s=s
        ).to_dict()
    wavelength = rng.uniform(0.3, 0.6) * size
    peak = rng.uniform(0.05, 0.2)  # amplitude k: the largest normal strain
    amplitude = peak * wavelength / (2 * np.pi)
    return Field("sinusoid", center, amplitude=amplitude, wavelength=wavelength).to_dict()


def _draw_light(rng: np.random.Generator, size: int) -> Light:
    fade = rng.uniform(0.0, 0.4) if rng.random() < 0.75 else -rng.uniform(0.0, 0.25)
    heading = rng.uniform(0, 2 * np.pi)
    tilt = abs(fade) * rng.uniform(0, 0.8)  # the fade is 0.6-1.4 times as deep at the edges
    slope, direction = rng.uniform(0, 0.35), rng.uniform(0, 2 * np.pi)
    spots: tuple = ()
    if rng.random() < 0.25:
        spots = tuple(
            (
                float(rng.uniform(0.2, 0.8) * size),
                float(rng.uniform(0.2, 0.8) * size),
                float(rng.uniform(0.01, 0.025) * size),
                float(rng.uniform(30, 70)),
            )
            for _ in range(int(rng.integers(1, 3)))
        )
    return Light(
        fade=float(fade),
        gradient=(float(slope * np.cos(direction)), float(slope * np.sin(direction))),
        spots=spots,
        fade_gradient=(float(tilt * np.cos(heading)), float(tilt * np.sin(heading))),
    )


def _brightest_gain(light: Light, size: int) -> float:
    """The light's largest gain over the frame and the video, specular spots aside."""
    plain = replace(light, spots=())
    return max(float(plain.apply(np.ones((size, size)), t).max()) for t in (0.0, 1.0))


def _draw_crop(rng: np.random.Generator, name: str) -> tuple[float, float, float, float]:
    from sample_data_synth.tissue import _pixels

    if name in _PROCEDURAL:
        return (0.0, 0.0, 1.0, 1.0)
    h, w = _pixels(name).shape[:2]
    side = rng.uniform(0.3, 0.9) * min(h, w)
    x0, y0 = rng.uniform(0, w - side), rng.uniform(0, h - side)
    return (x0 / w, y0 / h, (x0 + side) / w, (y0 + side) / h)


def weakest_texture_to_noise(variant: Variant, reference: np.ndarray) -> float:
    """Smallest texture-to-noise ratio of a variant's grid points on its last frame.

    :func:`texture_strength` of ``reference`` (the variant's frame 0 without
    noise) at each grid point, times the light's gain on the last frame where
    it dims, over the noise's standard deviation at the frame's mean gray level.
    """
    strength = texture_strength(reference)
    return _weakest(variant, reference, strength, variant_truth(variant).grid(variant.grid))


def _weakest(variant: Variant, reference, strength, points) -> float:
    light = variant.light
    h, w = reference.shape
    x, y = points[:, 0] - w / 2, points[:, 1] - h / 2
    fade = light.fade + (light.fade_gradient[0] * x + light.fade_gradient[1] * y) / max(h, w)
    gain = np.minimum(1.0, 1.0 - fade)
    ix = np.clip(np.rint(points[:, 0]).astype(int), 0, w - 1)
    iy = np.clip(np.rint(points[:, 1]).astype(int), 0, h - 1)
    level = max(float(reference.mean()), 0.0)
    noise = np.sqrt(variant.read_noise**2 + variant.shot_gain * level)
    return float(np.min(gain * strength[iy, ix]) / noise)


def variant_reference(variant: Variant) -> np.ndarray:
    """Frame 0 of a variant without noise, ``(size, size)`` float: its texture, lit and
    blurred; :func:`make_variant`'s frame 0 is this plus the sensor noise, in 8 bits."""
    texture = _variant_texture(
        variant.texture, variant.crop, variant.contrast, variant.size, variant.seed
    )
    image = variant.light.apply(texture, 0.0)
    return ndimage.gaussian_filter(image, variant.blur, mode="mirror")


def _draw_variant(index: int, seq: np.random.SeedSequence, name: str, kind: str) -> Variant:
    """Variant ``index`` of texture ``name`` and field ``kind``: its size and length are
    drawn once, the rest again until every grid point stays in view with texture enough."""
    rng = np.random.default_rng(seq)
    size = int(rng.integers(400, 601))
    n_frames = int(rng.integers(11, 22))
    for _ in range(200):
        crop = _draw_crop(rng, name)
        light = _draw_light(rng, size)
        lo, hi = rng.uniform(20, 70), rng.uniform(170, 225)
        brightest = _brightest_gain(light, size)  # the texture never saturates
        contrast = (float(lo / max(brightest, 1.0)), float(min(hi, 250 / brightest)))
        blur = float(rng.uniform(0.0, 2.0))
        read_noise, shot_gain = float(rng.uniform(0.5, 3.0)), float(rng.uniform(0.005, 0.06))
        seed = int(rng.integers(2**31))
        reference = strength = None
        for _ in range(20):  # grid regions and fields on this texture
            room = size - 2 - 2 * _EDGE_MARGIN
            width, height = np.minimum(rng.uniform(0.35, 0.7, 2) * (size - 1), room)
            x0 = rng.uniform(_EDGE_MARGIN, size - 1 - _EDGE_MARGIN - width)
            y0 = rng.uniform(_EDGE_MARGIN, size - 1 - _EDGE_MARGIN - height)
            roi = (float(x0), float(y0), float(x0 + width), float(y0 + height))
            center = (float(rng.uniform(roi[0], roi[2])), float(rng.uniform(roi[1], roi[3])))
            grid = (int(rng.integers(7, 16)), int(rng.integers(7, 16)))
            variant = Variant(
                f"variant-{index:02d}-{name}-{kind}",
                name,
                crop,
                contrast,
                size,
                n_frames,
                _draw_deformation(rng, kind, center, size),
                light,
                blur,
                read_noise,
                shot_gain,
                grid,
                roi,
                seed,
            )
            truth = variant_truth(variant)
            points = truth.grid(grid)
            path = truth.positions(points)
            if not np.all((path >= _EDGE_MARGIN) & (path <= size - 1 - _EDGE_MARGIN)):
                continue
            if reference is None:  # the texture, once per draw of it
                reference = variant_reference(variant)
                strength = texture_strength(reference)
            if _weakest(variant, reference, strength, points) >= MIN_TEXTURE_TO_NOISE:
                return variant
    raise RuntimeError(f"no variant {index} with texture enough in 200 draws")  # pragma: no cover


def tissue_variants(n: int = 32, *, rng: int | None = 0) -> list[Variant]:
    """``n`` randomised variants of the tissue suite (see the module docstring).

    Parameters
    ----------
    n : int
        Number of variants (>= 1).
    rng : int, keyword-only
        Seed; variant ``i`` depends on it and on ``i`` alone.

    Returns
    -------
    list of Variant
    """
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ValueError(f"n must be a whole number >= 1, got {n!r}")
    root = np.random.SeedSequence(rng)
    textures = PHOTOGRAPHS + _PROCEDURAL
    first_texture, first_field = (int(v) for v in root.generate_state(2) % 1000)
    variants = []
    for i, child in enumerate(root.spawn(int(n))):
        # every texture once before any twice; the fields in turn, shifted each round
        name = textures[(first_texture + i) % len(textures)]
        kind = _FIELDS[(first_field + i + i // len(textures)) % len(_FIELDS)]
        variants.append(_draw_variant(i, child, name, kind))
    return variants


def variant_truth(variant: Variant) -> GroundTruth:
    """The exact motion of a variant (what :func:`make_variant` returns, without rendering).

    ``params`` holds the variant's :meth:`Variant.to_dict` and a description.
    """
    params = {
        "description": variant.describe(),
        "suite": "tissue-variants",
        **variant.to_dict(),
        "interpolation": "cubic B-spline",
    }
    size = variant.size
    return GroundTruth(
        variant.name,
        deformation_from_dict(variant.deformation),
        variant.n_frames,
        (size, size),
        variant.roi,
        params,
    )


def make_variant(
    variant: Variant, *, progress: Callable[[int, int], None] | None = None
) -> SyntheticVideo:
    """Render a variant of :func:`tissue_variants`.

    ``truth.params`` holds the variant's :meth:`Variant.to_dict` (``grid``
    among it); ``truth.grid(variant.grid)`` gives its grid.
    """
    texture = _variant_texture(
        variant.texture, variant.crop, variant.contrast, variant.size, variant.seed
    )
    truth = variant_truth(variant)
    frames = render_frames(
        texture,
        truth.deformation,
        np.arange(variant.n_frames) / (variant.n_frames - 1),
        light=variant.light,
        blur=variant.blur,
        read_noise=variant.read_noise,
        shot_gain=variant.shot_gain,
        rng=np.random.SeedSequence(variant.seed).spawn(1)[0],
        progress=progress,
    )
    return SyntheticVideo(frames, truth)
