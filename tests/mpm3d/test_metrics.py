import math

import numpy as np
import pytest

from mpm3d.errors import InputError
from mpm3d.heightmap import height_map
from mpm3d.io import read_stack, select_channel
from mpm3d.metrics import (
    detrend,
    fold_metrics,
    fold_orientation,
    fold_profiles,
    fold_spectrum,
    roughness,
)
from sample_data_synth import fold_height_field
from tests.mpm3d.helpers import axis_diff
from tests.tolerances import EXACT, MPM_FOLD_RELATIVE, MPM_ORIENTATION_DEG


def _wave(shape, spacing, *, crest_deg, wavelength, amplitude=1.0):
    dy, dx = spacing
    y, x = np.mgrid[0 : shape[0], 0 : shape[1]]
    t = math.radians(crest_deg)
    u = -x * dx * math.sin(t) + y * dy * math.cos(t)
    return amplitude * np.cos(2 * np.pi * u / wavelength)


def test_roughness_of_a_sinusoid_is_analytic():
    # an integer number of periods along x: the sample moments are exact
    a = 7.0
    h = _wave((40, 400), (1.0, 1.0), crest_deg=90, wavelength=50.0, amplitude=a)
    r = roughness(h, spacing=(1.0, 1.0))
    assert r["Sq_um"] == pytest.approx(a / math.sqrt(2), rel=1e-9)
    assert r["Sa_um"] == pytest.approx(2 * a / math.pi, rel=2e-3)  # sampled |cos|
    assert r["Ssk"] == pytest.approx(0.0, abs=1e-9)
    assert r["Sku"] == pytest.approx(1.5, rel=1e-9)
    assert r["Sz_um"] == pytest.approx(2 * a, rel=1e-9)
    assert r["Sp_um"] == pytest.approx(a, rel=1e-9) and r["Sv_um"] == pytest.approx(a, rel=1e-9)


@pytest.mark.parametrize("slope", [0.0, 0.3, 2.0])
def test_sdr_of_a_plane_is_its_area_ratio(slope):
    # unequal pixel sizes: a swapped dx / dy would change the answer
    rows, cols = np.mgrid[0:30, 0:40]
    y, x = rows * 3.0, cols * 2.0
    r = roughness(1.0 + slope * x - 0.5 * slope * y, spacing=(3.0, 2.0))
    assert r["Sdr_percent"] == pytest.approx(100 * (math.sqrt(1 + 1.25 * slope**2) - 1), abs=EXACT)


def test_detrend_removes_a_tilted_plane_and_keeps_the_rest():
    y, x = np.mgrid[0:50, 0:60] * 1.5
    bumps = _wave((50, 60), (1.5, 1.5), crest_deg=30, wavelength=15.0)
    z = detrend(4.0 + 0.2 * x - 0.7 * y + 0.01 * bumps, spacing=(1.5, 1.5))
    assert np.abs(z - 0.01 * (bumps - bumps.mean())).max() < 2e-3
    q = detrend(0.01 * x**2 + 0.02 * x * y, spacing=(1.5, 1.5), order=2)
    assert np.abs(q).max() < 1e-9
    with pytest.raises(InputError):
        detrend(x, spacing=(1.5, 1.5), order=3)


@pytest.mark.parametrize("crest_deg", [0.0, 17.0, 45.0, 90.0, 123.0, 170.0])
@pytest.mark.parametrize("wavelength", [23.3, 61.7])
def test_spectral_wavelength_and_orientation_off_the_grid(crest_deg, wavelength):
    spacing = (1.5, 2.0)
    h = _wave((150, 120), spacing, crest_deg=crest_deg, wavelength=wavelength, amplitude=3.0)
    s = fold_spectrum(h, spacing=spacing)
    assert s.wavelength_um == pytest.approx(wavelength, rel=2e-3)
    assert axis_diff(s.orientation_deg, crest_deg) < 0.2
    assert s.peak_fraction > 0.9


@pytest.mark.parametrize("crest_deg", [0.0, 35.0, 90.0, 145.0])
def test_structure_tensor_orientation_and_coherency(crest_deg):
    h = _wave((128, 128), (1.0, 1.0), crest_deg=crest_deg, wavelength=20.0)
    o, c = fold_orientation(h, spacing=(1.0, 1.0))
    assert axis_diff(o, crest_deg) < 0.5
    assert c > 0.98
    rng = np.random.default_rng(3)
    _, c_iso = fold_orientation(rng.normal(size=(128, 128)), spacing=(1.0, 1.0))
    assert c_iso < 0.1


def test_fold_profiles_give_each_folds_exact_height():
    heights = (80.0, 120.0, 95.0, 110.0, 70.0, 130.0)
    h, info = fold_height_field(
        (200, 240),
        (2.5, 2.5),
        wavelength_um=120.0,
        orientation_deg=70.0,
        fold_heights_um=heights,
    )
    table = fold_profiles(h, spacing=(2.5, 2.5), orientation_deg=70.0, wavelength_um=120.0)
    truth = {round(f["crest_offset_um"]): f["crest_height_um"] for f in info["folds"]}
    assert table.n_folds >= 4
    for offset, height in zip(table.folds["offset_um"], table.folds["height_um"], strict=True):
        nearest = min(truth, key=lambda u: abs(u - offset))
        assert abs(nearest - offset) < 2.5
        assert height == pytest.approx(truth[nearest], rel=0.01)


@pytest.mark.parametrize("name", ["before", "after"])
def test_fold_metrics_on_synthetic_stacks_match_the_truth(mpm_pair, name):
    path, case = mpm_pair[name]
    stack = read_stack(path)
    volume, _ = select_channel(stack)
    hm = height_map(volume, spacing=stack.spacing)
    m, _, table = fold_metrics(hm.height_um, spacing=stack.spacing, mask=hm.valid)
    info = case.info
    assert m["fold_wavelength_um"] == pytest.approx(info["wavelength_um"], rel=MPM_FOLD_RELATIVE)
    assert axis_diff(m["fold_orientation_deg"], info["orientation_deg"]) < MPM_ORIENTATION_DEG
    assert m["fold_coherency"] > 0.9
    # every fold the profiles measured has its true height; median and max follow
    truth = {f["crest_offset_um"]: f["crest_height_um"] for f in info["folds"]}
    matched = []
    for offset, height in zip(table.folds["offset_um"], table.folds["height_um"], strict=True):
        nearest = min(truth, key=lambda u: abs(u - offset))
        assert abs(nearest - offset) < 0.1 * info["wavelength_um"]
        assert height == pytest.approx(truth[nearest], rel=MPM_FOLD_RELATIVE)
        matched.append(truth[nearest])
    in_view = [f["crest_height_um"] for f in info["folds"] if f["in_view"]]
    assert len(matched) == len(in_view)
    assert m["fold_height_um"] == pytest.approx(
        info["median_fold_height_um"], rel=MPM_FOLD_RELATIVE
    )
    assert m["max_fold_height_um"] == pytest.approx(
        info["max_fold_height_um"], rel=MPM_FOLD_RELATIVE
    )
    # roughness parameters agree with those of the true surface
    t, _, _ = fold_metrics(case.height_um, spacing=stack.spacing)
    for key in ("Sa_um", "Sq_um", "Sz_um"):
        assert m[key] == pytest.approx(t[key], rel=MPM_FOLD_RELATIVE)
    assert m["Sdr_percent"] == pytest.approx(t["Sdr_percent"], rel=0.1)


def test_bad_arguments_are_named():
    h = np.zeros((20, 20))
    with pytest.raises(InputError, match="spacing"):
        roughness(h, spacing=(1.0, -1.0))
    with pytest.raises(InputError, match="wavelength_um"):
        fold_profiles(h, spacing=(1, 1), orientation_deg=0, wavelength_um=0)
    with pytest.raises(InputError, match="8 x 8"):
        fold_spectrum(np.zeros((4, 20)), spacing=(1, 1))


@pytest.mark.parametrize("phase", [0.0, 0.25])
def test_fold_heights_of_a_partial_period_ignore_the_specimens_tilt(phase):
    """1.6 periods of 400 um folds: a least-squares plane would tilt with the folds; the
    plane through the troughs does not, and a tilted specimen gives the same heights."""
    h, info = fold_height_field(
        (128, 128),
        (5.0, 5.0),
        wavelength_um=400.0,
        orientation_deg=85.0,
        fold_height_range_um=(80, 120),
        phase_um=phase * 400,
        roughness_um=4.0,
        rng=1,
    )
    y, x = np.mgrid[0:128, 0:128] * 5.0
    flat, _, _ = fold_metrics(h, spacing=(5.0, 5.0), resolution_um=4.0)
    tilted, _, _ = fold_metrics(h - 0.1 * x + 0.2 * y, spacing=(5.0, 5.0), resolution_um=4.0)
    for key in ("fold_height_um", "max_fold_height_um"):
        assert tilted[key] == pytest.approx(flat[key], rel=1e-6)
    assert flat["n_folds"] == info["n_folds_in_view"]
    truth = (info["median_fold_height_um"], info["max_fold_height_um"])
    assert flat["fold_height_um"] == pytest.approx(truth[0], rel=MPM_FOLD_RELATIVE)
    assert flat["max_fold_height_um"] == pytest.approx(truth[1], rel=MPM_FOLD_RELATIVE)
    assert flat["fold_wavelength_um"] is None and flat["fold_periods_in_view"] < 2


@pytest.mark.parametrize("rows", [1, 7, 1000])
def test_metrics_taken_in_bands_are_the_whole_maps(rows, monkeypatch):
    """Detrending, roughness and the structure tensor a band of rows at a time (the bands
    cut through the filters' reach) against the whole-map formulas."""
    from scipy import ndimage

    import mpm3d.metrics as metrics

    monkeypatch.setattr(metrics, "BAND_ROWS", rows)
    spacing = (1.5, 2.0)
    rng = np.random.default_rng(3)
    h = _wave((61, 47), spacing, crest_deg=35, wavelength=23.0, amplitude=4.0)
    h += 0.1 * rng.normal(size=h.shape) + 0.05 * np.arange(61)[:, None]
    mask = rng.random(h.shape) > 0.1
    # detrend: the least-squares plane over the mask
    y, x = np.mgrid[0:61, 0:47] * np.array(spacing)[:, None, None]
    basis = np.stack([np.ones(h.size), x.ravel(), y.ravel()], 1)
    coef, *_ = np.linalg.lstsq(basis[mask.ravel()], h.ravel()[mask.ravel()], rcond=None)
    z = detrend(h, spacing=spacing, mask=mask)
    assert np.abs(z - (h - (basis @ coef).reshape(h.shape))).max() < 1e-12
    # roughness
    r = roughness(z, spacing=spacing, mask=mask)
    v = z[mask] - z[mask].mean()
    assert r["Sq_um"] == pytest.approx(np.sqrt(np.mean(v**2)), rel=1e-12)
    assert r["Sku"] == pytest.approx(np.mean(v**4) / np.mean(v**2) ** 2, rel=1e-12)
    assert r["Sp_um"] == pytest.approx(v.max(), rel=1e-12)
    zx = ((z[:-1, 1:] - z[:-1, :-1]) + (z[1:, 1:] - z[1:, :-1])) / (2 * spacing[1])
    zy = ((z[1:, :-1] - z[:-1, :-1]) + (z[1:, 1:] - z[:-1, 1:])) / (2 * spacing[0])
    cells = mask[:-1, :-1] & mask[1:, :-1] & mask[:-1, 1:] & mask[1:, 1:]
    sdr = 100 * (np.sqrt(1 + zx[cells] ** 2 + zy[cells] ** 2).mean() - 1)
    assert r["Sdr_percent"] == pytest.approx(sdr, rel=1e-12)
    # the structure tensor of the smoothed map
    g = ndimage.gaussian_filter(z, (4.0 / 1.5, 4.0 / 2.0), mode="nearest")
    gy, gx = np.gradient(g, *spacing)
    jxx, jyy, jxy = (np.mean(a[mask]) for a in (gx * gx, gy * gy, gx * gy))
    o, c = fold_orientation(z, spacing=spacing, mask=mask)
    assert o == pytest.approx((0.5 * math.degrees(math.atan2(2 * jxy, jxx - jyy)) + 90) % 180)
    assert c == pytest.approx(math.hypot(jxx - jyy, 2 * jxy) / (jxx + jyy), rel=1e-12)
    # the work done in the caller's array gives the same metrics
    m1, _, _ = fold_metrics(h.copy(), spacing=spacing, mask=mask)
    m2, _, _ = fold_metrics(h.copy(), spacing=spacing, mask=mask, overwrite=True)
    assert m1 == m2


def test_kept_profiles_are_the_longest_and_carry_their_crests(mpm_pair, monkeypatch):
    """Each kept profile names its index in ``crests``: every crest of it lies on its
    samples (profiles that leave the map early are skipped, so the list's position is
    not the index), and the figure marks those crests on it."""
    import mpm3d.metrics as metrics
    from mpm3d.figures import plot_profiles

    path, _ = mpm_pair["after"]
    stack = read_stack(path)
    volume, _ = select_channel(stack)
    hm = height_map(volume, spacing=stack.spacing)
    _, _, table = fold_metrics(hm.height_um, spacing=stack.spacing, mask=hm.valid)
    kept = table.profiles
    assert 0 < len(kept) <= metrics.KEPT_PROFILES
    # the longest ones (the first of equal length), in their order
    monkeypatch.setattr(metrics, "KEPT_PROFILES", 10**6)
    _, _, every = fold_metrics(hm.height_um, spacing=stack.spacing, mask=hm.valid)
    assert len(every.profiles) > len(kept)
    ranked = sorted(every.profiles, key=lambda p: (-len(p["s_um"]), p["profile"]))
    longest = sorted(p["profile"] for p in ranked[: len(kept)])
    assert [p["profile"] for p in kept] == longest
    assert kept[0]["profile"] > 0  # the first offsets run off the map: skipped
    for p in kept:
        on = table.crests["profile"] == p["profile"]
        for x, y in zip(table.crests["x_um"][on], table.crests["y_um"][on], strict=True):
            assert np.min(np.hypot(p["x_um"] - x, p["y_um"] - y)) < 1e-9
    # the figure: each drawn profile, then its crests' markers
    lines = plot_profiles(table).axes[0].get_lines()
    drawn = 0
    for line, markers in zip(lines[::2], lines[1::2], strict=True):
        p = next(p for p in kept if np.array_equal(p["s_um"], line.get_xdata()))
        assert line.get_label() == f"profile {p['profile']}"
        on = table.crests["profile"] == p["profile"]
        assert on.any() and np.array_equal(markers.get_xdata(), table.crests["offset_um"][on])
        drawn += 1
    assert drawn == 3
