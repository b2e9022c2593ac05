"""Ctrl-C (and SIGTERM, SIGHUP) that arrives where Python cannot raise it cleanly.

Python turns SIGINT into :class:`KeyboardInterrupt` at the next bytecode,
wherever that is.  Four places go wrong:

* inside a numba kernel's call back into Python, where it ends as
  ``SystemError: ... returned a result with an exception set``;
* inside an import, where a native extension (VTK) that is initialising can
  be left half-built and crash the process later (SIGSEGV);
* inside a finalizer or weakref callback, where Python swallows it
  ("Exception ignored in: ...") and the program runs on;
* inside library code that loses it: compiled code that clears the error or
  replaces it with its own (matplotlib's pybind11 functions turn it into a
  ``TypeError`` or ``ValueError`` when it lands in an argument's
  ``__array__``; CPython itself at times drops it for the ``ValueError`` of
  an ``int("normal")`` that matplotlib's font matching catches), or Python
  code that catches every exception and goes on.

SIGTERM (``kill``, ``timeout``, SLURM's ``scancel``, ``docker stop``) and
SIGHUP (the terminal closed) end a process at once by default, leaving its
temporary results behind.  While the command runner runs they take Ctrl-C's
path: they are raised as :class:`Terminated`, a KeyboardInterrupt that names
its signal, so that every ``except KeyboardInterrupt`` cleans up after them
too, and the four places above are handled for them alike.

While :func:`handling_interrupts` is active (the command runner turns it on),
Ctrl-C (or SIGTERM, SIGHUP) in an import is held until the import is done and
then sent again, the same signal, and one in a finalizer is recorded;
:func:`deferred_interrupt` holds it for the length of a block (a kernel
call); :func:`raise_if_interrupted` (called by progress counters and before a
result is renamed into place) raises what was held, and raises again a
Ctrl-C whose KeyboardInterrupt did not end the command, so that one that was
lost never lets a result be written; :func:`was_interrupted` tells the
command runner that an error (or a normal end) came after a Ctrl-C, and
:func:`interrupt_signal` which signal it was.  Outside the command runner,
Python's own behaviour is left as it is (SIGTERM and SIGHUP end the process).
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import threading
import time
from collections.abc import Iterator

__all__ = [
    "SIGNALS",
    "Terminated",
    "deferred_interrupt",
    "exit_status",
    "handling_interrupts",
    "interrupt_signal",
    "is_interrupt",
    "note_interrupted",
    "raise_if_interrupted",
    "signal_name",
    "was_interrupted",
]


log = logging.getLogger(__name__)

#: the signals that end a command the way Ctrl-C does: SIGINT (Ctrl-C), SIGTERM (``kill``,
#: ``timeout``, ``scancel``, ``docker stop``) and SIGHUP (the terminal closed), where the
#: platform has them
SIGNALS: tuple[int, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)


class Terminated(KeyboardInterrupt):
    """The KeyboardInterrupt raised for SIGTERM or SIGHUP: it ends a command as Ctrl-C does.

    A subclass, so that every ``except KeyboardInterrupt`` (and
    :func:`is_interrupt`) treats it as Ctrl-C; ``signum`` is the signal.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    def __str__(self) -> str:
        return signal_name(self.signum)


def signal_name(signum: int) -> str:
    """``"SIGTERM"`` for ``signal.SIGTERM``; ``"signal N"`` for a number without a name."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def exit_status(signum: int) -> int:
    """The exit status of a command a signal ended: ``128 + signum`` (130 after Ctrl-C, 143 after
    SIGTERM, 129 after SIGHUP), as shells report it."""
    return 128 + int(signum)


def _interruption(signum: int | None) -> KeyboardInterrupt:
    """The exception ``signum`` raises: KeyboardInterrupt for Ctrl-C, :class:`Terminated` else."""
    if signum is None or signum == signal.SIGINT:
        return KeyboardInterrupt()
    return Terminated(signum)


def _default(signum: int):
    """Python's own handler of ``signum``: what is installed when nobody else handles it."""
    return signal.default_int_handler if signum == signal.SIGINT else signal.SIG_DFL


class _State:
    pending = False  # a signal was held back
    raised = False  # one was raised as KeyboardInterrupt (which library code may lose)
    interrupted = False  # the command is ending because of one
    signum: int | None = None  # the first signal that came
    depth = 0  # nesting of deferred_interrupt blocks
    redelivering = False
    generation = 0  # changes whenever handling starts or ends: stale redeliveries stand down


_state = _State()


def _importing(frame) -> bool:
    """Whether ``frame`` runs inside an import (importlib's frames are on its stack)."""
    while frame is not None:
        name = frame.f_code.co_filename
        if name.startswith("<frozen importlib") or name.endswith(
            (os.path.join("importlib", "_bootstrap.py"), "_bootstrap_external.py")
        ):  # frozen, or not (python -X frozen_modules=off)
            return True
        frame = frame.f_back
    return False


def _redeliver(generation: int) -> None:
    """Send the held signal again once the main thread has left the import it was in."""
    main = threading.main_thread()
    try:
        while main.is_alive() and generation == _state.generation:
            time.sleep(0.02)
            frame = sys._current_frames().get(main.ident)
            if frame is None or not _importing(frame):
                break
        signum = _state.signum or signal.SIGINT
        current = (
            generation == _state.generation
            and signal.getsignal(signum) is _handler
            and _state.pending
            and _state.depth == 0
        )
        if current and main.is_alive():
            # to the main thread itself, so that a sleep or a blocking call there wakes up
            signal.pthread_kill(main.ident, signum)
    finally:
        _state.redelivering = False


def _handler(signum, frame) -> None:
    if _state.signum is None:
        _state.signum = signum
    if _state.depth:
        _state.pending = True
        return
    if _importing(frame):
        _state.pending = True
        if not _state.redelivering:
            _state.redelivering = True
            threading.Thread(target=_redeliver, args=(_state.generation,), daemon=True).start()
        return
    _state.pending = False
    _state.raised = True  # remembered: the KeyboardInterrupt may never arrive
    raise _interruption(_state.signum)


def _unraisable(previous):
    def hook(unraisable) -> None:
        if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
            _state.pending = True  # swallowed by Python in a finalizer: raise it later
        elif _state.interrupted:
            # an object that Ctrl-C left half-built fails in its finalizer: not news
            log.debug("after Ctrl-C: %s in %r", unraisable.exc_value, unraisable.object)
        else:
            previous(unraisable)

    return hook


def note_interrupted() -> None:
    """The command is ending because of Ctrl-C: finalizers' errors are its consequences."""
    _state.interrupted = True


@contextlib.contextmanager
def handling_interrupts() -> Iterator[None]:
    """Hold Ctrl-C during imports and record one swallowed in a finalizer (main thread only).

    Each of :data:`SIGNALS` is handled so unless someone else handles or ignores
    it: ``nohup`` ignores SIGHUP, and a shell's background job starts with
    SIGINT ignored; they stay so.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    installed = [s for s in SIGNALS if signal.getsignal(s) is _default(s)]
    if not installed:  # handled by an outer command runner (a batch's run), or by others
        yield
        return
    previous_hook = sys.unraisablehook
    _state.pending = _state.raised = _state.interrupted = False
    _state.signum = None
    _state.generation += 1
    for signum in installed:
        signal.signal(signum, _handler)
    sys.unraisablehook = _unraisable(previous_hook)
    try:
        yield
    finally:
        _state.generation += 1
        for signum in installed:
            signal.signal(signum, _default(signum))
        sys.unraisablehook = previous_hook
        _state.pending = _state.raised = _state.interrupted = False
        _state.signum = None


def raise_if_interrupted() -> None:
    """Raise the KeyboardInterrupt that was held back, if there is one, or again one that was
    raised before and did not end the command (library code lost it); :class:`Terminated`
    for SIGTERM and SIGHUP."""
    if (_state.pending or _state.raised) and _state.depth == 0:
        _state.pending = False
        raise _interruption(_state.signum)


def was_interrupted() -> bool:
    """Whether Ctrl-C (or SIGTERM, SIGHUP) reached the running command: held back, or raised
    (and perhaps lost)."""
    return _state.pending or _state.raised


def interrupt_signal(exc: BaseException | None = None) -> int:
    """The signal that is ending the command: the first one that reached it, else the one a
    :class:`Terminated` in the chain of ``exc`` names, else SIGINT (a KeyboardInterrupt
    raised by other means is Ctrl-C's)."""
    if _state.signum is not None:
        return _state.signum
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, Terminated):
            return exc.signum
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return signal.SIGINT


@contextlib.contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Run the block with Ctrl-C (and, in the command runner, SIGTERM and SIGHUP) deferred to
    its end.

    Outside the main thread, or when SIGINT is handled by someone else's
    handler (or ignored), the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    installed = signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if not installed and not any(signal.getsignal(s) is _handler for s in SIGNALS):
        yield
        return
    if installed:
        _state.pending = False
        _state.signum = None
        signal.signal(signal.SIGINT, _handler)
    _state.depth += 1
    try:
        yield
    except BaseException as exc:
        if _leave(installed) and not isinstance(exc, KeyboardInterrupt):
            # the signal came: it wins over the error
            raise _interruption(_state.signum) from exc
        raise
    if _leave(installed):
        raise _interruption(_state.signum)


def _leave(installed: bool) -> bool:
    """End a deferred block; whether a signal held in it is now due."""
    if installed:  # first: outside the runner, our handler never raises (nothing left behind)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    _state.depth -= 1
    if _state.depth == 0 and _state.pending:
        _state.pending = False
        return True
    return False


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a KeyboardInterrupt (:class:`Terminated` too), or an error raised
    because of one.

    Compiled code that is interrupted can wrap the KeyboardInterrupt in a
    ``SystemError`` (possibly several); the chain of causes tells.
    """
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False
