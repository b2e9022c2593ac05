"""``imported``: tracks computed by another tool (e.g. CoTracker3 run elsewhere).

Reads CSV (``frame,point,x,y[,visible,quality]``), ``.npy`` ``(T, N, 2)`` or
``.npz`` files (see :mod:`strain2d.tracks`).  When reference points are given,
each is matched to the imported point nearest to it on frame 0, within
``match_tolerance`` pixels; otherwise all imported points are used.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable

import numpy as np
from scipy.spatial import cKDTree

from strain2d.errors import InputError
from strain2d.trackers import TrackerOption, register_tracker
from strain2d.tracks import Tracks, read_tracks


@register_tracker(
    "imported",
    description="tracks made by another tool, read from CSV/NPY/NPZ",
    needs_frames=False,
    options=[
        TrackerOption(
            "tracks_file",
            "--tracks-file",
            "tracks from another tool (CSV, NPY or NPZ)",
            metavar="FILE",
            is_file=True,
        )
    ],
)
def track_imported(
    frames: Iterable[np.ndarray] | None,
    points: np.ndarray | None,
    *,
    tracks_file: str | os.PathLike | None = None,
    match_tolerance: float = 1.0,
    progress: Callable[[int, int | None], None] | None = None,
) -> Tracks:
    """Load tracks from a file, optionally selecting given reference points.

    Parameters
    ----------
    frames : sized iterable or None
        If it has a length, the file must hold that many frames.
    points : (N, 2) float or None
        Reference positions to select; None keeps every imported point.
    tracks_file : path, keyword-only
        The tracks to import (required).
    match_tolerance : float, keyword-only
        Largest distance (pixels) between a requested point and its match.

    Returns
    -------
    Tracks
    """
    if tracks_file is None:
        raise InputError("the imported tracker needs --tracks-file FILE (CSV, NPY or NPZ)")
    tracks = read_tracks(tracks_file)
    if frames is not None and hasattr(frames, "__len__") and len(frames) != tracks.n_frames:
        raise InputError(
            f"{tracks_file} holds {tracks.n_frames} frames but the video has {len(frames)}"
        )
    if not np.all(tracks.visible[0]):
        raise InputError(f"{tracks_file}: every point must be visible on the reference frame 0")
    meta = {"tracker": "imported", "options": {"tracks_file": str(tracks_file)}}
    if points is None:
        keep = np.arange(tracks.n_points)
    else:
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        dist, keep = cKDTree(tracks.reference).query(points)
        if np.any(dist > match_tolerance):
            i = int(np.argmax(dist))
            raise InputError(
                f"point {i} at ({points[i, 0]:g}, {points[i, 1]:g}) has no imported track "
                f"within {match_tolerance:g} px on frame 0"
            )
        meta["options"]["match_tolerance"] = match_tolerance
    if progress:
        progress(tracks.n_frames, tracks.n_frames)
    unc = None if tracks.uncertainty is None else tracks.uncertainty[:, keep]
    return Tracks(
        tracks.positions[:, keep], tracks.visible[:, keep], tracks.quality[:, keep], meta, unc
    )
