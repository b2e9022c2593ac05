"""The command runner every command line of the toolkit uses.

:func:`run_command` runs a parsed command's handler and gives every command
the same behaviour:

* errors a user can cause (:class:`~tissue_core.errors.InputError`,
  :class:`~tissue_core.errors.SourceError`, any other ``OSError`` such as a
  full disk or a missing permission, and the command's own ``errors``) end
  with one line ``PROG COMMAND: error: ...`` on stderr and exit status 2; so
  does an allocation that fails (``MemoryError``) where no check of the
  options (:mod:`tissue_core.resources`) foresaw it;
* Ctrl-C ends with one line ``PROG COMMAND: interrupted; no output written``
  and exit status 130, also when it arrives inside compiled code or library
  code loses its KeyboardInterrupt; SIGTERM and SIGHUP the same way, with
  ``PROG COMMAND: terminated (SIGTERM); no output written`` and the status
  ``128 + signal`` (143, 129); a line that cannot be printed (the terminal
  closed) is left out, never a traceback;
* warnings (``UserWarning``: the toolkit's, and those its libraries raise)
  are one line each, ``PROG COMMAND: warning: ...``; numerical warnings
  (``RuntimeWarning`` and the like) go to the log, shown with ``-v``;
* the command line is recorded in the marker of every result folder.

:class:`CommandLine` builds every package's parser the same way: the global
options ``--version``, ``-q/--quiet`` and ``-v/--verbose`` are accepted
before or after the command's name, and ``-q`` with ``-v`` is refused.
"""

from __future__ import annotations

import argparse
import logging
import re
import sys
import warnings

from tissue_core.errors import InputError, SourceError
from tissue_core.filenames import readable
from tissue_core.interrupt import (
    SIGNALS,
    exit_status,
    handling_interrupts,
    interrupt_signal,
    is_interrupt,
    note_interrupted,
    signal_name,
    was_interrupted,
)
from tissue_core.outputs import recorded_command, written
from tissue_core.progress import close_open_lines, record_line

__all__ = ["ArgumentParser", "CommandLine", "one_line", "run_command", "run_module"]

log = logging.getLogger(__name__)


class ArgumentParser(argparse.ArgumentParser):
    """argparse with usage errors as one line and exit status 2."""

    def error(self, message: str) -> None:
        self.exit(2, f"{self.prog}: error: {one_line(message)}\n")


class CommandLine:
    """A package's command line: its parser, subcommands and global options.

    Parameters
    ----------
    prog : str
        The program's name (``"strain2d"``), as ``python -m PROG`` and the
        console script are called.
    description : str
        One sentence for ``--help``.

    Examples
    --------
    >>> cli = CommandLine("demo", "A demonstration.")
    >>> p = cli.command("run", lambda args: 0, help="run it")
    >>> _ = p.add_argument("--out")
    >>> args = cli.parse_args(["run", "-q", "--out", "x"])
    >>> (args.command, args.quiet, args.verbose, args.out)
    ('run', True, False, 'x')
    """

    def __init__(self, prog: str, description: str) -> None:
        self.prog = prog
        self._later: dict[str, tuple[argparse.ArgumentParser, object]] = {}
        self.parser = ArgumentParser(prog=prog, description=description)
        self._add_global_options(self.parser, default=False)
        self._sub = self.parser.add_subparsers(
            dest="command", required=True, parser_class=ArgumentParser
        )

    def command(self, name: str, handler, *, later=None, **kwargs) -> argparse.ArgumentParser:
        """Add the subcommand ``name`` run by ``handler(args) -> int``; returns its parser.

        ``later(parser)`` adds options that are costly to build (they import
        modules), only when ``name`` is the command given; ``kwargs`` go to
        ``add_parser`` (``help``, ``description``).
        """
        p = self._sub.add_parser(name, **kwargs)
        # SUPPRESS: a global option not repeated after the command keeps the value given
        # before it
        self._add_global_options(p, default=argparse.SUPPRESS)
        p.set_defaults(handler=handler)
        if later is not None:
            self._later[name] = (p, later)
        return p

    def parse_args(self, argv: list[str] | None = None) -> argparse.Namespace:
        """Parse ``argv``; conflicting global options end as a usage error."""
        argv = sys.argv[1:] if argv is None else list(argv)
        command = next((a for a in argv if not a.startswith("-")), None)
        if command in self._later:  # the command's costly options, once
            p, later = self._later.pop(command)
            later(p)
        args = self.parser.parse_args(argv)
        if args.quiet and args.verbose:
            self.parser.exit(
                2,
                f"{self.prog} {args.command}: error: "
                "-q/--quiet and -v/--verbose cannot be used together\n",
            )
        return args

    def _add_global_options(self, p: argparse.ArgumentParser, *, default) -> None:
        from tissue_core.version import __version__

        g = p.add_argument_group("global options (before or after the command)")
        g.add_argument("--version", action="version", version=f"{self.prog} {__version__}")
        g.add_argument(
            "-q", "--quiet", action="store_true", default=default, help="no progress output"
        )
        g.add_argument("-v", "--verbose", action="store_true", default=default, help="log details")


#: an undecodable byte of a file name as ``repr`` shows it (``'vid\\udce9o.avi'``)
_REPR_BYTE = re.compile(r"\\udc([89a-f][0-9a-f])")


def one_line(message: object) -> str:
    """A message folded onto one line (a file's own error text may hold newlines).

    Bytes of file names that are not UTF-8 are shown as ``\\xNN``, also where
    the message quotes a name with ``repr`` (Python's own ``OSError`` text).
    """
    text = _REPR_BYTE.sub(r"\\x\1", readable(" ".join(str(message).split())))
    return text or "unknown error"


#: the toolkit's packages: their log records reach the terminal without -v
_TOOLKIT = frozenset(
    {"tissue_core", "strain2d", "surface_strain", "stereo", "mpm3d", "sample_data_synth"}
)


def _toolkit_or_verbose(prog: str):
    """A filter that passes the libraries' log records (tifffile's ``ERROR: ...`` on a damaged
    file, ...) only with -v: without it, the command's one error line stays the only one.
    The toolkit's records, and those of the program ``prog``, always pass."""
    own = _TOOLKIT | {prog}

    def passes(record: logging.LogRecord) -> bool:
        if record.name.split(".")[0] in own:
            return True
        return logging.getLogger().getEffectiveLevel() <= logging.INFO

    return passes


class _ReadableFormatter(logging.Formatter):
    """Log lines that show file names whose bytes are not UTF-8 as ``\\xNN``."""

    def format(self, record: logging.LogRecord) -> str:
        return readable(super().format(record))


def _show_warning(prefix: str):
    def show(message, category, filename, lineno, file=None, line=None) -> None:
        if issubclass(category, UserWarning):
            close_open_lines()
            print(f"{prefix}: warning: {one_line(message)}", file=sys.stderr, flush=True)
            record_line(f"warning: {one_line(message)}")
        else:
            log.info("%s (%s:%s)", message, filename, lineno)

    return show


def run_command(
    prog: str,
    parser: argparse.ArgumentParser | CommandLine,
    argv: list[str] | None = None,
    *,
    errors: tuple[type[BaseException], ...] = (),
) -> int:
    """Parse ``argv`` and run the command's handler the way every command of the toolkit does.

    Parameters
    ----------
    prog : str
        The program's name, e.g. ``"strain2d"``.
    parser : CommandLine or argparse.ArgumentParser
        Its subcommands set ``command`` and ``handler`` (a function of the
        parsed arguments returning the exit status); ``verbose`` turns on
        INFO logging.
    argv : list of str, optional
        The arguments (default ``sys.argv[1:]``), recorded in the marker of
        every result folder.
    errors : tuple of exception types
        Further exceptions that are the user's doing.

    Returns
    -------
    int
        0 on success, 2 for an error the user can fix, 130 after Ctrl-C (143 after
        SIGTERM, 129 after SIGHUP).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    prefix = prog
    token = recorded_command.set([prog, *argv])
    written.clear()
    try:
        args = parser.parse_args(argv)
        prefix = f"{prog} {args.command}"
        log_lines = logging.StreamHandler()
        log_lines.setFormatter(_ReadableFormatter("%(levelname)s: %(message)s"))
        log_lines.addFilter(_toolkit_or_verbose(prog))
        logging.basicConfig(
            level=logging.INFO if getattr(args, "verbose", False) else logging.WARNING,
            handlers=[log_lines],
        )
        with warnings.catch_warnings(), handling_interrupts():
            warnings.simplefilter("always", UserWarning)
            warnings.showwarning = _show_warning(prefix)
            try:
                status = args.handler(args)
            except (InputError, SourceError, OSError, *errors) as exc:
                if is_interrupt(exc) or was_interrupted():  # Ctrl-C wins over what it caused
                    return _interrupted(prefix, exc)
                close_open_lines()
                print(f"{prefix}: error: {one_line(exc)}", file=sys.stderr, flush=True)
                return 2
            except MemoryError as exc:  # an allocation no check foresaw: still one line
                close_open_lines()
                what = one_line(exc) if str(exc) else "an allocation failed"
                print(f"{prefix}: error: not enough memory: {what}", file=sys.stderr, flush=True)
                return 2
            except KeyboardInterrupt as exc:  # here: finalizers run under handling_interrupts
                return _interrupted(prefix, exc)
            except Exception as exc:
                # compiled code interrupted mid-call (SystemError), or library code that
                # turned the KeyboardInterrupt into an error of its own (matplotlib's pybind11
                # functions: TypeError, ValueError)
                if is_interrupt(exc) or was_interrupted():
                    return _interrupted(prefix, exc)
                raise
            if was_interrupted():  # a KeyboardInterrupt that library code swallowed
                return _interrupted(prefix)
            return status
    except KeyboardInterrupt as exc:  # also a second Ctrl-C while the first was handled
        return _interrupted(prefix, exc)
    finally:
        recorded_command.reset(token)


def run_module(cli_module: str, *, held: frozenset[int] = frozenset()) -> None:
    """``python -m PACKAGE`` and the console scripts: run ``cli_module.main()`` and exit.

    Ctrl-C (SIGTERM, SIGHUP) during the imports ends with exit status 130 (143,
    129) and no traceback, as it does later.  ``held``: signals the caller
    blocked until they are handled here (:mod:`tissue_core.main`); a signal
    that came meanwhile is handled as soon as they are unblocked.
    """
    import importlib
    import os
    import signal

    try:
        # from the first import on, not only once the command runs: a Ctrl-C that lands in
        # one of importlib's weakref callbacks is otherwise swallowed by Python ("Exception
        # ignored in ...") and the command runs on to the end
        with handling_interrupts():
            if held:
                signal.pthread_sigmask(signal.SIG_UNBLOCK, held)
            status = importlib.import_module(cli_module).main()
        for signum in SIGNALS:  # done: a late signal changes nothing
            signal.signal(signum, signal.SIG_IGN)
    except KeyboardInterrupt as exc:  # while importing, building the parser, just after main()
        status = _interrupted(cli_module.split(".")[0], exc)
    if status in {exit_status(signum) for signum in SIGNALS}:
        # When Ctrl-C lands in code run by exec() (SciPy's imports do that), CPython
        # marks the interrupt as unhandled and, at exit, kills itself with SIGINT even
        # though it was handled: leave at once with the status the contract promises.
        # (atexit handlers do not run then; the results were cleaned up before)
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):  # a closed pipe, a closed stream (SIGHUP)
                pass
        os._exit(status)
    sys.exit(status)


def _interrupted(prefix: str, exc: BaseException | None = None) -> int:
    """Say that the signal (Ctrl-C, SIGTERM, SIGHUP) ended the command; its exit status."""
    import signal

    signum = interrupt_signal(exc)
    note_interrupted()
    if signum == signal.SIGINT:
        what, newline = "interrupted", "\n"  # on a terminal, ^C was echoed on the open line
    else:
        what, newline = f"terminated ({signal_name(signum)})", ""
    what += (
        f" after the results were written to {readable(', '.join(written))}"
        if written
        else "; no output written"
    )
    try:
        close_open_lines()
        if not getattr(sys.stderr, "isatty", lambda: False)():
            newline = ""
        print(f"{newline}{prefix}: {what}", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr is gone: a closed terminal (SIGHUP), a closed pipe
        pass
    return exit_status(signum)
