"""The 2D pipeline: track -> mesh -> strain per frame -> nodal fields."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from strain2d.errors import InputError
from strain2d.grid import validate_points
from strain2d.trackers import get_tracker
from strain2d.tracks import Tracks
from surface_strain import StrainField, compute_strain, delaunay_triangles

__all__ = ["Analysis", "analyze", "strain_from_tracks", "track"]


@dataclass(frozen=True)
class Analysis:
    """Tracks and the strain field computed from them."""

    tracks: Tracks
    field: StrainField


def track(
    frames: Iterable[np.ndarray] | None,
    points: np.ndarray | None,
    *,
    tracker: str = "klt",
    options: dict | None = None,
    progress: Callable[[int, int | None], None] | None = None,
) -> Tracks:
    """Track reference points through frames with a registered tracker.

    Parameters
    ----------
    frames : iterable of (H, W) float, or None for trackers that read files
    points : (N, 2) float or None
        Reference positions in pixels (x = column, y = row).
    tracker : str, keyword-only
        A name from :func:`strain2d.trackers.available_trackers`.
    options : dict, keyword-only
        Tracker options (see each tracker's docstring).
    progress : callable(done, total), keyword-only
    """
    spec = get_tracker(tracker)
    options = dict(options or {})
    if points is not None:
        shape = getattr(frames, "shape", None)
        points = validate_points(points, None if shape is None else tuple(shape[-2:]))
    if spec.needs_frames and frames is None:
        raise InputError(f"the {tracker} tracker needs frames")
    try:
        tracks = spec.function(frames, points, progress=progress, **options)
    except TypeError as exc:
        if "unexpected keyword argument" in str(exc):
            raise InputError(f"tracker {tracker!r}: {exc}") from None
        raise
    validate_points(tracks.reference)
    return tracks


def strain_from_tracks(
    tracks: Tracks,
    *,
    triangles: np.ndarray | None = None,
    min_triangle_quality: float = 0.1,
) -> StrainField:
    """Mesh the reference positions (Delaunay) and compute strain on every frame.

    Points the tracker lost (``visible`` False) leave their triangles out of
    that frame (NaN) and out of the nodal averages.
    """
    reference = validate_points(tracks.reference)
    if triangles is None:
        try:
            triangles = delaunay_triangles(reference, min_quality=min_triangle_quality)
        except ValueError as exc:
            raise InputError(str(exc)) from None
    return compute_strain(reference, tracks.positions, triangles, visible=tracks.visible)


def analyze(
    frames: Iterable[np.ndarray] | None,
    points: np.ndarray | None,
    *,
    tracker: str = "klt",
    options: dict | None = None,
    min_triangle_quality: float = 0.1,
    progress: Callable[[int, int | None], None] | None = None,
) -> Analysis:
    """Track points and compute the strain field.

    Examples
    --------
    >>> import numpy as np
    >>> from sample_data_synth.cases import make_case
    >>> from strain2d.grid import make_grid
    >>> video = make_case("equibiaxial", size=200, n_frames=6)
    >>> grid = make_grid((200, 200), shape=(4, 4), roi=video.truth.roi)
    >>> result = analyze(video.frames, grid, tracker="klt", options={"window": 21})
    >>> bool(abs(np.nanmean(result.field.nodal_E[-1, :, 0, 0]) - 0.625) < 0.02)
    True
    """
    tracks = track(frames, points, tracker=tracker, options=options, progress=progress)
    field = strain_from_tracks(tracks, min_triangle_quality=min_triangle_quality)
    return Analysis(tracks, field)
