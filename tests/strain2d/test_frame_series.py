"""Trackers write their per-frame rows into arrays made once (strain2d.trackers._series):
the same tracks as rows stacked at the end, however wrong the frame count the source gives,
with the tracks held once rather than twice at the end of a long video."""

import tracemalloc

import numpy as np
import pytest

from sample_data_synth import make_case
from strain2d.grid import make_grid
from strain2d.trackers import get_tracker
from strain2d.trackers._series import FrameSeries


def _rows(n: int, rng) -> list[dict]:
    return [
        {"positions": rng.normal(size=(5, 2)), "visible": rng.random(5) > 0.3,
         "quality": rng.random(5)}
        for _ in range(n)
    ]  # fmt: skip


@pytest.mark.parametrize("total", [7, 3, 20, None, 0])  # exact, under, over, unknown
def test_the_series_equal_the_rows_stacked_whatever_the_count_said(total):
    rows = _rows(7, np.random.default_rng(1))
    series = FrameSeries(total, **rows[0])
    for row in rows[1:]:
        series.append(**row)
    assert len(series) == 7
    out = series.arrays()
    for name in rows[0]:
        np.testing.assert_array_equal(out[name], np.stack([r[name] for r in rows]))
        assert out[name].dtype == rows[0][name].dtype and out[name].flags.owndata


def test_a_row_must_name_every_series():
    series = FrameSeries(3, positions=np.zeros((2, 2)), visible=np.ones(2, bool))
    with pytest.raises(ValueError, match="visible"):
        series.append(positions=np.zeros((2, 2)))


class _Frames:
    """The case's frames with a frame count that may be wrong (a container's metadata)."""

    def __init__(self, frames, says: int | None):
        self.frames, self.says = frames, says

    def __iter__(self):
        yield from self.frames

    def __len__(self):
        return self.says


@pytest.mark.parametrize("tracker", ["klt", "gdic"])
def test_tracks_do_not_depend_on_the_frame_count_the_source_gives(tracker):
    case = make_case("equibiaxial", size=96, n_frames=6, rng=0)
    points = make_grid((96, 96), shape=(3, 3), roi=(24, 24, 72, 72))
    track = get_tracker(tracker).function
    expected = track(list(case.frames), points)
    for says in (2, 6, 40):
        got = track(_Frames(case.frames, says), points)
        np.testing.assert_array_equal(got.positions, expected.positions)
        np.testing.assert_array_equal(got.visible, expected.visible)
        np.testing.assert_array_equal(got.quality, expected.quality)
    got = track(iter(case.frames), points)  # a generator: no count at all
    np.testing.assert_array_equal(got.positions, expected.positions)


def _klt_peak(n_frames: int) -> tuple[int, int]:
    """Heap peak of klt over a still video of ``n_frames`` and the bytes of its tracks."""
    rng = np.random.default_rng(0)
    frame = (rng.random((64, 64)) * 255).astype(np.uint8)
    points = make_grid((64, 64), shape=(20, 20), roi=(12, 12, 52, 52))  # 400 points

    def frames():
        for _ in range(n_frames):
            yield frame  # made on the fly: nothing held

    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracks = get_tracker("klt").function(
            _Frames(frames(), n_frames), points, affine_correction=False
        )
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    return peak, tracks.positions.nbytes + tracks.visible.nbytes + tracks.quality.nbytes


def test_klt_holds_its_tracks_once_at_the_end_of_a_long_video():
    """What a longer video adds to the peak is its tracks, once.  Rows kept in lists and
    stacked at the end added 1.9 times as much (each row, then the stack)."""
    _klt_peak(3)  # the first call's imports and caches
    short_peak, short = _klt_peak(40)
    long_peak, long = _klt_peak(400)
    assert long - short > 3_000_000
    grown = (long_peak - short_peak) / (long - short)
    assert grown < 1.2, f"the peak grew by {grown:.2f} times the tracks"
