"""The two-camera model: projection with lens distortion, triangulation.

Conventions (OpenCV's): pixel ``(x, y)`` = (column, row), the centre of the
top-left pixel is ``(0, 0)``; distortion ``(k1, k2, p1, p2, k3)``; world
coordinates are the left camera's, and a point ``X`` is ``R X + T`` in the
right camera's.  Lengths are in the calibration's unit (e.g. mm).

Skew: the camera matrix ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`` maps the
distorted normalized point ``(xd, yd)`` to the pixel ``(fx xd + s yd + cx,
fy yd + cy)`` (Hartley & Zisserman 2004, eq. 6.10; Bouguet's toolbox, VIC-3D
and DICe's VIC-3D model).  OpenCV's own functions ignore ``s`` (its
calibration always writes 0), so with ``s = 0`` this is exactly
``cv2.projectPoints``; with ``s != 0`` the skew is carried exactly, in
:func:`distort` and :func:`undistort` alike.

References
----------
* R. Hartley, A. Zisserman, Multiple View Geometry in Computer Vision, 2nd
  ed., Cambridge University Press 2004, doi:10.1017/CBO9780511811685
  (linear triangulation, section 12.2; reprojection-error refinement, 12.3).
* D. C. Brown, Decentering distortion of lenses, Photogrammetric
  Engineering 32 (1966) 444-462 (the distortion model OpenCV uses).
"""

from __future__ import annotations

import numpy as np

__all__ = ["distort", "project", "reprojection_errors", "triangulate", "undistort"]


def _coefficients(dist) -> np.ndarray:
    """OpenCV's distortion vector as 12 coefficients (k1..k3, p1, p2, k4..k6, s1..s4)."""
    d = np.asarray(dist, np.float64).ravel()
    if d.size not in (0, 4, 5, 8, 12, 14):
        raise ValueError(f"distortion needs 4, 5, 8, 12 or 14 coefficients, got {d.size}")
    if d.size == 14 and np.any(d[12:] != 0):
        raise ValueError("tilted-sensor distortion (tau x, tau y) is not supported")
    out = np.zeros(12)
    out[: min(12, d.size)] = d[:12]
    return out


def distort(normalized: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Pixel positions of normalized image points ``(x/z, y/z)``.

    Parameters
    ----------
    normalized : (..., 2)
    K : (3, 3) camera matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``; the skew
        ``s`` shears the distorted point: ``u = fx xd + s yd + cx``
    dist : OpenCV's coefficients: (k1, k2, p1, p2[, k3[, k4, k5, k6[, s1, s2, s3, s4]]]);
        the rational (k4-k6) and thin-prism (s1-s4) terms are supported, the
        tilted-sensor terms (14 coefficients) only when zero

    Returns
    -------
    (..., 2) pixels

    Examples
    --------
    >>> K = np.array([[1000.0, 0, 500], [0, 1000, 400], [0, 0, 1]])
    >>> distort(np.array([0.1, -0.05]), K, np.zeros(5)).tolist()
    [600.0, 350.0]
    """
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = _coefficients(dist)
    x, y = normalized[..., 0], normalized[..., 1]
    r2 = x * x + y * y
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + r2 * (s3 + s4 * r2)
    u = K[0, 0] * xd + K[0, 1] * yd + K[0, 2]
    v = K[1, 1] * yd + K[1, 2]
    return np.stack([u, v], axis=-1)


def undistort(pixels: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Normalized image points of pixel positions (the inverse of :func:`distort`).

    OpenCV's iterative undistortion, polished by Newton steps on
    :func:`distort` so the round trip holds to 1e-9 px even for strong
    distortion.  OpenCV ignores the skew ``K[0, 1]``; it is taken out of the
    pixels first (``u - s (v - cy) / fy`` is the pixel of the same distorted
    point without skew), so the skew is inverted exactly.

    Parameters
    ----------
    pixels : (N, 2)

    Returns
    -------
    (N, 2) normalized coordinates
    """
    import cv2

    pixels = np.asarray(pixels, np.float64).reshape(-1, 2)
    if pixels.size == 0:
        return pixels.copy()
    d = np.asarray(dist, np.float64).ravel()
    K = np.asarray(K, np.float64)
    unskewed = pixels.copy()
    unskewed[:, 0] -= K[0, 1] * (pixels[:, 1] - K[1, 2]) / K[1, 1]
    K0 = K.copy()
    K0[0, 1] = 0.0
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        start = cv2.undistortPointsIter(unskewed[:, None, :], K0, d, None, None, crit)[:, 0, :]
    except AttributeError:  # OpenCV 5 folds the criteria into undistortPoints
        start = cv2.undistortPoints(unskewed[:, None, :], K0, d, criteria=crit)[:, 0, :]
    p = start.astype(np.float64)
    eps = 1e-7
    ex, ey = np.array([eps, 0.0]), np.array([0.0, eps])
    for _ in range(5):
        r = distort(p, K, d) - pixels
        if np.abs(r).max() < 1e-10:
            break
        jx = (distort(p + ex, K, d) - distort(p - ex, K, d)) / (2 * eps)
        jy = (distort(p + ey, K, d) - distort(p - ey, K, d)) / (2 * eps)
        J = np.stack([jx, jy], axis=-1)  # (N, 2, 2)
        p = p - np.linalg.solve(J, r[..., None])[..., 0]
    return p


def project(points: np.ndarray, K: np.ndarray, dist: np.ndarray, R=None, T=None) -> np.ndarray:
    """Pixel positions of 3D points (world = left camera) in a camera ``(R, T)``.

    Parameters
    ----------
    points : (..., 3)
    R, T : (3, 3), (3,), optional
        The camera's pose: ``X_cam = R X + T``; identity for the left camera.

    Returns
    -------
    (..., 2) pixels (NaN behind the camera)
    """
    X = np.asarray(points, np.float64)
    if R is not None:
        X = X @ np.asarray(R, np.float64).T + np.asarray(T, np.float64).ravel()
    z = X[..., 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        normalized = X[..., :2] / np.where(z > 0, z, np.nan)[..., None]
    return distort(normalized, np.asarray(K, np.float64), dist)


def _dlt(nl: np.ndarray, nr: np.ndarray, R: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Linear triangulation from normalized coordinates in both cameras, (N, 3)."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([R, T.reshape(3, 1)])
    A = np.stack(
        [
            nl[:, :1] * P1[2] - P1[0],
            nl[:, 1:] * P1[2] - P1[1],
            nr[:, :1] * P2[2] - P2[0],
            nr[:, 1:] * P2[2] - P2[1],
        ],
        axis=1,
    )  # (N, 4, 4)
    _, _, vt = np.linalg.svd(A)
    h = vt[:, -1, :]
    return h[:, :3] / h[:, 3:]


def triangulate(
    left_px: np.ndarray,
    right_px: np.ndarray,
    calib,
    *,
    refine: bool = True,
    iterations: int = 10,
) -> tuple[np.ndarray, np.ndarray]:
    """3D points from their pixel positions in both views.

    Linear triangulation (DLT) on undistorted coordinates, then Gauss-Newton
    on the reprojection error in pixels of both views, distortion included
    (Hartley & Zisserman 2004, sections 12.2-12.3).

    Parameters
    ----------
    left_px, right_px : (N, 2) pixels; NaN rows give NaN points
    calib : stereo.calibration.Calibration (or anything with ``K_left``,
        ``dist_left``, ``K_right``, ``dist_right``, ``R``, ``T``)

    Returns
    -------
    points : (N, 3) in the calibration's unit, left-camera frame
    reproj_error : (N,) RMS over the two views of the reprojection error, px
    """
    left_px = np.asarray(left_px, np.float64).reshape(-1, 2)
    right_px = np.asarray(right_px, np.float64).reshape(-1, 2)
    n = len(left_px)
    out = np.full((n, 3), np.nan)
    err = np.full(n, np.nan)
    ok = np.isfinite(left_px).all(axis=1) & np.isfinite(right_px).all(axis=1)
    if not ok.any():
        return out, err
    Kl, dl, Kr, dr = calib.K_left, calib.dist_left, calib.K_right, calib.dist_right
    R, T = np.asarray(calib.R, np.float64), np.asarray(calib.T, np.float64).ravel()
    ul, ur = left_px[ok], right_px[ok]
    X = _dlt(undistort(ul, Kl, dl), undistort(ur, Kr, dr), R, T)

    def residual(P: np.ndarray) -> np.ndarray:
        return np.concatenate([project(P, Kl, dl) - ul, project(P, Kr, dr, R, T) - ur], axis=1)

    if refine:
        scale = max(1e-6, float(np.nanmedian(np.abs(X[:, 2])))) * 1e-7
        for _ in range(iterations):
            r = residual(X)  # (M, 4)
            J = np.empty((len(X), 4, 3))
            for k in range(3):
                step = np.zeros(3)
                step[k] = scale
                J[:, :, k] = (residual(X + step) - residual(X - step)) / (2 * scale)
            JtJ = np.einsum("mik,mil->mkl", J, J)
            Jtr = np.einsum("mik,mi->mk", J, r)
            delta = np.linalg.solve(JtJ + 1e-12 * np.eye(3), Jtr[..., None])[..., 0]
            X = X - delta
            if np.abs(delta).max() < 1e-10 * max(1.0, float(np.abs(X).max())):
                break
    r = residual(X)
    out[ok] = X
    err[ok] = np.sqrt((r[:, 0] ** 2 + r[:, 1] ** 2 + r[:, 2] ** 2 + r[:, 3] ** 2) / 2)
    return out, err


def reprojection_errors(
    points: np.ndarray, left_px: np.ndarray, right_px: np.ndarray, calib
) -> np.ndarray:
    """(N, 2) reprojection error magnitude in px, left and right."""
    el = project(points, calib.K_left, calib.dist_left) - left_px
    er = project(points, calib.K_right, calib.dist_right, calib.R, calib.T) - right_px
    return np.stack([np.hypot(el[:, 0], el[:, 1]), np.hypot(er[:, 0], er[:, 1])], axis=1)
