"""The stereo camera model: OpenCV's pinhole camera with distortion, and a realistic rig.

:class:`StereoRig` holds the two cameras' matrices ``K``, their distortion
``(k1, k2, p1, p2, k3)`` and the extrinsics ``R``, ``T`` with ``X_right = R @
X_left + T``; :meth:`StereoRig.project` is ``cv2.projectPoints`` and
:func:`undistort_points` its exact inverse along a ray.  The conventions
(world frame, units, pixels) are those of :mod:`sample_data_synth.stereo`.

References
----------
Zhang, Z. (2000). A flexible new technique for camera calibration. IEEE
TPAMI 22(11), 1330-1334. https://doi.org/10.1109/34.888718
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["Camera", "StereoRig", "default_rig", "undistort_points"]

Camera = Literal["left", "right"]


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


@dataclass(frozen=True, eq=False)
class StereoRig:
    """A calibrated stereo pair (OpenCV's camera model, see :mod:`sample_data_synth.stereo`).

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
