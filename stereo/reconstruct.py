"""3D tracks of grid points from two synchronized, calibrated videos.

:func:`reconstruct` places the points on the left reference frame, matches
them to the right reference frame (:func:`stereo.match.match_views`),
tracks them through time in each view with a 2D tracker (``dic`` by
default), and triangulates every frame (:func:`stereo.camera.triangulate`),
keeping each point's reprojection error and visibility.  The result feeds
:func:`surface_strain.compute_strain` directly.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from strain2d import Tracks
from tissue_core.errors import InputError

__all__ = ["Reconstruction", "reconstruct"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """Points tracked in 3D.

    Attributes
    ----------
    tracks : Tracks
        The 3D tracks (:class:`strain2d.Tracks`, ``(T, N, 3)``) in calibration
        units, left-camera frame, NaN where lost; their quality is the
        negative reprojection error (higher is better).
    reproj_error : (T, N) float, RMS reprojection error over the two views, px
    left, right : (T, N, 2) float, the 2D tracks in each view, px, NaN where that
        view's tracker lost the point (a tracker keeps its last position) and, in
        the right view, where the point was never matched
    meta : dict
        The tracker and its options, the cross-view match (``match``,
        ``match_quality``: each point's ZNCC between the views, ``epipolar_px``),
        ``tracking_quality``: what ``left_quality`` and ``right_quality`` measure.
    left_quality, right_quality : (T, N) float, optional
        The 2D tracker's quality of each point in each view (ZNCC for ``dic``
        and ``gdic``, forward-backward agreement for ``klt``; 1 is best), NaN
        where the point was not tracked in that view: lost by the tracker there,
        or never matched between the views (then NaN in both).
    """

    tracks: Tracks
    reproj_error: np.ndarray
    left: np.ndarray
    right: np.ndarray
    meta: dict = field(default_factory=dict)
    left_quality: np.ndarray | None = None
    right_quality: np.ndarray | None = None

    @property
    def points(self) -> np.ndarray:
        """(T, N, 3) float: the tracks' positions."""
        return self.tracks.positions

    @property
    def visible(self) -> np.ndarray:
        """(T, N) bool."""
        return self.tracks.visible

    @property
    def n_frames(self) -> int:
        return self.tracks.n_frames

    @property
    def n_points(self) -> int:
        return self.tracks.n_points


#: what each tracker's ``Tracks.quality`` measures, for summaries and reports
TRACKING_QUALITY = {
    "dic": "ZNCC",
    "gdic": "ZNCC",
    "klt": "forward-backward agreement (1 - error / threshold)",
}


def _first(frames):
    """Frame 0 of a frame source or of a sequence of arrays."""
    return frames.first() if hasattr(frames, "first") else frames[0]


def reconstruct(
    left_frames: Sequence[np.ndarray],
    right_frames: Sequence[np.ndarray],
    calib,
    points: np.ndarray,
    *,
    tracker: str = "dic",
    options: dict | None = None,
    match_options: dict | None = None,
    max_reproj_px: float = 1.0,
    progress: Callable[[str], None] | None = None,
) -> Reconstruction:
    """Track ``points`` (left reference frame, px) in 3D through both videos.

    Parameters
    ----------
    left_frames, right_frames : sequences of (H, W) gray frames, same length
        (e.g. :class:`strain2d.frames.FrameSource`); frame 0 is the reference.
    calib : stereo.calibration.Calibration
    points : (N, 2) pixels in the left reference frame
    tracker, options
        The 2D tracker and its options (see ``python -m strain2d track``).
    match_options : dict, optional
        Passed to :func:`stereo.match.match_views`.
    max_reproj_px : float
        Points whose reprojection error exceeds this are not visible.

    Returns
    -------
    Reconstruction
    """
    from stereo.calibration import check_baseline_ratio
    from stereo.camera import triangulate
    from stereo.match import match_views
    from strain2d import track

    say = progress or (lambda message: None)
    n_left, n_right = len(left_frames), len(right_frames)
    if n_left != n_right:
        raise InputError(f"the views have different frame counts: {n_left} left, {n_right} right")
    first_left = np.asarray(_first(left_frames), np.float64)
    first_right = np.asarray(_first(right_frames), np.float64)
    width, height = calib.image_size
    for name, img in (("left", first_left), ("right", first_right)):
        if img.shape != (height, width):
            raise InputError(
                f"the {name} frames are {img.shape[1]}x{img.shape[0]} px but the calibration "
                f"is for {width}x{height}"
            )
    points = np.asarray(points, np.float64).reshape(-1, 2)
    say(f"matching {len(points)} points between the views")
    matches = match_views(first_left, first_right, points, calib=calib, **(match_options or {}))
    if matches.visible.sum() < 3:
        raise InputError(
            f"only {int(matches.visible.sum())} of {len(points)} points were found in the right "
            "view; check the calibration and that both views see the grid"
        )
    matched = np.flatnonzero(matches.visible)
    # a baseline that is a sliver of the distance measures no depth: refused before tracking
    X0, _ = triangulate(points[matched], matches.right[matched], calib)
    distance = np.linalg.norm(X0, axis=1)
    distance = distance[np.isfinite(distance)]
    if distance.size:
        check_baseline_ratio(
            calib.baseline, float(np.median(distance)), unit=calib.unit, what="the surface"
        )

    def progress_of(view: str):
        def report(done: int, total: int | None) -> None:
            if total:
                say(f"tracking the {view} view: frame {done}/{total}")

        return report

    left_tracks = track(
        left_frames, points, tracker=tracker, options=options, progress=progress_of("left")
    )
    # only the points found in the right view are tracked there
    right_sub = track(
        right_frames,
        matches.right[matched],
        tracker=tracker,
        options=options,
        progress=progress_of("right"),
    )
    T, N = left_tracks.positions.shape[:2]
    right_positions = np.full((T, N, 2), np.nan)
    right_positions[:, matched] = np.where(
        right_sub.visible[..., None], right_sub.positions, np.nan
    )
    right_visible = np.zeros((T, N), bool)
    right_visible[:, matched] = right_sub.visible
    # a view's tracking quality counts only the points tracked in it: matched
    # between the views and not lost (a lost point's quality is the tracker's 0)
    right_quality = np.full((T, N), np.nan)
    right_quality[:, matched] = np.where(right_sub.visible, right_sub.quality, np.nan)
    left_quality = np.where(
        left_tracks.visible & matches.visible[None, :], left_tracks.quality, np.nan
    )
    say("triangulating")
    X = np.full((T, N, 3), np.nan)
    err = np.full((T, N), np.nan)
    seen = left_tracks.visible & right_visible
    for t in range(T):
        pl = np.where(seen[t][:, None], left_tracks.positions[t], np.nan)
        pr = np.where(seen[t][:, None], right_positions[t], np.nan)
        X[t], err[t] = triangulate(pl, pr, calib)
    visible = seen & (err <= max_reproj_px)
    X[~visible] = np.nan
    meta = {
        "tracker": tracker,
        "options": dict(options or {}),
        "max_reproj_px": max_reproj_px,
        "match": {k: v for k, v in matches.meta.items() if k != "homography"},
        "match_quality": matches.quality.tolist(),
        "epipolar_px": matches.epipolar_px.tolist(),
        "tracking_quality": TRACKING_QUALITY.get(tracker, "the tracker's quality (1 is best)"),
        "unit": calib.unit,
    }
    return Reconstruction(
        tracks=Tracks(X, visible, np.where(np.isfinite(err), -err, -np.inf), meta),
        reproj_error=err,
        left=np.where(left_tracks.visible[..., None], left_tracks.positions, np.nan),
        right=right_positions,
        meta=meta,
        left_quality=np.asarray(left_quality, np.float64),
        right_quality=right_quality,
    )
