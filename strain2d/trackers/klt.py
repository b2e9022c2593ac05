"""``klt``: pyramidal Lucas-Kanade optical flow (OpenCV) frame to frame.

Each point is tracked from the previous frame to the current one, with the
previous frame's velocity as the initial guess, then tracked back; the
forward-backward distance ``fb`` (pixels) decides visibility.  A point is lost
for good once ``fb`` exceeds ``fb_threshold``, LK fails, or its window leaves
the image; its position then stays at the last good value.

``quality = 1 - fb / fb_threshold`` (1 = forward and backward agree exactly,
0 = lost).

Window-deformation bias correction
----------------------------------
Translation-only Lucas-Kanade assumes the window moves rigidly.  When the
tissue stretches or rotates by a displacement-gradient increment ``dG`` between
two frames, the converged LK step is, to first order,

    d = u(p) + H^-1 sum_w g g^T dG (x - p),     H = sum_w g g^T,

i.e. the motion of a gradient-weighted point of the window rather than of its
centre ``p`` (``g`` are the template's image gradients).  The second term is a
bias of a few hundredths of a pixel per frame that has the same sign frame
after frame for a given point, so it accumulates linearly along the video
(about 2 px after a 1.5 stretch in 30 frames with a 31 px window).  With
``affine_correction=True`` (default) ``dG`` is estimated at each point by a
least-squares affine fit of the LK steps of its nearest tracked neighbours and
the bias term is subtracted.  This needs at least 3 non-collinear points;
with fewer, or where the fit is singular, no correction is applied.

References
----------
.. [1] Bouguet, J.-Y. (2001). Pyramidal implementation of the affine Lucas
   Kanade feature tracker. Intel Corporation.
.. [2] Kalal, Z., Mikolajczyk, K., & Matas, J. (2010). Forward-backward error:
   automatic detection of tracking failures. ICPR, 2756-2759.
   https://doi.org/10.1109/ICPR.2010.675
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from scipy.spatial import cKDTree

from strain2d.errors import InputError
from strain2d.trackers import TrackerOption, register_tracker
from strain2d.trackers._convert import to_uint8
from strain2d.trackers._series import FrameSeries
from strain2d.tracks import Tracks


def _window_bias(
    template: np.ndarray,
    points: np.ndarray,
    steps: np.ndarray,
    neighbours: np.ndarray,
    alive: np.ndarray,
    window: int,
) -> np.ndarray:
    """First-order LK bias ``H^-1 sum g g^T dG (x - p)`` of each point's step, ``(N, 2)``.

    ``dG`` comes from an affine least-squares fit of the steps of each point's
    ``neighbours`` (``(N, k)`` indices, the point itself included).
    """
    import cv2

    h, w = template.shape
    gx = cv2.Scharr(template, cv2.CV_32F, 1, 0) / 32.0
    gy = cv2.Scharr(template, cv2.CV_32F, 0, 1) / 32.0
    off = np.arange(-(window // 2), window // 2 + 1)
    oy, ox = (a.ravel() for a in np.meshgrid(off, off, indexing="ij"))
    cx = np.rint(points[:, 0]).astype(int)[:, None] + ox
    cy = np.rint(points[:, 1]).astype(int)[:, None] + oy
    inside = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h)
    cx, cy = np.clip(cx, 0, w - 1), np.clip(cy, 0, h - 1)
    g = np.stack([gx[cy, cx], gy[cy, cx]], axis=-1).astype(float) * inside[..., None]
    rel = np.stack([cx - points[:, :1], cy - points[:, 1:]], axis=-1)
    gT = np.swapaxes(g, 1, 2)
    H = gT @ g  # (N, 2, 2)

    use = alive[neighbours].astype(float)[..., None]  # (N, k, 1)
    offsets = points[neighbours] - points[:, None]  # (N, k, 2)
    A = np.concatenate([np.ones_like(offsets[..., :1]), offsets], axis=-1) * use
    coef = np.linalg.pinv(A) @ (steps[neighbours] * use)  # (N, 3, 2): rows a, dG^T
    dG = np.swapaxes(coef[:, 1:, :], 1, 2)
    rank_ok = np.linalg.matrix_rank(A) == 3
    s = np.sum((g @ dG) * rel, axis=-1)  # g^T dG (x - p) per pixel, (N, W)
    b = (gT @ s[..., None])[..., 0]
    det = np.linalg.det(H)
    ok = rank_ok & (det > 1e-6 * np.einsum("nii->n", H) ** 2)
    bias = np.zeros_like(points, dtype=float)
    bias[ok] = np.linalg.solve(H[ok], b[ok][..., None])[..., 0]
    return bias


@register_tracker(
    "klt",
    description="OpenCV pyramidal Lucas-Kanade, frame to frame, forward-backward check",
    options=[
        TrackerOption("window", "--window", "window side in px", type=int),
        TrackerOption("levels", "--levels", "pyramid levels", type=int),
        TrackerOption(
            "fb_threshold",
            "--fb-threshold",
            "forward-backward error in px that marks a point lost",
            type=float,
        ),
    ],
)
def track_klt(
    frames: Iterable[np.ndarray],
    points: np.ndarray,
    *,
    window: int = 31,
    levels: int = 3,
    fb_threshold: float = 1.0,
    max_iterations: int = 50,
    epsilon: float = 1e-3,
    affine_correction: bool = True,
    neighbours: int = 9,
    value_range: tuple[float, float] | None = None,
    progress: Callable[[int, int | None], None] | None = None,
) -> Tracks:
    """Track points with pyramidal Lucas-Kanade.

    Parameters
    ----------
    frames : iterable of (H, W) float
        Frame 0 is the reference.  A :class:`~strain2d.frames.FrameSource`
        supplies its ``value_range`` and length.
    points : (N, 2) float
        Reference positions (x, y) in pixels.
    window : int, keyword-only
        Side of the square LK window in pixels (odd, >= 5).
    levels : int, keyword-only
        Pyramid levels above the full resolution.
    fb_threshold : float, keyword-only
        Forward-backward distance (pixels) above which a point is lost.
    max_iterations, epsilon : keyword-only
        LK stopping criteria per level.
    affine_correction : bool, keyword-only
        Remove the window-deformation bias (see the module docstring).
    neighbours : int, keyword-only
        Points (itself included) whose steps give the local affine fit.
    value_range : (lo, hi), keyword-only
        Intensity range mapped to 0..255; default the source's, else the first
        frame's min and max.
    progress : callable(done, total), keyword-only
        Called after each frame.

    Returns
    -------
    Tracks
    """
    import cv2

    if window < 5 or window % 2 == 0:
        raise InputError(f"--window must be an odd number >= 5, got {window}")
    if levels < 0 or not (np.isfinite(fb_threshold) and fb_threshold > 0):
        raise InputError("--levels must be >= 0 and --fb-threshold a positive number")
    points = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    total = len(frames) if hasattr(frames, "__len__") else None
    if value_range is None:
        value_range = getattr(frames, "value_range", None)
    if value_range is None and isinstance(frames, np.ndarray) and frames.dtype == np.uint8:
        value_range = (0.0, 255.0)
    it = iter(frames)
    try:
        ref = next(it)
    except StopIteration:
        raise InputError("no frames to track") from None
    if value_range is None:
        lo, hi = float(ref.min()), float(ref.max())
        value_range = (lo, hi if hi > lo else lo + 1.0)
    h, w = ref.shape
    if window >= min(h, w):
        raise InputError(f"--window {window} must be smaller than the {w}x{h} px frames")
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, max_iterations, epsilon)
    lk = {"winSize": (window, window), "maxLevel": levels, "criteria": criteria}
    half = window // 2
    k = min(neighbours, len(points))
    if affine_correction and k >= 3:
        _, near = cKDTree(points).query(points, k)
        near = near.reshape(len(points), k)
    else:
        affine_correction = False

    prev_img = to_uint8(ref, value_range)
    prev = points.copy()
    velocity = np.zeros_like(prev)
    alive = np.ones(len(points), dtype=bool)
    rows = FrameSeries(
        total, positions=points.astype(float), visible=alive, quality=np.ones(len(points))
    )
    if progress:
        progress(1, total)
    for frame in it:
        img = to_uint8(frame, value_range)
        guess = prev + velocity
        nxt, st, _ = cv2.calcOpticalFlowPyrLK(
            prev_img, img, prev, guess.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk
        )
        back, st_back, _ = cv2.calcOpticalFlowPyrLK(
            img, prev_img, nxt, prev.copy(), flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk
        )
        if affine_correction:
            step = (nxt - prev).astype(float)
            moved = alive & (st.ravel() == 1)  # neighbours LK followed in this frame
            nxt = (
                nxt - _window_bias(prev_img, prev.astype(float), step, near, moved, window)
            ).astype(np.float32)
        fb = np.linalg.norm(back - prev, axis=1)
        inside = (
            (nxt[:, 0] >= half)
            & (nxt[:, 0] <= w - 1 - half)
            & (nxt[:, 1] >= half)
            & (nxt[:, 1] <= h - 1 - half)
        )
        ok = alive & (st.ravel() == 1) & (st_back.ravel() == 1) & (fb < fb_threshold) & inside
        ok &= np.all(np.isfinite(nxt), axis=1)
        new = np.where(ok[:, None], nxt, prev)
        velocity = np.where(ok[:, None], new - prev, 0.0).astype(np.float32)
        alive = ok
        rows.append(
            positions=new,
            visible=alive,
            quality=np.where(alive, np.clip(1.0 - fb / fb_threshold, 0.0, 1.0), 0.0),
        )
        prev, prev_img = new.astype(np.float32), img
        if progress:
            progress(len(rows), total)
    if len(rows) < 2:
        raise InputError("tracking needs at least 2 frames")
    options = {
        "window": window,
        "levels": levels,
        "fb_threshold": fb_threshold,
        "max_iterations": max_iterations,
        "epsilon": epsilon,
        "affine_correction": affine_correction,
        "neighbours": neighbours,
    }
    series = rows.arrays()
    return Tracks(
        series["positions"],
        series["visible"],
        series["quality"],
        {"tracker": "klt", "options": options},
    )
