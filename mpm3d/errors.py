"""Exceptions and warnings for problems a user can cause.

They subclass the built-in ``ValueError`` / ``OSError`` / ``UserWarning`` so
callers can catch them generically; ``python -m mpm3d`` turns the errors into
one line on stderr and exit status 2, and the warnings into one line each.
"""

from __future__ import annotations

__all__ = ["InputError", "MissingSpacingWarning", "SourceError", "SurfaceOutsideWarning"]


class InputError(ValueError):
    """Invalid option, channel, spacing or stack content (e.g. no surface found)."""


class SourceError(OSError):
    """A stack file that is missing, unreadable or not a z-stack."""


class MissingSpacingWarning(UserWarning):
    """The stack carries no voxel spacing and none was given; 1 um voxels are assumed."""


class SurfaceOutsideWarning(UserWarning):
    """Part of the surface lies above the first slice: the stack does not contain it."""
