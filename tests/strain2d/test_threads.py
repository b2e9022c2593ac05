"""Threads: the tracks do not depend on how many there are; frames are read ahead."""

import threading

import numpy as np
import pytest

from sample_data_synth import make_case
from strain2d import track
from strain2d.errors import InputError
from strain2d.trackers._threads import available_threads, prefetched, using_threads, worker_count


@pytest.mark.parametrize("tracker", ["gdic", "dic"])
def test_tracks_are_identical_for_one_and_two_threads(tracker):
    video = make_case("gaussian", size=240, n_frames=4, rng=2)
    points = video.truth.grid((6, 6))
    one = track(video.frames, points, tracker=tracker, options={"threads": 1})
    two = track(video.frames, points, tracker=tracker, options={"threads": 2})
    assert np.array_equal(one.positions, two.positions)
    assert np.array_equal(one.visible, two.visible)
    assert np.array_equal(one.quality, two.quality)
    if tracker == "gdic":
        assert np.array_equal(one.uncertainty, two.uncertainty, equal_nan=True)


def test_the_thread_count_is_the_option_then_the_environment_then_the_cores(monkeypatch):
    import numba

    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    assert available_threads() == 3  # a job scheduler's setting
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    assert available_threads() == 2
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    monkeypatch.delenv("OMP_NUM_THREADS")
    assert available_threads() >= 1
    before = numba.get_num_threads()
    with using_threads(1) as n:
        assert n == 1 and worker_count() == 1 and numba.get_num_threads() == 1
    assert numba.get_num_threads() == before  # restored


def _blas_threads() -> set[int]:
    from threadpoolctl import threadpool_info

    return {pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"}


def test_blas_runs_on_one_thread_inside_the_trackers_and_as_before_after():
    """The trackers' own threads each call BLAS (a banded Cholesky, small products): BLAS
    threads of its own on top of them only wait (gdic took twice as long with them)."""
    import scipy.linalg  # noqa: F401  (loads LAPACK's library, as the trackers do)
    from threadpoolctl import threadpool_limits

    if not _blas_threads():  # NumPy built on a BLAS that threadpoolctl cannot control
        pytest.skip("no BLAS library that threadpoolctl controls")
    with threadpool_limits(limits=2, user_api="blas"):
        assert _blas_threads() == {2}
        with using_threads(2):
            inside = _blas_threads()
        assert inside == {1}
        assert _blas_threads() == {2}  # restored


@pytest.mark.parametrize("threads", [0, -2, 10_000, 1.5])
def test_a_thread_count_that_cannot_be_used_is_refused(threads):
    video = make_case("rotation", size=120, n_frames=2, rng=1)
    points = np.array([[50.0, 50], [70, 70], [60, 45]])
    with pytest.raises(InputError, match="--threads"):
        track(video.frames, points, tracker="gdic", options={"threads": threads})


def test_frames_read_ahead_come_in_order_and_errors_where_they_happened():
    assert list(prefetched(iter(range(7)), depth=2)) == list(range(7))

    def broken():
        yield 0
        yield 1
        raise OSError("frame 2 cannot be decoded")

    got = []
    with pytest.raises(OSError, match="frame 2"):
        for item in prefetched(broken()):
            got.append(item)
    assert got == [0, 1]


def test_a_consumer_that_stops_early_stops_the_reader():
    read = []

    def frames():
        for k in range(1000):
            read.append(k)
            yield k

    items = prefetched(frames(), depth=2)
    assert next(items) == 0
    items.close()  # the tracker failed, or Ctrl-C
    for thread in threading.enumerate():
        if thread.name == "frames-ahead":
            thread.join(timeout=5)
    assert len(read) < 10
    assert not any(t.name == "frames-ahead" and t.is_alive() for t in threading.enumerate())
