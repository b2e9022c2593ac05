"""The stereo scenes' renderer: sub-pixel rays through the camera model onto textured surfaces.

How a frame is made and how exact it is: "Rendering" in
:mod:`sample_data_synth.stereo`.  A scene gives a ``Shader``, the gray level
seen along each ray; :func:`_render_view` averages the sub-pixel samples over
each pixel and :func:`_finish` adds the lens blur, uneven lighting, sensor
noise, 8-bit quantization and JPEG compression.  Textures are
:class:`_Raster` images in material coordinates.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from sample_data_synth._common import non_negative as _non_negative
from sample_data_synth.camera import Camera, StereoRig, undistort_points
from sample_data_synth.render import add_sensor_noise

# gray levels of the textures before lighting and noise
_DARK, _LIGHT, _BACKGROUND = 30.0, 220.0, 70.0


@dataclass(frozen=True)
class _Raster:
    """A band-limited texture in material coordinates, sampled bilinearly.

    ``values[i, j]`` is the texture at ``(x0 + j * texel, y0 + i * texel)``.
    """

    values: np.ndarray
    origin: tuple[float, float]
    texel: float

    def __post_init__(self) -> None:
        h, w = self.values.shape
        if max(h, w) >= 32000:  # cv2.remap's limit
            raise ValueError(f"texture of {w} x {h} texels is too large")

    def sample(self, X: np.ndarray, outside: float) -> np.ndarray:
        """Bilinear samples ``(N,)`` at material points ``X`` ``(N, 2)``; ``outside``
        beyond the raster (blended over one texel) and at NaN."""
        import cv2

        n = len(X)
        width = 4096
        uv = np.full((-(-n // width) * width, 2), -8.0, dtype=np.float32)
        with np.errstate(invalid="ignore"):
            uv[:n] = (X - self.origin) / self.texel
        uv[~np.isfinite(uv).all(axis=1)] = -8.0
        uv = uv.reshape(-1, width, 2)
        # cv2.remap interpolates with 1/32-texel weights: 0.002 mm for the boards
        values = cv2.remap(
            self.values,
            uv,
            None,
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
            borderValue=float(outside),
        )
        return values.ravel()[:n].astype(float)


def _sample_rays(rig: StereoRig, camera: Camera, supersample: int) -> np.ndarray:
    """Normalized rays ``(2, H * s, W * s)`` (``x_n``, ``y_n``) of every sub-pixel sample."""
    w, h = rig.image_size
    s = supersample
    off = (np.arange(s) + 0.5) / s - 0.5
    xs = (np.arange(w)[:, None] + off).ravel()
    ys = (np.arange(h)[:, None] + off).ravel()
    rays = np.empty((2, h * s, w * s))
    step = max(1, 250_000 // len(xs))
    for r0 in range(0, len(ys), step):
        yy = np.broadcast_to(ys[r0 : r0 + step, None], (len(ys[r0 : r0 + step]), len(xs)))
        xn = undistort_points(rig, np.stack([np.broadcast_to(xs, yy.shape), yy], -1), camera=camera)
        rays[:, r0 : r0 + step] = np.moveaxis(xn, -1, 0)
    return rays


#: ``shade(origin (3,), M (3, 3), x_n (n,), y_n (n,)) -> (n,)`` gray levels of the rays
#: from ``origin`` along ``M @ (x_n, y_n, 1)`` (left coordinates)
Shader = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _local_rays(
    origin: np.ndarray, M: np.ndarray, xn: np.ndarray, yn: np.ndarray, center, axes
) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Ray origin and direction components in the frame ``(center, axes)``."""
    o = (np.asarray(origin, dtype=float) - center) @ axes
    A = axes.T @ M
    return o, tuple(A[i, 0] * xn + A[i, 1] * yn + A[i, 2] for i in range(3))


def _render_view(
    rig: StereoRig, camera: Camera, rays: np.ndarray, shade: Shader, supersample: int
) -> np.ndarray:
    """Average the shaded sub-pixel samples over each pixel."""
    Rc, Cc = rig.pose(camera)
    s = supersample
    w, h = rig.image_size
    image = np.empty((h, w))
    rows = max(1, 250_000 // (w * s * s))
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        xn = rays[0, r0 * s : r1 * s].ravel()
        yn = rays[1, r0 * s : r1 * s].ravel()
        values = shade(Cc, Rc, xn, yn).reshape((r1 - r0) * s, w, s).sum(axis=-1)
        image[r0:r1] = values.reshape(r1 - r0, s, w).sum(axis=1) / (s * s)
    return image


def _finish(
    image: np.ndarray,
    rng: np.random.Generator,
    *,
    blur_sigma: float,
    lighting: float,
    noise: float,
    jpeg_quality: int | None,
) -> np.ndarray:
    """Lens blur, uneven lighting, Gaussian noise, 8 bits, optional JPEG."""
    if blur_sigma > 0:
        image = ndimage.gaussian_filter(image, blur_sigma, mode="nearest")
    if lighting > 0:
        h, w = image.shape
        angle = rng.uniform(0, 2 * np.pi)
        yy, xx = np.mgrid[0:h, 0:w]
        ramp = (xx - (w - 1) / 2) * np.cos(angle) + (yy - (h - 1) / 2) * np.sin(angle)
        image = image * (1 + lighting * ramp / (0.5 * math.hypot(w, h)))
    out = add_sensor_noise(image, read_noise=noise, shot_gain=0.0, rng=rng)
    if jpeg_quality is not None:
        import cv2

        ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)])
        if not ok:
            raise OSError("OpenCV could not encode a JPEG")
        out = cv2.imdecode(buf, cv2.IMREAD_GRAYSCALE)
    return out


def _check_render_options(supersample: int, blur_sigma: float, noise: float) -> None:
    if int(supersample) != supersample or not 1 <= supersample <= 8:
        raise ValueError(f"supersample must be an integer in 1..8, got {supersample!r}")
    _non_negative(blur_sigma, "blur_sigma")
    _non_negative(noise, "noise")
