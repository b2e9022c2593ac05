"""The 2D pipeline: track -> mesh -> strain per frame -> nodal fields."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from strain2d.errors import InputError, PointsLeftOutWarning
from strain2d.grid import validate_points
from strain2d.trackers import get_tracker
from strain2d.tracks import Tracks
from surface_strain import Mesh, StrainField, choose_mesh, compute_strain, streamed_strain

__all__ = [
    "TRACK_BYTES",
    "Analysis",
    "analysis_of",
    "analyze",
    "blank_start",
    "check_tracks_fit",
    "strain_from_tracks",
    "track",
]

#: bytes a tracked point takes per frame in the tracks a tracker returns: its position (two
#: float64), visibility (bool), quality and uncertainty (float64 each)
TRACK_BYTES = 2 * 8 + 1 + 8 + 8


@dataclass(frozen=True, repr=False)
class Analysis:
    """Tracks, the strain field computed from them, and how (for :func:`strain2d.write_run`).

    Attributes
    ----------
    tracks : Tracks
    field : StrainField
    tracker : str or None
        The tracker's name (None: the one the tracks' ``meta`` names).
    mesh : surface_strain.Mesh or None
        The triangles and how they were chosen (None: the field's triangles,
        given).
    grid_shape : (n_cols, n_rows) or None
        The points form this row-major grid.
    min_triangle_quality : float
        The Delaunay quality bound (used when the points are not a grid).
    points : (N, 2) float or None
        The reference points as given (trackers may keep them in float32).
    """

    tracks: Tracks
    field: StrainField
    tracker: str | None = None
    mesh: Mesh | None = None
    grid_shape: tuple[int, int] | None = None
    min_triangle_quality: float = 0.1
    points: np.ndarray | None = None

    def __repr__(self) -> str:
        how = self.mesh.description if self.mesh is not None else "given triangles"
        return (
            f"Analysis({self.tracks.n_frames} frames, {self.tracks.n_points} points, "
            f"{self.field.n_triangles} triangles ({how}), tracker={self.tracker})"
        )


def check_tracks_fit(
    n_points: int,
    n_frames: int,
    *,
    views: int = 1,
    remedy: str = "use fewer points (--grid, --points) or frames (--stop, --step)",
) -> None:
    """Refuse, before any work, tracks that cannot fit the memory available.

    Parameters
    ----------
    n_points, n_frames : int
        The points tracked and the frames they are tracked over.
    views : int, keyword-only
        Tracks of this many views held together (stereo: 2).
    remedy : str, keyword-only
        What to do instead, the end of the message.

    Raises
    ------
    InputError
        Naming the points, the frames, the memory they need and the memory
        available (see :func:`tissue_core.resources.check_fits`).
    """
    from tissue_core.resources import check_fits

    where = f" in each of {views} views" if views > 1 else ""
    check_fits(
        f"tracking {n_points} points over {n_frames} frames{where}",
        memory=float(views) * n_points * n_frames * TRACK_BYTES,
        remedy=remedy,
    )


def track(
    frames: Iterable[np.ndarray] | None,
    points: np.ndarray | None,
    *,
    tracker: str = "gdic",
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

    Raises
    ------
    InputError
        Bad points or options, or tracks that cannot fit the memory
        (:func:`check_tracks_fit`), before any frame is tracked.
    """
    spec = get_tracker(tracker)
    options = dict(options or {})
    if points is not None:
        shape = getattr(frames, "shape", None)
        points = validate_points(points, None if shape is None else tuple(shape[-2:]))
        if hasattr(frames, "__len__"):
            check_tracks_fit(len(points), len(frames))
    if spec.needs_frames and frames is None:
        raise InputError(f"the {tracker} tracker needs frames")
    try:
        tracks = spec.function(frames, points, progress=progress, **options)
    except TypeError as exc:
        if "unexpected keyword argument" in str(exc):
            raise InputError(f"tracker {tracker!r}: {exc}") from None
        raise
    validate_points(tracks.reference)
    _check_reference_visibility(tracks, tracker, frames)
    return tracks


#: frames read, at most, to find where a video that starts blank gets its texture
_FADE_SCAN = 120


def blank_start(frames, points: np.ndarray) -> tuple[int, float, float] | None:
    """Where a video that starts blank gets its texture: ``(frame, spread at the reference,
    largest spread)``, or None when the reference is not blank.

    A recording may fade in, or start on a dark or empty frame; nothing can be matched
    on such a reference.  The grey levels' standard deviation over the points' region
    (the spread), frame by frame (at most :data:`_FADE_SCAN` frames, read again): the
    reference is blank when its spread is below a quarter of the largest, and the frame
    given (counted in ``frames``) is the first that reaches 80 % of it.  None also when
    ``frames`` cannot be read again (a one-pass iterator).
    """
    if frames is None or iter(frames) is frames:
        return None
    ok = np.isfinite(points).all(axis=1)
    if not ok.any():
        return None
    (x0, y0), (x1, y1) = np.floor(points[ok].min(axis=0)), np.ceil(points[ok].max(axis=0))
    spreads = []
    for k, frame in enumerate(frames):
        if k >= _FADE_SCAN:
            break
        h, w = np.shape(frame)[-2:]
        box = np.asarray(frame, dtype=float)[
            max(int(y0), 0) : min(int(y1) + 1, h), max(int(x0), 0) : min(int(x1) + 1, w)
        ]
        spreads.append(float(box.std()) if box.size else 0.0)
    spreads = np.asarray(spreads)
    if spreads.size < 2 or not spreads[0] < 0.25 * spreads.max():
        return None
    first = int(np.flatnonzero(spreads >= 0.8 * spreads.max())[0])
    return first, float(spreads[0]), float(spreads.max())


def _blank_start_hint(frames, points: np.ndarray) -> str:
    """What to say when :func:`blank_start` finds the reference blank ("" when not): the
    frame to start at, in the video's own frames (``--start`` and ``--step`` counted)."""
    blank = blank_start(frames, points)
    if blank is None:
        return ""
    first, spread, largest = blank
    span = getattr(frames, "frame_range", None) or {"start": 0, "step": 1}
    at = span["start"] + first * span["step"]
    return (
        f"; the reference frame is almost blank (its grey levels spread {spread:.2g} "
        f"against {largest:.2g} on later frames: the video fades in or starts dark), "
        f"so let a textured frame be the reference, e.g. --start {at}"
    )


def _check_reference_visibility(tracks: Tracks, tracker: str, frames=None) -> None:
    """Say which points cannot be used from the reference frame on; refuse if too few remain.

    When most cannot, and the reference frame is blank where later frames are not,
    say which frame to start at instead (:func:`blank_start`).
    """
    lost = np.flatnonzero(~tracks.visible[0])
    if lost.size == 0:
        # a tracker that takes every point on the reference (dic, klt) loses them after a
        # blank one
        later = tracks.visible[1:].mean(axis=0) if tracks.n_frames > 1 else np.ones(1)
        gone = int((later < 0.5).sum())
        hint = _blank_start_hint(frames, tracks.reference) if 2 * gone >= tracks.n_points else ""
        if hint:
            warnings.warn(
                PointsLeftOutWarning(
                    f"{gone} of {tracks.n_points} points are lost on most frames{hint}"
                ),
                stacklevel=3,
            )
        return
    n = tracks.n_points
    named = ", ".join(
        f"point {i} at ({tracks.reference[i, 0]:g}, {tracks.reference[i, 1]:g})" for i in lost[:3]
    )
    more = f" and {lost.size - 3} more" if lost.size > 3 else ""
    why = (
        "not visible, or not finite, on frame 0 of the imported tracks"
        if tracker == "imported"
        else "too close to the image edge for the tracker's window, or on texture it cannot follow"
    )
    if tracker != "imported" and 2 * lost.size >= n:
        why += _blank_start_hint(frames, tracks.reference)
    if n - lost.size < 3:
        raise InputError(
            f"only {n - lost.size} of {n} points can be used on the reference frame with the "
            f"{tracker} tracker ({named}{more} cannot: {why}); at least 3 are needed"
        )
    warnings.warn(
        PointsLeftOutWarning(
            f"{lost.size} of {n} points cannot be used on the reference frame and are left out "
            f"of the strain ({named}{more}): {why}"
        ),
        stacklevel=3,
    )


def strain_from_tracks(
    tracks: Tracks,
    *,
    triangles: np.ndarray | None = None,
    grid_shape: tuple[int, int] | None = None,
    min_triangle_quality: float = 0.1,
    streamed: bool = False,
) -> StrainField:
    """Mesh the reference positions and compute strain on every frame.

    Parameters
    ----------
    tracks : Tracks
    triangles : (M, 3) int, keyword-only
        A mesh to use as is.
    grid_shape : (n_cols, n_rows), keyword-only
        The points form a row-major grid (as from :func:`strain2d.grid.make_grid`):
        mesh it with alternating diagonals
        (:func:`surface_strain.grid_triangles`), which is symmetric, unlike a
        Delaunay mesh of a square grid whose diagonals are arbitrary.
    min_triangle_quality : float, keyword-only
        Delaunay meshes (the default without ``triangles`` or ``grid_shape``)
        drop triangles with a smaller radius ratio.
    streamed : bool, keyword-only
        Compute the strain a block of frames at a time when it is read
        (:func:`surface_strain.streamed_strain`): the field then holds no
        more than the tracks, however long the video.  The values are the
        same.

    Notes
    -----
    Points the tracker lost (``visible`` False) leave their triangles out of
    that frame (NaN) and out of the nodal averages.
    """
    reference = validate_points(tracks.reference)
    if triangles is None:
        triangles = choose_mesh(reference, grid=grid_shape, min_quality=min_triangle_quality)[0]
    if streamed:
        return streamed_strain(reference, tracks.positions, triangles, visible=tracks.visible)
    return compute_strain(reference, tracks.positions, triangles, visible=tracks.visible)


def analyze(
    frames: Iterable[np.ndarray] | None,
    points: np.ndarray | None,
    *,
    tracker: str = "gdic",
    options: dict | None = None,
    grid_shape: tuple[int, int] | None = None,
    min_triangle_quality: float = 0.1,
    progress: Callable[[int, int | None], None] | None = None,
) -> Analysis:
    """Track points and compute the strain field.

    ``grid_shape`` (n_cols, n_rows) says the points are a row-major grid and
    meshes it cell by cell (see :func:`strain_from_tracks`); otherwise the
    points get a Delaunay mesh.

    Examples
    --------
    >>> import numpy as np
    >>> from sample_data_synth.cases import make_case
    >>> from strain2d.grid import make_grid
    >>> video = make_case("equibiaxial", size=200, n_frames=6)
    >>> grid = make_grid((200, 200), shape=(4, 4), roi=video.truth.roi)
    >>> result = analyze(video.frames, grid, tracker="klt", options={"window": 21},
    ...                  grid_shape=(4, 4))
    >>> bool(abs(np.nanmean(result.field.nodal_E[-1, :, 0, 0]) - 0.625) < 0.02)
    True
    """
    tracks = track(frames, points, tracker=tracker, options=options, progress=progress)
    return analysis_of(
        tracks,
        tracker=tracker,
        grid_shape=grid_shape,
        min_triangle_quality=min_triangle_quality,
        points=points,
    )


def analysis_of(
    tracks: Tracks,
    *,
    tracker: str,
    grid_shape: tuple[int, int] | None = None,
    min_triangle_quality: float = 0.1,
    points: np.ndarray | None = None,
    streamed: bool = False,
    mesh: Mesh | None = None,
) -> Analysis:
    """Mesh tracks and compute their strain field (:func:`analyze` once tracked).

    ``points`` are the reference points given to the tracker, if any;
    ``streamed`` computes the field a block of frames at a time when read
    (see :func:`strain_from_tracks`), as ``strain2d analyze`` does; ``mesh``
    is used as it is (a grid in a tissue mask: :func:`strain2d.grid.masked_grid`)
    instead of one made from ``grid_shape`` or by Delaunay."""
    if mesh is None:
        mesh = choose_mesh(
            validate_points(tracks.reference), grid=grid_shape, min_quality=min_triangle_quality
        )
    else:
        validate_points(tracks.reference)
    field = strain_from_tracks(tracks, triangles=mesh.triangles, streamed=streamed)
    points = None if points is None else np.asarray(points, dtype=float)
    return Analysis(tracks, field, tracker, mesh, grid_shape, min_triangle_quality, points)
