"""The source paper's benchmark cases as synthetic videos with exact ground truth.

=============  ===========================================  ====================
case           mapping at the last frame                    analytic E
=============  ===========================================  ====================
equibiaxial    x = c + 1.5 (X - c)                          Exx = Eyy = 0.625
rotation       rigid rotation by 30 degrees about c         0
shear          x = X + 0.5 (Y - Y0), y = Y                  Eyy = 0.125, Exy = 0.25
tissue         x = c + 0.6 (X - c) on a tissue photograph   Exx = Eyy = -0.32
=============  ===========================================  ====================

Beyond the paper, three heterogeneous fields with analytic truth (see
:class:`sample_data_synth.deformations.Field`): ``gaussian`` (a local
contraction), ``sinusoid`` (strain varying periodically) and ``fold`` (a narrow
compression band, a fold-like strain concentration).

Geometry follows the paper (800 x 800 px, 7 x 7 grid): each case's grid
region is placed so the largest grid displacement matches the paper's (about
140, 105 and 200 px for equibiaxial, rotation and shear).  Every frame ramps
the deformation linearly in its parameter from the identity (frame 0) to the
final value, so the video is a video and not a before/after pair.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sample_data_synth.deformations import (
    Contraction,
    Field,
    Homogeneous,
    RampHold,
    Twitch,
    deformation_from_dict,
    equibiaxial,
    rotation,
    simple_shear,
    time_profile_from_dict,
)
from sample_data_synth.render import add_sensor_noise, render_image, render_speckle
from sample_data_synth.speckle import speckle_pattern

__all__ = ["CASES", "GroundTruth", "SyntheticVideo", "load_ground_truth", "make_case"]


def _version() -> str:
    from sample_data_synth import __version__

    return __version__


@dataclass(frozen=True)
class _CaseSpec:
    description: str
    texture: str  # "speckle" or "tissue"
    # fractions of the image size: grid region (x0, y0, x1, y1) and fixed point
    roi: tuple[float, float, float, float]
    center: tuple[float, float]
    make: Callable[[tuple[float, float], float], Homogeneous | Field]  # (centre px, size px)
    paper_max_displacement_px: float | None


def _sym(half: float) -> tuple[float, float, float, float]:
    return (0.5 - half, 0.5 - half, 0.5 + half, 0.5 + half)


CASES: dict[str, _CaseSpec] = {
    "equibiaxial": _CaseSpec(
        "equibiaxial stretch 1.5 of a speckle pattern",
        "speckle",
        _sym(0.2475),
        (0.5, 0.5),
        lambda c, size: equibiaxial(1.5, c),
        140.0,
    ),
    "rotation": _CaseSpec(
        "rigid rotation by 30 degrees of a speckle pattern",
        "speckle",
        _sym(0.1794),
        (0.5, 0.5),
        lambda c, size: rotation(30.0, c),
        105.0,
    ),
    "shear": _CaseSpec(
        "simple shear 0.5 of a speckle pattern, fixed line at the top of the grid",
        "speckle",
        (0.2, 0.25, 0.55, 0.75),
        (0.375, 0.25),
        lambda c, size: simple_shear(0.5, c),
        200.0,
    ),
    "tissue": _CaseSpec(
        "equibiaxial contraction 0.6 of a tissue photograph",
        "tissue",
        _sym(0.3125),
        (0.5, 0.5),
        lambda c, size: equibiaxial(0.6, c),
        None,
    ),
    # heterogeneous fields (beyond the paper); sizes scale with the frame
    "gaussian": _CaseSpec(
        "local Gaussian contraction of a speckle pattern (a = 0.3, s = 8% of the frame; "
        "E = -0.255 at the centre)",
        "speckle",
        _sym(0.3),
        (0.5, 0.5),
        lambda c, size: Field("gaussian", c, a=0.3, s=0.08 * size),
        None,
    ),
    "sinusoid": _CaseSpec(
        "sinusoidal displacement of a speckle pattern (amplitude 1%, wavelength 40% of "
        "the frame; Exx, Eyy between -0.15 and 0.17)",
        "speckle",
        _sym(0.3),
        (0.5, 0.5),
        lambda c, size: Field("sinusoid", c, amplitude=0.01 * size, wavelength=0.4 * size),
        None,
    ),
    "fold": _CaseSpec(
        "fold-like compression band across x of a speckle pattern (a = 0.4, half-width "
        "4% of the frame; Exx = -0.32 on its axis)",
        "speckle",
        _sym(0.3),
        (0.5, 0.5),
        lambda c, size: Field("fold", c, a=0.4, width=0.04 * size),
        None,
    ),
}


@dataclass
class GroundTruth:
    """Exact motion of every point of a synthetic video.

    Attributes
    ----------
    case : str
    deformation : Homogeneous, Field or Contraction
        Positions, gradient and strain at any reference point and time.
    n_frames : int
    image_size : (H, W)
    roi : (x0, y0, x1, y1)
        The case's grid region in pixels.
    params : dict
        Rendering parameters (pattern, noise, seed).
    time_profile : RampHold, Twitch or None
        How frames map to the deformation's time ``t``; None (the benchmark
        cases) is the linear ramp ``t = k / (n_frames - 1)``.
    """

    case: str
    deformation: Homogeneous | Field | Contraction
    n_frames: int
    image_size: tuple[int, int]
    roi: tuple[float, float, float, float]
    params: dict = field(default_factory=dict)
    time_profile: RampHold | Twitch | None = None

    def __post_init__(self) -> None:
        if self.n_frames < 2:
            raise ValueError(f"a video needs at least 2 frames, got n_frames={self.n_frames}")
        if len(self.image_size) != 2 or min(self.image_size) < 1:
            raise ValueError(f"image_size must be (width, height) > 0, got {self.image_size}")
        if len(self.roi) != 4 or not all(math.isfinite(v) for v in self.roi):
            raise ValueError(f"roi must be four finite numbers, got {self.roi}")
        if self.time_profile is not None and self.time_profile.endpoint > self.n_frames - 1:
            raise ValueError(
                f"the time profile's endpoint {self.time_profile.endpoint} is past the last "
                f"frame {self.n_frames - 1}"
            )

    def time(self, frame: int) -> float:
        """Normalized time of a frame: 0 on the first, 1 on the last (linear ramp), or
        as ``time_profile`` says (from the endpoint on for a ramp and hold)."""
        if self.time_profile is not None:
            return self.time_profile(frame)
        return frame / (self.n_frames - 1)

    def positions(self, points: np.ndarray, frame: int | None = None) -> np.ndarray:
        """True positions of reference ``points`` (N, 2): ``(N, 2)`` for one frame,
        ``(T, N, 2)`` for all frames when ``frame`` is None."""
        if frame is None:
            return np.stack([self.positions(points, k) for k in range(self.n_frames)])
        return self.deformation.forward(points, self.time(frame))

    def gradient(self, points: np.ndarray, frame: int) -> np.ndarray:
        """True deformation gradient at reference ``points``, ``(N, 2, 2)``."""
        return self.deformation.gradient(points, self.time(frame))

    def strain(self, points: np.ndarray, frame: int) -> np.ndarray:
        """True Green-Lagrange strain at reference ``points``, ``(N, 2, 2)``."""
        return self.deformation.strain(points, self.time(frame))

    def grid(self, shape: tuple[int, int] = (7, 7)) -> np.ndarray:
        """Reference grid ``(n_rows * n_cols, 2)`` over the case's ROI, row-major."""
        x0, y0, x1, y1 = self.roi
        gx, gy = np.meshgrid(np.linspace(x0, x1, shape[0]), np.linspace(y0, y1, shape[1]))
        return np.column_stack([gx.ravel(), gy.ravel()])

    def to_dict(self) -> dict:
        # at the deformation's centre (the strain is uniform for the paper's cases)
        final_E = self.strain(self.deformation.center[None], self.n_frames - 1)[0]
        if self.case in CASES:
            description = CASES[self.case].description
        else:
            description = self.params.get("description", "")
        out = {
            "case": self.case,
            "description": description,
            "deformation": self.deformation.to_dict(),
            "n_frames": self.n_frames,
            "image_size": list(self.image_size),
            "roi": list(self.roi),
            "final_E": {"Exx": final_E[0, 0], "Eyy": final_E[1, 1], "Exy": final_E[0, 1]},
            "time": "linear ramp: frame k has t = k / (n_frames - 1)",
            "pixel_convention": "x = column, y = row, centre of the top-left pixel at (0, 0)",
            "params": self.params,
            "software": {"sample_data_synth": _version()},
        }
        if self.time_profile is not None:
            out["time"] = self.time_profile.describe()
            out["time_profile"] = self.time_profile.to_dict()
        return out

    def save(self, path: str | os.PathLike) -> None:
        from tissue_core.jsonio import write_json

        write_json(path, self.to_dict())


def load_ground_truth(path: str | os.PathLike) -> GroundTruth:
    """Read ground truth written by :meth:`GroundTruth.save`.

    Raises
    ------
    tissue_core.errors.SourceError
        The file is missing or unreadable.
    tissue_core.errors.InputError
        It is not a ground-truth file (malformed JSON, missing or ill-typed keys).
    """
    from tissue_core.errors import InputError, SourceError

    try:
        with open(path, encoding="utf-8") as f:
            d = json.load(f)
    except IsADirectoryError:
        raise SourceError(f"{path} is a folder, not a ground-truth file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SourceError(f"cannot read the ground truth {path}: {exc}") from None
    except ValueError as exc:
        raise InputError(f"{path} is not a ground-truth file: malformed JSON ({exc})") from None
    try:
        return GroundTruth(
            case=str(d["case"]),
            deformation=deformation_from_dict(d["deformation"]),
            n_frames=int(d["n_frames"]),
            image_size=tuple(int(v) for v in d["image_size"]),
            roi=tuple(float(v) for v in d["roi"]),
            params=dict(d.get("params", {})),
            time_profile=time_profile_from_dict(d["time_profile"]) if "time_profile" in d else None,
        )
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        raise InputError(
            f"{path} is not a ground-truth file written by sample_data_synth "
            f"({type(exc).__name__}: {exc})"
        ) from None


@dataclass
class SyntheticVideo:
    """Frames ``(T, H, W)`` uint8 and their ground truth."""

    frames: np.ndarray
    truth: GroundTruth


def _reference_bounds(deformation, shape, times, margin: float) -> tuple[float, ...]:
    h, w = shape
    corners = np.array([[0, 0], [w - 1, 0], [0, h - 1], [w - 1, h - 1]], dtype=float)
    pts = np.concatenate([deformation.inverse(corners, t) for t in times])
    lo, hi = pts.min(axis=0) - margin, pts.max(axis=0) + margin
    return (lo[0], lo[1], hi[0], hi[1])


def make_case(
    name: str,
    *,
    size: int = 800,
    n_frames: int = 31,
    speckle_radius: float = 2.0,
    speckle_density: float = 1.0,
    speckle_contrast: float = 0.8,
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    rng: int | None = 0,
    progress: Callable[[int, int], None] | None = None,
) -> SyntheticVideo:
    """Render one of the paper's cases (see the module docstring).

    Parameters
    ----------
    name : {"equibiaxial", "rotation", "shear", "tissue", "gaussian", "sinusoid", "fold"}
    size : int, keyword-only
        Frame width and height in pixels (the paper: 800).  The geometry
        scales with it; speckle size does not.
    n_frames : int, keyword-only
        Frames including the reference (>= 2).
    speckle_radius, speckle_density, speckle_contrast : keyword-only
        See :func:`sample_data_synth.speckle.speckle_pattern`.
    read_noise, shot_gain : keyword-only
        See :func:`sample_data_synth.render.add_sensor_noise`; 0 and 0 give
        noise-free (only quantized) frames.
    rng : int, keyword-only
        Seed for the pattern and the noise.
    progress : callable(done, total), keyword-only

    Returns
    -------
    SyntheticVideo
    """
    if name not in CASES:
        raise ValueError(f"unknown case {name!r}; choose from {', '.join(CASES)}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    if size < 64:
        raise ValueError(f"size must be >= 64 px, got {size}")
    spec = CASES[name]
    scale = size - 1
    roi = tuple(f * scale for f in spec.roi)
    center = (spec.center[0] * scale, spec.center[1] * scale)
    deformation = spec.make(center, size)
    shape = (size, size)
    times = np.linspace(0.0, 1.0, n_frames)
    seq = np.random.SeedSequence(rng)
    pattern_rng, noise_rng = (np.random.default_rng(s) for s in seq.spawn(2))
    params: dict = {
        "texture": spec.texture,
        "seed": rng,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
    }
    if spec.texture == "speckle":
        bounds = _reference_bounds(deformation, shape, times, margin=6 * speckle_radius)
        pattern = speckle_pattern(
            bounds,
            radius=speckle_radius,
            density=speckle_density,
            contrast=speckle_contrast,
            rng=pattern_rng,
        )
        params.update(
            speckle_radius=speckle_radius,
            speckle_density=speckle_density,
            speckle_contrast=speckle_contrast,
            psf_sigma=0.5,
        )

        def render(t: float) -> np.ndarray:
            return render_speckle(pattern, deformation, t, shape)
    else:
        from scipy import ndimage

        from sample_data_synth.texture import tissue_photograph

        coefficients = ndimage.spline_filter(tissue_photograph(size), order=3, mode="mirror")
        params.update(
            photograph="scikit-image ihc.png, gray, resized", interpolation="cubic B-spline"
        )

        def render(t: float) -> np.ndarray:
            return render_image(coefficients, deformation, t, shape)

    frames = np.empty((n_frames, size, size), dtype=np.uint8)
    for k, t in enumerate(times):
        frames[k] = add_sensor_noise(
            render(t), read_noise=read_noise, shot_gain=shot_gain, rng=noise_rng
        )
        if progress:
            progress(k + 1, n_frames)
    truth = GroundTruth(name, deformation, n_frames, shape, roi, params)
    truth.params["paper_max_displacement_px"] = spec.paper_max_displacement_px
    return SyntheticVideo(frames, truth)


def write_video(frames: np.ndarray, path: str | os.PathLike, *, fps: float = 10.0) -> None:
    """Write ``(T, H, W)`` uint8 frames as ``.avi`` (lossless FFV1), ``.mp4`` (MPEG-4
    part 2, lossy) or ``.tif`` (multi-page, lossless)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".tif", ".tiff"):
        import tifffile

        tifffile.imwrite(path, frames, photometric="minisblack")
        return
    import cv2

    from tissue_core.filenames import utf8_output

    fourcc = {".avi": "FFV1", ".mp4": "mp4v", ".mkv": "FFV1"}.get(suffix)
    if fourcc is None:
        raise ValueError(f"video format must be .avi, .mp4, .mkv or .tif, got {path.name}")
    h, w = frames.shape[1:]
    with utf8_output(path) as target:  # OpenCV crashes on a name that is not UTF-8
        code = cv2.VideoWriter_fourcc(*fourcc)
        writer = cv2.VideoWriter(str(target), code, fps, (w, h), isColor=False)
        if not writer.isOpened():
            raise OSError(f"OpenCV cannot write {path} with codec {fourcc}")
        try:
            for frame in frames:
                writer.write(np.ascontiguousarray(frame))
        finally:
            writer.release()
