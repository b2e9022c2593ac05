"""Exceptions for errors a user can cause.

They subclass the built-in ``ValueError`` / ``OSError`` so callers can catch
them generically; the command line turns them into one line on stderr and
exit status 2.
"""

from __future__ import annotations

__all__ = ["InputError", "SourceError"]


class InputError(ValueError):
    """Invalid option, point set, region of interest or track file content."""


class SourceError(OSError):
    """A frame source that is missing, unreadable or too short."""
