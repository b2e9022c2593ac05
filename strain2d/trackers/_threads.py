"""How many threads the trackers use, and frames decoded ahead of the tracker.

The compiled kernels (numba ``prange`` over points), the spline prefilter and
sampling (SciPy in a thread pool) and OpenCV all run on several threads. Their
number is, in order:

1. the ``threads`` option of a tracker (``--threads`` on the command line);
2. the usual environment variables: ``NUMBA_NUM_THREADS``, then
   ``OMP_NUM_THREADS`` (set by SLURM, PBS and most job schedulers);
3. the cores this process may run on (``os.sched_getaffinity``).

Results do not depend on it: every parallel loop runs over independent
points, rows or lines, each computed whole by one thread.

:func:`prefetched` reads (decodes) the next frames in a background thread
while the tracker works on the current one.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import os
import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor

from strain2d.errors import InputError

__all__ = [
    "THREADS_OPTION",
    "available_threads",
    "parallel_map",
    "prefetched",
    "threads_option",
    "using_threads",
    "worker_count",
]

#: the thread count set by :func:`using_threads` for the code it runs
_threads: contextvars.ContextVar[int | None] = contextvars.ContextVar("threads", default=None)


def available_threads() -> int:
    """The default thread count: the environment's (see the module docstring), or the cores."""
    for name in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS"):
        text = os.environ.get(name, "").strip()
        if text.isdigit() and int(text) > 0:
            return int(text)
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def worker_count() -> int:
    """Threads the code running now may use (the option, or :func:`available_threads`)."""
    n = _threads.get()
    return n if n is not None else available_threads()


def threads_option(text: str) -> int:
    """``--threads``: a whole number of threads >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"must be a whole number of threads, got {text!r}") from None
    if value < 1:
        raise ValueError(f"must be at least 1, got {value}")
    return value


def _threads_option_factory():
    from strain2d.trackers import TrackerOption

    return TrackerOption(
        "threads",
        "--threads",
        "threads to use (default: NUMBA_NUM_THREADS or OMP_NUM_THREADS if set, else every "
        "core this process may run on); the tracks do not depend on it",
        type=threads_option,
    )


@contextlib.contextmanager
def using_threads(threads: int | None) -> Iterator[int]:
    """Run the block with ``threads`` threads (None: :func:`available_threads`); yields the count.

    Sets numba's thread count and OpenCV's for the block and restores them
    after.  numba cannot use more threads than it started with
    (``NUMBA_NUM_THREADS``): more is refused with one line.  BLAS and LAPACK
    (NumPy's and SciPy's OpenBLAS or MKL) get one thread in the block: the
    trackers split their work over the threads themselves, and a BLAS call
    inside that work (a banded Cholesky of a few thousand unknowns, a small
    matrix product) gains nothing from threads of its own while the others
    wait for them.  With OpenBLAS's default of a thread per core, gdic on the
    vessels case (bench/bench_default_tracker.py) took 1.7x as long on 2
    cores and 3.3x as long on 16 (20.7 s against 6.3 s); the tracks are the
    same.
    """
    import cv2
    import numba
    from threadpoolctl import threadpool_limits

    if threads is not None and (isinstance(threads, bool) or int(threads) != threads):
        raise InputError(f"--threads must be a whole number, got {threads!r}")
    n = available_threads() if threads is None else int(threads)
    most = numba.config.NUMBA_NUM_THREADS
    if n < 1:
        raise InputError(f"--threads must be at least 1, got {n}")
    if threads is not None and n > most:
        raise InputError(
            f"--threads {n} is more than the {most} threads available to this process "
            "(NUMBA_NUM_THREADS, or the cores it may run on)"
        )
    n = min(n, most)
    token = _threads.set(n)
    old_numba, old_cv = numba.get_num_threads(), cv2.getNumThreads()
    numba.set_num_threads(n)
    cv2.setNumThreads(n)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield n
    finally:
        numba.set_num_threads(old_numba)
        cv2.setNumThreads(old_cv)
        _threads.reset(token)


@functools.cache
def _map_pool() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max(os.cpu_count() or 1, 2), thread_name_prefix="parts")


def parallel_map(function: Callable, items: list) -> list:
    """``[function(item) for item in items]`` on :func:`worker_count` threads, in order.

    For work that NumPy does with the GIL released (array arithmetic, batched
    linear algebra); each call runs with one thread of its own (its inner
    sampling is not split again). Serial where one thread is allowed.
    """
    workers = worker_count()
    if workers == 1 or len(items) < 2:
        return [function(item) for item in items]

    def one(item):
        token = _threads.set(1)
        try:
            return function(item)
        finally:
            _threads.reset(token)

    pool = _map_pool()
    results: list = [None] * len(items)
    # at most `workers` calls at a time, each in a context of its own
    for start in range(0, len(items), workers):
        part = items[start : start + workers]
        futures = [pool.submit(contextvars.copy_context().run, one, item) for item in part]
        for k, future in enumerate(futures):
            results[start + k] = future.result()
    return results


class _Ended:
    """What the reader thread hands over last: the end of the frames, or the error raised."""

    def __init__(self, error: BaseException | None = None) -> None:
        self.error = error


def prefetched(frames: Iterable, depth: int = 2) -> Iterator:
    """The items of ``frames``, read up to ``depth`` ahead in a background thread.

    A video's decoding (OpenCV and FFmpeg release the GIL) then overlaps the
    tracking of the frame before.  An error raised while reading is raised
    here, at the item where it happened.  When the consumer stops early (an
    error, Ctrl-C), the reader stops after the item it is reading.
    """
    items: queue.Queue = queue.Queue(maxsize=max(int(depth), 1))
    stop = threading.Event()

    def put(item) -> bool:
        """Hand ``item`` over, waiting for room; False once the consumer stopped."""
        while not stop.is_set():
            try:
                items.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def read() -> None:
        try:
            for item in frames:
                if not put(item):
                    return
            ended = _Ended()
        except BaseException as exc:  # handed to the consumer, raised there
            ended = _Ended(exc)
        put(ended)

    reader = threading.Thread(target=read, name="frames-ahead", daemon=True)
    reader.start()
    try:
        while True:
            item = items.get()
            if isinstance(item, _Ended):
                if item.error is not None:
                    raise item.error
                return
            yield item
    finally:
        stop.set()


#: the ``--threads`` option that the trackers which run in parallel offer
THREADS_OPTION = _threads_option_factory()
