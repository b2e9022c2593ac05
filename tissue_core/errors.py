"""Exceptions for errors a user can cause.

They subclass the built-in ``ValueError`` / ``OSError`` so callers can catch
them generically; every command line of the toolkit turns them into one line
on stderr and exit status 2 (:func:`tissue_core.cli.run_command`).
"""

from __future__ import annotations

__all__ = ["InputError", "SourceError"]


class InputError(ValueError):
    """Invalid option, point set, file content, or an output that may not be written."""


class SourceError(OSError):
    """An input file that is missing, unreadable, truncated or of the wrong kind."""
