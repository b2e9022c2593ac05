"""Conversion of float frames to the 8-bit images OpenCV's trackers need."""

from __future__ import annotations

import numpy as np


def to_uint8(frame: np.ndarray, value_range: tuple[float, float]) -> np.ndarray:
    """Scale ``frame`` linearly from ``value_range`` to 0..255 (one fixed scale for all frames)."""
    lo, hi = value_range
    if isinstance(frame, np.ndarray) and frame.dtype == np.uint8:
        return frame
    if lo == 0.0 and hi == 255.0:
        return np.clip(np.rint(frame), 0, 255).astype(np.uint8)
    scaled = (np.asarray(frame, dtype=np.float32) - lo) * (255.0 / (hi - lo))
    return np.clip(np.rint(scaled), 0, 255).astype(np.uint8)
