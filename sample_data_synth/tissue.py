"""Speckle-free tissue videos: natural texture, uneven light, large motion.

What a lab films on a bladder wall is not a speckle pattern: smooth mucosa
with sparse vessels, fibres, light that falls off across the field and fades
over time, specular spots that stay where the lamp puts them, and blur. This
suite renders such videos with exact ground truth, to measure whether a
tracker keeps every grid point on weak texture.

=====================  ================================================  ======
case                   texture, motion and light                          grid
=====================  ================================================  ======
retina-contraction     fundus photograph (scikit-image ``retina``),        7x7
                       uniform contraction to 0.6
fur-gaussian           cat-fur photograph (``chelsea``), local Gaussian    13x13
                       contraction, 30 % fade with a gradient
closeup-gaussian       blurry retinal close-up (vessels on a smooth        13x13
                       background), same field and light
vessels-contraction    procedural mucosa with sparse vessels and two       9x9
                       specular spots, contraction 0.75 with a 10-degree
                       turn, 30 % fade
fibres-shear           procedural fur-like fibres, simple shear 0.3,       9x9
                       light gradient
rotation-20            fundus photograph turned by 20 degrees per frame    9x9
=====================  ================================================  ======

Frames are 800 x 800 px (scaled with ``size``), 21 frames by default (the
rotation: 5, i.e. 80 degrees). Each pixel is inverse-mapped to the
reference configuration and the texture sampled there with cubic B-splines;
then the light is applied in the image frame (it does not move with the
tissue): ``I = (1 - fade t) (1 + gradient . (x - c) / size) T + specular``,
and Poisson-Gaussian sensor noise, 8 bits. The photographs ship inside
scikit-image, so nothing is downloaded.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from sample_data_synth.cases import GroundTruth, SyntheticVideo
from sample_data_synth.deformations import Field, Homogeneous
from sample_data_synth.render import add_sensor_noise

__all__ = ["TISSUE_CASES", "Light", "make_tissue_case", "render_frames", "tissue_texture"]


# ----------------------------------------------------------------------------- textures


def _unit(image: np.ndarray, lo: float = 25.0, hi: float = 225.0) -> np.ndarray:
    a, b = np.percentile(image, [0.5, 99.5])
    return lo + (hi - lo) * np.clip((image - a) / max(b - a, 1e-12), 0, 1)


@functools.cache
def _pixels(name: str) -> np.ndarray:
    """A photograph of ``skimage.data`` by its function name, read once (read-only)."""
    from skimage import data

    image = getattr(data, name)()
    image.setflags(write=False)
    return image


def _photograph(name: str, size: int, crop: tuple[float, float, float, float]) -> np.ndarray:
    from skimage import color, transform

    rgb = _pixels(name)
    h, w = rgb.shape[:2]
    x0, y0, x1, y1 = crop
    part = rgb[int(y0 * h) : int(y1 * h), int(x0 * w) : int(x1 * w)]
    gray = color.rgb2gray(part) if part.ndim == 3 else part / 255.0
    return transform.resize(gray, (size, size), order=3, anti_aliasing=True, mode="reflect")


def _smooth_noise(rng: np.random.Generator, size: int, scale: float) -> np.ndarray:
    field = ndimage.gaussian_filter(rng.standard_normal((size, size)), scale, mode="wrap")
    return field / (field.std() + 1e-12)


def _vessels(rng: np.random.Generator, size: int) -> np.ndarray:
    """Sparse, branching dark vessels on smooth mucosa with faint granularity."""
    image = 0.6 * _smooth_noise(rng, size, size / 12) + 0.08 * _smooth_noise(rng, size, 1.5)
    ink = np.zeros((size, size))
    for _ in range(14):
        x, y = rng.uniform(0, size, 2)
        heading = rng.uniform(0, 2 * np.pi)
        width = rng.uniform(1.5, 5.0)
        for _ in range(int(rng.uniform(0.4, 1.2) * size)):
            heading += rng.normal(0, 0.08)
            x, y = x + np.cos(heading), y + np.sin(heading)
            if not (0 <= x < size and 0 <= y < size):
                break
            ink[int(y), int(x)] = max(ink[int(y), int(x)], width)
            if rng.random() < 0.004:  # a branch
                heading += rng.choice([-1, 1]) * rng.uniform(0.5, 1.0)
                width *= 0.75
    vessels = np.zeros((size, size))
    for w in np.unique(ink[ink > 0].round(1)):
        vessels = np.maximum(vessels, ndimage.gaussian_filter((ink.round(1) == w) * 1.0, w) * w)
    vessels /= vessels.max() + 1e-12
    return image - 2.5 * vessels


def _fibres(rng: np.random.Generator, size: int) -> np.ndarray:
    """Fur-like short strokes whose orientation varies smoothly over the image."""
    theta = np.pi * _smooth_noise(rng, size, size / 6)
    image = np.zeros((size, size))
    n = int(size * size / 60)
    xs, ys = rng.uniform(0, size, n), rng.uniform(0, size, n)
    length = rng.uniform(6, 18, n)
    shade = rng.choice([-1.0, 1.0], n) * rng.uniform(0.3, 1.0, n)
    a = theta[ys.astype(int), xs.astype(int)]
    for step in np.linspace(-0.5, 0.5, 12):
        px = (xs + step * length * np.cos(a)).astype(int) % size
        py = (ys + step * length * np.sin(a)).astype(int) % size
        np.add.at(image, (py, px), shade)
    return ndimage.gaussian_filter(image, 0.8) + 0.3 * _smooth_noise(rng, size, size / 10)


def tissue_texture(kind: str, size: int = 800, *, rng: int | None = 0) -> np.ndarray:
    """A gray tissue-like texture ``(size, size)``, values 25-225 (float64).

    ``kind``: ``retina`` (fundus photograph), ``fur`` (cat photograph),
    ``closeup`` (a blurry quarter of the fundus enlarged four times:
    vessels on a smooth background), ``vessels`` or ``fibres`` (procedural).
    """
    generator = np.random.default_rng(rng)
    if kind == "retina":
        return _unit(_photograph("retina", size, (0.2, 0.2, 0.8, 0.8)))
    if kind == "fur":
        return _unit(_photograph("chelsea", size, (0.05, 0.0, 0.65, 1.0)))
    if kind == "closeup":
        return _unit(_photograph("retina", size, (0.30, 0.42, 0.45, 0.57)), 60.0, 190.0)
    if kind == "vessels":
        return _unit(_vessels(generator, size), 70.0, 200.0)
    if kind == "fibres":
        return _unit(_fibres(generator, size))
    raise ValueError(f"unknown texture {kind!r}")


# ----------------------------------------------------------------------------- light


@dataclass(frozen=True)
class Light:
    """Illumination in the image frame (it does not move with the tissue).

    ``I = (1 - t (fade + fx (x - cx) / size + fy (y - cy) / size))
    (1 + gx (x - cx) / size + gy (y - cy) / size) T + spots``:
    ``fade`` dims the light over the video (a negative one brightens it),
    ``fade_gradient = (fx, fy)`` makes the fade deeper towards one side, and
    ``gradient = (gx, gy)`` is the fixed fall-off of the light across the field;
    each specular spot is a Gaussian of ``amplitude`` gray levels, clipped at 255.
    """

    fade: float = 0.0
    gradient: tuple[float, float] = (0.0, 0.0)
    spots: tuple[tuple[float, float, float, float], ...] = ()  # (x, y, radius, amplitude)
    fade_gradient: tuple[float, float] = (0.0, 0.0)

    def apply(self, image: np.ndarray, t: float) -> np.ndarray:
        h, w = image.shape
        yy, xx = np.mgrid[0:h, 0:w].astype(float)
        size = max(h, w)
        fx, fy = self.fade_gradient
        fade = self.fade + fx * (xx - w / 2) / size + fy * (yy - h / 2) / size
        gain = (1 - fade * t) * (
            1 + self.gradient[0] * (xx - w / 2) / size + self.gradient[1] * (yy - h / 2) / size
        )
        out = gain * image
        for x, y, r, amplitude in self.spots:
            out += amplitude * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / (2 * r * r))
        return np.clip(out, 0, 255)

    def to_dict(self) -> dict:
        return {
            "fade": self.fade,
            "gradient": list(self.gradient),
            "spots": list(self.spots),
            "fade_gradient": list(self.fade_gradient),
        }


# ----------------------------------------------------------------------------- frames


def render_frames(
    texture: np.ndarray,
    deformation,
    times: Sequence[float] | np.ndarray,
    *,
    light: Light | None = None,
    blur: float = 0.0,
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    rng: int | np.random.Generator | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> np.ndarray:
    """Frames of a texture deformed over time, lit and blurred in the image frame.

    Each pixel of a frame is inverse-mapped to the reference configuration
    and the texture sampled there with cubic B-splines (mirrored beyond its
    edges); then the light is applied (:meth:`Light.apply`), the optics'
    Gaussian blur, and Poisson-Gaussian sensor noise
    (:func:`sample_data_synth.render.add_sensor_noise`).

    Parameters
    ----------
    texture : (H, W) float
        The reference image in gray levels; the frames have its shape.
    deformation : object with ``inverse(x, t)``
    times : (T,) float
        The deformation's normalized time of each frame.
    light : Light, keyword-only
        Default: uniform light that does not change.
    blur : float, keyword-only
        Standard deviation of the optics' Gaussian blur in px (0: none).
    read_noise, shot_gain : float, keyword-only
        See :func:`sample_data_synth.render.add_sensor_noise`.
    rng : int or Generator, keyword-only
        Seed of the noise.
    progress : callable(done, total), keyword-only

    Returns
    -------
    frames : (T, H, W) uint8
        Frame ``k`` at ``t = times[k]``: with ``times[0] = 0`` and no light
        change, blur or noise, frame 0 is ``texture`` rounded to 8 bits.
    """
    light = Light() if light is None else light
    noise_rng = np.random.default_rng(rng)
    times = np.asarray(times, dtype=float)
    h, w = texture.shape
    coefficients = ndimage.spline_filter(np.asarray(texture, float), order=3, mode="mirror")
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    here = np.stack([xx, yy], axis=-1)
    frames = np.empty((len(times), h, w), dtype=np.uint8)
    for k, t in enumerate(times):
        X = deformation.inverse(here, t)
        image = ndimage.map_coordinates(
            coefficients, [X[..., 1], X[..., 0]], order=3, mode="mirror", prefilter=False
        )
        image = light.apply(image, t)
        if blur > 0:
            image = ndimage.gaussian_filter(image, blur, mode="mirror")
        frames[k] = add_sensor_noise(
            image, read_noise=read_noise, shot_gain=shot_gain, rng=noise_rng
        )
        if progress:
            progress(k + 1, len(times))
    return frames


# ----------------------------------------------------------------------------- cases


@dataclass(frozen=True)
class _TissueSpec:
    description: str
    texture: str
    roi: tuple[float, float, float, float]  # fractions of the frame
    grid: tuple[int, int]
    make: Callable[[tuple[float, float], float, int], Homogeneous | Field]
    light: Callable[[float], Light]
    n_frames: int = 21
    kind: str = "textured"  # "textured" or "smooth": the issue's two accuracy classes


def _fade(fade: float, gradient=(0.25, -0.15)) -> Callable[[float], Light]:
    return lambda size: Light(fade=fade, gradient=gradient)


TISSUE_CASES: dict[str, _TissueSpec] = {
    "retina-contraction": _TissueSpec(
        "fundus photograph, uniform contraction to 0.6",
        "retina",
        (0.25, 0.25, 0.75, 0.75),
        (7, 7),
        lambda c, size, n: Homogeneous("stretch", c, lx=0.6, ly=0.6),
        lambda size: Light(),
    ),
    "fur-gaussian": _TissueSpec(
        "cat-fur photograph, local Gaussian contraction (a = 0.3, s = 8 % of the frame), "
        "30 % fade with a light gradient",
        "fur",
        (0.2, 0.2, 0.8, 0.8),
        (13, 13),
        lambda c, size, n: Field("gaussian", c, a=0.3, s=0.08 * size),
        _fade(0.3),
    ),
    "closeup-gaussian": _TissueSpec(
        "blurry retinal close-up (vessels on a smooth background), local Gaussian "
        "contraction, 30 % fade with a light gradient",
        "closeup",
        (0.2, 0.2, 0.8, 0.8),
        (13, 13),
        lambda c, size, n: Field("gaussian", c, a=0.3, s=0.08 * size),
        _fade(0.3),
        kind="smooth",
    ),
    "vessels-contraction": _TissueSpec(
        "procedural mucosa with sparse vessels, contraction 0.75 with a 10-degree turn, "
        "two specular spots, 30 % fade",
        "vessels",
        (0.25, 0.25, 0.75, 0.75),
        (9, 9),
        lambda c, size, n: Homogeneous("turn", c, stretch=0.75, angle_deg=10.0),
        lambda size: Light(
            fade=0.3,
            gradient=(0.2, 0.1),
            spots=(
                (0.38 * size, 0.42 * size, 0.02 * size, 60.0),
                (0.64 * size, 0.6 * size, 0.015 * size, 50.0),
            ),
        ),
        kind="smooth",
    ),
    "fibres-shear": _TissueSpec(
        "procedural fur-like fibres, simple shear 0.3, light gradient",
        "fibres",
        (0.3, 0.25, 0.6, 0.75),
        (9, 9),
        lambda c, size, n: Homogeneous("shear", c, gamma=0.3),
        lambda size: Light(gradient=(0.3, 0.0)),
    ),
    "rotation-20": _TissueSpec(
        "fundus photograph turned by 20 degrees per frame",
        "retina",
        (0.32, 0.32, 0.68, 0.68),
        (9, 9),
        lambda c, size, n: Homogeneous("rotation", c, angle_deg=20.0 * (n - 1)),
        lambda size: Light(),
        n_frames=5,
    ),
}


def make_tissue_case(
    name: str,
    *,
    size: int = 800,
    n_frames: int | None = None,
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    rng: int | None = 0,
    progress: Callable[[int, int], None] | None = None,
) -> SyntheticVideo:
    """Render one case of the tissue suite (see the module docstring).

    ``truth.params`` holds the texture, the light, the grid shape
    (``grid``) and the accuracy class (``kind``: textured or smooth).
    ``truth.grid(tuple(truth.params["grid"]))`` gives the case's grid.
    """
    if name not in TISSUE_CASES:
        raise ValueError(f"unknown tissue case {name!r}; choose from {', '.join(TISSUE_CASES)}")
    if size < 64:
        raise ValueError(f"size must be >= 64 px, got {size}")
    spec = TISSUE_CASES[name]
    n_frames = spec.n_frames if n_frames is None else int(n_frames)
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    scale = size - 1
    roi = tuple(f * scale for f in spec.roi)
    center = (0.5 * scale, 0.5 * scale)
    deformation = spec.make(center, size, n_frames)
    light = spec.light(size)
    seq = np.random.SeedSequence(rng)
    texture_rng, noise_rng = (np.random.default_rng(s) for s in seq.spawn(2))
    texture = tissue_texture(spec.texture, size, rng=texture_rng)
    frames = render_frames(
        texture,
        deformation,
        np.arange(n_frames) / (n_frames - 1),
        light=light,
        read_noise=read_noise,
        shot_gain=shot_gain,
        rng=noise_rng,
        progress=progress,
    )
    params = {
        "description": spec.description,
        "suite": "tissue",
        "texture": spec.texture,
        "kind": spec.kind,
        "grid": list(spec.grid),
        "light": light.to_dict(),
        "seed": rng,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
        "interpolation": "cubic B-spline",
    }
    return SyntheticVideo(
        frames, GroundTruth(name, deformation, n_frames, (size, size), roi, params)
    )
