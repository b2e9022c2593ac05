"""The camera's frame and the microscope's x-y, registered automatically.

The microscope's surface-intensity projection (the tissue's surface as the
microscope sees it) and the camera's reference frame show the same tissue
at different scales, orientations and contrasts.  :func:`register_images`
finds the similarity between them from SIFT features (scale- and
rotation-invariant, indifferent to a monotone change of contrast): matches
that pass Lowe's ratio test, a RANSAC fit of a similarity (OpenCV's
``estimateAffinePartial2D``) that keeps the matches it explains, and the
least-squares similarity through those (:meth:`Similarity.from_landmarks`),
whose residual per match is reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from multimodal.geometry import _PLAUSIBLE, Similarity
from tissue_core.errors import InputError

__all__ = ["Registration", "register_images"]

#: the fewest matches RANSAC must keep for a registration to count
MIN_INLIERS = 12


@dataclass(frozen=True)
class Registration:
    """A registration and how well it holds.

    Attributes
    ----------
    transform : Similarity
        Camera pixels to microscope micrometres.
    camera_px, microscope_um : (K, 2) float
        The matches it kept.
    residual_um : (K,) float
        Each kept match's distance from the transform.
    n_matches : int
        Matches that passed the ratio test (before RANSAC).
    """

    transform: Similarity
    camera_px: np.ndarray
    microscope_um: np.ndarray
    residual_um: np.ndarray
    n_matches: int

    def as_dict(self) -> dict:
        return {
            **self.transform.as_dict(),
            "from": "features",
            "matches": self.n_matches,
            "inliers": len(self.residual_um),
            "residual_um_rms": float(np.sqrt(np.mean(self.residual_um**2))),
            "residual_um_max": float(self.residual_um.max()),
        }


def _gray8(image: np.ndarray) -> np.ndarray:
    """The image as 8 bits, its 0.5-99.5 percentiles stretched over 0-255."""
    image = np.asarray(image, dtype=float)
    if image.ndim == 3:
        image = image.mean(axis=2)
    if image.ndim != 2 or min(image.shape) < 16:
        raise InputError(f"an image to register must be 2D and at least 16 x 16, got {image.shape}")
    finite = image[np.isfinite(image)]
    if finite.size == 0:
        raise InputError("an image to register has no finite pixel")
    lo, hi = np.percentile(finite, [0.5, 99.5])
    if not hi > lo:
        raise InputError("an image to register is uniform: nothing to match")
    scaled = (np.nan_to_num(image, nan=lo) - lo) / (hi - lo) * 255.0
    return np.clip(scaled, 0, 255).astype(np.uint8)


def register_images(
    camera: np.ndarray,
    microscope: np.ndarray,
    pixel_um: tuple[float, float] | float,
    *,
    mirrored: bool = False,
    ratio: float = 0.75,
    threshold_px: float = 3.0,
) -> Registration:
    """The similarity from the camera's image (pixels) to the microscope's (micrometres).

    Parameters
    ----------
    camera : (H, W) array
        The camera's reference frame.
    microscope : (Yh, Xh) array
        The microscope's surface-intensity projection.
    pixel_um : float or (dy, dx)
        The microscope image's pixel size (square pixels are assumed for the
        fit: the mean is used).
    mirrored : bool
        The microscope sees the tissue mirrored (the camera's image is
        flipped top to bottom before matching).
    ratio : float
        Lowe's ratio test.
    threshold_px : float
        RANSAC's distance for a match to count, in microscope pixels.

    Raises
    ------
    InputError
        Fewer than :data:`MIN_INLIERS` matches agree on one similarity.
    """
    import cv2

    size = float(np.mean(np.broadcast_to(np.asarray(pixel_um, float), 2)))
    if not (np.isfinite(size) and _PLAUSIBLE[0] <= size <= _PLAUSIBLE[1]):
        raise InputError(f"the microscope's pixel size must be positive, got {pixel_um}")
    cam = _gray8(camera)
    if mirrored:
        cam = cam[::-1].copy()
    mic = _gray8(microscope)
    sift = cv2.SIFT_create()
    kc, dc = sift.detectAndCompute(cam, None)
    km, dm = sift.detectAndCompute(mic, None)
    if dc is None or dm is None or len(kc) < 2 or len(km) < 2:
        raise InputError("could not register: one of the images has no features to match")
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(dc, dm, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < ratio * p[1].distance]
    if len(good) < MIN_INLIERS:
        raise InputError(
            f"could not register: only {len(good)} features match between the images "
            f"(at least {MIN_INLIERS} needed); give landmark pairs instead (--landmarks)"
        )
    src = np.array([kc[m.queryIdx].pt for m in good], dtype=np.float64)
    dst = np.array([km[m.trainIdx].pt for m in good], dtype=np.float64)
    _, inliers = cv2.estimateAffinePartial2D(
        src, dst, method=cv2.RANSAC, ransacReprojThreshold=threshold_px, maxIters=5000,
        confidence=0.999, refineIters=20,
    )  # fmt: skip
    keep = np.zeros(len(good), bool) if inliers is None else inliers.ravel().astype(bool)
    if keep.sum() < MIN_INLIERS:
        hint = "" if mirrored else " (is the microscope's image mirrored? try --mirrored)"
        raise InputError(
            f"could not register: only {int(keep.sum())} of {len(good)} matches agree on one "
            f"similarity{hint}; else give landmark pairs (--landmarks)"
        )
    camera_px = src[keep]
    if mirrored:  # back to the camera's own rows
        camera_px = np.column_stack([camera_px[:, 0], cam.shape[0] - 1 - camera_px[:, 1]])
    microscope_um = dst[keep] * size
    try:
        transform, residual = Similarity.from_landmarks(camera_px, microscope_um, mirrored=mirrored)
    except InputError:
        raise InputError(
            "could not register: the matches kept do not fix a similarity (is the "
            "microscope's pixel size right?)"
        ) from None
    return Registration(transform, camera_px, microscope_um, residual, len(good))
