import logging
import math

import numpy as np
import pytest
import tifffile

from mpm3d.errors import InputError, MissingSpacingWarning, NoDataWarning, SourceError
from mpm3d.io import Stack, parse_spacing, read_stack, select_channel
from tests.tolerances import EXACT

NAMES = ["collagen", "urothelium"]


def _zcyx(z=4, c=2, y=6, x=7, seed=0):
    """Random uint16 stack (Z, C, Y, X)."""
    return np.random.default_rng(seed).integers(0, 4000, (z, c, y, x), dtype=np.uint16)


def _write_imagej(path, data, *, spacing=4.0, unit="um", pixel=1.24, axes="ZCYX", **kwargs):
    metadata = {"axes": axes}
    if spacing is not None:
        metadata["spacing"] = spacing
    if unit is not None:
        metadata["unit"] = unit
    metadata.update(kwargs.pop("metadata", {}))
    tifffile.imwrite(
        path, data, imagej=True, resolution=(1 / pixel, 1 / pixel), metadata=metadata, **kwargs
    )
    return path


def _write_ome(path, data_czyx, *, sizes=(4.0, 1.24, 1.24), units=("µm",) * 3, names=NAMES):
    metadata = {"axes": "CZYX", "Channel": {"Name": names}}
    for axis, size, unit in zip("ZYX", sizes, units, strict=True):
        metadata[f"PhysicalSize{axis}"] = size
        metadata[f"PhysicalSize{axis}Unit"] = unit
    tifffile.imwrite(path, data_czyx, ome=True, photometric="minisblack", metadata=metadata)
    return path


def test_imagej_hyperstack_round_trip(tmp_path):
    data = _zcyx()
    labels = NAMES * data.shape[0]  # ImageJ slice labels, C varying fastest
    path = _write_imagej(tmp_path / "s.tif", data, metadata={"Labels": labels})
    stack = read_stack(path)
    assert stack.spacing == (4.0, 1.24, 1.24)
    assert stack.spacing_source == "imagej"
    assert stack.axes == "ZCYX"
    assert stack.channel_names == tuple(NAMES)
    assert stack.memmapped
    assert not stack.data.flags.writeable
    assert stack.path == str(path)
    np.testing.assert_array_equal(stack.data, data)
    text = repr(stack)
    assert "Spacing (dz, dy, dx): (4, 1.24, 1.24) um from imagej" in text
    assert "collagen, urothelium" in text


@pytest.mark.parametrize(
    ("unit", "spacing", "pixel"),
    [
        ("micron", 4.0, 1.24),
        ("microns", 4.0, 1.24),
        ("\\u00B5m", 4.0, 1.24),  # ImageJ's escaped micro sign (descriptions are ASCII)
        ("nm", 4000.0, 1240.0),
        ("mm", 0.004, 0.00124),
    ],
)
def test_imagej_units(tmp_path, unit, spacing, pixel):
    path = _write_imagej(tmp_path / "s.tif", _zcyx(), spacing=spacing, unit=unit, pixel=pixel)
    stack = read_stack(path)
    assert stack.spacing == pytest.approx((4.0, 1.24, 1.24), rel=EXACT)
    assert stack.spacing_source == "imagej"
    assert stack.channel_names == ("0", "1")


def test_imagej_units_from_resolution_unit_cm(tmp_path):
    # no unit in the description: ImageJ reads spacing and pixel size in ResolutionUnit
    path = _write_imagej(
        tmp_path / "s.tif",
        _zcyx(),
        spacing=4e-4,
        unit=None,
        pixel=1.24e-4,
        resolutionunit="CENTIMETER",
    )
    stack = read_stack(path)
    assert stack.spacing == pytest.approx((4.0, 1.24, 1.24), rel=EXACT)
    assert stack.spacing_source == "tiff-resolution"


def test_imagej_unknown_unit_is_missing_spacing(tmp_path):
    path = _write_imagej(tmp_path / "s.tif", _zcyx(), unit="furlong")
    with pytest.warns(MissingSpacingWarning, match="no voxel spacing"):
        stack = read_stack(path)
    assert stack.spacing == (1.0, 1.0, 1.0)
    assert stack.spacing_source == "none"


@pytest.mark.parametrize(
    ("sizes", "units"),
    [
        ((4.0, 1.24, 1.24), ("µm", "µm", "µm")),  # MICRO SIGN
        ((4.0, 1.24, 1.24), ("μm", "μm", "μm")),  # GREEK SMALL LETTER MU
        ((4000.0, 1240.0, 1240.0), ("nm", "nm", "nm")),
        ((4000.0, 1.24, 1.24), ("nm", "um", "micron")),
    ],
)
def test_ome_czyx_round_trip(tmp_path, sizes, units):
    data = _zcyx()
    path = _write_ome(tmp_path / "s.ome.tif", np.moveaxis(data, 1, 0), sizes=sizes, units=units)
    stack = read_stack(path)
    assert stack.axes == "CZYX"
    assert stack.spacing == pytest.approx((4.0, 1.24, 1.24), rel=EXACT)
    assert stack.spacing_source == "ome"
    assert stack.channel_names == tuple(NAMES)
    assert stack.memmapped
    assert stack.shape == data.shape
    np.testing.assert_array_equal(stack.data, data)


def test_ome_without_z_size_warns_with_what_it_found(tmp_path):
    path = tmp_path / "s.ome.tif"
    metadata = {"axes": "CZYX", "PhysicalSizeX": 1.24, "PhysicalSizeY": 1.24}
    tifffile.imwrite(path, _zcyx(), ome=True, photometric="minisblack", metadata=metadata)
    with pytest.warns(MissingSpacingWarning, match=r"1.24 x 1.24 um but no Z step"):
        stack = read_stack(path)
    assert stack.spacing_source == "none"


@pytest.mark.parametrize("metadata", [{}, None])  # tifffile "shaped" (QYX) or bare pages (IYX)
def test_plain_multipage_tiff_warns_and_assumes_1um(tmp_path, metadata):
    data = _zcyx(c=1)[:, 0]
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, data, photometric="minisblack", metadata=metadata)
    with pytest.warns(MissingSpacingWarning, match=r"pass --spacing Z,Y,X") as record:
        stack = read_stack(path)
    assert record[0].filename == __file__  # stacklevel points at the caller
    assert stack.axes in ("QYX", "IYX")
    assert stack.spacing == (1.0, 1.0, 1.0)
    assert stack.spacing_source == "none"
    assert stack.channel_names == ("0",)
    assert stack.memmapped
    np.testing.assert_array_equal(stack.data, data[:, np.newaxis])


def test_pages_written_one_by_one_are_read_without_memmap(tmp_path):
    data = _zcyx(c=1)[:, 0]
    path = tmp_path / "s.tif"
    for page in data:
        tifffile.imwrite(path, page, photometric="minisblack", metadata=None, append=True)
    with pytest.warns(MissingSpacingWarning):
        stack = read_stack(path)
    assert not stack.memmapped
    np.testing.assert_array_equal(stack.data[:, 0], data)


def test_plain_tiff_resolution_is_reported_but_not_used(tmp_path):
    path = tmp_path / "s.tif"
    tifffile.imwrite(
        path,
        _zcyx(c=1)[:, 0],
        photometric="minisblack",
        resolution=(1 / 1.24e-4, 1 / 1.24e-4),
        resolutionunit="CENTIMETER",
    )
    with pytest.warns(MissingSpacingWarning, match=r"1.24 x 1.24 um but no Z step"):
        stack = read_stack(path)
    assert stack.spacing == (1.0, 1.0, 1.0)


def test_user_spacing_overrides_metadata(tmp_path):
    path = _write_imagej(tmp_path / "s.tif", _zcyx())
    stack = read_stack(path, spacing=(2, 0.5, 0.5))
    assert stack.spacing == (2.0, 0.5, 0.5)
    assert stack.spacing_source == "user"


def test_user_spacing_silences_the_missing_spacing_warning(tmp_path):
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, _zcyx(c=1)[:, 0], photometric="minisblack")
    stack = read_stack(path, spacing=np.array([2.0, 0.5, 0.5]))  # filterwarnings=error
    assert stack.spacing == (2.0, 0.5, 0.5)


@pytest.mark.parametrize("spacing", [(1, 1), (0, 1, 1), (math.nan, 1, 1), (-1, 1, 1), "1,1,1"])
def test_bad_user_spacing(tmp_path, spacing):
    with pytest.raises(InputError, match="spacing must be three finite positive numbers"):
        read_stack(tmp_path / "does-not-matter.tif", spacing=spacing)


def test_compressed_file_is_decoded(tmp_path):
    data = _zcyx()
    path = _write_imagej(tmp_path / "s.tif", data, compression="zlib")
    stack = read_stack(path)
    assert not stack.memmapped
    assert stack.spacing == (4.0, 1.24, 1.24)
    np.testing.assert_array_equal(stack.data, data)


def test_singleton_time_axis_is_squeezed(tmp_path):
    data = _zcyx()
    path = _write_imagej(tmp_path / "s.tif", data[np.newaxis], axes="TZCYX")
    np.testing.assert_array_equal(read_stack(path).data, data)


def test_time_axis_is_refused(tmp_path):
    data = np.zeros((5, 3, 2, 4, 5), np.uint8)
    path = _write_imagej(tmp_path / "s.tif", data, axes="TZCYX")
    with pytest.raises(InputError, match=r"has a time axis \(T=5\); pass one time point"):
        read_stack(path)


@pytest.mark.parametrize("shape", [(6, 7), (1, 2, 6, 7)])
def test_2d_image_is_refused(tmp_path, shape):
    path = tmp_path / "s.tif"
    if len(shape) == 2:
        tifffile.imwrite(path, np.zeros(shape, np.uint8), photometric="minisblack")
    else:
        _write_imagej(path, np.zeros(shape, np.uint8))  # Z == 1
    with pytest.raises(InputError, match=r"is a 2D image .* not a z-stack"):
        read_stack(path)


def test_rgb_is_refused(tmp_path):
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, np.zeros((3, 6, 7, 3), np.uint8), photometric="rgb")
    with pytest.raises(InputError, match="RGB colour samples"):
        read_stack(path)


def test_ambiguous_axes_are_refused(tmp_path):
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, _zcyx(), photometric="minisblack")  # shaped: "QQYX"
    with pytest.raises(InputError, match="cannot tell the Z axis apart"):
        read_stack(path)


def test_source_errors(tmp_path):
    with pytest.raises(SourceError, match=r"stack file not found: .*missing\.tif"):
        read_stack(tmp_path / "missing.tif")
    with pytest.raises(SourceError, match="is a folder"):
        read_stack(tmp_path)
    text = tmp_path / "notes.tif"
    text.write_text("not a TIFF")
    with pytest.raises(SourceError, match=r"cannot read .*notes\.tif as a TIFF stack"):
        read_stack(text)


@pytest.fixture
def stack(tmp_path):
    data = _zcyx(z=5, y=9, x=11)
    data[:, 1] //= 40  # a dim second channel
    path = _write_imagej(tmp_path / "s.tif", data, metadata={"Labels": NAMES * 5})
    return read_stack(path)


@pytest.mark.parametrize(("channel", "index"), [(1, 1), ("Urothelium", 1), ("0", 0), (0, 0)])
def test_select_one_channel_is_a_view(stack, channel, index):
    volume, label = select_channel(stack, channel)
    assert label == NAMES[index]
    assert volume.shape == (5, 9, 11)
    assert np.shares_memory(volume, stack.data)
    np.testing.assert_array_equal(volume, stack.data[:, index])


@pytest.mark.parametrize(
    ("channel", "message"),
    [
        ("dapi", "channel 'dapi' not found; the stack has channels: collagen, urothelium"),
        (2, "channel 2 out of range: the stack has 2 channels"),
        ("2", "channel 2 out of range"),
        (-1, "channel -1 out of range"),
        (1.0, "channel must be an index or a name"),
    ],
)
def test_select_missing_channel(stack, channel, message):
    with pytest.raises(InputError, match=message):
        select_channel(stack, channel)


def test_combined_channels(stack):
    volume, label = select_channel(stack)
    assert label == "max of collagen, urothelium"
    assert volume.dtype == np.uint16
    assert volume.shape == (5, 9, 11)
    expected = np.zeros(volume.shape)
    for c in range(2):
        channel = stack.data[:, c].astype(np.float64)
        lo, hi = np.percentile(channel, [0.1, 99.9])
        expected = np.maximum(expected, np.clip((channel - lo) / (hi - lo), 0, 1))
    np.testing.assert_allclose(volume, np.rint(expected * 65535), atol=1)
    assert volume.max() == 65535  # each channel reaches full scale, the dim one too


def test_combined_channels_ignore_a_constant_channel():
    data = np.zeros((2, 2, 3, 3), np.float32)
    data[:, 0] = np.arange(18).reshape(2, 3, 3)
    data[0, 0, 0, 0] = np.nan
    stack = Stack(data, (1.0, 1.0, 1.0), "user", ("a", "b"), "mem", "ZCYX")
    with pytest.warns(NoDataWarning, match="NaN"):
        volume, _ = select_channel(stack)
    assert volume[0, 0, 0] == 0
    assert volume[-1, -1, -1] == 65535


def test_single_channel_stack_needs_no_choice(tmp_path):
    data = _zcyx(c=1)
    path = _write_imagej(tmp_path / "s.tif", data[:, 0], axes="ZYX")
    stack = read_stack(path)
    assert stack.axes == "ZYX"
    volume, label = select_channel(stack)
    assert label == "0"
    np.testing.assert_array_equal(volume, data[:, 0])


def test_stack_validates_its_fields():
    with pytest.raises(InputError, match="channel_names has 1 names for 2 channels"):
        Stack(np.zeros((2, 2, 3, 3)), (1, 1, 1), "user", ("a",), "mem", "ZCYX")
    with pytest.raises(InputError, match="spacing_source"):
        Stack(np.zeros((2, 1, 3, 3)), (1, 1, 1), "guess", ("a",), "mem", "ZCYX")
    with pytest.raises(InputError, match=r"\(Z, C, Y, X\)"):
        Stack(np.zeros((2, 3, 3)), (1, 1, 1), "user", ("a",), "mem", "ZYX")


def test_parse_spacing():
    assert parse_spacing("4,1.24,1.24") == (4.0, 1.24, 1.24)
    for bad in ["4,1.24", "a,b,c", "4,0,1", "4,1,inf", ""]:
        with pytest.raises(InputError, match=r"--spacing must be Z,Y,X in micrometres, got '"):
            parse_spacing(bad)


# --------------------------------------------------------------------------- damaged files


def _cut(path, fraction):
    """Keep the first ``fraction`` of the file's bytes, as an interrupted copy does."""
    raw = path.read_bytes()
    path.write_bytes(raw[: int(len(raw) * fraction)])
    return path


@pytest.mark.parametrize("fraction", [0.6, 0.3, 0.05])
def test_truncated_imagej_hyperstack_is_named_truncated(tmp_path, fraction):
    path = _cut(_write_imagej(tmp_path / "s.tif", _zcyx(z=20, y=16, x=16)), fraction)
    with pytest.raises(SourceError) as info:
        read_stack(path)
    message = str(info.value)
    assert message.startswith(f"{path} is truncated or damaged: ")
    assert "ImageJ metadata announces 40 images but the file holds 1 page" in message
    assert "\n" not in message


@pytest.mark.parametrize(
    "write",
    [
        pytest.param(lambda p, d: _write_ome(p, np.moveaxis(d, 1, 0)), id="ome"),
        pytest.param(
            lambda p, d: tifffile.imwrite(p, d[:, 0], photometric="minisblack"), id="pages"
        ),
        pytest.param(
            lambda p, d: tifffile.imwrite(p, d[:, 0], photometric="minisblack", metadata=None),
            id="bare-pages",
        ),
        pytest.param(lambda p, d: _write_imagej(p, d, compression="zlib"), id="imagej-zlib"),
    ],
)
def test_truncated_files_are_named_truncated(tmp_path, write):
    path = tmp_path / "s.tif"
    write(path, _zcyx(z=20, y=16, x=16))
    _cut(path, 0.6)
    with pytest.raises(SourceError, match=r"is truncated or damaged: .*invalid page offset"):
        read_stack(path, spacing=(4, 1, 1))


def _tags_first_tiff(path, data, *, compression=1):
    """A classic little-endian TIFF of uint16 pages whose tags all precede the pixels."""
    import struct

    z, h, w = data.shape
    ifd_size = 2 + 9 * 12 + 4
    first_pixel = 8 + z * ifd_size
    out = bytearray(struct.pack("<2sHI", b"II", 42, 8))
    for k in range(z):
        tags = [
            (256, 3, w),  # ImageWidth, SHORT
            (257, 3, h),  # ImageLength
            (258, 3, 16),  # BitsPerSample
            (259, 3, compression),  # Compression: 1 none
            (262, 3, 1),  # PhotometricInterpretation: min-is-black
            (273, 4, first_pixel + k * h * w * 2),  # StripOffsets, LONG
            (277, 3, 1),  # SamplesPerPixel
            (278, 3, h),  # RowsPerStrip
            (279, 4, h * w * 2),  # StripByteCounts
        ]
        out += struct.pack("<H", len(tags))
        for code, kind, value in tags:
            out += struct.pack("<HHI", code, kind, 1) + struct.pack(
                "<I" if kind == 4 else "<HH", *((value,) if kind == 4 else (value, 0))
            )
        out += struct.pack("<I", 8 + (k + 1) * ifd_size if k < z - 1 else 0)
    out += data.astype("<u2").tobytes()
    path.write_bytes(bytes(out))
    return path


@pytest.mark.parametrize("cut", [0, 100, 3000])
def test_pixel_data_past_the_end_is_named_truncated(tmp_path, cut):
    """Every page's tags are there, but the last bytes of the pixels are not."""
    data = _zcyx(z=6, c=1, y=32, x=32)[:, 0]
    path = _tags_first_tiff(tmp_path / "s.tif", data)
    if not cut:  # the whole file reads back
        np.testing.assert_array_equal(read_stack(path, spacing=(4, 1, 1)).data[:, 0], data)
        return
    path.write_bytes(path.read_bytes()[:-cut])
    with pytest.raises(SourceError, match=r"is truncated: its pixel data runs to byte \d+ but"):
        read_stack(path, spacing=(4, 1, 1))


def test_lzw_stacks_are_read_and_a_missing_codec_is_named(tmp_path, monkeypatch):
    """imagecodecs is a dependency: compressed stacks read; a broken install names it."""

    data = _zcyx(z=3, c=1, y=8, x=8)[:, 0]
    path = tmp_path / "s.tif"
    tifffile.imwrite(path, data, compression="lzw", photometric="minisblack")
    np.testing.assert_array_equal(read_stack(path, spacing=(4, 1, 1)).data[:, 0], data)

    def no_codec(self, *args, **kwargs):
        raise ValueError("<COMPRESSION.LZW: 5> requires the 'imagecodecs' package")

    monkeypatch.setattr(tifffile.TiffPageSeries, "asarray", no_codec)
    with pytest.raises(SourceError) as info:
        read_stack(path, spacing=(4, 1, 1))
    assert str(info.value) == (
        f"cannot read {path} as a TIFF stack: its pixels are LZW-compressed, which needs "
        "the imagecodecs package: pip install imagecodecs"
    )


def test_tifffile_messages_become_the_error_not_log_lines(tmp_path, caplog):
    """The CLI logs WARNING and above to stderr: tifffile's own lines would break the one line."""
    path = _cut(_write_imagej(tmp_path / "s.tif", _zcyx(z=20, y=16, x=16)), 0.6)
    with caplog.at_level(logging.DEBUG), pytest.raises(SourceError):
        read_stack(path)
    assert [r for r in caplog.records if r.levelno >= logging.WARNING] == []
    assert any("tifffile: " in r.getMessage() for r in caplog.records)  # -v shows them


def test_empty_file(tmp_path):
    path = tmp_path / "empty.tif"
    path.touch()
    with pytest.raises(SourceError, match=r"empty\.tif is empty \(0 bytes\), not a TIFF stack"):
        read_stack(path)
