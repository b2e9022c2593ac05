"""A lumen wall that folds as it contracts, seen by the camera and by the microscope.

The camera looks at the wall from above (an orthographic view: the
projection on the x-y plane); the multiphoton microscope measures the wall's
height over a sub-region, before and after.  The wall folds along one
direction ``n`` (crests along ``m``, perpendicular): material coordinates
``(S, Q)`` along ``n`` and ``m`` are arc lengths on the reference wall, and
the folds are attached to the material,

    z = a(t) sin(K S + phase),

with ``K = 2 pi / wavelength``.  The wall also stretches by ``lambda_n(t)``
along the surface in the folding direction and ``lambda_m(t)`` across; its
projection along ``n`` is then

    s(S, t) = integral from 0 to S of sqrt(lambda_n^2 - (a K cos(K u + phase))^2) du,

and ``lambda_m Q`` across (the centre of the view stays put).  The true
membrane strain is homogeneous: ``E = diag((lambda_n^2 - 1) / 2,
(lambda_m^2 - 1) / 2)`` in the ``(n, m)`` frame, whatever the folds do; the
camera's projected strain is not.

Three cases: ``folding`` (no true stretch: the apparent contraction is all
folding), ``mixed`` (a true contraction plus folding) and ``oblique``
(folds across a direction 30 degrees from x, with unequal true stretches:
every component of the projected strain is off).  The reference wall is flat
in ``folding`` and ``oblique``, folded already in ``mixed``.

:func:`make_folding_wall` renders the camera's video (a tissue photograph
carried by the material) and the microscope's height maps before and after
over a sub-region, in the microscope's own pixels and orientation (a known
similarity transform from the camera's pixels), with the exact truth.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sample_data_synth._common import positive, version, write_calibrated_tiff

__all__ = [
    "FOLD_CASES",
    "FoldingWall",
    "FoldingWallCase",
    "folding_wall_stacks",
    "make_folding_wall",
    "write_folding_wall",
]


@dataclass(frozen=True)
class FoldingWall:
    """The wall's geometry over time ``t`` in 0..1 (see the module docstring).

    Lengths in micrometres; the projected plane's origin is the view's centre.
    """

    wavelength_um: float = 150.0
    amplitude_um: tuple[float, float] = (0.0, 30.0)
    stretch: tuple[float, float] = (1.0, 1.0)
    angle_deg: float = 0.0
    phase: float = 0.3
    extent_um: float = 6000.0

    def __post_init__(self) -> None:
        positive(self.wavelength_um, "wavelength_um")
        positive(self.extent_um, "extent_um")
        for lam in self.stretch:
            positive(lam, "stretch")
        k = 2 * math.pi / self.wavelength_um
        for t in (0.0, 1.0):
            a, (ln, _) = self._amplitude(t), self._stretch(t)
            if a * k >= 0.98 * ln:
                raise ValueError(
                    f"folds of {a:g} um over {self.wavelength_um:g} um would overhang "
                    f"(a K = {a * k:.2f} >= stretch {ln:g}): the camera could not see the wall"
                )

    # ------------------------------------------------------------------ over time

    @staticmethod
    def _ramp(t: float) -> float:
        t = min(max(float(t), 0.0), 1.0)
        return t * t * (3 - 2 * t)

    def _amplitude(self, t: float) -> float:
        a0, a1 = self.amplitude_um
        return a0 + (a1 - a0) * self._ramp(t)

    def _stretch(self, t: float) -> tuple[float, float]:
        s = self._ramp(t)
        return 1 + (self.stretch[0] - 1) * s, 1 + (self.stretch[1] - 1) * s

    @property
    def axes(self) -> np.ndarray:
        """(2, 2): columns ``n`` (the folding direction) and ``m``."""
        a = math.radians(self.angle_deg)
        return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])

    def _table(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Material ``S`` and its projection ``s`` on a fine grid (exact to ~1e-9 um)."""
        cache = self.__dict__.setdefault("_tables", {})
        key = round(float(t), 12)
        if key not in cache:
            a, (ln, _) = self._amplitude(t), self._stretch(t)
            k = 2 * math.pi / self.wavelength_um
            S = np.linspace(-self.extent_um, self.extent_um, 2 * int(self.extent_um * 8) + 1)
            slope = a * k * np.cos(k * S + self.phase)
            speed = np.sqrt(ln**2 - slope**2)
            # cumulative Simpson-like (trapezoid on a grid of 1/8 um: error ~1e-10 um per um)
            s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(S))])
            s -= np.interp(0.0, S, s)
            cache[key] = (S, s)
        return cache[key]

    def project(self, material_um: np.ndarray, t: float) -> np.ndarray:
        """Material points (..., 2) (reference wall, flattened) to projected x-y (um) at ``t``."""
        P = np.asarray(material_um, float)
        nm = P @ self.axes  # (S, Q)
        S_tab, s_tab = self._table(t)
        s = np.interp(nm[..., 0], S_tab, s_tab)
        q = nm[..., 1] * self._stretch(t)[1]
        return np.stack([s, q], axis=-1) @ self.axes.T

    def material(self, xy_um: np.ndarray, t: float) -> np.ndarray:
        """Projected points (..., 2) at ``t`` to material points (:meth:`project` undone)."""
        p = np.asarray(xy_um, float) @ self.axes
        S_tab, s_tab = self._table(t)
        S = np.interp(p[..., 0], s_tab, S_tab)
        Q = p[..., 1] / self._stretch(t)[1]
        return np.stack([S, Q], axis=-1) @ self.axes.T

    def height(self, xy_um: np.ndarray, t: float) -> np.ndarray:
        """The wall's height (um) over projected points at ``t``."""
        S = (self.material(xy_um, t) @ self.axes)[..., 0]
        k = 2 * math.pi / self.wavelength_um
        return self._amplitude(t) * np.sin(k * S + self.phase)

    def true_strain(self) -> np.ndarray:
        """(2, 2): the membrane strain at ``t = 1`` in the x-y frame of the reference wall
        (exact; the reference's surface frame over x when the reference is folded and the
        folds run along x)."""
        ln, lm = self.stretch
        Q = self.axes
        return Q @ np.diag([(ln**2 - 1) / 2, (lm**2 - 1) / 2]) @ Q.T

    def tortuosity(self, t: float) -> float:
        """Mean surface length over projected length along ``n`` at ``t``."""
        S, s = self._table(t)
        ln, _ = self._stretch(t)
        return float(ln * (S[-1] - S[0]) / (s[-1] - s[0]))

    def to_dict(self) -> dict:
        return {
            "wavelength_um": self.wavelength_um,
            "amplitude_um": list(self.amplitude_um),
            "stretch": list(self.stretch),
            "angle_deg": self.angle_deg,
            "phase": self.phase,
        }


#: the cases of :func:`make_folding_wall`
FOLD_CASES = {
    # no true stretch: the wall folds (a K = 0.92: tortuosity 1.37 at the end), which the
    # camera sees as a contraction of Exx = -0.23
    "folding": FoldingWall(amplitude_um=(0.0, 22.0), stretch=(1.0, 1.0)),
    # a true contraction of 0.9 along x and 0.96 across, on a wall folded already
    "mixed": FoldingWall(amplitude_um=(10.0, 19.0), stretch=(0.9, 0.96)),
    # folds across 30 degrees from x, true stretches 0.95 and 1.03
    "oblique": FoldingWall(amplitude_um=(0.0, 20.0), stretch=(0.95, 1.03), angle_deg=30.0),
}


@dataclass
class FoldingWallCase:
    """The camera's video and the microscope's height maps of a folding wall, with truth.

    Attributes
    ----------
    frames : (T, H, W) uint8
        The camera's video, ``camera_um`` micrometres per pixel.
    before, after : (Yh, Xh) float
        Height maps (um) of the microscope's sub-region at ``t = 0`` and 1.
    wall : FoldingWall
    camera_um : float
    microscope_um : float
        The height maps' pixel size.
    transform : dict
        Camera pixels to microscope micrometres (``scale_um_per_px``,
        ``angle_deg``, ``shift_um``, ``mirrored``): ``m = scale R(angle) c +
        shift``.
    landmarks : (K, 4) float
        ``camera_x, camera_y`` (px) and ``microscope_x, microscope_y`` (um) of
        K features, as a user would pick them.
    surface_image : (Yh, Xh) uint8
        The microscope's surface-intensity projection of the reference wall:
        the tissue's own texture at the microscope's pixels, with another
        contrast than the camera's (what an automatic registration matches).
    params : dict
    """

    frames: np.ndarray
    before: np.ndarray
    after: np.ndarray
    wall: FoldingWall
    camera_um: float
    microscope_um: float
    transform: dict
    landmarks: np.ndarray
    surface_image: np.ndarray | None = None
    params: dict = field(default_factory=dict)

    @property
    def centre_px(self) -> np.ndarray:
        _, H, W = self.frames.shape
        return np.array([(W - 1) / 2, (H - 1) / 2])

    def camera_to_plane(self, xy_px: np.ndarray) -> np.ndarray:
        """Camera pixels to the projected plane (um, origin at the view's centre)."""
        return (np.asarray(xy_px, float) - self.centre_px) * self.camera_um

    def plane_to_camera(self, xy_um: np.ndarray) -> np.ndarray:
        return np.asarray(xy_um, float) / self.camera_um + self.centre_px

    def true_positions(self, reference_px: np.ndarray, t: float) -> np.ndarray:
        """Where the material under ``reference_px`` on frame 0 is at ``t`` (camera px)."""
        material = self.wall.material(self.camera_to_plane(reference_px), 0.0)
        return self.plane_to_camera(self.wall.project(material, t))


def make_folding_wall(
    case: str = "folding",
    *,
    size: int = 480,
    n_frames: int = 11,
    camera_um: float = 6.0,
    microscope_um: float = 3.0,
    microscope_px: int = 480,
    microscope_angle_deg: float = 12.0,
    noise: float = 1.0,
    rng: int | None = 0,
) -> FoldingWallCase:
    """Render a folding wall (``case`` in :data:`FOLD_CASES`).

    The camera's view is ``size`` pixels square at ``camera_um`` um/px; the
    microscope's height maps are ``microscope_px`` square at ``microscope_um``
    um/px over the view's centre, turned by ``microscope_angle_deg`` (the
    microscope's x axis against the camera's), so the transform from camera
    pixels to the microscope's micrometres is a similarity with scale,
    rotation and shift.
    """
    from scipy import ndimage

    from sample_data_synth.render import add_sensor_noise
    from sample_data_synth.texture import tissue_photograph

    if case not in FOLD_CASES:
        raise ValueError(f"unknown case {case!r}; choose from {', '.join(FOLD_CASES)}")
    wall = FOLD_CASES[case]
    positive(camera_um, "camera_um")
    positive(microscope_um, "microscope_um")
    generator = np.random.default_rng(rng)
    # the texture the material carries: a tissue photograph on a grid of camera pixels
    margin = 1.6
    tex_size = math.ceil(size * margin)
    texture = tissue_photograph(tex_size)
    coefficients = ndimage.spline_filter(texture, order=3, mode="mirror")
    tex_centre = (tex_size - 1) / 2
    yy, xx = np.mgrid[0:size, 0:size].astype(float)
    centre = np.array([(size - 1) / 2, (size - 1) / 2])
    plane = (np.stack([xx, yy], axis=-1) - centre) * camera_um
    frames = []
    times = np.linspace(0.0, 1.0, n_frames)
    for t in times:
        # the material under each pixel, in texture pixels
        m = wall.material(plane, t) / camera_um + tex_centre
        image = ndimage.map_coordinates(
            coefficients, [m[..., 1], m[..., 0]], order=3, mode="mirror", prefilter=False
        )
        frames.append(add_sensor_noise(image, read_noise=noise, rng=generator))
    # the microscope: its pixel (0, 0) and axes in the projected plane
    angle = float(microscope_angle_deg)
    half = (microscope_px - 1) / 2 * microscope_um
    a = math.radians(angle)
    axes = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    # microscope coordinates (um, its own axes, pixel (0, 0) at 0) of plane point p:
    # mic = axes^T p + half
    jj, ii = np.meshgrid(np.arange(microscope_px), np.arange(microscope_px))
    mic = np.stack([jj, ii], axis=-1) * microscope_um
    plane_of_mic = (mic - half) @ axes.T
    before = wall.height(plane_of_mic, 0.0)
    after = wall.height(plane_of_mic, 1.0)
    # the same tissue as the microscope sees its surface: finer pixels, another contrast
    m = wall.material(plane_of_mic, 0.0) / camera_um + tex_centre
    seen = ndimage.map_coordinates(
        coefficients, [m[..., 1], m[..., 0]], order=3, mode="mirror", prefilter=False
    )
    seen = 30.0 + 200.0 * (np.clip(seen, 0.0, 255.0) / 255.0) ** 1.4
    surface_image = add_sensor_noise(seen, read_noise=2.0 * noise, rng=generator)
    # camera px -> plane um: (c - centre) * camera_um; plane -> mic: axes^T p + half
    scale = camera_um
    rot = -angle  # axes^T is a rotation by -angle
    shift = half - scale * (axes.T @ centre)
    transform = {
        "scale_um_per_px": scale,
        "angle_deg": rot,
        "shift_um": [float(shift[0]), float(shift[1])],
        "mirrored": False,
    }
    # landmarks a user would pick: features inside the microscope's field, on frame 0
    k = 6
    picks = generator.uniform(-0.35, 0.35, size=(k, 2)) * (microscope_px * microscope_um)
    cam = picks / camera_um + centre  # frame 0 shows the reference wall
    mic_pts = picks @ axes + half  # plane -> microscope
    # picked by hand: a third of a camera pixel, a micrometre on the microscope's image
    cam = cam + generator.normal(0.0, 0.3, cam.shape)
    mic_pts = mic_pts + generator.normal(0.0, 1.0, mic_pts.shape)
    landmarks = np.column_stack([cam, mic_pts])
    return FoldingWallCase(
        frames=np.stack(frames),
        before=before,
        after=after,
        wall=wall,
        camera_um=camera_um,
        microscope_um=microscope_um,
        transform=transform,
        landmarks=landmarks,
        surface_image=surface_image,
        params={
            "generator": "sample_data_synth.folds",
            "version": version(),
            "case": case,
            "size": size,
            "n_frames": n_frames,
            "camera_um": camera_um,
            "microscope_um": microscope_um,
            "microscope_px": microscope_px,
            "microscope_angle_deg": angle,
            "noise": noise,
            "rng": rng,
            "wall": wall.to_dict(),
        },
    )


def write_folding_wall(case: FoldingWallCase, out: str | os.PathLike) -> dict[str, Path]:
    """Write the case into folder ``out``: ``video.avi``, ``before_heightmap.tif`` and
    ``after_heightmap.tif`` (float32 um with their pixel size, as ``mpm3d analyze`` writes
    them), ``before_surface.tif`` (the microscope's surface-intensity projection),
    ``landmarks.csv``, ``transform.json`` and ``truth.json``."""
    import json

    from sample_data_synth.cases import write_video

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "video": out / "video.avi",
        "before": out / "before_heightmap.tif",
        "after": out / "after_heightmap.tif",
        "surface": out / "before_surface.tif",
        "landmarks": out / "landmarks.csv",
        "transform": out / "transform.json",
        "truth": out / "truth.json",
    }
    write_video(case.frames, paths["video"])
    for name in ("before", "after"):
        heights = getattr(case, name).astype(np.float32)
        write_calibrated_tiff(paths[name], heights, case.microscope_um, spacing=1.0)
    if case.surface_image is not None:
        write_calibrated_tiff(paths["surface"], case.surface_image, case.microscope_um)
    rows = ["camera_x,camera_y,microscope_x,microscope_y"]
    rows += [",".join(f"{v:.6f}" for v in row) for row in case.landmarks]
    paths["landmarks"].write_text("\n".join(rows) + "\n", encoding="utf-8")
    paths["transform"].write_text(json.dumps(case.transform, indent=2) + "\n", encoding="utf-8")
    truth = {
        **case.params,
        "transform": case.transform,
        "true_strain_xy": case.wall.true_strain().tolist(),
        "tortuosity": [case.wall.tortuosity(0.0), case.wall.tortuosity(1.0)],
    }
    paths["truth"].write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return paths


def folding_wall_stacks(
    case: FoldingWallCase,
    *,
    dz_um: float = 2.0,
    tissue_below_um: float = 40.0,
    rng: int | None = 0,
) -> tuple:
    """Multiphoton z-stacks of the microscope's sub-region before and after: the tissue
    under the wall's surface as :func:`sample_data_synth.stacks.render_stack` renders it
    (a :class:`~sample_data_synth.stacks.SyntheticStack` each, the exact surface with it),
    the urothelium textured with the reference wall's pattern (``surface_image``; after
    the deformation the stack shows it unmoved, as only the reference is registered)."""
    from sample_data_synth.stacks import SyntheticStack, render_stack

    positive(dz_um, "dz_um")
    generator = np.random.default_rng(rng)
    top = max(float(np.max(case.before)), float(np.max(case.after)))
    low = min(float(np.min(case.before)), float(np.min(case.after)))
    margin = 3 * dz_um
    n_slices = math.ceil((top - low + margin + tissue_below_um) / dz_um) + 1
    spacing = (dz_um, case.microscope_um, case.microscope_um)
    stacks = []
    for name, height in (("before", case.before), ("after", case.after)):
        # depth below slice 0: the highest crest lies `margin` below it
        depth = margin + (top - height)
        # the urothelium carries the tissue's own pattern (what the camera sees too), drawn on
        # the reference wall: its surface-intensity projection registers to the camera's frame
        stack = render_stack(
            depth, n_slices=n_slices, spacing=spacing, rng=generator,
            cell_texture=case.surface_image, urothelium_contrast=0.15,
        )  # fmt: skip
        stacks.append(
            SyntheticStack(
                name=f"folding wall {name}",
                stack=stack,
                spacing=spacing,
                depth_um=depth,
                height_um=(n_slices - 1) * dz_um - depth,
                info={"surface_offset_um": margin + top},
                params={**case.params, "state": name, "dz_um": dz_um},
            )
        )
    return tuple(stacks)
