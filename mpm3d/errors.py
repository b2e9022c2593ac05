"""Exceptions and warnings for problems a user can cause.

The errors are the toolkit's (:mod:`tissue_core.errors`); they and the
warnings subclass the built-in ``ValueError`` / ``OSError`` / ``UserWarning`` so
callers can catch them generically; ``python -m mpm3d`` turns the errors into
one line on stderr and exit status 2, and the warnings into one line each.
"""

from __future__ import annotations

from tissue_core.errors import InputError, SourceError

__all__ = ["InputError", "MissingSpacingWarning", "SourceError", "SurfaceOutsideWarning"]


class MissingSpacingWarning(UserWarning):
    """The stack carries no voxel spacing and none was given; 1 um voxels are assumed."""


class SurfaceOutsideWarning(UserWarning):
    """Part of the surface lies above the first slice: the stack does not contain it."""
