"""Random speckle patterns defined analytically, so any deformation renders exactly.

A pattern is a set of Gaussian dots in reference coordinates (pixels).  Its
ink density is ``S(X) = sum_k exp(-|X - X_k|^2 / (2 s_k^2))`` and the image is
``I = I_bg - (I_bg - I_ink) (1 - exp(-S))``: smooth, saturating where dots
overlap, like an airbrushed or sprayed pattern (cf. the muDIC speckle
generator).  Size, density and contrast are controllable.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["SpecklePattern", "speckle_pattern"]


@dataclass(frozen=True)
class SpecklePattern:
    """Gaussian speckle dots.

    Attributes
    ----------
    centers : (K, 2) float
        Dot centres (x, y) in reference pixels.
    sigmas : (K,) float
        Gaussian radii in reference pixels.
    background, ink : float
        Gray levels (0-255) of bare surface and of saturated ink.
    """

    centers: np.ndarray
    sigmas: np.ndarray
    background: float = 200.0
    ink: float = 40.0


def speckle_pattern(
    bounds: tuple[float, float, float, float],
    *,
    radius: float = 2.0,
    density: float = 1.0,
    contrast: float = 0.8,
    size_spread: float = 0.25,
    rng: int | np.random.Generator | None = None,
) -> SpecklePattern:
    """Random speckles covering a rectangle of the reference configuration.

    Parameters
    ----------
    bounds : (x0, y0, x1, y1)
        Region to cover, in reference pixels (cover everything any frame sees).
    radius : float, keyword-only
        Mean Gaussian radius (sigma) of a dot in pixels; dots look about
        ``4 * radius`` wide.
    density : float, keyword-only
        Fraction of the surface covered by dots (area of the 2-sigma disc per
        dot times the dot count over the area), in (0, 2].
    contrast : float, keyword-only
        ``(I_bg - I_ink) / I_bg`` in (0, 1].
    size_spread : float, keyword-only
        Relative standard deviation of the dot radius.
    rng : int or Generator, keyword-only

    Returns
    -------
    SpecklePattern
    """
    if radius <= 0 or not 0 < density <= 2 or not 0 < contrast <= 1:
        raise ValueError("radius must be > 0, density in (0, 2], contrast in (0, 1]")
    rng = np.random.default_rng(rng)
    x0, y0, x1, y1 = bounds
    area = (x1 - x0) * (y1 - y0)
    n = round(density * area / (np.pi * (2 * radius) ** 2))
    centers = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])
    sigmas = radius * np.clip(1 + size_spread * rng.standard_normal(n), 0.4, 2.0)
    background = 200.0
    return SpecklePattern(centers, sigmas, background, background * (1 - contrast))
