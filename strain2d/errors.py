"""Exceptions for errors a user can cause.

They subclass the built-in ``ValueError`` / ``OSError`` so callers can catch
them generically; the command line turns them into one line on stderr and
exit status 2.
"""

from __future__ import annotations

import logging
import sys

__all__ = ["InputError", "SourceError", "run_command"]


class InputError(ValueError):
    """Invalid option, point set, region of interest or track file content."""


class SourceError(OSError):
    """A frame source that is missing, unreadable or too short."""


def run_command(prog: str, args, *, errors: tuple[type[BaseException], ...] = ()) -> int:
    """Run a parsed command line's handler the way every command of the toolkit does.

    Logging goes to stderr (INFO with ``args.verbose``); :class:`InputError`,
    :class:`SourceError`, other ``OSError`` (permissions, a full disk) and the
    extra ``errors`` become one line ``PROG COMMAND: error: ...`` and exit
    status 2; Ctrl-C exits with 130.  Returns the exit status.
    """
    logging.basicConfig(
        level=logging.INFO if getattr(args, "verbose", False) else logging.WARNING,
        format="%(levelname)s: %(message)s",
    )
    try:
        return args.handler(args)
    except (InputError, SourceError, OSError, *errors) as exc:
        print(f"{prog} {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog} {args.command}: interrupted; no output written", file=sys.stderr)
        return 130
