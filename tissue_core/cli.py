"""The command runner every command line of the toolkit uses.

:func:`run_command` runs a parsed command's handler and gives every command
the same behaviour:

* errors a user can cause (:class:`~tissue_core.errors.InputError`,
  :class:`~tissue_core.errors.SourceError`, any other ``OSError`` such as a
  full disk or a missing permission, and the command's own ``errors``) end
  with one line ``PROG COMMAND: error: ...`` on stderr and exit status 2;
* Ctrl-C ends with one line ``PROG COMMAND: interrupted; no output written``
  and exit status 130, also when it arrives inside compiled code;
* the toolkit's warnings (``UserWarning``) are one line each,
  ``PROG COMMAND: warning: ...``; other libraries' numerical warnings go to
  the log (``-v``);
* the command line is recorded in the marker of every result folder.
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings

from tissue_core.errors import InputError, SourceError
from tissue_core.interrupt import is_interrupt
from tissue_core.outputs import recorded_command
from tissue_core.progress import close_open_lines

__all__ = ["ArgumentParser", "one_line", "run_command"]

log = logging.getLogger(__name__)


class ArgumentParser(argparse.ArgumentParser):
    """argparse with usage errors as one line and exit status 2."""

    def error(self, message: str) -> None:
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


def one_line(message: object) -> str:
    """A message folded onto one line (a file's own error text may hold newlines)."""
    text = " ".join(str(message).split())
    return text or "unknown error"


def _show_warning(prefix: str):
    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, UserWarning):
            close_open_lines()
            print(f"{prefix}: warning: {one_line(message)}", file=sys.stderr, flush=True)
        else:
            log.debug("%s (%s:%s)", message, filename, lineno)

    return show


def run_command(
    prog: str,
    args: argparse.Namespace,
    *,
    argv: list[str] | None = None,
    errors: tuple[type[BaseException], ...] = (),
) -> int:
    """Run ``args.handler(args)`` the way every command of the toolkit does; return the status.

    Parameters
    ----------
    prog : str
        The program's name, e.g. ``"strain2d"``.
    args : argparse.Namespace
        Parsed arguments with ``handler`` and ``command``; ``verbose`` turns
        on INFO logging.
    argv : list of str, optional
        The arguments that were parsed (default ``sys.argv[1:]``), recorded
        in the marker of every result folder.
    errors : tuple of exception types
        Further exceptions that are the user's doing.
    """
    logging.basicConfig(
        level=logging.INFO if getattr(args, "verbose", False) else logging.WARNING,
        format="%(levelname)s: %(message)s",
    )
    prefix = f"{prog} {args.command}"
    token = recorded_command.set([prog, *(sys.argv[1:] if argv is None else argv)])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", UserWarning)
            warnings.showwarning = _show_warning(prefix)
            try:
                return args.handler(args)
            except (InputError, SourceError, OSError, *errors) as exc:
                close_open_lines()
                print(f"{prefix}: error: {one_line(exc)}", file=sys.stderr, flush=True)
                return 2
            except KeyboardInterrupt:
                return _interrupted(prefix)
            except SystemError as exc:  # compiled code interrupted mid-call
                if is_interrupt(exc):
                    return _interrupted(prefix)
                raise
    except KeyboardInterrupt:  # a second Ctrl-C while the first was being handled
        return _interrupted(prefix)
    finally:
        recorded_command.reset(token)


def _interrupted(prefix: str) -> int:
    close_open_lines()
    # on a terminal, ^C was echoed on the open line
    newline = "\n" if getattr(sys.stderr, "isatty", lambda: False)() else ""
    print(f"{newline}{prefix}: interrupted; no output written", file=sys.stderr, flush=True)
    return 130
