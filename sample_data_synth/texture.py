"""A real tissue photograph for texture benchmarks.

scikit-image ships ``ihc.png`` (immunohistochemistry of a tissue section,
512 x 512 RGB) inside the package, so no download is needed.  It is converted
to gray and resized to the benchmark size as in the source paper's texture
case.
"""

from __future__ import annotations

import numpy as np

__all__ = ["tissue_photograph"]


def tissue_photograph(size: int = 800) -> np.ndarray:
    """Gray tissue image of ``size x size`` pixels, values 0-255 (float64)."""
    from skimage import color, data, transform

    rgb = data.immunohistochemistry()
    gray = color.rgb2gray(rgb)
    resized = transform.resize(gray, (size, size), order=3, anti_aliasing=True, mode="reflect")
    lo, hi = np.percentile(resized, [0.5, 99.5])
    return np.clip((resized - lo) / (hi - lo), 0, 1) * 215.0 + 20.0
