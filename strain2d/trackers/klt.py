"""``klt``: pyramidal Lucas-Kanade optical flow (OpenCV) frame to frame.

Each point is tracked from the previous frame to the current one, with the
previous frame's velocity as the initial guess, then tracked back; the
forward-backward distance ``fb`` (pixels) decides visibility.  A point is lost
for good once ``fb`` exceeds ``fb_threshold``, LK fails, or its window leaves
the image; its position then stays at the last good value.

``quality = 1 - fb / fb_threshold`` (1 = forward and backward agree exactly,
0 = lost).

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

from strain2d.errors import InputError
from strain2d.trackers import register_tracker
from strain2d.trackers._convert import to_uint8
from strain2d.tracks import Tracks


@register_tracker(
    "klt", description="OpenCV pyramidal Lucas-Kanade, frame to frame, forward-backward check"
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
    if levels < 0 or fb_threshold <= 0:
        raise InputError("levels must be >= 0 and fb_threshold > 0")
    points = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    total = len(frames) if hasattr(frames, "__len__") else None
    if value_range is None:
        value_range = getattr(frames, "value_range", None)
    it = iter(frames)
    try:
        ref = next(it)
    except StopIteration:
        raise InputError("no frames to track") from None
    if value_range is None:
        lo, hi = float(ref.min()), float(ref.max())
        value_range = (lo, hi if hi > lo else lo + 1.0)
    h, w = ref.shape
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, max_iterations, epsilon)
    lk = {"winSize": (window, window), "maxLevel": levels, "criteria": criteria}
    half = window // 2

    prev_img = to_uint8(ref, value_range)
    prev = points.copy()
    velocity = np.zeros_like(prev)
    alive = np.ones(len(points), dtype=bool)
    positions, visible, quality = [points.astype(float)], [alive.copy()], [np.ones(len(points))]
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
        positions.append(new.astype(float))
        visible.append(alive.copy())
        quality.append(np.where(alive, np.clip(1.0 - fb / fb_threshold, 0.0, 1.0), 0.0))
        prev, prev_img = new.astype(np.float32), img
        if progress:
            progress(len(positions), total)
    if len(positions) < 2:
        raise InputError("tracking needs at least 2 frames")
    options = {
        "window": window,
        "levels": levels,
        "fb_threshold": fb_threshold,
        "max_iterations": max_iterations,
        "epsilon": epsilon,
    }
    return Tracks(
        np.stack(positions),
        np.stack(visible),
        np.stack(quality),
        {"tracker": "klt", "options": options},
    )
