"""Synthetic stereo scenes with exact ground truth: calibration targets and deforming surfaces.

Conventions (a contract: the stereo package is written against it)
-------------------------------------------------------------------
* Camera model: OpenCV's pinhole camera with distortion ``(k1, k2, p1, p2,
  k3)``; :meth:`StereoRig.project` is ``cv2.projectPoints``.
* A point ``X_left`` in left-camera coordinates is ``X_right = R @ X_left + T``
  in right-camera coordinates (``cv2.stereoCalibrate``'s ``R``, ``T``).  The
  world frame is the left camera frame.  Lengths are in millimetres.
* Pixels: ``x`` = column, ``y`` = row, the centre of the top-left pixel is
  ``(0, 0)`` (OpenCV's convention).
* Board poses: ``X_left = R_b @ X_board + t_b`` with ``X_board = (x, y, 0)`` on
  the board, ``x`` along its columns, ``y`` along its rows, ``z`` into the
  board (away from a camera that faces it).  A :class:`Checkerboard`'s origin is
  its first inner corner, its object points are ``(j * square, i * square, 0)``
  row-major (OpenCV's usual ``objp``); a :class:`CharucoBoard`'s are
  ``cv2.aruco.CharucoBoard.getChessboardCorners()`` (origin at the board's
  outer top-left corner); a :class:`CircleGrid`'s are its dot centres in
  ``cv2.findCirclesGrid``'s order (origin at the first dot).  The "corners"
  of a circle grid (``image_points``) are the projected dot centres, which
  are not the centres of the dots' images (an ellipse's centre is not the
  projection of the circle's centre): a detector that takes blob centroids is
  biased by a few hundredths of a pixel on tilted views.
* Surfaces: a material point ``X = (X1, X2)`` (mm) of the reference sheet or
  disc sits at ``c + X1 e1 + X2 e2`` at frame 0; ``e1``, ``e2`` are the
  material axes (``e1`` roughly along image x, ``e2`` along image y) and the
  strains are Green-Lagrange tensors in that ``(X1, X2)`` frame.  Frame ``k``
  of ``T`` has the normalized time ``t = k / (T - 1)``; every mapping
  parameter ramps linearly in ``t``.

Rendering
---------
Every output pixel is split into ``supersample x supersample`` sub-pixel rays;
each sample's pixel position is undistorted to a normalized ray
(``cv2.undistortPoints``, then Newton's method on the OpenCV distortion model:
the round trip through ``cv2.projectPoints`` is below 1e-9 px), the ray is
intersected with the scene surface in closed form, mapped to the surface's
material (texture) coordinates and the texture is sampled there.  Textures
are rasters in material coordinates (boards drawn at 200 texels per square
and band-limited by a Gaussian of one texel; speckle dots evaluated exactly
at ``speckle_radius / 5`` per texel), sampled bilinearly by ``cv2.remap``
(1/32-texel weights: 0.002 mm on a 10 mm board).  The samples are averaged
(pixel integration), blurred (``blur_sigma``, the lens), optionally lit
unevenly, given Gaussian sensor noise and quantized to 8 bits (and
optionally JPEG-compressed).

Features land where ``cv2.projectPoints`` says.  Rendered at 4x the
resolution, checkerboard corners found by ``cv2.cornerSubPix`` lie 0.005 px
RMS (in 1x pixels) from the projected truth: the renderer's own error.  At
1x with the default 0.7 px blur, ``cornerSubPix`` reads them 0.02-0.05 px
RMS off (0.03 px over 15 default views at 1024 x 768; its own sampling bias
on corners a few pixels wide, with no mean shift), and ``cv2.stereoCalibrate``
on those views returns the baseline within 0.01 % at 0.03 px RMS.  The
ChArUco detector's corners are 0.03-0.16 px RMS off per image: its marker
edges sit close to the corners on steeply tilted views.

Cases
-----
``stretch``
    A flat speckled sheet (80 x 60 mm) about 450 mm from the cameras, slightly
    tilted, stretched biaxially in its plane:
    ``x = c + lam1(t) X1 e1 + lam2(t) X2 e2`` with ``lam1`` from 1 to 1.25 and
    ``lam2`` from 1 to 1.10, so ``E11 = (lam1^2 - 1) / 2``,
    ``E22 = (lam2^2 - 1) / 2``, ``E12 = 0``.
``dome``
    A flat circular membrane (radius ``a`` = 35 mm) clamped in a fixed plate,
    inflating into a spherical cap whose apex rises from 0 to 12 mm.  The
    material radius ``rho`` maps to the arc length ``s = lam_m rho`` from the
    apex on a sphere of curvature ``kappa = 2 h / (a^2 + h^2)`` (apex height
    ``h``), with the meridional stretch ``lam_m = asin(kappa a) / (kappa a)``
    uniform, so the rim stays in place.  The circumferential stretch is
    ``lam_c = sin(kappa s) / (kappa rho)``; in the (meridional,
    circumferential) frame ``E = diag((lam_m^2 - 1) / 2, (lam_c^2 - 1) / 2)``.
    The flat frame (``kappa = 0``) is the limit of the same stable
    expressions.  The plate around the membrane does not move.

Modules
-------
The parts live beside this module: the camera model in
:mod:`sample_data_synth.camera`, the calibration targets in
:mod:`sample_data_synth.boards`, the renderer in ``_raytrace`` and the
analytic surfaces in ``_surfaces``.  This module composes them into scenes,
writes and reads the scenes' files, and re-exports the parts' public names.

References
----------
Zhang, Z. (2000). A flexible new technique for camera calibration. IEEE
TPAMI 22(11), 1330-1334. https://doi.org/10.1109/34.888718

Holzapfel, G. A. (2000). Nonlinear Solid Mechanics. Wiley (Green-Lagrange
strain ``E = (F^T F - I) / 2``, section 2.4).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from sample_data_synth._common import Rng
from sample_data_synth._common import positive as _positive
from sample_data_synth._common import spawn as _spawn
from sample_data_synth._common import version as _version
from sample_data_synth._raytrace import (
    _BACKGROUND,
    _DARK,
    _LIGHT,
    _check_render_options,
    _finish,
    _local_rays,
    _render_view,
    _sample_rays,
)
from sample_data_synth._raytrace import Shader as Shader
from sample_data_synth._surfaces import (
    TextureKind,
    _Dome,
    _Sheet,
    _surface_from_dict,
    _surface_texture,
)
from sample_data_synth.boards import Board, CharucoBoard, Checkerboard, CircleGrid, parse_board
from sample_data_synth.camera import (
    Camera,
    StereoRig,
    _rotation,
    _rotation_vector,
    default_rig,
    undistort_points,
)
from sample_data_synth.speckle import SpecklePattern
from tissue_core.jsonio import write_json

__all__ = [
    "STEREO_CASES",
    "CalibrationViews",
    "CharucoBoard",
    "Checkerboard",
    "CircleGrid",
    "StereoRig",
    "StereoScene",
    "default_rig",
    "load_stereo_scene",
    "parse_board",
    "render_calibration_views",
    "render_surface_scene",
    "save_calibration_views",
    "save_stereo_scene",
    "undistort_points",
]

SurfaceCase = Literal["stretch", "dome"]
StrainAxes = Literal["material", "polar"]

#: the stereo cases and what they show
STEREO_CASES: dict[str, str] = {
    "calibration": "stereo views of a checkerboard or ChArUco target with the true board poses",
    "stretch": "speckled 80 x 60 mm sheet at 450 mm stretched biaxially to 1.25 x 1.10",
    "dome": "speckled membrane (radius 35 mm) at 450 mm inflating into a 12 mm spherical cap",
}

CONVENTIONS = {
    "camera_model": "OpenCV pinhole with distortion (k1, k2, p1, p2, k3); cv2.projectPoints",
    "extrinsics": "X_right = R @ X_left + T (cv2.stereoCalibrate); world frame = left camera",
    "unit": "mm",
    "pixels": "x = column, y = row, centre of the top-left pixel at (0, 0)",
    "board_pose": "X_left = R @ X_board + t; X_board = (x, y, 0), z into the board",
    "material": "X = (X1, X2) mm along the material axes e1, e2; strains in that frame",
    "time": "frame k of T has t = k / (T - 1); mapping parameters ramp linearly in t",
}


# --------------------------------------------------------------------------- calibration


@dataclass
class CalibrationViews:
    """Rendered stereo views of a calibration board and the true board poses.

    Attributes
    ----------
    left, right : (V, H, W) uint8
        The views of the left and right camera.
    rig : StereoRig
    board : Checkerboard, CharucoBoard or CircleGrid
    rotations : (V, 3, 3) float
        ``R_b`` per view: ``X_left = R_b @ X_board + t_b``.
    translations : (V, 3) float
        ``t_b`` per view, mm.
    fully_visible : (V,) bool
        Whether the whole board (with its margin) is inside both images.
    params : dict
        Rendering parameters.
    """

    left: np.ndarray
    right: np.ndarray
    rig: StereoRig
    board: Board
    rotations: np.ndarray
    translations: np.ndarray
    fully_visible: np.ndarray
    params: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        w, h = self.rig.image_size
        n = len(self.rotations)
        for name in ("left", "right"):
            if getattr(self, name).shape != (n, h, w):
                raise ValueError(f"{name} must be ({n}, {h}, {w}), got {getattr(self, name).shape}")
        if self.translations.shape != (n, 3) or self.fully_visible.shape != (n,):
            raise ValueError("translations must be (V, 3) and fully_visible (V,)")

    @property
    def n_views(self) -> int:
        return len(self.rotations)

    def object_points(self) -> np.ndarray:
        """The board's corners ``(N, 3)`` in board mm (see the board class)."""
        return self.board.object_points()

    def image_points(self, view: int, camera: Camera = "left") -> np.ndarray:
        """True pixel positions ``(N, 2)`` of the board's corners in one view."""
        points = self.object_points() @ self.rotations[view].T + self.translations[view]
        return self.rig.project(points, camera)

    def __repr__(self) -> str:
        w, h = self.rig.image_size
        return (
            f"CalibrationViews({self.board.spec()}, {self.n_views} views of {w}x{h} px, "
            f"{int(self.fully_visible.sum())} fully visible)"
        )


def _outline(extent: tuple[float, float, float, float], n: int = 12) -> np.ndarray:
    """Points ``(4 n, 3)`` along a board's border."""
    x0, y0, x1, y1 = extent
    s = np.linspace(0, 1, n, endpoint=False)
    return np.concatenate(
        [
            np.column_stack([x0 + s * (x1 - x0), np.full(n, y0), np.zeros(n)]),
            np.column_stack([np.full(n, x1), y0 + s * (y1 - y0), np.zeros(n)]),
            np.column_stack([x1 - s * (x1 - x0), np.full(n, y1), np.zeros(n)]),
            np.column_stack([np.full(n, x0), y1 - s * (y1 - y0), np.zeros(n)]),
        ]
    )


def _inside(rig: StereoRig, xy: np.ndarray, margin: float) -> np.ndarray:
    w, h = rig.image_size
    return (
        (xy[:, 0] >= margin)
        & (xy[:, 0] <= w - 1 - margin)
        & (xy[:, 1] >= margin)
        & (xy[:, 1] <= h - 1 - margin)
    )


def _board_poses(
    rig: StereoRig,
    board: Board,
    n_full: int,
    n_partial: int,
    fill: float,
    max_tilt: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random board poses that keep the board in both views (or partly out for ``n_partial``)."""
    extent = board.extent()
    outline = _outline(extent)
    corners = board.object_points()
    center = np.array([(extent[0] + extent[2]) / 2, (extent[1] + extent[3]) / 2, 0.0])
    w, _ = rig.image_size
    f = rig.K_left[0, 0]
    z_fit = f * max(extent[2] - extent[0], extent[3] - extent[1]) / (fill * w)
    margin = 0.015 * w
    Rr, Cr = rig.pose("right")
    rotations, translations, full = [], [], []
    for _ in range(2000 * (n_full + n_partial)):
        partial = len(rotations) >= n_full
        if len(rotations) == n_full + n_partial:
            break
        ax, ay = rng.uniform(-max_tilt, max_tilt, 2)
        Rb = _rotation(ax, ay, rng.uniform(-20, 20))
        z = z_fit * rng.uniform(0.85, 1.25)
        # aim between the two optical axes at this depth
        axis = Rr[:, 2]
        mid = 0.5 * (np.array([0.0, 0.0, z]) + Cr + (z - Cr[2]) / axis[2] * axis)
        reach = (0.9 if partial else 0.35) * z * w / (2 * f)
        p = mid + np.array([rng.uniform(-reach, reach), rng.uniform(-0.6, 0.6) * reach, 0.0])
        t = p - Rb @ center
        world = outline @ Rb.T + t
        if np.any(world[:, 2] <= 0) or np.any(world @ rig.R[2] + rig.T[2] <= 0):
            continue  # behind a camera
        normal = Rb[:, 2]
        if normal @ (t - Cr) <= 0 or normal @ t <= 0:  # seen from behind
            continue
        outline_in = [_inside(rig, rig.project(world, c), margin) for c in ("left", "right")]
        if not partial:
            if not (outline_in[0].all() and outline_in[1].all()):
                continue
        else:
            world_corners = corners @ Rb.T + t
            frac = [
                _inside(rig, rig.project(world_corners, c), 0).mean() for c in ("left", "right")
            ]
            if min(frac) < 0.3 or not any(0.3 <= v <= 0.85 for v in frac):
                continue
        rotations.append(Rb)
        translations.append(t)
        full.append(bool(outline_in[0].all() and outline_in[1].all()))
    if len(rotations) < n_full + n_partial:
        raise ValueError(
            f"cannot place {board.spec()} in view of both cameras; try a smaller board or fill"
        )
    return np.array(rotations), np.array(translations), np.array(full)


def render_calibration_views(
    rig: StereoRig,
    board: Board | str = "checkerboard:9x6:10",
    *,
    n_views: int = 15,
    rng: Rng = 0,
    noise: float = 1.0,
    blur_sigma: float = 0.7,
    supersample: int = 3,
    fill: float = 0.45,
    max_tilt_deg: float = 30.0,
    partial_views: int = 0,
    jpeg_quality: int | None = None,
    lighting: float = 0.0,
    progress: Callable[[int, int], None] | None = None,
) -> CalibrationViews:
    """Render stereo views of a calibration board at random, known poses.

    Parameters
    ----------
    rig : StereoRig
    board : Checkerboard, CharucoBoard, CircleGrid or str
        The target, or its spelling for :func:`parse_board`.
    n_views : int, keyword-only
        Views with the whole board (and its margin) inside both images.
    rng : int or Generator, keyword-only
        Seed for the poses, the lighting and the noise.
    noise : float, keyword-only
        Standard deviation of the Gaussian sensor noise in gray levels.
    blur_sigma : float, keyword-only
        Gaussian lens blur in pixels after pixel integration.
    supersample : int, keyword-only
        Sub-pixel rays per pixel along each axis.
    fill : float, keyword-only
        The board's larger side (with margin) spans about this fraction of the
        image width at the nominal distance; the distance varies by
        -15/+25 %, the tilts about x and y up to ``max_tilt_deg``, the
        rotation in the board's plane up to 20 degrees.
    max_tilt_deg : float, keyword-only
    partial_views : int, keyword-only
        Extra views (after the ``n_views`` full ones) in which 15-70 % of the
        board's corners fall outside one image.
    jpeg_quality : int or None, keyword-only
        Compress every image as JPEG of this quality (1-100).
    lighting : float, keyword-only
        Uneven lighting: a linear gain ramp ``1 +- lighting`` from one image
        corner to the opposite, in a random direction per image.
    progress : callable(done, total), keyword-only

    Returns
    -------
    CalibrationViews
    """
    if isinstance(board, str):
        board = parse_board(board)
    if not isinstance(board, Checkerboard | CharucoBoard | CircleGrid):
        raise ValueError(
            f"board must be a Checkerboard, CharucoBoard, CircleGrid or str, got {board!r}"
        )
    for name, value in (("n_views", n_views), ("partial_views", partial_views)):
        if int(value) != value or value < 0:
            raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    if n_views + partial_views < 1:
        raise ValueError("n_views + partial_views must be >= 1")
    _check_render_options(supersample, blur_sigma, noise)
    if not 0.05 <= fill <= 0.95:
        raise ValueError(f"fill must be in [0.05, 0.95], got {fill}")
    if not 0 <= max_tilt_deg <= 60:
        raise ValueError(f"max_tilt_deg must be in [0, 60], got {max_tilt_deg}")
    if jpeg_quality is not None and not 1 <= int(jpeg_quality) <= 100:
        raise ValueError(f"jpeg_quality must be in 1..100, got {jpeg_quality}")
    if not 0 <= lighting < 1:
        raise ValueError(f"lighting must be in [0, 1), got {lighting}")
    pose_rng, noise_rng = _spawn(rng, 2)
    rotations, translations, full = _board_poses(
        rig, board, int(n_views), int(partial_views), fill, max_tilt_deg, pose_rng
    )
    texture = board._texture(200)
    n = len(rotations)
    w, h = rig.image_size
    images = {c: np.empty((n, h, w), np.uint8) for c in ("left", "right")}
    for camera in ("left", "right"):
        rays = _sample_rays(rig, camera, supersample)
        for k, (Rb, tb) in enumerate(zip(rotations, translations, strict=True)):

            @np.errstate(divide="ignore", invalid="ignore", over="ignore")
            def shade(origin, M, xn, yn, Rb=Rb, tb=tb) -> np.ndarray:
                o, (dx, dy, dz) = _local_rays(origin, M, xn, yn, tb, Rb)
                depth = -o[2] / dz
                X = np.column_stack([o[0] + depth * dx, o[1] + depth * dy])
                X[~(depth > 0)] = np.nan
                return texture.sample(X, _BACKGROUND)

            image = _render_view(rig, camera, rays, shade, supersample)
            images[camera][k] = _finish(
                image,
                noise_rng,
                blur_sigma=blur_sigma,
                lighting=lighting,
                noise=noise,
                jpeg_quality=jpeg_quality,
            )
            if progress:
                progress(k + 1 + (n if camera == "right" else 0), 2 * n)
        del rays
    params = {
        "board": board.spec(),
        "n_views": int(n_views),
        "partial_views": int(partial_views),
        "seed": rng if not isinstance(rng, np.random.Generator) else None,
        "noise": noise,
        "blur_sigma": blur_sigma,
        "supersample": supersample,
        "fill": fill,
        "max_tilt_deg": max_tilt_deg,
        "jpeg_quality": jpeg_quality,
        "lighting": lighting,
        "gray_levels": {"dark": _DARK, "light": _LIGHT, "background": _BACKGROUND},
    }
    return CalibrationViews(
        images["left"], images["right"], rig, board, rotations, translations, full, params
    )


# --------------------------------------------------------------------------- surface scenes


@dataclass
class StereoScene:
    """Stereo frames of a deforming surface and its exact motion.

    Attributes
    ----------
    left, right : (T, H, W) uint8
        Frames of the left and right camera.
    rig : StereoRig
    case : {"stretch", "dome"}
    params : dict
        Scene and rendering parameters.
    surface : object
        The analytic surface (see the module docstring); its ``to_dict()`` is
        what ``truth.json`` stores.
    pattern : SpecklePattern or None
        The speckle dots in material coordinates (mm) for ``texture="speckle"``.
    """

    left: np.ndarray
    right: np.ndarray
    rig: StereoRig
    case: str
    params: dict
    surface: _Sheet | _Dome
    pattern: SpecklePattern | None = None

    def __post_init__(self) -> None:
        w, h = self.rig.image_size
        shape = (self.surface.n_frames, h, w)
        for name in ("left", "right"):
            if getattr(self, name).shape != shape:
                raise ValueError(f"{name} must be {shape}, got {getattr(self, name).shape}")

    @property
    def n_frames(self) -> int:
        return self.surface.n_frames

    def time(self, frame: int) -> float:
        """Normalized time of a frame (0 on the first, 1 on the last)."""
        if not -self.n_frames <= frame < self.n_frames:
            raise ValueError(f"frame must be in 0..{self.n_frames - 1}, got {frame}")
        return (frame % self.n_frames) / (self.n_frames - 1)

    def positions(self, material_points: np.ndarray, frame: int | None = None) -> np.ndarray:
        """Left/world positions (mm) of material points ``(N, 2)`` (mm).

        ``(N, 3)`` for one frame, ``(T, N, 3)`` for all when ``frame`` is None.
        """
        X = np.asarray(material_points, dtype=float).reshape(-1, 2)
        if frame is None:
            return np.stack([self.positions(X, k) for k in range(self.n_frames)])
        return self.surface.positions(X, self.time(frame))

    def gradient(self, material_points: np.ndarray, frame: int) -> np.ndarray:
        """Deformation gradient ``dx/dX`` ``(N, 3, 2)``: world mm per material mm."""
        X = np.asarray(material_points, dtype=float).reshape(-1, 2)
        return self.surface.gradient(X, self.time(frame))

    def strain(
        self, material_points: np.ndarray, frame: int, *, axes: StrainAxes = "material"
    ) -> np.ndarray:
        """Green-Lagrange membrane strain ``(N, 2, 2)`` of material points ``(N, 2)``.

        ``axes="material"``: components in the material frame ``(e1, e2)``
        (the ``X1``, ``X2`` axes of the reference sheet or disc);
        ``axes="polar"``: in the (radial/meridional, circumferential) frame
        ``(e_rho, e_phi)`` about the material origin (``e_rho = e1`` at the
        origin).
        """
        if axes not in ("material", "polar"):
            raise ValueError(f"axes must be 'material' or 'polar', got {axes!r}")
        X = np.asarray(material_points, dtype=float).reshape(-1, 2)
        E = self.surface.strain(X, self.time(frame))
        if axes == "polar":
            phi = np.arctan2(X[:, 1], X[:, 0])
            c, s = np.cos(phi), np.sin(phi)
            Q = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)  # columns e_rho, e_phi
            E = np.einsum("nki,nkl,nlj->nij", Q, E, Q)
        return E

    def pixels(
        self, material_points: np.ndarray, frame: int, *, camera: Camera = "left"
    ) -> np.ndarray:
        """True pixel positions ``(N, 2)`` of material points in one camera's frame."""
        return self.rig.project(self.positions(material_points, frame), camera)

    def material_from_pixel(
        self, xy: np.ndarray, frame: int = 0, *, camera: Camera = "left"
    ) -> np.ndarray:
        """Material point ``(N, 2)`` (mm) seen at pixel positions ``xy`` ``(N, 2)``.

        NaN where the pixel shows no surface (background).  For the dome,
        points with ``|X| > radius`` lie on the fixed clamp plate.
        """
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        xn = undistort_points(self.rig, xy, camera=camera)
        Rc, Cc = self.rig.pose(camera)
        return self.surface.hit(Cc, Rc, xn[:, 0], xn[:, 1], self.time(frame))

    def material_from_left_pixel(self, xy: np.ndarray, frame: int = 0) -> np.ndarray:
        """:meth:`material_from_pixel` for the left camera."""
        return self.material_from_pixel(xy, frame, camera="left")

    def grid(self, shape: tuple[int, int] = (7, 7)) -> np.ndarray:
        """Reference grid ``(rows * cols, 2)`` of material points (mm), row-major.

        Over 80 % of the sheet for ``stretch``, over the square inscribed in
        90 % of the membrane for ``dome``.
        """
        cols, rows = shape
        if self.case == "stretch":
            hx, hy = 0.8 * self.surface.half_size
        else:
            hx = hy = 0.9 * self.surface.radius / math.sqrt(2)
        gx, gy = np.meshgrid(np.linspace(-hx, hx, cols), np.linspace(-hy, hy, rows))
        return np.column_stack([gx.ravel(), gy.ravel()])

    def __repr__(self) -> str:
        t, h, w = self.left.shape
        return f"StereoScene({self.case!r}, {t} frames of {w}x{h} px, {self.rig!r})"


def _scene_frame(rig: StereoRig, distance: float, tilt_deg: tuple[float, float]):
    """Centre and axes of a surface at ``distance`` between the two optical axes."""
    Rr, Cr = rig.pose("right")
    axis = Rr[:, 2]
    center = 0.5 * (np.array([0.0, 0.0, distance]) + Cr + (distance - Cr[2]) / axis[2] * axis)
    # face the midpoint of the two cameras, then tilt
    view = center - 0.5 * Cr
    yaw = math.degrees(math.atan2(view[0], view[2]))
    axes = _rotation(0.0, yaw + tilt_deg[0], 0.0) @ _rotation(tilt_deg[1], 0.0, 0.0)
    return center, axes


def render_surface_scene(
    rig: StereoRig,
    case: SurfaceCase,
    *,
    n_frames: int = 11,
    rng: Rng = 0,
    texture: TextureKind = "speckle",
    distance: float = 450.0,
    tilt_deg: tuple[float, float] = (10.0, -8.0),
    sheet_size: tuple[float, float] = (80.0, 60.0),
    stretch: tuple[float, float] = (1.25, 1.10),
    dome_radius: float = 35.0,
    dome_height: float = 12.0,
    speckle_radius: float = 0.3,
    speckle_density: float = 1.0,
    speckle_contrast: float = 0.8,
    noise: float = 1.0,
    blur_sigma: float = 0.7,
    supersample: int = 3,
    progress: Callable[[int, int], None] | None = None,
) -> StereoScene:
    """Render a deforming surface in both cameras, frame by frame, with exact truth.

    Parameters
    ----------
    rig : StereoRig
    case : {"stretch", "dome"}
        See the module docstring.
    n_frames : int, keyword-only
        Frames including the undeformed reference (>= 2).
    rng : int or Generator, keyword-only
        Seed for the texture and the noise.
    texture : {"speckle", "checker"}, keyword-only
        Gaussian speckle dots (see :func:`sample_data_synth.speckle_pattern`)
        or a 2 mm checker, both fixed in material coordinates.
    distance : float, keyword-only
        Depth (mm, left camera z) of the surface's centre, which lies midway
        between the two cameras' optical axes at that depth.
    tilt_deg : (yaw, pitch), keyword-only
        Tilt of the surface about the vertical and the horizontal axis away
        from facing the midpoint of the two cameras, degrees.
    sheet_size : (width, height), keyword-only
        Reference sheet size in mm (``stretch``).
    stretch : (lambda1, lambda2), keyword-only
        Stretches along ``e1``, ``e2`` at the last frame (``stretch``).
    dome_radius, dome_height : float, keyword-only
        Membrane radius and final apex height in mm (``dome``; height <
        radius).  The clamp plate around it is textured out to
        ``radius + 20`` mm.
    speckle_radius, speckle_density, speckle_contrast : keyword-only
        Gaussian radius (mm), coverage and contrast of the speckle dots.  At
        450 mm the default rig images about 3.1 px/mm, so the 0.3 mm dots are
        about 0.95 px in sigma and 4 px across.
    noise : float, keyword-only
        Gaussian sensor noise in gray levels.
    blur_sigma : float, keyword-only
        Gaussian lens blur in pixels.
    supersample : int, keyword-only
        Sub-pixel rays per pixel along each axis.
    progress : callable(done, total), keyword-only

    Returns
    -------
    StereoScene
    """
    if case not in ("stretch", "dome"):
        raise ValueError(f"case must be 'stretch' or 'dome', got {case!r}")
    if texture not in ("speckle", "checker"):
        raise ValueError(f"texture must be 'speckle' or 'checker', got {texture!r}")
    if int(n_frames) != n_frames or n_frames < 2:
        raise ValueError(f"n_frames must be an integer >= 2, got {n_frames!r}")
    _check_render_options(supersample, blur_sigma, noise)
    distance = _positive(distance, "distance")
    for name, value in (("speckle_radius", speckle_radius), ("dome_radius", dome_radius)):
        _positive(value, name)
    if not 0 < speckle_density <= 2 or not 0 < speckle_contrast <= 1:
        raise ValueError("speckle_density must be in (0, 2] and speckle_contrast in (0, 1]")
    if len(tilt_deg) != 2 or not all(abs(float(v)) < 60 for v in tilt_deg):
        raise ValueError(f"tilt_deg must be (yaw, pitch) in degrees below 60, got {tilt_deg!r}")
    center, axes = _scene_frame(rig, distance, tuple(float(v) for v in tilt_deg))
    if case == "stretch":
        if len(sheet_size) != 2 or len(stretch) != 2:
            raise ValueError("sheet_size and stretch must be pairs")
        half = [_positive(v, "sheet_size") / 2 for v in sheet_size]
        lam = [_positive(v, "stretch") for v in stretch]
        surface: _Sheet | _Dome = _Sheet(center, axes, half, lam, n_frames)
    else:
        if not 0 <= dome_height < dome_radius:
            raise ValueError(f"dome_height must be in [0, dome_radius), got {dome_height}")
        surface = _Dome(center, axes, dome_radius, dome_height, dome_radius + 20.0, n_frames)
    tex_rng, noise_rng = _spawn(rng, 2)
    raster, pattern = _surface_texture(
        surface,
        texture,
        speckle_radius=speckle_radius,
        speckle_density=speckle_density,
        speckle_contrast=speckle_contrast,
        rng=tex_rng,
    )
    w, h = rig.image_size
    frames = {c: np.empty((n_frames, h, w), np.uint8) for c in ("left", "right")}
    for camera in ("left", "right"):
        rays = _sample_rays(rig, camera, supersample)
        for k in range(n_frames):
            t = k / (n_frames - 1)

            def shade(origin, M, xn, yn, t=t) -> np.ndarray:
                X = surface.hit(origin, M, xn, yn, t)
                return raster.sample(X, _BACKGROUND) * surface.texture_gain(X)

            image = _render_view(rig, camera, rays, shade, supersample)
            frames[camera][k] = _finish(
                image,
                noise_rng,
                blur_sigma=blur_sigma,
                lighting=0.0,
                noise=noise,
                jpeg_quality=None,
            )
            if progress:
                progress(k + 1 + (n_frames if camera == "right" else 0), 2 * n_frames)
        del rays
    params = {
        "description": STEREO_CASES[case],
        "seed": rng if not isinstance(rng, np.random.Generator) else None,
        "texture": texture,
        "distance_mm": distance,
        "tilt_deg": list(tilt_deg),
        "noise": noise,
        "blur_sigma": blur_sigma,
        "supersample": supersample,
        "background_gray": _BACKGROUND,
    }
    if case == "stretch":
        params.update(sheet_size_mm=list(sheet_size), final_stretch=list(stretch))
    else:
        params.update(dome_radius_mm=dome_radius, dome_height_mm=dome_height)
    if texture == "speckle":
        params.update(
            speckle_radius_mm=speckle_radius,
            speckle_density=speckle_density,
            speckle_contrast=speckle_contrast,
        )
    return StereoScene(frames["left"], frames["right"], rig, case, params, surface, pattern)


# --------------------------------------------------------------------------- files


def _write_png(path: Path, image: np.ndarray) -> None:
    """Encoded in memory, written by Python: any file name (OpenCV's own crash on names that
    are not UTF-8)."""
    import cv2

    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"OpenCV cannot write {path}")
    Path(path).write_bytes(data.tobytes())


def _read_png(path: Path) -> np.ndarray:
    import cv2

    from tissue_core.images import read_image

    return read_image(path, flags=cv2.IMREAD_UNCHANGED)


def save_stereo_scene(folder: str | os.PathLike, scene: StereoScene) -> None:
    """Write a scene's frames, true calibration and truth into ``folder``.

    Files: ``left/frame_000.png ...``, ``right/frame_000.png ...`` (8-bit
    PNG), ``rig.json`` (:meth:`StereoRig.to_dict`), ``truth.json`` (case,
    parameters, conventions, the surface and its mapping parameters per
    frame) and ``truth.npz``: the reference 7 x 7 material grid
    ``material`` (N, 2) mm, ``positions`` (T, N, 3) mm, ``strain`` (T, N, 2, 2)
    (Green-Lagrange, material axes), ``left_px`` and ``right_px`` (T, N, 2),
    and for speckle textures ``speckle_centers`` (K, 2) mm and
    ``speckle_sigmas`` (K,) mm.
    """
    folder = Path(folder)
    for camera in ("left", "right"):
        (folder / camera).mkdir(parents=True, exist_ok=True)
        for k, image in enumerate(getattr(scene, camera)):
            _write_png(folder / camera / f"frame_{k:03d}.png", image)
    write_json(folder / "rig.json", scene.rig.to_dict())
    n = scene.n_frames
    write_json(
        folder / "truth.json",
        {
            "case": scene.case,
            "description": STEREO_CASES.get(scene.case, ""),
            "n_frames": n,
            "image_size": list(scene.rig.image_size),
            "surface": scene.surface.to_dict(),
            "frames": [scene.surface.mapping(k / (n - 1)) for k in range(n)],
            "grid": "truth.npz: 7 x 7 material grid, row-major (see StereoScene.grid)",
            "conventions": CONVENTIONS,
            "params": scene.params,
            "software": {"sample_data_synth": _version()},
        },
    )
    grid = scene.grid((7, 7))
    positions = scene.positions(grid)
    arrays = {
        "material": grid,
        "positions": positions,
        "strain": np.stack([scene.strain(grid, k) for k in range(n)]),
        "left_px": np.stack([scene.rig.project(p, "left") for p in positions]),
        "right_px": np.stack([scene.rig.project(p, "right") for p in positions]),
    }
    if scene.pattern is not None:
        arrays.update(
            speckle_centers=scene.pattern.centers,
            speckle_sigmas=scene.pattern.sigmas,
            speckle_gray=np.array([scene.pattern.background, scene.pattern.ink]),
        )
    with open(folder / "truth.npz", "wb") as f:
        np.savez_compressed(f, **arrays)


def load_stereo_scene(folder: str | os.PathLike) -> StereoScene:
    """Read a scene written by :func:`save_stereo_scene` (frames and exact truth)."""
    folder = Path(folder)
    try:
        rig = StereoRig.from_dict(json.loads((folder / "rig.json").read_text()))
        truth = json.loads((folder / "truth.json").read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{folder}: malformed JSON ({exc})") from None
    surface = _surface_from_dict(truth["surface"])
    frames = {
        c: np.stack([_read_png(folder / c / f"frame_{k:03d}.png") for k in range(surface.n_frames)])
        for c in ("left", "right")
    }
    pattern = None
    with np.load(folder / "truth.npz") as npz:
        if "speckle_centers" in npz:
            background, ink = npz["speckle_gray"]
            pattern = SpecklePattern(
                npz["speckle_centers"], npz["speckle_sigmas"], float(background), float(ink)
            )
    return StereoScene(
        frames["left"], frames["right"], rig, truth["case"], truth["params"], surface, pattern
    )


def save_calibration_views(folder: str | os.PathLike, views: CalibrationViews) -> None:
    """Write calibration views, the true calibration and the true board poses.

    Files: ``left/view_00.png ...``, ``right/view_00.png ...``, ``rig.json``
    (:meth:`StereoRig.to_dict`) and ``poses.json``: the board
    (:meth:`Checkerboard.to_dict` / :meth:`CharucoBoard.to_dict`), its
    ``object_points`` (N, 3) mm and per view ``R``, ``t`` (``X_left = R @
    X_board + t``), ``rvec``, ``fully_visible`` and the true corner pixels
    ``left_px``, ``right_px`` (N, 2).
    """
    folder = Path(folder)
    digits = max(2, len(str(views.n_views - 1)))
    for camera in ("left", "right"):
        (folder / camera).mkdir(parents=True, exist_ok=True)
        for k, image in enumerate(getattr(views, camera)):
            _write_png(folder / camera / f"view_{k:0{digits}d}.png", image)
    write_json(folder / "rig.json", views.rig.to_dict())
    write_json(
        folder / "poses.json",
        {
            "board": views.board.to_dict(),
            "object_points": views.object_points().tolist(),
            "convention": CONVENTIONS["board_pose"],
            "views": [
                {
                    "view": k,
                    "left_image": f"left/view_{k:0{digits}d}.png",
                    "right_image": f"right/view_{k:0{digits}d}.png",
                    "R": views.rotations[k].tolist(),
                    "t": views.translations[k].tolist(),
                    "rvec": _rotation_vector(views.rotations[k]).tolist(),
                    "fully_visible": bool(views.fully_visible[k]),
                    "left_px": views.image_points(k, "left").tolist(),
                    "right_px": views.image_points(k, "right").tolist(),
                }
                for k in range(views.n_views)
            ],
            "conventions": CONVENTIONS,
            "params": views.params,
            "software": {"sample_data_synth": _version()},
        },
    )
