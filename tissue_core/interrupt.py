"""Ctrl-C held back while compiled code runs.

A SIGINT that arrives while a numba kernel runs can surface inside the
kernel's call back into Python and end as ``SystemError: ... returned a
result with an exception set`` instead of :class:`KeyboardInterrupt`.
:func:`deferred_interrupt` records the signal instead, lets the kernel
finish (one frame's work: milliseconds to a second), then raises a clean
:class:`KeyboardInterrupt`.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["deferred_interrupt", "is_interrupt"]


@contextlib.contextmanager
def deferred_interrupt() -> Iterator[None]:
    """Run the block with Ctrl-C deferred to its end.

    Outside the main thread, or when SIGINT is not handled by Python's default
    handler (ignored, or handled by the caller), the block runs unchanged.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.default_int_handler:
        yield
        return
    received: list[int] = []
    signal.signal(signal.SIGINT, lambda signum, frame: received.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if received:
        raise KeyboardInterrupt


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
