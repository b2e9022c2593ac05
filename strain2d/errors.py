"""Exceptions for errors a user can cause (the toolkit's, from :mod:`tissue_core.errors`).

They subclass the built-in ``ValueError`` / ``OSError`` so callers can catch
them generically; the command line turns them into one line on stderr and
exit status 2.
"""

from __future__ import annotations

from tissue_core.errors import InputError, SourceError

__all__ = ["InputError", "PointsLeftOutWarning", "SourceError"]


class PointsLeftOutWarning(UserWarning):
    """Some points cannot be used on the reference frame and are left out of the mesh."""
