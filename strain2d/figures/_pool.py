"""Figures drawn in worker processes while the run goes on with the rest of its outputs.

A run's figures are independent of each other and of the animation, and each
is mostly Python (Matplotlib's layout and drawing), so threads would take
turns; :class:`FigurePool` draws them in worker processes, one per core the
process may use, while the caller writes the tables and the animation.
Without a second core (or inside a daemonic process, such as a Dask
worker's, which may not start processes) the same calls run here, one after
the other, when submitted.

Each worker has a pipe of its own (no shared queues, whose semaphores would
outlive an interrupted run); a thread of the pool gives a task to a worker
as soon as the worker is idle, whatever the caller is doing meanwhile (the
tables, the animation).  The workers ignore Ctrl-C (the command
handles it): leaving the pool on an error or an interrupt ends them before
the caller removes what they were writing into.  A task runs with the
caller's Matplotlib settings, and its warnings are raised again here: as if
it had run here.
"""

from __future__ import annotations

import collections
import logging
import multiprocessing
import os
import sys
import threading
import traceback
import warnings
from collections.abc import Callable
from typing import Any

__all__ = ["FigurePool"]

log = logging.getLogger(__name__)

#: modules the workers import before their first task (what every figure needs)
_PRELOAD = ["strain2d.figures"]
#: the most workers: a run has about seven figures
MAX_WORKERS = 4


def _available_cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _context(warm_here: bool = True):
    """How the workers start: forked, where that is safe and cheap, else from a fresh server.

    A fork copies the caller's imports for free but is unsafe with other
    threads running (a lock one holds stays locked in the child) and on
    macOS; there the workers are forked from a server started afresh.
    ``warm_here``: load the fonts here first, so that forked workers start
    with them.
    """
    if sys.platform.startswith("linux") and threading.active_count() == 1:
        if warm_here:
            _warm_up()
        return multiprocessing.get_context("fork")
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    context = multiprocessing.get_context(method)
    if method == "forkserver":
        context.set_forkserver_preload(_PRELOAD)
    return context


def _warm_up() -> None:
    """Draw a small figure with a mathematical label here, once: the workers forked from this
    process then start with Matplotlib's fonts and math-text parser loaded."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1), dpi=72)
    fig.text(0.5, 0.5, r"$E_{xx}$ (-)")
    FigureCanvasAgg(fig).draw()


def _style() -> dict:
    """The caller's Matplotlib settings that differ from those read at import (a style, an
    ``rc_context``): the figures drawn elsewhere look as they would here."""
    from matplotlib import rcParams, rcParamsOrig

    return {k: v for k, v in rcParams.items() if k != "backend" and rcParamsOrig.get(k) != v}


def _call(fn: Callable, args: tuple, kwargs: dict, style: dict) -> tuple[Any, list]:
    """Run a task in the caller's style; return its value and its warnings (category, text)."""
    from matplotlib import rc_context

    with warnings.catch_warnings(record=True) as caught, rc_context(style):
        warnings.simplefilter("always")
        value = fn(*args, **kwargs)
    return value, [(w.category, str(w.message)) for w in caught]


class _RemoteTraceback(Exception):
    """Where a worker's error came from (its traceback, as text)."""

    def __str__(self) -> str:
        return self.args[0]


def _serve(connection, inherited: list, warm: bool = False) -> None:
    """A worker: run the tasks that come down ``connection`` until told to stop.

    ``inherited`` are the caller's ends of the workers' pipes that a fork
    copied here: closed, so that each worker sees its pipe end with the caller.
    ``warm``: load Matplotlib's fonts and math text before the first task.
    """
    import pickle
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the command's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # the pool ends a worker with SIGTERM
    for other in inherited:
        other.close()
    for name in _PRELOAD:
        __import__(name)
    if warm:
        _warm_up()
    while True:
        try:
            task = connection.recv()
        except EOFError:  # the caller is gone
            return
        if task is None:
            return
        number, fn, args, kwargs, style = task
        try:
            reply = (number, True, _call(fn, args, kwargs, style))
        except Exception as exc:
            reply = (number, False, (exc, traceback.format_exc()))
        try:
            connection.send(reply)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:  # cannot travel
            what = reply[2][0] if not reply[1] else exc
            error = RuntimeError(f"{type(what).__name__}: {what}")
            connection.send((number, False, (error, traceback.format_exc())))


class _Result:
    """What :meth:`FigurePool.submit` returns: ``result()`` gives the call's value or raises
    its error, waiting for it if a worker makes it."""

    def __init__(self, pool: FigurePool | None, number: int, value: Any = None) -> None:
        self._pool, self._number, self._value = pool, number, value

    def result(self) -> Any:
        if self._pool is not None:
            self._value = self._pool._wait(self._number)
            self._pool = None
        return self._value


class FigurePool:
    """Worker processes that draw figures; a context manager.

    Parameters
    ----------
    workers : int, optional
        How many processes; default one per core this process may use (at
        most :data:`MAX_WORKERS`), none with a single core.  0 runs every call
        here, when it is submitted.
    warm : bool, keyword-only
        Start the workers ready to draw: each loads Matplotlib's fonts and
        math text before its first task, not the caller before it starts
        them.  For a pool started before long work (the tracking), while the
        caller has one thread: the workers are then forked (not started
        from a fresh server, as they are once threads run), and load while
        the caller works.

    Examples
    --------
    >>> with FigurePool(0) as pool:
    ...     pending = pool.submit(divmod, 7, 2)
    >>> pending.result()
    (3, 1)
    """

    def __init__(self, workers: int | None = None, *, warm: bool = False) -> None:
        if workers is None:
            workers = _available_cores()
            workers = 0 if workers < 2 else min(workers, MAX_WORKERS)
        if workers < 0:
            raise ValueError(f"workers must be 0 or more, got {workers}")
        if workers and multiprocessing.current_process().daemon:
            workers = 0  # a daemonic process (a Dask worker's) may not start processes
        self.workers = workers
        self.warm = warm
        self._processes: list = []
        self._idle: list = []  # connections of the workers without a task
        self._busy: dict = {}  # connection -> the number of its task
        self._queued: collections.deque = collections.deque()
        self._done: dict[int, tuple[bool, Any]] = {}
        self._count = 0
        # the pool's state is shared with its dispatching thread (started with the workers)
        self._lock = threading.RLock()
        self._finished = threading.Condition(self._lock)  # notified as tasks end
        self._dispatcher: threading.Thread | None = None
        self._ending = False
        self._broken = False  # the dispatcher failed: the tasks run here
        self._lost: list = []  # connections of workers left busy when the dispatcher failed

    def __enter__(self) -> FigurePool:
        self._ending, self._broken, self._lost = False, False, []
        if self.workers:
            try:
                context = _context(warm_here=not self.warm)
                forked = context.get_start_method() == "fork"
                for _ in range(self.workers):
                    mine, theirs = context.Pipe()
                    inherited = [*self._idle, mine] if forked else []
                    process = context.Process(
                        target=_serve,
                        args=(theirs, inherited, self.warm),
                        daemon=True,
                    )
                    process.start()
                    theirs.close()
                    self._processes.append(process)
                    self._idle.append(mine)
            except OSError as exc:  # no processes here (a sandbox): draw here instead
                log.debug("figures drawn in this process: %s", exc)
                self._stop(kill=True)
                self.workers = 0
                return self
            try:  # started after the forks: they are made while this process has one thread
                self._wake_reader, self._wake_writer = multiprocessing.Pipe(duplex=False)
                self._dispatcher = threading.Thread(
                    target=self._dispatch, name="figure-pool", daemon=True
                )
                self._dispatcher.start()
            except BaseException:
                self._dispatcher = None
                self._stop(kill=True)
                raise
        return self

    def submit(self, fn: Callable, /, *args, **kwargs) -> _Result:
        """Call ``fn(*args, **kwargs)`` in a worker, or here without workers."""
        if not self._processes:
            return _Result(None, 0, fn(*args, **kwargs))
        with self._lock:
            self._count += 1
            self._queued.append((self._count, fn, args, kwargs, _style()))
            number = self._count
        self._wake_up()
        return _Result(self, number)

    def _wake_up(self) -> None:
        try:
            self._wake_writer.send_bytes(b"")
        except (OSError, AttributeError):  # the dispatcher has ended
            pass

    def _dispatch(self) -> None:
        """The pool's thread: give each idle worker the next task as soon as it is idle, and
        take in what the workers finish, until the pool ends."""
        import signal
        from multiprocessing.connection import wait

        if hasattr(signal, "pthread_sigmask"):  # signals are the caller's to take
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:
            while True:
                with self._lock:
                    if self._ending:
                        return
                    self._hand_out()
                    watched = [*self._busy, self._wake_reader]
                for connection in wait(watched):
                    if connection is self._wake_reader:
                        while self._wake_reader.poll():
                            self._wake_reader.recv_bytes()
                        continue
                    with self._lock:
                        self._take_in(connection)
                        self._finished.notify_all()
        except Exception as exc:  # never leave the caller waiting for tasks nobody runs
            with self._lock:
                for number in self._busy.values():
                    self._done[number] = (False, (exc, traceback.format_exc()))
                self._lost.extend(self._busy)  # their workers are ended with the pool
                self._busy.clear()
                self._broken = True  # what is queued, and submitted from now on, runs here
                self._finished.notify_all()

    def _hand_out(self) -> None:
        """Queued tasks to idle workers (the lock held)."""
        from multiprocessing.reduction import ForkingPickler

        while self._idle and self._queued:
            task = self._queued.popleft()
            try:
                data = ForkingPickler.dumps(task)
            except Exception as exc:  # the task cannot travel: its error
                self._done[task[0]] = (False, (exc, traceback.format_exc()))
                self._finished.notify_all()
                continue
            connection = self._idle.pop()
            try:
                connection.send_bytes(data)
            except OSError:  # the worker is gone (killed while idle): another one, or here
                connection.close()
                self._queued.appendleft(task)
                self._finished.notify_all()
                continue
            self._busy[connection] = task[0]

    def _take_in(self, connection) -> None:
        """A busy worker's reply (the lock held)."""
        number = self._busy.pop(connection)
        try:
            _, ok, outcome = connection.recv()
        except (EOFError, OSError):  # the worker died (killed, out of memory): not given more
            connection.close()
            error = RuntimeError("a process drawing the figures ended unexpectedly")
            self._done[number] = (False, (error, ""))
            return
        except Exception as exc:  # a reply that cannot be rebuilt here (read whole, though)
            self._idle.append(connection)
            self._done[number] = (False, (exc, traceback.format_exc()))
            return
        self._idle.append(connection)
        self._done[number] = (ok, outcome)

    def _left_here(self) -> bool:
        """Whether the queued tasks must run here: no worker left, or no thread to give them
        out (the lock held)."""
        return bool(self._queued) and (self._broken or not (self._idle or self._busy))

    def _wait(self, number: int) -> Any:
        with self._lock:
            while number not in self._done:
                if self._left_here():
                    self._run_here()
                    continue
                self._finished.wait()
            ok, outcome = self._done.pop(number)
        if not ok:
            error, where = outcome
            raise error from _RemoteTraceback(where)
        value, caught = outcome
        for category, message in caught:
            warnings.warn(message, category, stacklevel=3)
        return value

    def _run_here(self) -> None:
        """The queued tasks, here (the lock held)."""
        while self._queued:
            number, fn, args, kwargs, _ = self._queued.popleft()
            try:
                self._done[number] = (True, (fn(*args, **kwargs), []))
            except Exception as exc:
                self._done[number] = (False, (exc, traceback.format_exc()))

    def cancel(self) -> None:
        """End the workers at once, their tasks unfinished (what leaving on an error does)."""
        self._stop(kill=True)

    def _stop(self, *, kill: bool) -> None:
        """End the workers: after their tasks, or at once (``kill``: the tasks not finished
        fail, as cancelled)."""
        if self._dispatcher is not None:
            with self._lock:
                self._ending = True
            self._wake_up()
            self._dispatcher.join()
            self._dispatcher = None
            self._wake_reader.close()
            self._wake_writer.close()
        kill = kill or bool(self._lost)
        for connection in [*self._idle, *self._busy]:
            if not kill:
                try:
                    connection.send(None)
                except OSError:
                    pass
        for process in self._processes:
            if kill:
                process.terminate()
            process.join()
        for connection in [*self._idle, *self._busy, *self._lost]:
            connection.close()
        with self._lock:
            cancelled = RuntimeError("the figure's pool was ended before the task was done")
            for number in [*self._busy.values(), *(task[0] for task in self._queued)]:
                self._done[number] = (False, (cancelled, ""))
            self._queued.clear()
            self._processes, self._idle, self._busy, self._lost = [], [], {}, []
            self._finished.notify_all()

    def __exit__(self, kind, error, traceback) -> None:
        if self._processes and kind is None:
            try:
                with self._lock:
                    while self._busy or self._queued:  # submitted and not waited for
                        if self._left_here():
                            self._run_here()
                            break
                        self._finished.wait()
            except BaseException:  # Ctrl-C while waiting: the workers end at once
                self._stop(kill=True)
                raise
        self._stop(kill=kind is not None)
