"""Stacks that are not the happy case: no surface, flat or tilted surfaces, a surface cut
off by the stack, NaN voxels, a tiny field.  Each must give an honest answer or one
clear error, never a made-up fold."""

import numpy as np
import pytest

from mpm3d.analyze import analyze_stack
from mpm3d.errors import InputError, NoDataWarning, SurfaceOutsideWarning
from mpm3d.io import Stack

DZ = 4.0


def _stack(volume: np.ndarray, spacing=(DZ, 2.5, 2.5)) -> Stack:
    return Stack(
        data=volume[:, None],
        spacing=spacing,
        spacing_source="user",
        channel_names=("0",),
        path="synthetic.tif",
        axes="ZYX",
    )


def _slab(depth_um: np.ndarray, nz: int, rng=0, noise=20.0) -> np.ndarray:
    """Bright tissue below ``depth_um`` (blurred edge), dark lumen above, Gaussian noise."""
    z = (np.arange(nz) * DZ)[:, None, None]
    vol = 100 + 2000 / (1 + np.exp(-(z - depth_um[None]) / 1.5))
    return (vol + np.random.default_rng(rng).normal(0, noise, vol.shape)).astype(np.float32)


def test_pure_noise_has_no_surface():
    vol = np.random.default_rng(0).normal(500, 50, (40, 64, 64)).astype(np.float32)
    with pytest.raises(InputError, match="no surface found"):
        analyze_stack(_stack(vol), surface=False)


@pytest.mark.parametrize("slope", [0.0, 0.3])
def test_flat_and_tilted_surfaces_have_no_folds(slope):
    _, x = np.mgrid[0:96, 0:96] * 2.5
    a = analyze_stack(_stack(_slab(60.0 + slope * x, 60)), surface=False)
    m = a.metrics
    assert m["n_folds"] == 0
    assert m["fold_wavelength_um"] is None and m["fold_height_um"] is None
    assert m["Sq_um"] < 1.0  # the plane is removed; what is left is noise and the z-step


def test_a_surface_above_the_stack_is_flagged_not_measured():
    _, x = np.mgrid[0:64, 0:64] * 2.5
    depth = 40.0 + 60.0 * np.cos(2 * np.pi * x / 80.0)  # crests above slice 0
    with pytest.warns(SurfaceOutsideWarning, match="above the first slice"):
        a = analyze_stack(_stack(_slab(depth, 60)), surface=False)
    cut = depth < 0
    assert a.metrics["surface_cut_fraction"] == pytest.approx(cut.mean(), abs=0.05)
    assert not a.heightmap.valid[cut].any()


def test_nan_voxels_do_not_reach_the_mesh():
    _, x = np.mgrid[0:64, 0:64] * 2.5
    vol = _slab(80.0 + 20 * np.sin(2 * np.pi * x / 60.0), 50)
    vol[10:30, 20:30, 20:30] = np.nan
    with pytest.warns(NoDataWarning, match="count as lumen"):
        a = analyze_stack(_stack(vol), iso_bin=1)
    assert np.isfinite(a.surface.points).all()
    assert a.surface.n_cells > 1000


def test_a_field_smaller_than_a_wavelength_reports_no_wavelength():
    _, x = np.mgrid[0:16, 0:16] * 2.5  # 40 um wide
    a = analyze_stack(_stack(_slab(80.0 + 30 * np.sin(2 * np.pi * x / 200.0), 50)), surface=False)
    assert a.metrics["fold_wavelength_um"] is None
    assert np.isfinite(a.metrics["Sq_um"])


@pytest.mark.parametrize(
    "phase",
    [
        pytest.param(0.0, id="one-whole-fold"),  # a crest in the middle, a trough at each side
        pytest.param(0.5, id="two-half-folds"),  # two crests seen from their one shared trough
    ],
)
def test_fewer_than_two_periods_still_give_the_fold_heights(tmp_path, phase):
    """400 um folds in a 640 um field (1.6 periods): the heights of the folds in view are
    measured; the wavelength is not, and metrics.json says why."""
    import json

    from sample_data_synth import make_stack_case, write_stack
    from tests.mpm3d.helpers import cli, rel_err
    from tests.tolerances import MPM_FOLD_RELATIVE

    case = make_stack_case(
        "before",
        size=128,
        spacing=(4.0, 5.0, 5.0),
        wavelength_um=400.0,
        phase_um=phase * 400,
        rng=1,
    )
    path = tmp_path / "partial.tif"
    write_stack(path, case)
    out = tmp_path / "out"
    assert cli("analyze", path, "--out", out, "--no-surface", "--no-figures", "-q") == 0
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    info = case.info
    assert m["n_folds"] == info["n_folds_in_view"] == (1 if phase == 0 else 2)
    assert rel_err(m["fold_height_um"], info["median_fold_height_um"]) < MPM_FOLD_RELATIVE
    assert rel_err(m["max_fold_height_um"], info["max_fold_height_um"]) < MPM_FOLD_RELATIVE
    assert m["fold_wavelength_um"] is None
    assert 1.5 < m["fold_periods_in_view"] < 2.0
    assert m["fold_wavelength_note"].startswith("not measured: about 1.7 fold periods in view")
