"""A tracker's per-frame results, written into arrays made once for the whole video.

Trackers produce one row per frame (positions, visibility, quality, ...).
Kept as lists of small arrays and stacked at the end, every row is held twice
while the stack is made, and each small array carries its own header: about
three times the tracks' own size at the end of a long video.  Here each
series is one array sized for the frames the source says it has
(``len(frames)``); a source that yields more (a video whose container
under-counts) grows it by half in place, and a shorter one is cut to size in
place, so no second copy is made.
"""

from __future__ import annotations

import numpy as np

__all__ = ["FrameSeries"]

#: frames made room for when the source does not say how many it has
_UNKNOWN = 256


class FrameSeries:
    """Per-frame rows of named arrays, e.g. ``positions`` (T, N, 2) and ``visible`` (T, N).

    Parameters
    ----------
    total : int or None
        The frames expected (``len(frames)``); None when unknown.
    **first : array
        Frame 0's row of each series; it fixes the series' names, row shapes and dtypes.
    """

    def __init__(self, total: int | None, **first: np.ndarray) -> None:
        capacity = max(int(total), 1) if total else _UNKNOWN
        self._arrays: dict[str, np.ndarray] = {}
        for name, row in first.items():
            row = np.asarray(row)
            self._arrays[name] = np.empty((capacity, *row.shape), row.dtype)
            self._arrays[name][0] = row
        self._n = 1

    def __len__(self) -> int:
        return self._n

    def append(self, **row: np.ndarray) -> None:
        """Add the next frame's row of every series (the same names as frame 0's)."""
        if row.keys() != self._arrays.keys():
            raise ValueError(f"rows of {sorted(self._arrays)} expected, got {sorted(row)}")
        for name, array in self._arrays.items():
            if self._n == len(array):
                array = self._resized(name, self._n + max(self._n // 2, 1))
            array[self._n] = row[name]
        self._n += 1

    def arrays(self) -> dict[str, np.ndarray]:
        """Each series as one array of the frames added; the series is done with."""
        for name in self._arrays:
            if len(self._arrays[name]) != self._n:
                self._resized(name, self._n)
        out, self._arrays = self._arrays, {}
        return out

    def _resized(self, name: str, frames: int) -> np.ndarray:
        array = self._arrays[name]
        # in place (realloc: a large block is remapped, not copied); no view of it exists
        array.resize((frames, *array.shape[1:]), refcheck=False)
        return array
