"""Ctrl-C that arrives where Python cannot raise it cleanly.

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

While :func:`handling_interrupts` is active (the command runner turns it on),
Ctrl-C in an import is held until the import is done, and one in a finalizer
is recorded; :func:`deferred_interrupt` holds it for the length of a block
(a kernel call); :func:`raise_if_interrupted` (called by progress counters and
before a result is renamed into place) raises what was held, and raises again
a Ctrl-C whose KeyboardInterrupt did not end the command, so that one that
was lost never lets a result be written; :func:`was_interrupted` tells the
command runner that an error (or a normal end) came after a Ctrl-C.  Outside
the command runner, Python's own behaviour is left as it is.
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
    "deferred_interrupt",
    "handling_interrupts",
    "is_interrupt",
    "note_interrupted",
    "raise_if_interrupted",
    "was_interrupted",
]


log = logging.getLogger(__name__)


class _State:
    pending = False  # a Ctrl-C was held back
    raised = False  # a Ctrl-C was raised as KeyboardInterrupt (which library code may lose)
    interrupted = False  # the command is ending because of Ctrl-C
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
    """Send SIGINT again once the main thread has left the import it was in."""
    main = threading.main_thread()
    try:
        while main.is_alive() and generation == _state.generation:
            time.sleep(0.02)
            frame = sys._current_frames().get(main.ident)
            if frame is None or not _importing(frame):
                break
        current = (
            generation == _state.generation
            and signal.getsignal(signal.SIGINT) is _handler
            and _state.pending
            and _state.depth == 0
        )
        if current and main.is_alive():
            # to the main thread itself, so that a sleep or a blocking call there wakes up
            signal.pthread_kill(main.ident, signal.SIGINT)
    finally:
        _state.redelivering = False


def _handler(signum, frame) -> None:
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
    raise KeyboardInterrupt


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
    """Hold Ctrl-C during imports and record one swallowed in a finalizer (main thread only)."""
    if threading.current_thread() is not threading.main_thread() or (
        signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return
    previous_hook = sys.unraisablehook
    _state.pending = _state.raised = _state.interrupted = False
    _state.generation += 1
    signal.signal(signal.SIGINT, _handler)
    sys.unraisablehook = _unraisable(previous_hook)
    try:
        yield
    finally:
        _state.generation += 1
        signal.signal(signal.SIGINT, signal.default_int_handler)
        sys.unraisablehook = previous_hook
        _state.pending = _state.raised = _state.interrupted = False


def raise_if_interrupted() -> None:
    """Raise the KeyboardInterrupt that was held back, if there is one, or again one that was
    raised before and did not end the command (library code lost it)."""
    if (_state.pending or _state.raised) and _state.depth == 0:
        _state.pending = False
        raise KeyboardInterrupt


def was_interrupted() -> bool:
    """Whether Ctrl-C reached the running command: held back, or raised (and perhaps lost)."""
    return _state.pending or _state.raised


@contextlib.contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Run the block with Ctrl-C deferred to its end.

    Outside the main thread, or when SIGINT is handled by someone else's
    handler (or ignored), the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    current = signal.getsignal(signal.SIGINT)
    installed = current is signal.default_int_handler
    if not installed and current is not _handler:
        yield
        return
    if installed:
        _state.pending = False
        signal.signal(signal.SIGINT, _handler)
    _state.depth += 1
    try:
        yield
    except BaseException as exc:
        if _leave(installed) and not isinstance(exc, KeyboardInterrupt):
            raise KeyboardInterrupt from exc  # Ctrl-C was pressed: it wins over the error
        raise
    if _leave(installed):
        raise KeyboardInterrupt


def _leave(installed: bool) -> bool:
    """End a deferred block; whether a Ctrl-C held in it is now due."""
    if installed:  # first: outside the runner, our handler never raises (nothing left behind)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    _state.depth -= 1
    if _state.depth == 0 and _state.pending:
        _state.pending = False
        return True
    return False


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a KeyboardInterrupt, or an error raised because of one.

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
