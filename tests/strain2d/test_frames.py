import cv2
import numpy as np
import pytest
import tifffile

from sample_data_synth import write_video
from strain2d.errors import SourceError
from strain2d.frames import open_frames, to_gray


def _write_pngs(folder, frames, prefix="img"):
    folder.mkdir()
    paths = []
    for i, f in enumerate(frames):
        p = folder / f"{prefix}{i}.png"  # img10 must sort after img9 (natural order)
        cv2.imwrite(str(p), f)
        paths.append(p)
    return paths


@pytest.mark.parametrize("kind", ["avi", "tif", "folder", "list"])
def test_every_source_kind_reads_the_same_frames(tmp_path, smooth_frames, kind):
    if kind in ("avi", "tif"):
        path = tmp_path / f"v.{kind}"
        write_video(smooth_frames, path)
        source = open_frames(path)
    elif kind == "folder":
        _write_pngs(tmp_path / "frames", smooth_frames)
        source = open_frames(tmp_path / "frames")
    else:
        paths = _write_pngs(tmp_path / "frames", smooth_frames)
        source = open_frames(paths)
    assert len(source) == 5
    assert source.shape == (48, 64)
    assert source.value_range == (0.0, 255.0)
    np.testing.assert_array_equal(source.read_all(), smooth_frames.astype(np.float32))
    np.testing.assert_array_equal(source.frame(-1), smooth_frames[-1])


def test_natural_sort_of_folders(tmp_path, smooth_frames):
    frames = np.concatenate([smooth_frames, smooth_frames])  # 10 frames: img0..img9
    frames = np.concatenate([frames, smooth_frames[:2]])  # img10, img11
    _write_pngs(tmp_path / "f", frames)
    source = open_frames(tmp_path / "f")
    np.testing.assert_array_equal(source.read_all(), frames)


def test_frame_range_and_stride(tmp_path, smooth_frames):
    path = tmp_path / "v.avi"
    write_video(smooth_frames, path)
    source = open_frames(path, start=1, stop=5, step=2)
    np.testing.assert_array_equal(source.read_all(), smooth_frames[1:5:2])
    tif = tmp_path / "v.tif"
    write_video(smooth_frames, tif)
    np.testing.assert_array_equal(open_frames(tif, step=2).read_all(), smooth_frames[::2])


def test_colour_is_converted_to_gray(tmp_path):
    rgb = np.zeros((2, 8, 8, 3), np.uint8)
    rgb[..., 0] = 100  # red
    tifffile.imwrite(tmp_path / "c.tif", rgb, photometric="rgb")
    frames = open_frames(tmp_path / "c.tif").read_all()
    np.testing.assert_allclose(frames, 0.299 * 100, rtol=1e-6)
    np.testing.assert_allclose(to_gray(rgb[0, ..., ::-1], order="bgr"), 0.299 * 100, rtol=1e-6)


def test_ten_bit_data_in_sixteen_bits_keeps_its_contrast(tmp_path):
    """Microscopy cameras store 10/12-bit data in uint16: the 8-bit conversion must not
    squash it into a few gray levels, and tracking must work as on the 8-bit original."""
    from sample_data_synth import make_case
    from strain2d import track
    from strain2d.trackers._convert import to_uint8

    video = make_case("equibiaxial", size=200, n_frames=5, rng=3)
    ten_bit = (video.frames.astype(np.uint16) * 4)[:, None]  # 0..1020, saved as T pages
    tifffile.imwrite(tmp_path / "s.tif", ten_bit[:, 0], photometric="minisblack")
    source = open_frames(tmp_path / "s.tif")
    lo, hi = source.value_range
    assert 0 <= lo and hi <= 1400
    assert len(np.unique(to_uint8(source.first(), source.value_range))) > 100
    points = video.truth.grid((4, 4))
    tracks = track(source, points, tracker="klt", options={"window": 21})
    assert tracks.visible.all()
    err = np.linalg.norm(tracks.positions[-1] - video.truth.positions(points, 4), axis=1)
    assert err.max() < 0.5


def test_multichannel_tiff_is_refused(tmp_path):
    data = np.zeros((3, 2, 16, 16), np.uint16)
    tifffile.imwrite(tmp_path / "c.tif", data, imagej=True, metadata={"axes": "TCYX"})
    with pytest.raises(SourceError, match="2 channels"):
        open_frames(tmp_path / "c.tif")


def test_errors(tmp_path, smooth_frames):
    with pytest.raises(SourceError, match="no such file"):
        open_frames(tmp_path / "missing.avi")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"this is not a video" * 100)
    with pytest.raises(SourceError, match="cannot read"):
        open_frames(bad)
    tifffile.imwrite(tmp_path / "one.tif", smooth_frames[:1])
    with pytest.raises(SourceError, match="1 frame"):
        open_frames(tmp_path / "one.tif")
    (tmp_path / "empty").mkdir()
    with pytest.raises(SourceError, match="no images"):
        open_frames(tmp_path / "empty")
    write_video(smooth_frames, tmp_path / "v.avi")
    with pytest.raises(SourceError, match="selects no frame"):
        open_frames(tmp_path / "v.avi", start=10)


def _counted(source):
    """``source``, counting its decoding passes in the list returned with it."""
    reads = []
    original = source._iter_raw

    def counting():
        reads.append(1)
        yield from original()

    source._iter_raw = counting
    return source, reads


def test_end_frames_keeps_first_and_last_without_a_second_pass(tmp_path, smooth_frames):
    from strain2d.frames import EndFrames

    path = tmp_path / "v.avi"
    write_video(smooth_frames, path)
    source, reads = _counted(open_frames(path))
    wrapped = EndFrames(source)
    assert len(wrapped) == 5 and wrapped.shape == (48, 64)
    assert len(list(wrapped)) == 5
    first, last = wrapped.ends()
    assert len(reads) == 1  # one decoding pass in all
    np.testing.assert_array_equal(first, smooth_frames[0])
    np.testing.assert_array_equal(last, smooth_frames[-1])
    untouched = EndFrames(open_frames(path))  # a tracker that never iterates (imported)
    np.testing.assert_array_equal(untouched.ends()[1], smooth_frames[-1])


def test_end_frames_keep_every_eight_bit_frame_within_the_budget(tmp_path, smooth_frames):
    from strain2d.frames import EndFrames

    path = tmp_path / "v.avi"
    write_video(smooth_frames, path)
    size = smooth_frames[0].size
    source, reads = _counted(open_frames(path))
    wrapped = EndFrames(source, keep_bytes=5 * size)
    first_pass = list(wrapped)
    assert wrapped.kept
    second_pass = list(wrapped)
    assert len(reads) == 1  # the second pass decoded nothing
    assert all(f.dtype == np.float32 for f in second_pass)
    np.testing.assert_array_equal(np.stack(second_pass), np.stack(first_pass))
    np.testing.assert_array_equal(np.stack(second_pass), smooth_frames)
    # one byte short of the frames: decoded again, as without a budget
    source, reads = _counted(open_frames(path))
    short = EndFrames(source, keep_bytes=5 * size - 1)
    list(short), list(short)
    assert not short.kept and len(reads) == 2


def test_end_frames_do_not_keep_colour_or_sixteen_bit_frames(tmp_path, smooth_frames):
    from strain2d.frames import EndFrames

    colour = np.stack([smooth_frames, np.roll(smooth_frames, 3, axis=2), smooth_frames], -1)
    tifffile.imwrite(tmp_path / "colour.tif", colour, photometric="rgb")
    deep = tmp_path / "deep.tif"
    tifffile.imwrite(deep, smooth_frames.astype(np.uint16) * 200)
    for path in (tmp_path / "colour.tif", deep):
        source, reads = _counted(open_frames(path))
        wrapped = EndFrames(source, keep_bytes=2**30)
        first_pass = np.stack(list(wrapped))
        assert not wrapped.kept  # mixed from colour, or beyond 8 bits: decoded again
        np.testing.assert_array_equal(np.stack(list(wrapped)), first_pass)
        assert len(reads) == 2


@pytest.mark.parametrize(
    ("name", "codec", "params"),
    [
        ("h264.mp4", "libx264", ["-bf", "3"]),  # B-frames: decoded out of order
        ("mpeg4.avi", "mpeg4", []),
        ("mjpeg.avi", "mjpeg", []),
        ("vp9.webm", "libvpx-vp9", ["-crf", "30", "-b:v", "0"]),
        ("h264.mov", "libx264", []),
    ],
)
def test_videos_of_other_encoders_are_read_whole(tmp_path, name, codec, params):
    """Videos another tool wrote (FFmpeg's encoders, lossy): every frame, in order."""
    import imageio_ffmpeg

    rng = np.random.default_rng(0)
    base = rng.uniform(0, 255, (64, 64))
    frames = [np.clip(base + 12 * k, 0, 255).astype(np.uint8) for k in range(9)]
    writer = imageio_ffmpeg.write_frames(
        str(tmp_path / name), (64, 64), pix_fmt_in="gray", codec=codec, fps=10,
        output_params=params, macro_block_size=1, ffmpeg_log_level="error",
    )  # fmt: skip
    writer.send(None)
    for frame in frames:
        writer.send(np.ascontiguousarray(frame))
    writer.close()
    source = open_frames(tmp_path / name)
    read = source.read_all()
    assert len(source) == read.shape[0] == 9
    means = read.reshape(9, -1).mean(axis=1)
    assert np.all(np.diff(means) > 5)  # the frames come back in their order


@pytest.mark.parametrize(
    ("where", "printed"),
    [(12, "Unexpected element"), (24, "Unexpected element"), (216, "Failed to initialize")],
)
def test_a_damaged_video_header_is_one_line_on_the_terminal(tmp_path, where, printed):
    """OpenCV prints what it finds wrong in an AVI header straight to the process's stderr;
    the user sees the toolkit's one line, and -v shows what OpenCV said."""
    import subprocess
    import sys

    frames = np.random.default_rng(0).integers(0, 255, (3, 64, 64), dtype=np.uint8)
    good = tmp_path / "good.avi"
    write_video(frames, good)
    data = bytearray(good.read_bytes())
    data[where : where + 8] = bytes(range(200, 208))  # the LIST, avih or codec record damaged
    video = tmp_path / "damaged.avi"
    video.write_bytes(bytes(data))
    runs = {}
    for flag in ("-q", "-v"):
        argv = ["analyze", str(video), "--grid", "3x3", "--out", str(tmp_path / "out"), flag]
        runs[flag] = subprocess.run(
            [sys.executable, "-m", "strain2d", *argv], capture_output=True, text=True,
            errors="replace",
        )  # fmt: skip
    quiet, verbose = runs["-q"], runs["-v"]
    assert quiet.returncode == 2
    assert quiet.stderr.splitlines() == [f"strain2d analyze: error: cannot read video {video}"]
    assert printed in verbose.stderr  # OpenCV's own words, in the log
    assert not (tmp_path / "out").exists()


def test_float_frames_are_read_while_finite_and_refused_with_nonfinite_pixels(tmp_path):
    frames = np.random.default_rng(0).uniform(0, 1, (3, 32, 48)).astype(np.float32)
    frames[1, 0, 0] = np.finfo(np.float32).max  # extreme, but a value
    frames[2, 5, 7] = -np.finfo(np.float32).max
    tifffile.imwrite(tmp_path / "ok.tif", frames, photometric="minisblack")
    np.testing.assert_array_equal(open_frames(tmp_path / "ok.tif").read_all(), frames)
    frames[2, 30, 40] = np.nan
    frames[2, 31, 47] = np.inf
    tifffile.imwrite(tmp_path / "bad.tif", frames, photometric="minisblack")
    source = open_frames(tmp_path / "bad.tif")  # frame 0 is clean: opened
    with pytest.raises(SourceError, match=r"bad.tif: frame 2 holds 1 infinite and 1 NaN pixel "
                       r"values \(the first at x=40, y=30\)"):  # fmt: skip
        source.read_all()


@pytest.mark.parametrize("keep", [0.3, 0.9, 0.99])
def test_a_tiff_cut_short_is_truncated_not_fewer_frames(tmp_path, smooth_frames, keep):
    """tifffile reads the pages before the cut and logs the rest: that is not a shorter movie."""
    write_video(smooth_frames, tmp_path / "whole.tif")
    data = (tmp_path / "whole.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: int(len(data) * keep)])
    with pytest.raises(SourceError, match=r"cut\.tif is truncated") as info:
        open_frames(tmp_path / "cut.tif")
    assert "frame(s)" not in str(info.value)


@pytest.mark.parametrize("where", ["movie", "folder"])
def test_a_truncated_tiff_is_one_line_on_the_terminal(tmp_path, smooth_frames, where):
    """tifffile logs ``ERROR: ...`` and OpenCV's libtiff prints warnings on a cut TIFF; the user
    sees the toolkit's one line, and -v shows what tifffile said."""
    import subprocess
    import sys

    if where == "movie":
        write_video(smooth_frames, tmp_path / "whole.tif")
        data = (tmp_path / "whole.tif").read_bytes()
        source = tmp_path / "cut.tif"
        source.write_bytes(data[: len(data) // 2])
        named, said = source, "tifffile: "
    else:
        source = tmp_path / "frames"
        source.mkdir()
        for k, frame in enumerate(smooth_frames[:3]):
            tifffile.imwrite(source / f"f{k}.tif", frame)
        data = (source / "f2.tif").read_bytes()
        (source / "f2.tif").write_bytes(data[: len(data) // 2])
        named, said = source / "f2.tif", None  # refused before OpenCV's libtiff prints
    runs = {}
    for flag in ("-q", "-v"):
        argv = ["analyze", str(source), "--grid", "3x3", "--out", str(tmp_path / "out"), flag]
        runs[flag] = subprocess.run(
            [sys.executable, "-m", "strain2d", *argv], capture_output=True, text=True,
            errors="replace",
        )  # fmt: skip
    quiet, verbose = runs["-q"], runs["-v"]
    assert quiet.returncode == 2
    [line] = quiet.stderr.splitlines()
    assert line.startswith(f"strain2d analyze: error: {named} is truncated"), line
    assert said is None or said in verbose.stderr
    assert not (tmp_path / "out").exists()


def test_one_pass_at_a_time_keeps_the_frames(tmp_path, smooth_frames):
    """A second pass beside a keeping one (a reader thread and a check, say) keeps nothing,
    and a pass stopped early leaves the keeping to the next."""
    from strain2d.frames import EndFrames

    path = tmp_path / "v.avi"
    write_video(smooth_frames, path)
    wrapped = EndFrames(open_frames(path), keep_bytes=2**20)
    first = iter(wrapped)
    next(first)
    assert len(list(wrapped)) == 5 and not wrapped.kept  # beside the first: not kept
    assert len(list(first)) == 4 and wrapped.kept
    stopped = EndFrames(open_frames(path), keep_bytes=2**20)
    early = iter(stopped)
    next(early)
    early.close()
    assert not stopped.kept
    list(stopped)
    assert stopped.kept


def test_analyze_decodes_a_short_video_once_for_tracking_and_animation(
    tmp_path, smooth_frames, monkeypatch
):
    """``strain2d analyze`` with its animation decodes the video's first frame when it opens
    it and the whole video once, for the tracking: every later pass (the animation's, and
    the checks') reads the frames kept."""
    import strain2d.cli as cli
    from strain2d.frames import FrameSource

    path = tmp_path / "v.avi"
    write_video(np.repeat(smooth_frames, 2, axis=0), path)
    passes = []
    original = FrameSource._iter_raw

    def counting(self):
        passes.append(1)
        yield from original(self)

    monkeypatch.setattr(FrameSource, "_iter_raw", counting)
    counts = []
    for keep in (cli.KEEP_FRAMES_BYTES, 0):
        monkeypatch.setattr(cli, "KEEP_FRAMES_BYTES", keep)
        passes.clear()
        argv = ["-q", "analyze", str(path), "--grid", "3x3", "--tracker", "klt",
                "--out", str(tmp_path / f"run{keep}")]  # fmt: skip
        assert cli.main(argv) == 0
        assert (tmp_path / f"run{keep}" / "figures" / "strain_animation.mp4").is_file()
        counts.append(len(passes))
    assert counts[0] == 2 and counts[1] > 2, counts
