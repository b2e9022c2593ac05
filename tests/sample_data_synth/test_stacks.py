"""Synthetic MPM z-stacks: the fold geometry, the rendered surface and the files."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.special import ndtr

from sample_data_synth import (
    STACK_CASES,
    fold_height_field,
    make_stack_case,
    render_stack,
    save_stack_truth,
    write_stack,
)
from sample_data_synth.cli import main
from tests.tolerances import EXACT
from tissue_core.outputs import MARKER

#: the urothelium's 50 % edge against the true surface depth, in units of dz
EDGE_DZ = 0.1
#: sample statistics of seeded noise (relative)
STATISTICAL = 0.1

# (orientation, one pixel step (di, dj) along the normal n, one step along the crests):
# n = (-sin theta, cos theta) and the crest direction (cos theta, sin theta) in (x, y),
# written out by hand in (row, column) steps
DIRECTIONS = [
    (0.0, (1, 0), (0, 1)),
    (45.0, (1, -1), (1, 1)),
    (90.0, (0, -1), (1, 0)),
    (135.0, (-1, -1), (1, -1)),
]


def shifted_pairs(a, di, dj):
    """``a[i, j]`` and ``a[i + di, j + dj]`` over every pair inside the array."""
    ny, nx = a.shape
    rows = slice(max(0, -di), ny - max(0, di))
    cols = slice(max(0, -dj), nx - max(0, dj))
    rows2 = slice(max(0, di), ny - max(0, -di))
    cols2 = slice(max(0, dj), nx - max(0, -dj))
    return a[rows, cols], a[rows2, cols2]


@pytest.mark.parametrize(("theta", "normal_step", "crest_step"), DIRECTIONS)
def test_troughs_are_zero_and_crests_are_the_fold_heights(theta, normal_step, crest_step):
    heights = [30.0, 50.0, 70.0, 90.0]
    di, dj = normal_step
    step_um = 2.0 * math.hypot(di, dj)  # spacing 2 um on both axes
    h, info = fold_height_field(
        (81, 81),
        (2.0, 2.0),
        wavelength_um=8 * step_um,
        orientation_deg=theta,
        fold_heights_um=heights,
    )
    assert info["orientation_deg"] == theta
    # along n through the centre pixel: crest k every 8 steps, troughs half-way between
    for m in range(-40, 41):
        value = h[40 + m * di, 40 + m * dj]
        if m % 8 == 0:
            assert value == pytest.approx(heights[(m // 8) % 4], abs=EXACT)
        elif m % 8 == 4:
            assert abs(value) < EXACT
        else:
            assert 0 < value < max(heights)
    # constant along the crests
    a, b = shifted_pairs(h, *crest_step)
    np.testing.assert_allclose(a, b, atol=EXACT)
    assert h.min() >= -EXACT


def test_fold_table_and_in_view_statistics():
    heights = [30.0, 50.0, 70.0, 90.0]
    h, info = fold_height_field(
        (81, 41), (2.0, 3.0), wavelength_um=16.0, orientation_deg=0.0, fold_heights_um=heights
    )
    # u = y - 80 in [-80, 80]: crests k = -5..5 all cross the field of view
    folds = info["folds"]
    assert [f["index"] for f in folds] == list(range(-5, 6))
    assert all(f["in_view"] for f in folds)
    expected = [heights[k % 4] for k in range(-5, 6)]
    assert [f["crest_height_um"] for f in folds] == expected
    assert [f["crest_offset_um"] for f in folds] == [16.0 * k for k in range(-5, 6)]
    assert info["median_fold_height_um"] == np.median(expected)
    assert info["max_fold_height_um"] == 90.0
    for f in folds:  # the crest row holds the table's height
        row = round((f["crest_offset_um"] + 80.0) / 2.0)
        np.testing.assert_allclose(h[row], f["crest_height_um"], atol=EXACT)
    # a crest just outside the view is listed (its flank reaches in) but not counted
    _, info = fold_height_field(
        (81, 41),
        (2.0, 3.0),
        wavelength_um=16.0,
        orientation_deg=0.0,
        fold_heights_um=heights,
        phase_um=6.0,
    )
    outside = [f for f in info["folds"] if not f["in_view"]]
    assert [f["crest_offset_um"] for f in outside] == [86.0]
    assert info["n_folds_in_view"] == 10


def test_random_fold_heights_are_drawn_in_range_and_reported():
    kwargs = dict(wavelength_um=16.0, orientation_deg=0.0, fold_height_range_um=(80.0, 120.0))
    h, info = fold_height_field((81, 9), (2.0, 2.0), rng=5, **kwargs)
    crests = np.array([f["crest_height_um"] for f in info["folds"]])
    assert np.all((crests >= 80) & (crests < 120)) and np.unique(crests).size == crests.size
    np.testing.assert_allclose(h[40 + 8 * np.arange(-5, 6), 0], crests, atol=EXACT)
    assert info["median_fold_height_um"] == np.median(crests)
    again, _ = fold_height_field((81, 9), (2.0, 2.0), rng=5, **kwargs)
    other, _ = fold_height_field((81, 9), (2.0, 2.0), rng=6, **kwargs)
    np.testing.assert_array_equal(again, h)
    assert not np.allclose(other, h)
    _, wider = fold_height_field((161, 9), (2.0, 2.0), rng=5, **kwargs)
    by_index = {f["index"]: f["crest_height_um"] for f in wider["folds"]}
    assert all(by_index[f["index"]] == f["crest_height_um"] for f in info["folds"])


def test_roughness_has_the_requested_rms_and_correlation_length():
    kwargs = dict(wavelength_um=40.0, orientation_deg=30.0, fold_heights_um=[10.0, 20.0])
    smooth, _ = fold_height_field((256, 256), (1.0, 1.0), **kwargs)
    rough, info = fold_height_field(
        (256, 256), (1.0, 1.0), roughness_um=4.0, roughness_wavelength_um=10.0, rng=0, **kwargs
    )
    noise = rough - smooth
    assert noise.mean() == pytest.approx(0.0, abs=EXACT)
    assert np.sqrt(np.mean(noise**2)) == pytest.approx(4.0, rel=EXACT)
    assert info["roughness_um"] == 4.0
    # autocorrelation exp(-r^2 / l^2): 1/e at one correlation length
    lag = np.mean(noise[:, :-10] * noise[:, 10:]) / 16.0
    assert lag == pytest.approx(math.exp(-1), abs=STATISTICAL)


def test_orientation_and_wavelength_match_the_fourier_peak():
    """A field with a whole number of periods across the grid peaks at one exact bin."""
    ny, nx, dy, dx = 128, 256, 2.0, 1.5
    kx, ky = -4 / (nx * dx), 3 / (ny * dy)  # cycles per um, along the normal n
    wavelength = 1 / math.hypot(kx, ky)
    orientation = (math.degrees(math.atan2(ky, kx)) - 90.0) % 180.0
    h, info = fold_height_field(
        (ny, nx),
        (dy, dx),
        wavelength_um=wavelength,
        orientation_deg=orientation,
        fold_heights_um=50.0,
        phase_um=7.0,
        roughness_um=2.0,
        roughness_wavelength_um=6.0,
        rng=1,
    )
    spectrum = np.abs(np.fft.fft2(h - h.mean()))
    i, j = np.unravel_index(np.argmax(spectrum), spectrum.shape)
    fy, fx = np.fft.fftfreq(ny, dy)[i], np.fft.fftfreq(nx, dx)[j]
    assert 1 / math.hypot(fx, fy) == pytest.approx(info["wavelength_um"], rel=EXACT)
    measured = (math.degrees(math.atan2(fy, fx)) - 90.0) % 180.0
    assert measured == pytest.approx(info["orientation_deg"], abs=1e-9)


def test_fold_height_field_validates_its_arguments():
    good = dict(wavelength_um=10.0, orientation_deg=0.0, fold_heights_um=5.0)
    with pytest.raises(ValueError, match="exactly one"):
        fold_height_field((8, 8), (1.0, 1.0), **good, fold_height_range_um=(1, 2))
    with pytest.raises(ValueError, match="wavelength_um"):
        fold_height_field((8, 8), (1.0, 1.0), **{**good, "wavelength_um": 0})
    with pytest.raises(ValueError, match="fold_heights_um"):
        fold_height_field((8, 8), (1.0, 1.0), **{**good, "fold_heights_um": [-1.0]})
    with pytest.raises(ValueError, match="spacing_yx"):
        fold_height_field((8, 8), (1.0,), **good)
    with pytest.raises(ValueError, match="fold_height_range_um"):
        fold_height_field(
            (8, 8), (1.0, 1.0), wavelength_um=10.0, orientation_deg=0, fold_height_range_um=(3, 1)
        )


@pytest.mark.parametrize("name", ["before", "after"])
def test_urothelium_top_edge_lies_on_the_true_surface(name):
    dz = 4.0
    case = make_stack_case(name, size=48, spacing=(dz, 2.5, 2.5), read_noise=0, shot_gain=0, rng=3)
    uro = case.stack[:, 1].astype(float) - 100.0  # minus the background
    half = 0.5 * uro.max(axis=0)
    k = np.argmax(uro >= half, axis=0)  # first slice at or past half the plateau
    assert k.min() > 0
    i, j = np.indices(k.shape)
    before, after = uro[k - 1, i, j], uro[k, i, j]
    z50 = (k - 1 + (half - before) / (after - before)) * dz
    inner = (slice(3, -3), slice(3, -3))  # the lateral blur meets the border outside
    assert np.abs(z50 - case.depth_um)[inner].max() < EDGE_DZ * dz


def test_noise_free_intensities_are_the_analytic_profiles():
    """A flat surface: the urothelium plateau is I_u (Phi(t/2sz) - Phi(-t/2sz)) exp(-z/L_z),
    the lumen is the background, and the mean collagen signal follows its envelope."""
    dz, depth, sz, t = 2.5, 40.0, 3.0, 15.0
    stack = render_stack(
        np.full((96, 96), depth),
        n_slices=110,
        spacing=(dz, 2.5, 2.5),
        urothelium_intensity=2000.0,
        urothelium_contrast=0.0,
        axial_sigma_um=sz,
        shot_gain=0,
        read_noise=0,
        rng=0,
    )
    z_mid = depth + t / 2
    plateau = 2000.0 * (ndtr(t / 2 / sz) - ndtr(-t / 2 / sz)) * math.exp(-z_mid / 3000.0)
    np.testing.assert_allclose(stack[round(z_mid / dz), 1], round(plateau + 100.0))
    np.testing.assert_array_equal(stack[: round((depth - 8 * sz) / dz)], 100)
    e1, e2 = 60.0, 210.0  # below the urothelium's bottom edge
    m1, m2 = (stack[round((depth + t + e) / dz), 0].astype(float).mean() - 100.0 for e in (e1, e2))
    # f = max(g, 0) / 2 for unit Gaussian g has mean 1 / (2 sqrt(2 pi)); L = 150 um
    envelope = math.exp(-e1 / 150.0 + sz**2 / (2 * 150.0**2)) * ndtr(e1 / sz - sz / 150.0)
    expected = 2000.0 / (2 * math.sqrt(2 * math.pi)) * envelope * math.exp(-(depth + t + e1) / 3000)
    assert m1 == pytest.approx(expected, rel=STATISTICAL)
    expected = math.exp(-(e2 - e1) / 150.0) * math.exp(-(e2 - e1) / 3000.0)
    assert m2 / m1 == pytest.approx(expected, rel=STATISTICAL)


def test_noise_is_poisson_gaussian_on_the_noise_free_render():
    kwargs = dict(size=48, spacing=(4.0, 2.5, 2.5), fold_heights_um=50.0, rng=2)
    clean = make_stack_case("before", read_noise=0, shot_gain=0, **kwargs)
    noisy = make_stack_case("before", read_noise=4.0, shot_gain=8.0, **kwargs)
    np.testing.assert_array_equal(clean.depth_um, noisy.depth_um)
    lumen = noisy.stack[0].astype(float)  # 40 um above the crests: background only
    assert lumen.mean() == pytest.approx(100.0, abs=0.5)
    assert lumen.std() == pytest.approx(4.0, rel=STATISTICAL)
    signal = clean.stack.astype(float) - 100.0
    bright = signal > 1000
    residual = (noisy.stack.astype(float) - 100.0 - signal)[bright]
    variance = 16.0 + 8.0 * signal[bright]  # read^2 + gain * signal (counts^2)
    assert np.mean(residual**2 / variance) == pytest.approx(1.0, rel=STATISTICAL)


def test_case_geometry_and_slice_count():
    case = make_stack_case("before", size=32, spacing=(4.0, 5.0, 5.0), rng=1)
    spec = STACK_CASES["before"]
    dz = case.spacing[0]
    n_z = case.stack.shape[0]
    assert case.stack.shape == (n_z, 2, 32, 32) and case.stack.dtype == np.uint16
    assert case.depth_um.min() == pytest.approx(40.0, abs=EXACT)
    deepest = case.depth_um.max()
    assert (n_z - 1) * dz >= deepest + 60.0 > (n_z - 2) * dz  # the fewest slices that fit
    np.testing.assert_allclose(case.height_um, (n_z - 1) * dz - case.depth_um, atol=EXACT)
    assert case.info["wavelength_um"] == spec.wavelength_um
    assert case.info["orientation_deg"] == spec.orientation_deg
    lo, hi = spec.fold_height_range_um
    assert all(lo <= f["crest_height_um"] < hi for f in case.info["folds"])
    assert case.channel_names == ("collagen", "urothelium")
    assert "SyntheticStack('before'" in repr(case)
    with pytest.raises(ValueError, match=rf"n_slices=10 .* n_slices >= {n_z}"):
        make_stack_case("before", size=32, spacing=(4.0, 5.0, 5.0), n_slices=10, rng=1)
    more = make_stack_case("before", size=32, spacing=(4.0, 5.0, 5.0), n_slices=n_z + 5, rng=1)
    np.testing.assert_allclose(more.depth_um, case.depth_um)
    with pytest.raises(ValueError, match="unknown stack case"):
        make_stack_case("during")


@pytest.mark.parametrize("fmt", ["imagej", "ome"])
def test_written_stack_reads_back_with_axes_and_spacing(tmp_path, fmt):
    import tifffile

    case = make_stack_case(
        "before", size=24, spacing=(3.0, 2.0, 2.5), fold_heights_um=20.0, roughness_um=0, rng=0
    )
    path = tmp_path / ("s.tif" if fmt == "imagej" else "s.ome.tif")
    write_stack(path, case, format=fmt)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary left
    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        assert series.axes == "ZCYX"
        data = series.asarray()
        if fmt == "imagej":
            meta = tif.imagej_metadata
            assert meta["spacing"] == 3.0 and meta["unit"] == "um"
            assert meta["Labels"][:2] == ["collagen", "urothelium"]
            page = tif.pages[0]
            for tag, um in (("XResolution", 2.5), ("YResolution", 2.0)):
                num, den = page.tags[tag].value
                assert den / num == pytest.approx(um)
        else:
            pixels = tifffile.xml2dict(tif.ome_metadata)["OME"]["Image"]["Pixels"]
            assert (pixels["PhysicalSizeZ"], pixels["PhysicalSizeY"]) == (3.0, 2.0)
            assert pixels["PhysicalSizeX"] == 2.5 and pixels["PhysicalSizeXUnit"] == "µm"
            assert [c["Name"] for c in pixels["Channel"]] == ["collagen", "urothelium"]
    assert data.dtype == np.uint16
    np.testing.assert_array_equal(data, case.stack)
    with pytest.raises(ValueError, match="format"):
        write_stack(path, case, format="zarr")


def test_truth_files(tmp_path):
    case = make_stack_case("after", size=24, spacing=(4.0, 5.0, 5.0), rng=0)
    save_stack_truth(tmp_path / "after", case)
    truth = json.loads((tmp_path / "after_truth.json").read_text())
    assert truth["spacing_um"] == [4.0, 5.0, 5.0]
    assert truth["shape_zcyx"] == list(case.stack.shape)
    assert truth["wavelength_um"] == 450.0 and truth["orientation_deg"] == 80.0
    assert truth["folds"] == case.info["folds"]
    assert truth["median_fold_height_um"] == case.info["median_fold_height_um"]
    assert "sample_data_synth" in truth["software"]
    arrays = np.load(tmp_path / "after_truth.npz")
    assert arrays["depth_um"].dtype == np.float32
    np.testing.assert_allclose(arrays["depth_um"], case.depth_um, rtol=1e-6)
    np.testing.assert_allclose(arrays["height_um"], case.height_um, rtol=1e-6, atol=1e-4)


def test_cli_writes_stacks_and_truth(tmp_path, capsys):
    import tifffile

    out = tmp_path / "stacks"
    args = ["stack", "--case", "pair", "--size", "24", "--spacing", "4,5,5", "-q"]
    assert main([*args, "--out", str(out)]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        MARKER,
        "after.tif",
        "after_truth.json",
        "after_truth.npz",
        "before.tif",
        "before_truth.json",
        "before_truth.npz",
    ]
    with tifffile.TiffFile(out / "before.tif") as tif:
        assert tif.series[0].axes == "ZCYX" and tif.imagej_metadata["spacing"] == 4.0
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err and err.count("\n") == 1
    ome = ["stack", "--case", "after", "--size", "16", "--format", "ome", "-q"]
    assert main([*ome, "--out", str(out), "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        MARKER,
        "after.ome.tif",
        "after_truth.json",
        "after_truth.npz",
    ]
    bad = tmp_path / "bad"
    for argv in (
        ["--spacing", "4,5"],
        ["--spacing", "4,x,5"],
        ["--spacing", "0,5,5"],
        ["--case", "during"],
        ["--slices", "5"],
        ["--format", "zarr"],
    ):
        assert main(["stack", "--size", "16", "-q", *argv, "--out", str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
    assert not bad.exists()
    assert [p.name for p in tmp_path.iterdir()] == ["stacks"]  # no temporary folder left
    assert main(["list"]) == 0
    assert {"before", "after"} <= set(capsys.readouterr().out.split())


def test_import_stays_light():
    code = (
        "import sys, sample_data_synth; "
        "print(sorted(m for m in ('tifffile', 'strain2d', 'mpm3d', 'cv2', 'skimage') "
        "if m in sys.modules))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "[]"
