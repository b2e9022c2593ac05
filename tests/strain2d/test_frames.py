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


def test_sixteen_bit_range_comes_from_the_dtype(tmp_path):
    tifffile.imwrite(
        tmp_path / "s.tif", np.full((3, 8, 8), 1000, np.uint16), photometric="minisblack"
    )
    assert open_frames(tmp_path / "s.tif").value_range == (0.0, 65535.0)


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
