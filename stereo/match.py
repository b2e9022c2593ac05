"""Sub-pixel correspondences of points between the left and right views.

The two views of a surface differ by a large disparity and a perspective
change, which a frame-to-frame tracker cannot bridge directly.  So
:func:`match_views`:

1. estimates a homography from the left to the right image from SIFT
   features (Lowe 2004) matched with the ratio test and, when a calibration
   is given, kept only within :data:`FEATURE_EPIPOLAR_FACTOR` times
   ``max_epipolar_px`` of their epipolar line (keypoints are located less
   precisely than correlated subsets); RANSAC (MAGSAC++) fits it;
2. warps the right image onto the left one with that homography (cubic
   interpolation), which removes the disparity and most of the perspective
   difference;
3. correlates a subset around every point between the left image and the
   warped right one with the ``dic`` tracker (IC-GN with an affine or
   quadratic subset shape function, which absorbs the remaining
   perspective and surface-shape differences);
4. maps the matched positions back through the homography, and, with a
   calibration, rejects matches further than ``max_epipolar_px`` from their
   epipolar line.

References
----------
* D. G. Lowe, Distinctive image features from scale-invariant keypoints,
  IJCV 60 (2004) 91-110, doi:10.1023/B:VISI.0000029664.99615.94.
* D. Barath et al., MAGSAC++, CVPR 2020, doi:10.1109/CVPR42600.2020.00138.
* B. Pan, Digital image correlation for surface deformation measurement:
  historical developments, recent advances and future goals, Meas. Sci.
  Technol. 29 (2018) 082001, doi:10.1088/1361-6501/aac55b (stereo-DIC).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from tissue_core.errors import InputError

__all__ = [
    "FEATURE_EPIPOLAR_FACTOR",
    "Matches",
    "epipolar_distance",
    "estimate_homography",
    "match_views",
]

log = logging.getLogger(__name__)

#: the feature matches that relate the views are kept within this many times the
#: epipolar tolerance of the final matches (SIFT keypoints are located to about a pixel)
FEATURE_EPIPOLAR_FACTOR = 3.0


@dataclass(frozen=True, eq=False)
class Matches:
    """Correspondences of N points.

    Attributes
    ----------
    left, right : (N, 2) pixels (NaN in ``right`` where no match was found)
    quality : (N,) zero-normalized cross-correlation of the matched subsets
    visible : (N,) bool, the match was found and passed the checks
    epipolar_px : (N,) distance of the right point from the left point's
        epipolar line (NaN without calibration)
    meta : dict
    """

    left: np.ndarray
    right: np.ndarray
    quality: np.ndarray
    visible: np.ndarray
    epipolar_px: np.ndarray
    meta: dict = field(default_factory=dict)


def _gray8(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3:
        img = img.mean(axis=2)
    if img.dtype == np.uint8:
        return img
    lo, hi = np.percentile(img, [0.5, 99.5])
    return np.uint8(np.clip((img - lo) * 255.0 / max(hi - lo, 1e-12), 0, 255))


def epipolar_distance(left_px: np.ndarray, right_px: np.ndarray, calib) -> np.ndarray:
    """Distance in right-image pixels of each right point from its epipolar line.

    Measured on undistorted coordinates (the line is straight there) and
    scaled by the right camera's focal length.
    """
    from stereo.camera import undistort

    left_px = np.asarray(left_px, np.float64).reshape(-1, 2)
    right_px = np.asarray(right_px, np.float64).reshape(-1, 2)
    out = np.full(len(left_px), np.nan)
    ok = np.isfinite(left_px).all(axis=1) & np.isfinite(right_px).all(axis=1)
    if not ok.any():
        return out
    nl = undistort(left_px[ok], calib.K_left, calib.dist_left)
    nr = undistort(right_px[ok], calib.K_right, calib.dist_right)
    t = np.asarray(calib.T, np.float64).ravel()
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    E = tx @ np.asarray(calib.R, np.float64)
    hl = np.column_stack([nl, np.ones(len(nl))])
    hr = np.column_stack([nr, np.ones(len(nr))])
    lines = hl @ E.T  # epipolar lines in the right normalized image
    d = np.abs(np.sum(lines * hr, axis=1)) / np.hypot(lines[:, 0], lines[:, 1])
    f = 0.5 * (calib.K_right[0, 0] + calib.K_right[1, 1])
    out[ok] = d * f
    return out


def estimate_homography(
    left: np.ndarray,
    right: np.ndarray,
    *,
    calib=None,
    mask: np.ndarray | None = None,
    max_epipolar_px: float = 3.0,
    features: int = 6000,
) -> tuple[np.ndarray, dict]:
    """Homography mapping left pixels to right pixels, from SIFT matches.

    Parameters
    ----------
    left, right : (H, W) images
    calib : Calibration, optional
        Keeps only feature matches within ``max_epipolar_px`` of their
        epipolar line.
    mask : (H, W) uint8, optional
        Where to look for features in the left image (e.g. around the grid).

    Returns
    -------
    H : (3, 3)
    info : dict with ``features``, ``matches``, ``inliers``.
    """
    import cv2

    a, b = _gray8(left), _gray8(right)
    sift = cv2.SIFT_create(nfeatures=features)
    ka, da = sift.detectAndCompute(a, mask)
    kb, db = sift.detectAndCompute(b, None)
    if da is None or db is None or len(ka) < 8 or len(kb) < 8:
        raise InputError("too few features to match the two views (is the surface textured?)")
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(da, db, k=2)
    good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < 0.75 * n.distance]
    pa = np.float64([ka[m.queryIdx].pt for m in good]).reshape(-1, 2)
    pb = np.float64([kb[m.trainIdx].pt for m in good]).reshape(-1, 2)
    if calib is not None and len(pa):
        keep = epipolar_distance(pa, pb, calib) <= max_epipolar_px
        if keep.sum() < 8 <= len(pa):
            raise InputError(
                f"only {int(keep.sum())} of {len(pa)} feature matches between the views lie "
                f"within {max_epipolar_px:g} px of their epipolar lines: check that the "
                "calibration is of these cameras as they were set up (or allow more with "
                "--max-epipolar)"
            )
        pa, pb = pa[keep], pb[keep]
    if len(pa) < 8:
        raise InputError(
            f"only {len(pa)} feature matches between the views: cannot relate them "
            "(check the images are a stereo pair of one textured surface)"
        )
    H, inl = cv2.findHomography(pa, pb, cv2.USAC_MAGSAC, 3.0, maxIters=5000, confidence=0.999)
    if H is None or int(inl.sum()) < 8:
        raise InputError("no consistent homography between the two views")
    info = {"features": [len(ka), len(kb)], "matches": len(pa), "inliers": int(inl.sum())}
    return H, info


def _apply(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    h = np.column_stack([pts, np.ones(len(pts))]) @ H.T
    return h[:, :2] / h[:, 2:]


def match_views(
    left: np.ndarray,
    right: np.ndarray,
    points: np.ndarray,
    *,
    calib=None,
    subset: int = 41,
    shape_function: str = "quadratic",
    zncc_min: float = 0.8,
    max_epipolar_px: float = 1.0,
    homography: np.ndarray | None = None,
) -> Matches:
    """Find ``points`` of the left image in the right image, sub-pixel.

    Parameters
    ----------
    left, right : (H, W) images
    points : (N, 2) pixels in the left image
    calib : Calibration, optional
        Epipolar checks (features and final matches).
    subset, shape_function, zncc_min
        The ``dic`` correlation (see the dic tracker, :func:`strain2d.get_tracker`).
    max_epipolar_px : float
        With a calibration, matches further from their epipolar line are
        not visible, and the feature matches that relate the views are kept
        within :data:`FEATURE_EPIPOLAR_FACTOR` times this.
    homography : (3, 3), optional
        A left-to-right homography to start from instead of the SIFT one.

    Returns
    -------
    Matches
    """
    import cv2

    from strain2d import get_tracker

    track_dic = get_tracker("dic").function

    points = np.asarray(points, np.float64).reshape(-1, 2)
    a = np.asarray(left, np.float64)
    b = np.asarray(right, np.float64)
    if a.ndim != 2 or b.ndim != 2:
        raise InputError("match_views takes gray (H, W) images")
    if a.shape != b.shape:
        raise InputError(
            f"the views differ in size: {a.shape[1]}x{a.shape[0]} and {b.shape[1]}x{b.shape[0]}"
        )
    if len(points) == 0:
        raise InputError("no points to match")
    if not np.isfinite(points).all():
        raise InputError("the points to match must be finite numbers")
    outside = (points < 0).any(axis=1) | (points[:, 0] > a.shape[1] - 1)
    outside |= points[:, 1] > a.shape[0] - 1
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise InputError(
            f"point {i} at ({points[i, 0]:g}, {points[i, 1]:g}) lies outside the "
            f"{a.shape[1]}x{a.shape[0]} px left image"
        )
    if subset < 7 or subset % 2 == 0:
        raise InputError(f"the matching subset must be an odd number >= 7, got {subset}")
    if not (np.isfinite(max_epipolar_px) and max_epipolar_px > 0):
        raise InputError(f"the epipolar tolerance must be a positive number, got {max_epipolar_px}")
    if calib is not None and tuple(calib.image_size) != (a.shape[1], a.shape[0]):
        w, h = calib.image_size
        raise InputError(
            f"the calibration is for {w}x{h} images, the views are {a.shape[1]}x{a.shape[0]}"
        )
    info: dict = {}
    if homography is None:
        mask = np.zeros(a.shape, np.uint8)
        lo = np.floor(points.min(axis=0) - 3 * subset).astype(int).clip(0)
        hi = np.ceil(points.max(axis=0) + 3 * subset).astype(int)
        mask[lo[1] : hi[1], lo[0] : hi[0]] = 255
        H, info = estimate_homography(
            a,
            b,
            calib=calib,
            mask=mask,
            max_epipolar_px=FEATURE_EPIPOLAR_FACTOR * max_epipolar_px,
        )
    else:
        H = np.asarray(homography, np.float64)
    warped = cv2.warpPerspective(
        b.astype(np.float32),
        H,
        (a.shape[1], a.shape[0]),
        flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REPLICATE,
    )
    # the dic tracker itself, not strain2d's track(): matching needs no strain-ready grid
    tracks = track_dic(
        [a.astype(np.float32), warped],
        points,
        subset=subset,
        shape_function=shape_function,
        zncc_min=zncc_min,
    )
    found = tracks.positions[1]
    right_px = _apply(H, found)
    visible = tracks.visible[1].copy()
    inside = (right_px >= 0).all(axis=1) & (right_px[:, 0] <= b.shape[1] - 1)
    inside &= right_px[:, 1] <= b.shape[0] - 1
    visible &= inside
    epi = np.full(len(points), np.nan)
    if calib is not None:
        epi = epipolar_distance(points, right_px, calib)
        visible &= epi <= max_epipolar_px
    right_px[~visible] = np.nan
    info.update(
        {
            "subset": subset,
            "shape_function": shape_function,
            "zncc_min": zncc_min,
            "max_epipolar_px": max_epipolar_px if calib is not None else None,
            "feature_max_epipolar_px": (
                FEATURE_EPIPOLAR_FACTOR * max_epipolar_px if calib is not None else None
            ),
            "homography": H.tolist(),
        }
    )
    return Matches(
        left=points,
        right=right_px,
        quality=tracks.quality[1],
        visible=visible,
        epipolar_px=epi,
        meta=info,
    )
