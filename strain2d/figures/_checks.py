"""Checks of the figures' arguments: frame indices, 2D fields, component names, images."""

from __future__ import annotations

import operator
from collections.abc import Sequence

import numpy as np

from strain2d.errors import InputError
from surface_strain import StrainField, nodal_scalars


def _frame_index(field: StrainField, frame, name: str = "frame") -> int:
    T = field.n_frames
    try:
        k = operator.index(frame)
    except TypeError:
        raise InputError(f"{name} must be an integer frame index, got {frame!r}") from None
    if not -T <= k < T:
        raise InputError(f"{name} {k} is out of range for a field of {T} frames")
    return k % T


def _check_2d(field: StrainField) -> None:
    if field.points.shape[2] != 2:
        raise InputError(
            f"this figure draws 2D fields over images; the field has "
            f"{field.points.shape[2]}D points (see surface_strain.figures for 3D)"
        )


def _scalars(field: StrainField, components: Sequence[str]) -> dict[str, np.ndarray]:
    if isinstance(components, str):
        components = (components,)
    if len(components) == 0:
        raise InputError("components is empty; name at least one, e.g. ('Exx', 'Eyy')")
    scalars = nodal_scalars(field)
    unknown = [c for c in components if c not in scalars]
    if unknown:
        raise InputError(f"unknown strain component(s) {unknown}; choose from {list(scalars)}")
    return scalars


def _finite(values) -> np.ndarray:
    a = np.asarray(values, dtype=float).ravel()
    return a[np.isfinite(a)]


def _check_image(image, name: str = "image") -> np.ndarray:
    a = np.asarray(image)
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)) or 0 in a.shape:
        raise InputError(f"{name} must be a (H, W) gray or (H, W, 3) colour image, got {a.shape}")
    return a
