"""Property-based tests of mpm3d's readers: whatever text or bytes they are given, they return
a valid value or raise the toolkit's own error (never another exception), and every small
valid stack reads back as written."""

import math

import numpy as np
import pytest
import tifffile
from hypothesis import given
from hypothesis import strategies as st

from mpm3d.errors import InputError, SourceError
from mpm3d.io import Stack, parse_spacing, read_stack
from tests.properties import property_settings

SETTINGS = property_settings(40)

# --------------------------------------------------------------------------- parse_spacing

NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.sampled_from(["nan", "inf", "-inf", "1e-300", "1e300", "0", "-0", "", " ", "1_000", "0x10"]),
    st.text(max_size=6),
)


@SETTINGS
@given(st.one_of(st.text(max_size=40), st.lists(NUMBERS, min_size=0, max_size=5).map(",".join)))
def test_parse_spacing_gives_three_finite_positive_numbers_or_input_error(text):
    try:
        spacing = parse_spacing(text)
    except InputError as exc:
        assert "--spacing" in str(exc)
        return
    assert isinstance(spacing, tuple) and len(spacing) == 3
    assert all(isinstance(v, float) and math.isfinite(v) and v > 0 for v in spacing)


@SETTINGS
@given(st.lists(st.floats(1e-3, 1e4), min_size=3, max_size=3))
def test_parse_spacing_reads_back_what_was_written(values):
    assert parse_spacing(",".join(repr(v) for v in values)) == tuple(values)


# --------------------------------------------------------------------------- read_stack on bytes


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    """The bytes of small valid stacks of several kinds, to damage."""
    folder = tmp_path_factory.mktemp("seeds")
    data = np.random.default_rng(0).integers(0, 4000, (5, 2, 8, 8), dtype=np.uint16)
    ij = {"axes": "ZCYX", "spacing": 4.0, "unit": "um"}
    writers = [
        lambda p: tifffile.imwrite(p, data, imagej=True, metadata=ij),
        lambda p: tifffile.imwrite(p, data, imagej=True, metadata=ij, byteorder=">"),
        lambda p: tifffile.imwrite(
            p, data, ome=True, photometric="minisblack", metadata={"axes": "ZCYX"}
        ),
        lambda p: tifffile.imwrite(p, data[:, 0], photometric="minisblack", compression="zlib"),
        lambda p: tifffile.imwrite(p, data[:, 0] > 2000, photometric="minisblack"),
    ]
    out = []
    for k, write in enumerate(writers):
        path = folder / f"seed{k}.tif"
        write(path)
        out.append(path.read_bytes())
    return out


def _read(path):
    """read_stack's outcome: a Stack, or the toolkit's own error (anything else fails)."""
    try:
        stack = read_stack(path, spacing=(4.0, 1.0, 1.0))
    except (InputError, SourceError) as exc:
        assert "\n" not in str(exc).strip() or str(path) in str(exc)
        return exc
    assert isinstance(stack, Stack)
    assert stack.data.ndim == 4 and stack.data.dtype.kind in "iuf"
    np.asarray(stack.data).sum()  # every byte it promises can be read
    return stack


@SETTINGS
@given(st.binary(max_size=300))
def test_read_stack_on_arbitrary_bytes(tmp_path_factory, raw):
    path = tmp_path_factory.getbasetemp() / "arbitrary.tif"
    path.write_bytes(raw)
    _read(path)


@SETTINGS
@given(
    st.integers(0, 4),
    st.lists(st.tuples(st.integers(0, 10**6), st.integers(0, 255)), max_size=8),
    st.one_of(st.none(), st.floats(0, 1)),
)
def test_read_stack_on_damaged_stacks(tmp_path_factory, seeds, which, edits, keep):
    raw = bytearray(seeds[which])
    for position, value in edits:  # flipped bytes, in the header and tags mostly
        raw[position % min(len(raw), 600)] = value
    if keep is not None:  # cut short
        raw = raw[: int(keep * len(raw))]
    path = tmp_path_factory.getbasetemp() / "damaged.tif"
    path.write_bytes(bytes(raw))
    _read(path)


# --------------------------------------------------------------------------- valid stacks

DTYPES = ["u1", "i1", "u2", "i2", "u4", "i4", "f2", "f4", "f8", "?"]


@st.composite
def stacks(draw):
    """A small valid stack (Z, C, Y, X), how it is written, and the array as written."""
    kind = draw(st.sampled_from(["imagej", "ome", "pages"]))
    dtype = draw(st.sampled_from(["u1", "u2", "i2", "f4"] if kind == "imagej" else DTYPES))
    if kind == "ome" and dtype in ("f2", "?"):
        kind = "pages"  # OME has no half floats; tifffile writes bool pages as 1-bit
    z = draw(st.integers(2, 5))
    c = 1 if kind == "pages" else draw(st.integers(1, 3))
    y, x = draw(st.integers(2, 9)), draw(st.integers(2, 9))
    seed = draw(st.integers(0, 2**16))
    values = np.random.default_rng(seed).integers(0, 100, (z, c, y, x))
    data = (values > 50) if dtype == "?" else values.astype(dtype)
    byteorder = draw(st.sampled_from("<>"))
    return kind, data, byteorder


@SETTINGS
@given(stacks())
def test_small_valid_stacks_read_back_as_written(tmp_path_factory, written):
    kind, data, byteorder = written
    path = tmp_path_factory.getbasetemp() / "valid.tif"
    if kind == "imagej":
        axes = "ZCYX" if data.shape[1] > 1 else "ZYX"
        tifffile.imwrite(
            path,
            data if data.shape[1] > 1 else data[:, 0],
            imagej=True,
            byteorder=byteorder,
            metadata={"axes": axes},
        )
    elif kind == "ome":
        tifffile.imwrite(
            path,
            np.moveaxis(data, 1, 0),
            ome=True,
            byteorder=byteorder,
            photometric="minisblack",
            metadata={"axes": "CZYX"},
        )
    else:
        tifffile.imwrite(
            path, data[:, 0], byteorder=byteorder, photometric="minisblack", metadata=None
        )
    stack = read_stack(path, spacing=(4.0, 1.0, 1.0))
    expected = data.astype(np.uint8) if data.dtype == bool else data
    if data.dtype == np.float16:
        expected = data.astype(np.float32)
    assert stack.shape == data.shape
    assert stack.data.dtype == expected.dtype and stack.data.dtype.isnative
    np.testing.assert_array_equal(stack.data, expected)
