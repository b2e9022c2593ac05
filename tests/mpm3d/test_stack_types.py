"""Stacks in every pixel type and byte order a microscope, ImageJ/Fiji or tifffile writes are
analysed, and give the metrics of the same stack written as native little-endian uint16.

One small two-channel stack is scaled to grey values 0..127 so that every type holds the
very same numbers; each file is then analysed by ``python -m mpm3d analyze`` (in-process)
and its metrics compared with those of the native uint16 ImageJ hyperstack."""

import json

import numpy as np
import pytest
import tifffile

from mpm3d.io import read_stack
from sample_data_synth import make_stack_case
from tests.mpm3d.helpers import cli
from tests.tolerances import EXACT, MPM_FOLD_RELATIVE

SPACING = (4.0, 5.0, 5.0)
#: options for a quick, quiet run
FAST = ("--no-surface", "--no-figures", "-q")
#: the metrics compared between the native stack and its other types
KEYS = (
    "fold_height_um",
    "max_fold_height_um",
    "n_folds",
    "fold_wavelength_um",
    "fold_orientation_deg",
    "fold_coherency",
    "Sa_um",
    "Sq_um",
    "Sz_um",
    "surface_coverage",
)


def _write(path, data, *, kind, byteorder="<"):
    """Write ``data`` (Z, C, Y, X) as an ImageJ hyperstack, an OME-TIFF or plain pages."""
    dz, dy, dx = SPACING
    if kind == "imagej":
        tifffile.imwrite(
            path,
            data,
            imagej=True,
            byteorder=byteorder,
            resolution=(1 / dx, 1 / dy),
            metadata={"axes": "ZCYX", "spacing": dz, "unit": "um"},
        )
    elif kind == "ome":
        metadata = {"axes": "ZCYX", "PhysicalSizeZ": dz, "PhysicalSizeY": dy, "PhysicalSizeX": dx}
        tifffile.imwrite(
            path, data, ome=True, byteorder=byteorder, photometric="minisblack", metadata=metadata
        )
    else:  # plain pages of one channel, no metadata: the spacing is given on the command line
        tifffile.imwrite(
            path, data[:, 1], byteorder=byteorder, photometric="minisblack", metadata=None
        )
    return path


@pytest.fixture(scope="module")
def grey(tmp_path_factory):
    """The stack (Z, 2, Y, X) in grey values 0..127, and the native uint16 runs' metrics."""
    folder = tmp_path_factory.mktemp("types")
    case = make_stack_case("before", size=96, spacing=SPACING, rng=1)
    data = np.rint(case.stack / 32.0).astype(np.uint16)
    assert data.max() <= 127  # int8 holds it
    native = _write(folder / "native.tif", data, kind="imagej")
    metrics = {}
    for channel in ("1", None):
        out = folder / f"native-{channel}"
        extra = ("--channel", channel) if channel else ()
        assert cli("analyze", native, "--out", out, *FAST, *extra) == 0
        metrics[channel] = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert metrics["1"]["fold_height_um"] is not None
    return {"data": data, "metrics": metrics, "case": case}


def _analyze(path, out, *extra) -> dict:
    assert cli("analyze", path, "--out", out, *FAST, *extra) == 0
    return json.loads((out / "metrics.json").read_text(encoding="utf-8"))


def _assert_same(m: dict, ref: dict, rel: float) -> None:
    for key in KEYS:
        assert m[key] == pytest.approx(ref[key], rel=rel, abs=rel), key


# (kind, dtype, byte order): ImageJ writes uint8, uint16, int16 and float32; OME-TIFF any
# type but float16; plain TIFF any type
TYPES = [
    pytest.param("imagej", "u2", ">", id="imagej-uint16-big-endian"),
    pytest.param("imagej", "u1", ">", id="imagej-uint8"),
    pytest.param("imagej", "i2", ">", id="imagej-int16-big-endian"),
    pytest.param("imagej", "i2", "<", id="imagej-int16-little-endian"),
    pytest.param("imagej", "f4", ">", id="imagej-float32-big-endian"),
    pytest.param("imagej", "f4", "<", id="imagej-float32-little-endian"),
    pytest.param("ome", "u2", ">", id="ome-uint16-big-endian"),
    pytest.param("ome", "i1", "<", id="ome-int8"),
    pytest.param("ome", "u4", ">", id="ome-uint32-big-endian"),
    pytest.param("ome", "i4", "<", id="ome-int32-little-endian"),
    pytest.param("ome", "f8", ">", id="ome-float64-big-endian"),
    pytest.param("plain", "u2", ">", id="plain-uint16-big-endian"),
    pytest.param("plain", "f8", "<", id="plain-float64-little-endian"),
    pytest.param("plain", "f2", "<", id="plain-float16-little-endian"),
    pytest.param("plain", "f2", ">", id="plain-float16-big-endian"),
]


@pytest.mark.parametrize(("kind", "dtype", "byteorder"), TYPES)
def test_every_type_and_byte_order_gives_the_native_metrics(grey, tmp_path, kind, dtype, byteorder):
    path = _write(tmp_path / "s.tif", grey["data"].astype(dtype), kind=kind, byteorder=byteorder)
    extra = ("--spacing", "4,5,5") if kind == "plain" else ("--channel", "1")
    m = _analyze(path, tmp_path / "out", *extra)
    _assert_same(m, grey["metrics"]["1"], EXACT)
    assert m["spacing_um"] == {"z": 4.0, "y": 5.0, "x": 5.0}


def test_big_endian_hyperstack_with_channels_combined_and_surface(grey, tmp_path):
    """The reported crash: ImageJ's default big-endian hyperstack, every channel combined."""
    path = _write(tmp_path / "s.tif", grey["data"], kind="imagej", byteorder=">")
    assert not read_stack(path).memmapped  # decoded once, in the machine's byte order
    out = tmp_path / "out"
    assert cli("analyze", path, "--out", out, "--no-figures", "-q") == 0
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    _assert_same(m, grey["metrics"][None], EXACT)
    assert m["n_surface_triangles"] > 1000
    assert (out / "surface.vtp").stat().st_size > 0


def test_native_files_stay_memory_mapped(grey, tmp_path):
    for dtype in ("u1", "u2", "f4"):
        path = _write(tmp_path / f"{dtype}.tif", grey["data"].astype(dtype), kind="imagej")
        stack = read_stack(path)
        assert stack.memmapped and stack.data.dtype == np.dtype(dtype)


def test_signed_stack_with_negative_values(grey, tmp_path):
    """Background-subtracted data: the same surface, shifted grey values."""
    data = grey["data"].astype(np.int16) - 100
    path = _write(tmp_path / "s.tif", data, kind="imagej", byteorder=">")
    m = _analyze(path, tmp_path / "out", "--channel", "1")
    _assert_same(m, grey["metrics"]["1"], 1e-6)


def test_float_stack_with_nan_voxels(grey, tmp_path):
    """NaN where the microscope recorded nothing (the first slices' corner, the lumen)."""
    data = grey["data"].astype(np.float32)
    data[:4, :, :30, :30] = np.nan
    path = _write(tmp_path / "s.tif", data, kind="imagej", byteorder=">")
    m = _analyze(path, tmp_path / "out", "--channel", "1")
    ref = grey["metrics"]["1"]
    for key in ("fold_height_um", "max_fold_height_um", "Sq_um"):
        assert m[key] == pytest.approx(ref[key], rel=1e-3), key
    assert m["n_folds"] == ref["n_folds"]
    # NaN counts as lumen: said, and flagged in the report (a NaN band through the tissue
    # leaves the surface unmeasured there and walls the mesh)
    (said,) = [w for w in m["warnings"] if "NaN (no data" in w]
    assert said.startswith("about 0.") and "count as lumen" in said, said
    assert "count as lumen" in (tmp_path / "out" / "report.html").read_text()


@pytest.mark.parametrize("channel", ["1", None])
def test_infinite_voxels_count_as_the_brightest_and_change_nothing_far_from_them(
    grey, tmp_path, channel
):
    """+inf and -inf voxels (a float stack's overflow) in the corners: the corners are tissue
    (+inf) or lumen (-inf), as the brightest and the darkest finite values would be, and the
    metrics are theirs (the thresholds and channel ranges, from the finite voxels, move by
    the few voxels left out)."""
    data = grey["data"].astype(np.float32)
    top, bottom = float(data.max()), float(data.min())
    extreme, infinite = data.copy(), data.copy()
    for array, high, low in ((extreme, top, bottom), (infinite, np.inf, -np.inf)):
        array[:, :, -3:, -3:] = high  # nine columns
        array[:6, :, :3, :3] = low
    extra = ("--channel", channel) if channel else ()
    ref = _analyze(_write(tmp_path / "e.tif", extreme, kind="imagej"), tmp_path / "e", *extra)
    m = _analyze(_write(tmp_path / "i.tif", infinite, kind="imagej"), tmp_path / "i", *extra)
    _assert_same(m, ref, 1e-3)


def test_bool_stack(grey, tmp_path):
    """A thresholded (1-bit) stack: the surface is found to half a slice."""
    data = grey["data"][:, 1] > 40
    path = tmp_path / "mask.tif"
    tifffile.imwrite(path, data, photometric="minisblack")
    with tifffile.TiffFile(path) as tif:
        assert tif.pages[0].bitspersample == 1
    stack = read_stack(path, spacing=SPACING)
    assert stack.data.dtype == np.uint8 and set(np.unique(stack.data)) == {0, 1}
    m = _analyze(path, tmp_path / "out", "--spacing", "4,5,5")
    ref = grey["metrics"]["1"]
    assert m["n_folds"] == ref["n_folds"]
    for key in ("fold_height_um", "max_fold_height_um"):
        assert m[key] == pytest.approx(ref[key], rel=MPM_FOLD_RELATIVE), key


@pytest.mark.parametrize("dtype", ["c8", "c16"])
def test_complex_stack_is_refused_in_one_line(tmp_path, capsys, dtype):
    path = tmp_path / "fft.tif"
    tifffile.imwrite(path, np.ones((4, 8, 8), dtype), photometric="minisblack")
    assert cli("analyze", path, "--out", tmp_path / "out", "-q") == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("mpm3d analyze: error: ")
    assert str(path) in err[0] and "complex" in err[0]
    assert not (tmp_path / "out").exists()
