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
  outer top-left corner).
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
from scipy import ndimage

from sample_data_synth._common import Rng
from sample_data_synth._common import non_negative as _non_negative
from sample_data_synth._common import positive as _positive
from sample_data_synth._common import spawn as _spawn
from sample_data_synth._common import version as _version
from sample_data_synth.deformations import Homogeneous
from sample_data_synth.render import add_sensor_noise, render_speckle
from sample_data_synth.speckle import SpecklePattern, speckle_pattern

__all__ = [
    "STEREO_CASES",
    "CalibrationViews",
    "CharucoBoard",
    "Checkerboard",
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

Camera = Literal["left", "right"]
SurfaceCase = Literal["stretch", "dome"]
TextureKind = Literal["speckle", "checker"]
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

# gray levels of the textures before lighting and noise
_DARK, _LIGHT, _BACKGROUND = 30.0, 220.0, 70.0
_PLATE_GAIN = 0.75  # the dome's clamp plate is painted a little darker than the membrane
_DICTIONARIES = {f"DICT_{b}X{b}_{n}": n for b in (4, 5, 6, 7) for n in (50, 100, 250, 1000)} | {
    "DICT_ARUCO_ORIGINAL": 1024,
    "DICT_APRILTAG_16h5": 30,
    "DICT_APRILTAG_25h9": 35,
    "DICT_APRILTAG_36h10": 2320,
    "DICT_APRILTAG_36h11": 587,
    "DICT_ARUCO_MIP_36h12": 250,
}


def _check_counts(board, names: tuple[str, ...]) -> None:
    """Make the named fields of a frozen board integers >= 2, or raise ValueError."""
    for name in names:
        value = getattr(board, name)
        if int(value) != value or value < 2:
            raise ValueError(f"{name} must be an integer >= 2, got {value!r}")
        object.__setattr__(board, name, int(value))


def _check_camera(camera: str) -> None:
    if camera not in ("left", "right"):
        raise ValueError(f"camera must be 'left' or 'right', got {camera!r}")


def _rotation(rx_deg: float, ry_deg: float, rz_deg: float) -> np.ndarray:
    """``Rz @ Ry @ Rx`` for angles in degrees about the x, y and z axes."""
    a, b, c = np.radians([rx_deg, ry_deg, rz_deg])
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _rotation_vector(R: np.ndarray) -> np.ndarray:
    """Rotation vector (radians) of a rotation matrix, as ``cv2.Rodrigues``."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(R).as_rotvec()


# --------------------------------------------------------------------------- camera rig


@dataclass(frozen=True, eq=False)
class StereoRig:
    """A calibrated stereo pair (OpenCV's camera model, see the module docstring).

    Attributes
    ----------
    image_size : (width, height)
        Image size in pixels.
    K_left, K_right : (3, 3) float
        Camera matrices ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    dist_left, dist_right : (5,) float
        Distortion coefficients ``(k1, k2, p1, p2, k3)``.
    R : (3, 3) float
        Rotation from left to right camera coordinates.
    T : (3,) float
        Translation: ``X_right = R @ X_left + T``, in ``unit``.
    unit : str
        Length unit of ``T`` and of every scene coordinate ("mm").
    """

    image_size: tuple[int, int]
    K_left: np.ndarray
    dist_left: np.ndarray
    K_right: np.ndarray
    dist_right: np.ndarray
    R: np.ndarray
    T: np.ndarray
    unit: str = "mm"

    def __post_init__(self) -> None:
        size = tuple(int(v) for v in np.ravel(self.image_size))
        if len(size) != 2 or min(size) < 8 or np.any(np.ravel(self.image_size) != size):
            raise ValueError(
                f"image_size must be (width, height), integers >= 8, got {self.image_size!r}"
            )
        object.__setattr__(self, "image_size", size)
        for name, shape in (("K_left", (3, 3)), ("K_right", (3, 3)), ("R", (3, 3)), ("T", (3,))):
            value = np.array(getattr(self, name), dtype=float)
            if value.shape != shape or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be finite with shape {shape}, got {value.shape}")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        for name in ("K_left", "K_right"):
            K = getattr(self, name)
            if K[0, 0] <= 0 or K[1, 1] <= 0 or np.any(K[[1, 2, 2], [0, 0, 1]] != 0) or K[2, 2] != 1:
                raise ValueError(
                    f"{name} must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], fx, fy > 0"
                )
        for name in ("dist_left", "dist_right"):
            value = np.array(getattr(self, name), dtype=float).ravel()
            if value.size == 4:
                value = np.append(value, 0.0)
            if value.shape != (5,) or not np.all(np.isfinite(value)):
                raise ValueError(f"{name} must be (k1, k2, p1, p2[, k3]), got {value.shape}")
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-9) or np.linalg.det(self.R) < 0:
            raise ValueError("R must be a rotation matrix (orthonormal, det +1)")

    @property
    def baseline(self) -> float:
        """Distance between the two camera centres, ``|T|``."""
        return float(np.linalg.norm(self.T))

    def intrinsics(self, camera: Camera = "left") -> tuple[np.ndarray, np.ndarray]:
        """``(K, dist)`` of one camera."""
        _check_camera(camera)
        if camera == "left":
            return self.K_left, self.dist_left
        return self.K_right, self.dist_right

    def pose(self, camera: Camera = "left") -> tuple[np.ndarray, np.ndarray]:
        """``(R_c, C_c)`` with ``X_left = R_c @ X_camera + C_c`` (``C_c`` the camera centre)."""
        _check_camera(camera)
        if camera == "left":
            return np.eye(3), np.zeros(3)
        return self.R.T.copy(), -self.R.T @ self.T

    def project(self, points: np.ndarray, camera: Camera = "left") -> np.ndarray:
        """Pixel positions ``(N, 2)`` of points ``(N, 3)`` given in left (world) coordinates.

        ``cv2.projectPoints`` with the camera's intrinsics; points behind the
        camera are projected all the same (check their depth yourself).
        """
        import cv2

        _check_camera(camera)
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(points) == 0:
            return np.empty((0, 2))
        K, dist = self.intrinsics(camera)
        if camera == "left":
            rvec, tvec = np.zeros(3), np.zeros(3)
        else:
            rvec, tvec = cv2.Rodrigues(np.ascontiguousarray(self.R))[0].ravel(), self.T
        xy, _ = cv2.projectPoints(points[:, None, :], rvec, np.array(tvec, float), K, dist)
        return xy.reshape(-1, 2)

    def to_dict(self) -> dict:
        """The calibration JSON layout (``rms_px`` is 0: this is the truth)."""
        return {
            "image_size": list(self.image_size),
            "K_left": self.K_left.tolist(),
            "dist_left": self.dist_left.tolist(),
            "K_right": self.K_right.tolist(),
            "dist_right": self.dist_right.tolist(),
            "R": self.R.tolist(),
            "T": self.T.tolist(),
            "unit": self.unit,
            "rms_px": 0.0,
        }

    @classmethod
    def from_dict(cls, d: dict) -> StereoRig:
        """Rebuild a rig from :meth:`to_dict`'s layout (``rms_px`` is ignored)."""
        try:
            return cls(
                image_size=tuple(d["image_size"]),
                K_left=d["K_left"],
                dist_left=d["dist_left"],
                K_right=d["K_right"],
                dist_right=d["dist_right"],
                R=d["R"],
                T=d["T"],
                unit=d.get("unit", "mm"),
            )
        except KeyError as exc:
            raise ValueError(f"calibration dict lacks {exc.args[0]!r}") from None

    def __repr__(self) -> str:
        w, h = self.image_size
        angle = np.degrees(np.linalg.norm(_rotation_vector(self.R)))
        return (
            f"StereoRig({w}x{h} px, f = {self.K_left[0, 0]:.1f} / {self.K_right[0, 0]:.1f} px, "
            f"baseline {self.baseline:.2f} {self.unit}, rotation {angle:.2f} deg)"
        )


def default_rig(*, image_size: tuple[int, int] = (1024, 768)) -> StereoRig:
    """A realistic converging stereo pair for scenes about 450 mm away.

    At 1024 x 768 px: focal lengths about 1400 px (fx, fy differ slightly),
    principal points a few pixels off the image centre, mild distortion
    (``k1`` -0.08 / -0.075, ``k2`` 0.05 / 0.045, ``p1``, ``p2`` below 1e-3,
    ``k3`` 0), the right camera 120 mm to the right (and 1.5 mm down, 2 mm
    back) and turned 9 degrees towards the left one (plus 0.6 and -0.4
    degrees about x and z).  Another ``image_size`` scales the intrinsics with
    the width, so the field of view stays the same.

    Examples
    --------
    >>> rig = default_rig()
    >>> round(rig.baseline, 3)
    120.0
    >>> rig.project([[0.0, 0.0, 450.0]]).round(1)
    array([[519.4, 377.2]])
    """
    w, h = (int(v) for v in image_size)
    if w < 8 or h < 8:
        raise ValueError(f"image_size must be (width, height) >= 8 px, got {image_size!r}")
    s = w / 1024

    def K(fx: float, fy: float, dx: float, dy: float) -> np.ndarray:
        return np.array(
            [[fx * s, 0.0, (w - 1) / 2 + dx * s], [0.0, fy * s, (h - 1) / 2 + dy * s], [0, 0, 1]]
        )

    R = _rotation(0.6, 9.0, -0.4)
    center = np.array([120.0, 1.5, -2.0])
    center *= 120.0 / np.linalg.norm(center)
    return StereoRig(
        image_size=(w, h),
        K_left=K(1400.0, 1398.6, 7.9, -6.3),
        dist_left=[-0.08, 0.05, 0.0007, -0.0005, 0.0],
        K_right=K(1392.4, 1391.5, -9.2, 5.6),
        dist_right=[-0.075, 0.045, -0.0004, 0.0006, 0.0],
        R=R,
        T=-R @ center,
    )


def _distort(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """OpenCV's distortion of normalized coordinates ``(..., 2)``."""
    k1, k2, p1, p2, k3 = dist
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return np.stack(
        [
            x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y,
        ],
        axis=-1,
    )


@np.errstate(invalid="ignore", over="ignore", divide="ignore")
def _undistort(xd: np.ndarray, dist: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
    """Invert :func:`_distort` by Newton's method (quadratic convergence) from ``x0``.

    NaN where the residual stays above 1e-12 (about 1e-9 px).
    """
    k1, k2, p1, p2, k3 = dist
    x0 = xd if x0 is None else x0
    x, y = np.array(x0[..., 0], dtype=float), np.array(x0[..., 1], dtype=float)
    ux, uy = np.ascontiguousarray(xd[..., 0]), np.ascontiguousarray(xd[..., 1])
    for _ in range(30):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy2 = 2 * x * y
        fx = x * radial + p1 * xy2 + p2 * (r2 + 2 * x * x) - ux
        fy = y * radial + p1 * (r2 + 2 * y * y) + p2 * xy2 - uy
        if not np.any(np.abs(fx) + np.abs(fy) > 1e-15):  # NaN input stays NaN
            break
        dradial = 2 * (k1 + r2 * (2 * k2 + 3 * k3 * r2))  # d(radial) / d(r2), doubled
        jxx = radial + x * x * dradial + 2 * p1 * y + 6 * p2 * x
        jyy = radial + y * y * dradial + 6 * p1 * y + 2 * p2 * x
        jxy = 0.5 * xy2 * dradial + 2 * p1 * x + 2 * p2 * y
        det = jxx * jyy - jxy * jxy
        x -= (jyy * fx - jxy * fy) / det
        y -= (jxx * fy - jxy * fx) / det
    out = np.stack([x, y], axis=-1)
    out[~((np.abs(fx) < 1e-12) & (np.abs(fy) < 1e-12))] = np.nan
    return out


def undistort_points(rig: StereoRig, xy: np.ndarray, *, camera: Camera = "left") -> np.ndarray:
    """Normalized ray coordinates ``(N, 2)`` of pixel positions ``xy`` ``(N, 2)``.

    The ray through pixel ``xy`` is ``(x_n, y_n, 1)`` in the camera's
    coordinates: the exact inverse of :meth:`StereoRig.project` for a point on
    that ray (Newton's method on OpenCV's distortion model; NaN where it does
    not converge, far outside the image with strong distortion).

    Examples
    --------
    >>> rig = default_rig()
    >>> xy = np.array([[3.0, 5.0], [1000.0, 760.0]])
    >>> xn = undistort_points(rig, xy)
    >>> back = rig.project(np.column_stack([xn, np.ones(2)]))
    >>> bool(np.abs(back - xy).max() < 1e-9)
    True
    """
    import cv2

    K, dist = rig.intrinsics(camera)
    xy = np.asarray(xy, dtype=float)
    if xy.shape[-1:] != (2,):
        raise ValueError(f"xy must have shape (N, 2), got {xy.shape}")
    if xy.size == 0:
        return xy.copy()
    y = (xy[..., 1] - K[1, 2]) / K[1, 1]
    x = (xy[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
    # OpenCV's fixed-point iteration gives the start, Newton the last digits
    start = cv2.undistortPoints(xy.reshape(-1, 1, 2), K, dist).reshape(xy.shape)
    return _undistort(np.stack([x, y], axis=-1), dist, start)


# --------------------------------------------------------------------------- rendering


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


# --------------------------------------------------------------------------- calibration


@dataclass(frozen=True)
class Checkerboard:
    """A checkerboard target.

    Parameters
    ----------
    cols, rows : int
        Inner corners per row and per column (``patternSize = (cols, rows)``
        for ``cv2.findChessboardCorners``); the board has ``(cols + 1) x
        (rows + 1)`` squares, the top-left one black.
    square : float
        Square size in mm.
    margin : float or None
        White border around the squares in mm (default: one square).
    """

    cols: int = 9
    rows: int = 6
    square: float = 10.0
    margin: float | None = None

    def __post_init__(self) -> None:
        _check_counts(self, ("cols", "rows"))
        object.__setattr__(self, "square", _positive(self.square, "square"))
        margin = self.square if self.margin is None else _non_negative(self.margin, "margin")
        object.__setattr__(self, "margin", margin)

    kind = "checkerboard"

    @property
    def pattern_size(self) -> tuple[int, int]:
        """``(cols, rows)`` of inner corners, as ``cv2.findChessboardCorners`` wants."""
        return (self.cols, self.rows)

    def object_points(self) -> np.ndarray:
        """Inner corners ``(rows * cols, 3)`` in board mm, row-major: ``(j sq, i sq, 0)``."""
        jj, ii = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.column_stack(
            [jj.ravel() * self.square, ii.ravel() * self.square, np.zeros(jj.size)]
        )

    def extent(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the board with its margin, in board mm."""
        sq, m = self.square, self.margin
        return (-sq - m, -sq - m, self.cols * sq + m, self.rows * sq + m)

    def spec(self) -> str:
        """The command-line spelling, e.g. ``checkerboard:9x6:10``."""
        return f"checkerboard:{self.cols}x{self.rows}:{self.square:g}"

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "spec": self.spec(),
            "cols": self.cols,
            "rows": self.rows,
            "square_mm": self.square,
            "margin_mm": self.margin,
            "origin": "first inner corner; object points (j * square, i * square, 0) row-major",
        }

    def _texture(self, per_square: int) -> _Raster:
        d = self.square / per_square
        m = round(self.margin / d)
        cells = (np.add.outer(np.arange(self.rows + 1), np.arange(self.cols + 1)) % 2).astype(float)
        img = np.kron(cells, np.ones((per_square, per_square)))
        img = np.pad(img * (_LIGHT - _DARK) + _DARK, m, constant_values=_LIGHT)
        x0 = -self.square - m * d + 0.5 * d
        img = ndimage.gaussian_filter(img, 1.0, mode="nearest")
        return _Raster(img.astype(np.float32), (x0, x0), d)


@dataclass(frozen=True)
class CharucoBoard:
    """A ChArUco target, drawn by ``cv2.aruco.CharucoBoard.generateImage``.

    Parameters
    ----------
    squares_x, squares_y : int
        Squares per row and per column.
    square, marker : float
        Square and marker side lengths in mm (``marker < square``).
    dictionary : str
        An ``cv2.aruco`` predefined dictionary name, e.g. ``"DICT_4X4_50"``.
    margin : float or None
        White border around the squares in mm (default: one square).
    """

    squares_x: int = 11
    squares_y: int = 8
    square: float = 8.0
    marker: float = 6.0
    dictionary: str = "DICT_4X4_50"
    margin: float | None = None

    def __post_init__(self) -> None:
        _check_counts(self, ("squares_x", "squares_y"))
        object.__setattr__(self, "square", _positive(self.square, "square"))
        object.__setattr__(self, "marker", _positive(self.marker, "marker"))
        if self.marker >= self.square:
            raise ValueError(f"marker ({self.marker}) must be smaller than square ({self.square})")
        if self.dictionary not in _DICTIONARIES:
            raise ValueError(
                f"dictionary must be a cv2.aruco predefined dictionary such as DICT_4X4_50, "
                f"got {self.dictionary!r}"
            )
        if self.squares_x * self.squares_y // 2 > _DICTIONARIES[self.dictionary]:
            raise ValueError(
                f"{self.dictionary} has too few markers for {self.squares_x}x{self.squares_y}"
            )
        margin = self.square if self.margin is None else _non_negative(self.margin, "margin")
        object.__setattr__(self, "margin", margin)

    kind = "charuco"

    def cv2_board(self):
        """The ``cv2.aruco.CharucoBoard`` (for ``cv2.aruco.CharucoDetector``)."""
        import cv2

        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(
            (self.squares_x, self.squares_y), self.square, self.marker, dictionary
        )

    def object_points(self) -> np.ndarray:
        """Chessboard corners ``(N, 3)`` in board mm, in ChArUco id order."""
        return np.asarray(self.cv2_board().getChessboardCorners(), dtype=float).reshape(-1, 3)

    def extent(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` of the board with its margin, in board mm."""
        m = self.margin
        return (-m, -m, self.squares_x * self.square + m, self.squares_y * self.square + m)

    def spec(self) -> str:
        """The command-line spelling, e.g. ``charuco:11x8:8:6:DICT_4X4_50``."""
        return (
            f"charuco:{self.squares_x}x{self.squares_y}:{self.square:g}:{self.marker:g}:"
            f"{self.dictionary}"
        )

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "spec": self.spec(),
            "squares_x": self.squares_x,
            "squares_y": self.squares_y,
            "square_mm": self.square,
            "marker_mm": self.marker,
            "dictionary": self.dictionary,
            "margin_mm": self.margin,
            "origin": "outer top-left corner; object points from getChessboardCorners()",
        }

    def _texture(self, per_square: int) -> _Raster:
        d = self.square / per_square
        m = round(self.margin / d)
        img = self.cv2_board().generateImage(
            (self.squares_x * per_square, self.squares_y * per_square), marginSize=0, borderBits=1
        )
        img = img.astype(float) / 255.0 * (_LIGHT - _DARK) + _DARK
        img = np.pad(img, m, constant_values=_LIGHT)
        x0 = -m * d + 0.5 * d
        img = ndimage.gaussian_filter(img, 1.0, mode="nearest")
        return _Raster(img.astype(np.float32), (x0, x0), d)


Board = Checkerboard | CharucoBoard


def parse_board(text: str) -> Board:
    """A board from its command-line spelling.

    ``checkerboard:COLSxROWS:SQUARE`` (inner corners, mm) or
    ``charuco:SXxSY:SQUARE:MARKER[:DICTIONARY]`` (squares, mm; the dictionary
    defaults to ``DICT_4X4_50``).

    Examples
    --------
    >>> parse_board("checkerboard:9x6:10")
    Checkerboard(cols=9, rows=6, square=10.0, margin=10.0)
    >>> parse_board("charuco:11x8:8:6").dictionary
    'DICT_4X4_50'
    """
    parts = str(text).strip().split(":")
    try:
        kind = parts[0].lower()
        nx, ny = (int(v) for v in parts[1].lower().split("x"))
        if kind == "checkerboard" and len(parts) == 3:
            return Checkerboard(nx, ny, float(parts[2]))
        if kind == "charuco" and len(parts) in (4, 5):
            dictionary = parts[4] if len(parts) == 5 else "DICT_4X4_50"
            return CharucoBoard(nx, ny, float(parts[2]), float(parts[3]), dictionary)
    except (IndexError, ValueError) as exc:
        if "must" in str(exc):  # the board's own validation: say what is wrong
            raise ValueError(f"board {text!r}: {exc}") from None
    raise ValueError(
        f"board must be checkerboard:COLSxROWS:SQUARE or "
        f"charuco:SXxSY:SQUARE:MARKER[:DICTIONARY], got {text!r}"
    )


@dataclass
class CalibrationViews:
    """Rendered stereo views of a calibration board and the true board poses.

    Attributes
    ----------
    left, right : (V, H, W) uint8
        The views of the left and right camera.
    rig : StereoRig
    board : Checkerboard or CharucoBoard
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
    board : Checkerboard, CharucoBoard or str
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
    if not isinstance(board, Checkerboard | CharucoBoard):
        raise ValueError(f"board must be a Checkerboard, CharucoBoard or str, got {board!r}")
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


# --------------------------------------------------------------------------- surfaces


def _sinc(x: np.ndarray) -> np.ndarray:
    """``sin(x) / x`` (1 at 0)."""
    return np.sinc(np.asarray(x) / np.pi)


def _asinc(x: np.ndarray) -> np.ndarray:
    """``asin(x) / x`` (1 at 0)."""
    x = np.asarray(x, dtype=float)
    safe = np.where(x == 0, 1.0, x)
    return np.where(x == 0, 1.0, np.arcsin(np.clip(safe, -1, 1)) / safe)


class _Sheet:
    """Biaxial in-plane stretch of a flat rectangular sheet (the ``stretch`` case)."""

    kind = "stretch"

    def __init__(self, center, axes, half_size, stretch, n_frames) -> None:
        self.center = np.asarray(center, dtype=float)
        self.axes = np.asarray(axes, dtype=float)  # (3, 3): columns e1, e2, normal away
        self.half_size = np.asarray(half_size, dtype=float)
        self.stretch = np.asarray(stretch, dtype=float)
        self.n_frames = int(n_frames)

    def stretches(self, t: float) -> np.ndarray:
        return 1 + t * (self.stretch - 1)

    def positions(self, X: np.ndarray, t: float) -> np.ndarray:
        return self.center + (X * self.stretches(t)) @ self.axes[:, :2].T

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        F = self.axes[:, :2] * self.stretches(t)
        return np.broadcast_to(F, (len(X), 3, 2)).copy()

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        E = np.diag((self.stretches(t) ** 2 - 1) / 2)
        return np.broadcast_to(E, (len(X), 2, 2)).copy()

    @np.errstate(divide="ignore", invalid="ignore", over="ignore")
    def hit(self, origin, M, xn, yn, t: float) -> np.ndarray:
        """Material points ``(n, 2)`` hit by the rays (see ``Shader``); NaN: none."""
        o, (dx, dy, dz) = _local_rays(origin, M, xn, yn, self.center, self.axes)
        depth = -o[2] / dz
        lam = self.stretches(t)
        X = np.column_stack([(o[0] + depth * dx) / lam[0], (o[1] + depth * dy) / lam[1]])
        hx, hy = self.half_size
        X[~((depth > 0) & (np.abs(X[:, 0]) <= hx) & (np.abs(X[:, 1]) <= hy))] = np.nan
        return X

    def texture_extent(self) -> tuple[float, float, float, float]:
        hx, hy = self.half_size
        return (-hx, -hy, hx, hy)

    def texture_gain(self, X: np.ndarray) -> np.ndarray | float:
        return 1.0

    def mapping(self, t: float) -> dict:
        lam = self.stretches(t)
        E = (lam**2 - 1) / 2
        return {"t": t, "lambda1": lam[0], "lambda2": lam[1], "E11": E[0], "E22": E[1], "E12": 0}

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "center_mm": self.center.tolist(),
            "e1": self.axes[:, 0].tolist(),
            "e2": self.axes[:, 1].tolist(),
            "normal_away_from_cameras": self.axes[:, 2].tolist(),
            "half_size_mm": self.half_size.tolist(),
            "final_stretch": self.stretch.tolist(),
            "n_frames": self.n_frames,
            "map": "x = center + lambda1(t) X1 e1 + lambda2(t) X2 e2, |X1|, |X2| <= half_size",
            "strain": "E = diag((lambda1^2 - 1) / 2, (lambda2^2 - 1) / 2) in (e1, e2)",
        }


class _Dome:
    """A clamped circular membrane inflating into a spherical cap (the ``dome`` case)."""

    kind = "dome"

    def __init__(self, center, axes, radius, height, plate_half, n_frames) -> None:
        self.center = np.asarray(center, dtype=float)
        self.axes = np.asarray(axes, dtype=float)  # columns e1, e2, normal away from cameras
        self.up = -self.axes[:, 2]  # towards the cameras: the dome bulges this way
        self.radius = float(radius)
        self.height = float(height)
        self.plate_half = float(plate_half)
        self.n_frames = int(n_frames)

    def shape(self, t: float) -> tuple[float, float, float]:
        """Apex height ``h``, curvature ``kappa`` and meridional stretch ``lam_m`` at ``t``."""
        h = t * self.height
        kappa = 2 * h / (self.radius**2 + h**2)
        return h, kappa, float(_asinc(kappa * self.radius))

    def _polar(self, X: np.ndarray, t: float):
        h, kappa, lam_m = self.shape(t)
        rho = np.hypot(X[:, 0], X[:, 1])
        s = lam_m * rho  # arc length from the apex
        ratio = lam_m * _sinc(kappa * s)  # in-plane radius / rho = circumferential stretch
        on = rho <= self.radius
        return h, kappa, lam_m, rho, s, ratio, on

    def positions(self, X: np.ndarray, t: float) -> np.ndarray:
        h, kappa, _, _, s, ratio, on = self._polar(X, t)
        drop = 0.5 * kappa * s**2 * _sinc(0.5 * kappa * s) ** 2  # (1 - cos(kappa s)) / kappa
        inplane = X * np.where(on, ratio, 1.0)[:, None]
        height = np.where(on, h - drop, 0.0)
        return self.center + inplane @ self.axes[:, :2].T + height[:, None] * self.up

    def gradient(self, X: np.ndarray, t: float) -> np.ndarray:
        _, kappa, lam_m, rho, s, ratio, on = self._polar(X, t)
        safe = np.where(rho > 0, rho, 1.0)
        er = np.where((rho > 0)[:, None], X / safe[:, None], [1.0, 0.0])
        ephi = np.column_stack([-er[:, 1], er[:, 0]])
        er3, ephi3 = er @ self.axes[:, :2].T, ephi @ self.axes[:, :2].T
        tangent = np.cos(kappa * s)[:, None] * er3 - np.sin(kappa * s)[:, None] * self.up
        F = lam_m * np.einsum("ni,nj->nij", tangent, er) + ratio[:, None, None] * np.einsum(
            "ni,nj->nij", ephi3, ephi
        )
        F[~on] = self.axes[:, :2]
        return F

    def stretches(self, X: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Meridional and circumferential stretches ``(N,)``, 1 on the plate."""
        _, _, lam_m, _, _, ratio, on = self._polar(X, t)
        return np.where(on, lam_m, 1.0), np.where(on, ratio, 1.0)

    def strain(self, X: np.ndarray, t: float) -> np.ndarray:
        lam_m, lam_c = self.stretches(X, t)
        rho = np.hypot(X[:, 0], X[:, 1])
        safe = np.where(rho > 0, rho, 1.0)
        er = np.where((rho > 0)[:, None], X / safe[:, None], [1.0, 0.0])
        Em, Ec = (lam_m**2 - 1) / 2, (lam_c**2 - 1) / 2
        return Ec[:, None, None] * np.eye(2) + (Em - Ec)[:, None, None] * np.einsum(
            "ni,nj->nij", er, er
        )

    @np.errstate(divide="ignore", invalid="ignore", over="ignore")
    def hit(self, origin, M, xn, yn, t: float) -> np.ndarray:
        """Material points ``(n, 2)`` hit by the rays (see ``Shader``); NaN: none."""
        h, kappa, lam_m = self.shape(t)
        # local frame (e1, e2, -up); the sphere through the apex (0, 0, -h), stable for
        # kappa -> 0: kappa |p|^2 - 2 p_z = 0 with p relative to the apex
        o, (dx, dy, dz) = _local_rays(origin, M, xn, yn, self.center, self.axes)
        p0 = o + np.array([0.0, 0.0, h])
        A = kappa * (dx * dx + dy * dy + dz * dz)
        B = 2 * (kappa * (p0[0] * dx + p0[1] * dy + p0[2] * dz) - dz)
        C = kappa * (p0 @ p0) - 2 * p0[2]
        disc = B * B - 4 * A * C
        q = -0.5 * (B + np.copysign(np.sqrt(np.clip(disc, 0, None)), B))
        depth = C / q  # the root nearer the camera
        X = np.column_stack([o[0] + depth * dx, o[1] + depth * dy])
        r = np.hypot(X[:, 0], X[:, 1])
        on_cap = (disc >= 0) & (depth > 0) & (o[2] + depth * dz <= 0) & (r <= self.radius)
        depth = np.where(on_cap, depth, -o[2] / dz)  # else the plate's plane
        X = np.column_stack([o[0] + depth * dx, o[1] + depth * dy])
        r = np.hypot(X[:, 0], X[:, 1])
        X *= np.where(on_cap, _asinc(np.minimum(kappa * r, 1.0)) / lam_m, 1.0)[:, None]
        plate = ~on_cap & (depth > 0) & np.all(np.abs(X) <= self.plate_half, axis=1)
        X[~(on_cap | plate)] = np.nan
        return X

    def texture_extent(self) -> tuple[float, float, float, float]:
        b = self.plate_half
        return (-b, -b, b, b)

    def texture_gain(self, X: np.ndarray) -> np.ndarray:
        return np.where(X[:, 0] ** 2 + X[:, 1] ** 2 <= self.radius**2, 1.0, _PLATE_GAIN)

    def mapping(self, t: float) -> dict:
        h, kappa, lam_m = self.shape(t)
        return {
            "t": t,
            "apex_height_mm": h,
            "curvature_per_mm": kappa,
            "sphere_radius_mm": 1 / kappa if kappa > 0 else None,
            "sphere_center_mm": (
                (self.center + (h - 1 / kappa) * self.up).tolist() if kappa > 0 else None
            ),
            "meridional_stretch": lam_m,
            "rim_polar_angle_deg": math.degrees(math.asin(min(1.0, kappa * self.radius))),
            "E_meridional": (lam_m**2 - 1) / 2,
            "E_circumferential_apex": (lam_m**2 - 1) / 2,
            "E_circumferential_rim": 0.0,
        }

    def to_dict(self) -> dict:
        return {
            "kind": self.kind,
            "center_mm": self.center.tolist(),
            "e1": self.axes[:, 0].tolist(),
            "e2": self.axes[:, 1].tolist(),
            "normal_away_from_cameras": self.axes[:, 2].tolist(),
            "radius_mm": self.radius,
            "final_apex_height_mm": self.height,
            "plate_half_size_mm": self.plate_half,
            "plate_gain": _PLATE_GAIN,
            "n_frames": self.n_frames,
            "map": (
                "rho = |X| <= radius: s = lambda_m rho, x = center + (sin(kappa s) / kappa) "
                "X / rho + (h - (1 - cos(kappa s)) / kappa) up, up = -normal; rho > radius: "
                "x = center + X1 e1 + X2 e2 (fixed plate); h = t final_apex_height, "
                "kappa = 2 h / (radius^2 + h^2), lambda_m = asin(kappa radius) / (kappa radius)"
            ),
            "strain": (
                "E = diag((lambda_m^2 - 1) / 2, (lambda_c^2 - 1) / 2) in (e_rho, e_phi), "
                "lambda_c = sin(kappa s) / (kappa rho); 0 on the plate"
            ),
        }


def _surface_from_dict(d: dict):
    axes = np.column_stack([d["e1"], d["e2"], d["normal_away_from_cameras"]])
    if d["kind"] == "stretch":
        return _Sheet(d["center_mm"], axes, d["half_size_mm"], d["final_stretch"], d["n_frames"])
    if d["kind"] == "dome":
        return _Dome(
            d["center_mm"],
            axes,
            d["radius_mm"],
            d["final_apex_height_mm"],
            d["plate_half_size_mm"],
            d["n_frames"],
        )
    raise ValueError(f"unknown surface kind {d['kind']!r}")


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


def _surface_texture(
    surface: _Sheet | _Dome,
    texture: TextureKind,
    *,
    speckle_radius: float,
    speckle_density: float,
    speckle_contrast: float,
    rng: np.random.Generator,
) -> tuple[_Raster, SpecklePattern | None]:
    x0, y0, x1, y1 = surface.texture_extent()
    if texture == "speckle":
        texel = speckle_radius / 5
        pad = 4 * texel
        x0, y0, x1, y1 = x0 - pad, y0 - pad, x1 + pad, y1 + pad
        nx, ny = math.ceil((x1 - x0) / texel) + 1, math.ceil((y1 - y0) / texel) + 1
        margin = 6 * speckle_radius
        pattern = speckle_pattern(
            (x0 - margin, y0 - margin, x1 + margin, y1 + margin),
            radius=speckle_radius,
            density=speckle_density,
            contrast=speckle_contrast,
            rng=rng,
        )
        in_texels = SpecklePattern(
            (pattern.centers - (x0, y0)) / texel,
            pattern.sigmas / texel,
            pattern.background,
            pattern.ink,
        )
        identity = Homogeneous("stretch", (0.0, 0.0), lx=1.0, ly=1.0)
        values = render_speckle(in_texels, identity, 0.0, (ny, nx), psf_sigma=0.0)
        return _Raster(values.astype(np.float32), (x0, y0), texel), pattern
    square, per = 2.0, 40  # a 2 mm checker in material coordinates
    texel = square / per
    nx, ny = round((x1 - x0) / texel), round((y1 - y0) / texel)
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
    cx = np.floor((x0 + (jj + 0.5) * texel) / square)
    cy = np.floor((y0 + (ii + 0.5) * texel) / square)
    values = np.where((cx + cy) % 2 == 0, _DARK, _LIGHT)
    values = ndimage.gaussian_filter(values, 1.0, mode="nearest")
    origin = (x0 + 0.5 * texel, y0 + 0.5 * texel)
    return _Raster(values.astype(np.float32), origin, texel), None


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
    import cv2

    if not cv2.imwrite(str(path), image):
        raise OSError(f"OpenCV cannot write {path}")


def _read_png(path: Path) -> np.ndarray:
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise OSError(f"cannot read {path}")
    return image


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2))


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
    _write_json(folder / "rig.json", scene.rig.to_dict())
    n = scene.n_frames
    _write_json(
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
    _write_json(folder / "rig.json", views.rig.to_dict())
    _write_json(
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
