"""Long videos stream: what ``analyze`` holds does not grow with the number of frames.

Issue 17.  Each test runs the same step at two lengths and compares what it
holds: decoded frames alive at once (weak references to every frame the
source yields), or the peak of the Python heap (tracemalloc, which sees
NumPy's buffers), so nothing here depends on timing or on the process's
resident memory.
"""

import base64
import json
import tracemalloc
import weakref

import numpy as np
import pytest

from sample_data_synth import make_case, write_video
from strain2d.cli import main
from strain2d.figures import plot_principal_crosses
from strain2d.frames import FrameSource
from strain2d.report import write_run_report
from surface_strain import compute_strain, grid_triangles
from tissue_core.tables import write_long_table


@pytest.fixture(scope="module")
def films(tmp_path_factory):
    """The same stretch played back and forth: 6 and 18 frames of 128 x 128 px."""
    folder = tmp_path_factory.mktemp("films")
    frames = make_case("equibiaxial", size=128, n_frames=7, rng=0).frames[:4]
    order = [0, 1, 2, 3, 2, 1]  # then again: a periodic stretch, up to 1.22
    paths = {}
    for n in (6, 18):
        paths[n] = folder / f"film_{n}.avi"
        write_video(frames[[order[k % len(order)] for k in range(n)]], paths[n])
    return paths


def _frames_alive_during_analyze(monkeypatch, video, out) -> int:
    """The most decoded frames alive at once while ``strain2d analyze`` runs."""
    refs: list[weakref.ref] = []
    most = 0
    original = FrameSource.__iter__

    def counting(self):
        nonlocal most, refs
        for frame in original(self):
            refs = [r for r in refs if r() is not None]
            refs.append(weakref.ref(frame))
            most = max(most, len(refs))
            yield frame

    monkeypatch.setattr(FrameSource, "__iter__", counting)
    argv = ["-q", "analyze", str(video), "--grid", "3x3", "--roi", "40,40,88,88"]
    argv += ["--tracker", "klt", "--out", str(out)]
    assert main(argv) == 0
    return most


def test_analyze_holds_a_few_frames_however_long_the_video(films, monkeypatch, tmp_path):
    short = _frames_alive_during_analyze(monkeypatch, films[6], tmp_path / "short")
    long = _frames_alive_during_analyze(monkeypatch, films[18], tmp_path / "long")
    # the reference, the tracker's previous frame, the frames kept for the figures
    # (first, endpoint, last) and the one being read
    assert long == short
    assert long <= 6


def _peak(function, *args, **kwargs) -> int:
    """Bytes the Python heap grew by at most while ``function`` ran."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        function(*args, **kwargs)
        return tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()


def test_long_tables_are_written_a_block_of_frames_at_a_time(tmp_path, monkeypatch):
    monkeypatch.setattr("tissue_core.tables._BLOCK_ROWS", 128, raising=False)  # 6 frames

    def table(T: int) -> dict:
        values = np.linspace(0.0, 1.0, T * 20).reshape(T, 20)
        return {"x": (values, "%.6f"), "visible": (values > 0.5, "%d"), "E": (values, "%.8g")}

    short, long = table(40), table(400)
    write_long_table(tmp_path / "warm.csv", short)
    peak_short = _peak(write_long_table, tmp_path / "short.csv", short)
    peak_long = _peak(write_long_table, tmp_path / "long.csv", long)
    # the whole table at once: ten times the short one's
    assert peak_long < 1.2 * peak_short + 16 * 1024
    lines = (tmp_path / "long.csv").read_text().splitlines()
    assert lines[0] == "frame,point,x,visible,E"
    assert len(lines) == 1 + 400 * 20
    assert lines[1] == "0,0,0.000000,0,0"
    assert lines[-1] == "399,19,1.000000,1,1"


def test_report_streams_the_animation_into_the_page(tmp_path):
    """report.html embeds the MP4, whose base64 is a third larger than the video itself."""
    figures = tmp_path / "figures"
    figures.mkdir()
    video = np.random.default_rng(0).bytes(24 << 20)  # as long as a long run's animation
    (figures / "strain_animation.mp4").write_bytes(video)
    summary = {
        "software": {"name": "strain2d", "version": "test"},
        "figures": [{"files": ["figures/strain_animation.mp4"], "caption": "the video"}],
    }
    peak = _peak(write_run_report, tmp_path, summary)
    assert peak < 4 << 20  # a few blocks, not the video (old: 7 copies, 150 MB)
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    data = base64.b64encode(video).decode("ascii")
    assert f'<source src="data:video/mp4;base64,{data}" type="video/mp4">' in page
    assert page.count("<video") == 1
    assert json.loads(json.dumps(summary)) == summary  # the summary is left as it was


def _long_field(n_frames: int):
    """A 6 x 6 grid stretching and relaxing over ``n_frames`` frames."""
    x, y = np.meshgrid(np.linspace(20, 70, 6), np.linspace(20, 70, 6))
    reference = np.column_stack([x.ravel(), y.ravel()])
    stretch = 1 + 0.05 * np.sin(np.linspace(0, 20, n_frames))[:, None, None]
    points = 45 + (reference[None] - 45) * stretch * [1.0, 0.9]
    return compute_strain(reference, points, grid_triangles(6, 6))


def test_principal_crosses_work_on_their_frame_only():
    image = np.zeros((96, 96), np.float32)
    short, long = _long_field(20), _long_field(3000)
    plot_principal_crosses(image, short, 5)  # matplotlib's caches
    peak_short = _peak(plot_principal_crosses, image, short, 5)
    peak_long = _peak(plot_principal_crosses, image, long, 5)
    # directions of every frame: 3,000 x (36 nodes + 50 triangles) x 4 vectors, 16 MB
    assert peak_long < peak_short + (1 << 20)


def test_a_run_of_a_streamed_field_equals_the_in_memory_run_file_for_file(
    films, tmp_path, monkeypatch
):
    """``analyze`` computes the strain a block of frames at a time (issue 17): every table,
    figure, ParaView file and statistic equals the run of the field held whole, and no step
    reads a whole array of the field (which would hold every frame again)."""
    import dataclasses

    from strain2d import analyze, make_grid, open_frames, write_run
    from surface_strain import FrameArray, streamed_strain
    from tissue_core.batch import differences

    frames = open_frames(films[18])
    grid = make_grid(frames.shape, shape=(4, 4), roi=(40, 40, 88, 88))
    whole = analyze(frames, grid, tracker="klt", grid_shape=(4, 4))
    f = whole.field
    lazy = streamed_strain(
        f.reference,
        whole.tracks.positions,
        f.triangles,
        visible=whole.tracks.visible,
        block_frames=4,  # 18 frames: 5 blocks, the last one short
    )
    options = {"fps": 5, "animation": "gif", "scale": "0.01mm/px", "maps_at": [3, 9]}
    write_run(tmp_path / "whole", whole, frames, **options)

    def whole_array(self, dtype=None, copy=None):
        raise AssertionError(f"the run read the whole {self._name} of a streamed field")

    monkeypatch.setattr(FrameArray, "__array__", whole_array)
    write_run(tmp_path / "lazy", dataclasses.replace(whole, field=lazy), frames, **options)

    a, b = tmp_path / "whole", tmp_path / "lazy"
    assert len([p for p in a.rglob("*") if p.is_file()]) > 30
    # every file byte for byte; summary.json and statistics.json without time stamps
    assert differences(a, b) == []
    # the strain's time is the blocks' (computed as the outputs read them), not the figures'
    times = json.loads((b / "summary.json").read_text())["runtime_s"]
    assert times["strain"] == pytest.approx(lazy.seconds_computing) and times["strain"] > 0
    assert "strain" not in json.loads((a / "summary.json").read_text())["runtime_s"]


def test_colour_limits_of_a_long_streamed_video_compute_each_block_once(computed_blocks):
    """strain_limits samples 512 frames spread over a long video: every component's values
    come from one computation of each block, and equal those of the field held whole."""
    from strain2d.figures import strain_limits
    from surface_strain import streamed_strain

    rng = np.random.default_rng(3)
    X = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0)), -1).reshape(-1, 2)
    T = 2000
    P = X[None] * (1 + 0.1 * np.sin(np.arange(T) / 50))[:, None, None]
    P = P + rng.normal(0, 0.01, P.shape)
    tri = grid_triangles(4, 4)
    lazy = streamed_strain(X, P, tri, block_frames=16)
    limits = strain_limits(lazy, ("Exx", "Eyy", "Exy"))
    assert (
        len(computed_blocks) == 125
    )  # 512 frames spread over 2,000 touch all 125 blocks, once each
    assert limits == strain_limits(compute_strain(X, P, tri), ("Exx", "Eyy", "Exy"))
