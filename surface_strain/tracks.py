"""``Tracks``: the positions of tracked points over time, with visibility and quality."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tissue_core.errors import InputError

__all__ = ["Tracks"]


@dataclass(frozen=True, repr=False)
class Tracks:
    """Positions of N points over T frames, in the image (2D) or in space (3D).

    The one container of tracks in the toolkit: 2D trackers
    (:func:`strain2d.track`) return it in pixels, ``stereo`` reconstructs 3D
    ones in the calibration's unit, and ``surface_strain compute`` reads them.

    Attributes
    ----------
    positions : (T, N, 2) or (T, N, 3) float
        ``(x, y)`` in pixels, or ``(X, Y, Z)``; frame 0 is the reference.
    visible : (T, N) bool
        False where the tracker lost the point.
    quality : (T, N) float
        Tracker confidence, higher is better (each tracker documents its scale).
    meta : dict
        Tracker name and options, for provenance.
    uncertainty : (T, N) float or None
        Standard deviation of each coordinate of the position (in the
        positions' unit), NaN where unknown; None when it is not measured.
    """

    positions: np.ndarray
    visible: np.ndarray
    quality: np.ndarray
    meta: dict = field(default_factory=dict)
    uncertainty: np.ndarray | None = None

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions, dtype=float)
        if pos.ndim != 3 or pos.shape[2] not in (2, 3):
            raise InputError(
                f"track positions must have shape (T, N, 2) or (T, N, 3), got {pos.shape}"
            )
        vis = np.asarray(self.visible, dtype=bool)
        qual = np.asarray(self.quality, dtype=float)
        for name, arr in (("visible", vis), ("quality", qual)):
            if arr.shape != pos.shape[:2]:
                raise InputError(f"track {name} must have shape {pos.shape[:2]}, got {arr.shape}")
        if self.uncertainty is not None:
            unc = np.asarray(self.uncertainty, dtype=float)
            if unc.shape != pos.shape[:2]:
                raise InputError(
                    f"track uncertainty must have shape {pos.shape[:2]}, got {unc.shape}"
                )
            object.__setattr__(self, "uncertainty", unc)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "visible", vis)
        object.__setattr__(self, "quality", qual)

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_points(self) -> int:
        return self.positions.shape[1]

    @property
    def dims(self) -> int:
        """2 for image tracks, 3 for tracks in space."""
        return self.positions.shape[2]

    @property
    def reference(self) -> np.ndarray:
        """Positions on the reference frame, ``(N, d)``."""
        return self.positions[0]

    def __repr__(self) -> str:
        lost = int((~self.visible[-1]).sum())
        return (
            f"Tracks({self.n_frames} frames, {self.n_points} points, "
            f"{lost} lost on the last frame, tracker={self.meta.get('tracker', '?')})"
        )
