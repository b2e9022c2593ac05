"""Small helpers the synthetic-data modules share: argument checks, seeds, version."""

from __future__ import annotations

import math

import numpy as np

Rng = int | np.random.Generator | None


def version() -> str:
    """This package's version, for the truth files."""
    from sample_data_synth import __version__

    return __version__


def spawn(rng: Rng, n: int) -> list[np.random.Generator]:
    """``n`` independent generators from a seed or a generator."""
    if isinstance(rng, np.random.Generator):
        return list(rng.spawn(n))
    return [np.random.default_rng(s) for s in np.random.SeedSequence(rng).spawn(n)]


def positive(value: float, name: str) -> float:
    """``value`` as a float, checked finite and > 0 (``ValueError`` naming ``name``)."""
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value}")
    return value


def non_negative(value: float, name: str) -> float:
    """``value`` as a float, checked finite and >= 0 (``ValueError`` naming ``name``)."""
    value = float(value)
    if not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} must be a finite number >= 0, got {value}")
    return value


def write_calibrated_tiff(path, image: np.ndarray, pixel_um: float, **metadata) -> None:
    """An image (a height map, a projection) as an ImageJ TIFF with its pixel size in um, as
    ``mpm3d analyze`` writes them and the toolkit's readers take them."""
    import tifffile

    tifffile.imwrite(
        path,
        image,
        imagej=True,
        resolution=(1 / pixel_um, 1 / pixel_um),
        metadata={"unit": "um", **metadata},
    )
