"""Progress on stderr for the command lines: timestamped steps, and counters.

Every command prints what it does as timestamped lines (``[  12.3 s] tracking
(dic): 31/31 frames``), whether stderr is a terminal or a log file, so that
a batch job's log shows where the time went and where the results are.  On a
terminal a long loop also shows a live bar (tqdm); in a log it prints a line
every ``interval`` seconds instead.  ``quiet`` silences all of it.  The
library itself never prints: it takes a ``progress`` callback, and these
objects are such callbacks.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

from tissue_core.filenames import readable
from tissue_core.interrupt import raise_if_interrupted

__all__ = ["Progress", "close_open_lines", "record_line"]

#: counters whose terminal bar is on screen now (closed before an error line)
_OPEN: list[Task] = []
#: the recording progresses alive (``record=True``): the warnings shown go into them too
_RECORDERS: list[Progress] = []


#: the environment variable that sets the seconds between a counter's lines in a log (a
#: program that reads the lines, such as the napari widgets, asks for more of them)
INTERVAL_VARIABLE = "TISSUE_STRAIN_PROGRESS_INTERVAL"


def _default_interval() -> float:
    """10 s, or :data:`INTERVAL_VARIABLE`'s value (a positive number; others are ignored)."""
    import os

    try:
        value = float(os.environ.get(INTERVAL_VARIABLE, "10"))
    except ValueError:
        return 10.0
    return value if value > 0 and value == value and value != float("inf") else 10.0


def record_line(text: str) -> None:
    """Add ``text`` (a warning shown on stderr) to what every recording progress keeps."""
    for progress in _RECORDERS:
        progress._keep(text)


def _line(stream, text: str) -> None:
    """Write one whole line in a single call: ``print`` writes the text and the newline
    separately, and a Ctrl-C between the two left the interrupt message glued to it."""
    stream.write(text + "\n")
    stream.flush()


def close_open_lines() -> None:
    """End every live progress bar, so that what follows starts on a clean line."""
    for task in list(_OPEN):
        task.close(report=False)


class Progress:
    """Timestamped progress lines on ``stream`` (stderr), counted from creation.

    Parameters
    ----------
    quiet : bool
        Print nothing.
    stream : text stream, optional
        Default ``sys.stderr`` (looked up when printing, so tests can capture it).
    interval : float, optional
        Seconds between the lines a counter prints when ``stream`` is not a terminal;
        by default 10, or the environment variable :data:`INTERVAL_VARIABLE`.
    record : bool
        Keep every step, counter's total and warning, timestamped, in :attr:`lines`
        (``quiet`` or not): the run's own log (``run.log``).
    """

    def __init__(
        self,
        *,
        quiet: bool = False,
        stream: TextIO | None = None,
        interval: float | None = None,
        record: bool = False,
    ) -> None:
        self.quiet = quiet
        self._stream = stream
        self.interval = _default_interval() if interval is None else float(interval)
        self.start = time.perf_counter()
        self.lines: list[str] = []
        self._tasks: list[Task] = []
        if record:
            import weakref

            _RECORDERS.append(self)
            weakref.finalize(self, _RECORDERS.remove, self)

    def _stamped(self, text: str) -> str:
        from datetime import datetime

        stamp = datetime.now().astimezone().isoformat(timespec="seconds")
        return f"{stamp} [{self.elapsed():6.1f} s] {readable(text)}"

    def _keep(self, text: str) -> None:
        self.lines.append(self._stamped(text))

    def recorded(self) -> str:
        """What was kept (``record=True``), one line each; a counter still running ends it
        with how far it has got."""
        running = [
            self._stamped(f"{t.description}: {t._count()} (this log was written at the end "
                          "of this step)")
            for t in self._tasks
            if not t._closed and t.done
        ]  # fmt: skip
        return "".join(line + "\n" for line in [*self.lines, *running])

    @property
    def stream(self) -> TextIO:
        return self._stream if self._stream is not None else sys.stderr

    @property
    def is_terminal(self) -> bool:
        try:
            return self.stream.isatty()
        except (AttributeError, ValueError):
            return False

    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def say(self, message: str) -> None:
        """Print ``[ELAPSED s] message`` (a step, a result, where the output went)."""
        if self in _RECORDERS:
            self._keep(message)
        if self.quiet:
            return
        close_open_lines()
        _line(self.stream, f"[{self.elapsed():6.1f} s] {readable(message)}")

    __call__ = say

    def task(self, description: str, *, unit: str = "frame") -> Task:
        """A counter for a loop: call it with ``(done, total)``; use it as a context manager."""
        task = Task(self, description, unit)
        self._tasks.append(task)
        return task


class Task:
    """A counted step of a :class:`Progress`: a bar on a terminal, periodic lines in a log."""

    def __init__(self, progress: Progress, description: str, unit: str) -> None:
        self.progress = progress
        self.description = readable(description)
        self.unit = unit
        self.done = 0
        self.total: int | None = None
        self._bar = None
        self._start = time.perf_counter()
        self._last_line = self._start
        self._closed = False

    def __enter__(self) -> Task:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(report=exc_type is None)

    def _count(self) -> str:
        of = f"/{self.total}" if self.total is not None else ""
        return f"{self.done}{of} {self.unit}s"

    def __call__(self, done: int, total: int | None = None) -> None:
        raise_if_interrupted()  # a Ctrl-C that Python swallowed in a finalizer
        p = self.progress
        if self._closed:
            return
        self.done = int(done)
        if total is not None:
            self.total = int(total)
        if p.quiet:
            return
        if p.is_terminal:
            if self._bar is None:
                from tqdm import tqdm

                self._bar = tqdm(
                    desc=self.description,
                    unit=self.unit,
                    total=self.total,
                    leave=False,
                    file=p.stream,
                    dynamic_ncols=True,
                )
                _OPEN.append(self)
            if self.total is not None and self._bar.total != self.total:
                self._bar.total = self.total
            self._bar.update(self.done - self._bar.n)
            return
        now = time.perf_counter()
        first = self._last_line == self._start
        if first or now - self._last_line >= p.interval:  # the start, then every interval
            self._last_line = now
            _line(p.stream, f"[{p.elapsed():6.1f} s] {self.description}: {self._count()}")

    def close(self, *, report: bool = True) -> None:
        """Remove the bar; with ``report``, print how much was done and how long it took."""
        if self._closed:
            return
        self._closed = True
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        if self in _OPEN:
            _OPEN.remove(self)
        if report and self.done:  # say() keeps it for the run's log, quiet or not
            took = time.perf_counter() - self._start
            self.progress.say(f"{self.description}: {self._count()} in {took:.1f} s")
