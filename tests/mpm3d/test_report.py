"""The pages ``analyze`` and ``compare`` write (``report.html``), the one height datum of
the height map, the mesh and both height figures, and the quality measures they report."""

import hashlib
import html
import json

import numpy as np
import pytest
import tifffile
from scipy import ndimage

from mpm3d.compare import align_heightmaps
from mpm3d.heightmap import otsu_separability
from mpm3d.report import METRICS
from mpm3d.surface import add_height, heightmap_mesh, mesh_quality
from tests.mpm3d.helpers import cli
from tests.report_browser import problems

# --------------------------------------------------------------------------- the datum


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_one_datum_in_the_mesh_the_height_map_and_the_truth(after_run):
    """The mesh's height_um, heightmap.tif and the true surface share one datum."""
    import pyvista as pv

    m, case = after_run["m"], after_run["case"]
    dz = case.spacing[0]
    datum = (case.stack.shape[0] - 1) * dz  # the deepest slice, below the first
    assert m["height_datum"]["depth_below_first_slice_um"] == pytest.approx(datum)
    vtp = pv.read(after_run["out"] / "surface.vtp")
    height = np.asarray(vtp.point_data["height_um"])
    np.testing.assert_allclose(height, datum - np.asarray(vtp.points[:, 2]), atol=1e-3)
    assert float(vtp.field_data["height_datum_depth_um"][0]) == pytest.approx(datum)
    assert str(vtp.field_data["length_unit"][0]) == "um"
    assert "deepest slice" in str(vtp.field_data["height_datum"][0])
    with tifffile.TiffFile(after_run["out"] / "heightmap.tif") as tif:
        hmap = tif.asarray()[0]
    truth = datum - case.depth_um
    # the highest and lowest points agree with each other and with the truth, to a z-step
    for values in (height, hmap):
        assert float(values.max()) == pytest.approx(float(truth.max()), abs=dz)
        assert float(values.min()) == pytest.approx(float(truth.min()), abs=dz)
    assert m["height_range_um"] == pytest.approx([float(hmap.min()), float(hmap.max())], abs=1e-3)
    assert m["mesh_height_range_um"] == pytest.approx(
        [float(height.min()), float(height.max())], abs=1e-3
    )
    # both figures draw on one colour range that covers the map and the mesh
    lo, hi = m["height_colour_range_um"]
    assert lo == pytest.approx(min(hmap.min(), height.min()), abs=1e-3)
    assert hi == pytest.approx(max(hmap.max(), height.max()), abs=1e-3)
    assert m["surface3d_rendering"]["colour_range_um"] == [lo, hi]


def test_height_figure_uses_the_colour_range_it_is_given():
    from mpm3d.figures import HEIGHT_LABEL, plot_height_map

    height = np.add.outer(np.arange(20.0), np.arange(30.0))  # 0 .. 48 um
    fig = plot_height_map(height, spacing=(2.0, 1.0), clim=(-5.0, 60.0))
    assert fig.axes[0].images[0].get_clim() == (-5.0, 60.0)
    assert fig.axes[1].get_ylabel() == HEIGHT_LABEL
    assert plot_height_map(height, spacing=(2.0, 1.0)).axes[0].images[0].get_clim() == (0, 48)


def test_height_figure_marks_the_crests_of_at_most_so_many_profiles():
    """A wide field's hundreds of profiles would cover the map with dots: every k-th
    profile's crests are marked, and the legend says so; a few profiles are all marked."""
    from mpm3d.figures import MAX_CREST_PROFILES, plot_height_map
    from mpm3d.metrics import FoldTable

    height = np.zeros((40, 50))
    for n_profiles in (5, 7 * MAX_CREST_PROFILES):
        profile = np.repeat(np.arange(n_profiles), 3)
        crests = {"profile": profile, "x_um": np.arange(profile.size) % 50.0,
                  "y_um": profile % 40.0}  # fmt: skip
        folds = FoldTable(crests=crests, folds={"x_um": [], "y_um": []}, profiles=[],
                          normal=np.array([1.0, 0.0]))  # fmt: skip
        ax = plot_height_map(height, spacing=(1.0, 1.0), folds=folds).axes[0]
        dots = ax.collections[0].get_offsets()
        label = ax.get_legend().get_texts()[0].get_text()
        if n_profiles == 5:
            assert len(dots) == 15 and label == "crest (one per profile)"
        else:
            assert len(dots) == 3 * MAX_CREST_PROFILES and "one profile in 7" in label


def test_rendering_colours_by_height_above_the_datum(tmp_path):
    """A plane sloping from 20 to 40 um deep, datum 100 um deep: heights 60 to 80 um."""
    depth = np.tile(np.linspace(20.0, 40.0, 12), (10, 1))
    mesh = heightmap_mesh(depth, spacing=(4.0, 5.0, 5.0))
    from mpm3d.figures import render_surface

    drawn = render_surface(mesh, tmp_path / "s.png", datum_depth_um=100.0, window_size=(400, 320))
    assert drawn["clim"] == pytest.approx((60.0, 80.0))
    assert drawn["scale_bar_um"] == 10.0  # 1, 2, 5 x 10^k, at most a quarter of 55 um
    assert (tmp_path / "s.png").stat().st_size > 1000


def test_add_height_on_a_known_plane():
    mesh = add_height(heightmap_mesh(np.full((3, 3), 12.5), spacing=(1.0, 1.0)), 40.0, datum="d")
    assert mesh.point_data["height_um"].tolist() == [27.5] * 9
    assert str(mesh.field_data["height_datum"][0]) == "d"


# --------------------------------------------------------------------------- quality measures


def test_otsu_separability_known_answers():
    assert otsu_separability(np.r_[np.zeros(30), np.full(70, 5.0)], 2.5) == pytest.approx(1.0)
    # a normal distribution split at its mean: eta = 2 / pi
    values = np.random.default_rng(0).normal(size=400_000)
    assert otsu_separability(values, 0.0) == pytest.approx(2 / np.pi, abs=0.005)
    assert np.isnan(otsu_separability(np.ones(10), 0.5))
    assert np.isnan(otsu_separability(np.arange(10.0), 100.0))  # one class empty


def test_mesh_quality_of_known_sheets():
    flat = heightmap_mesh(np.zeros((5, 7)), spacing=(2.0, 3.0))
    q = mesh_quality(flat, edge_um=1.0)
    assert (q["triangles"], q["points"], q["boundary_loops"], q["holes"]) == (48, 35, 1, 0)
    assert q["boundary_edges"] == 2 * (4 + 6) and q["non_manifold_edges"] == 0
    assert q["area_um2"] == pytest.approx(18.0 * 8.0) == q["projected_area_um2"]
    # a ramp of slope 0.75: area = projected area * sqrt(1 + 0.75^2) = 1.25 x
    ramp = heightmap_mesh(np.tile(0.75 * 3.0 * np.arange(7.0), (5, 1)), spacing=(2.0, 3.0))
    q = mesh_quality(ramp, edge_um=1.0)
    assert q["area_um2"] / q["projected_area_um2"] == pytest.approx(1.25)
    # two squares cut out apart from each other and from the edge: two holes
    big = heightmap_mesh(np.zeros((6, 8)), spacing=(1.0, 1.0))  # 5 x 7 squares
    square = [7 * 1 + 1, 7 * 3 + 4]  # rows 1 and 3, columns 1 and 4
    cells = [c + k * 35 for c in square for k in (0, 1)]
    q = mesh_quality(big.remove_cells(cells), edge_um=0.5)
    assert (q["holes"], q["boundary_loops"], q["triangles"]) == (2, 3, 66)


def test_alignment_residual_known_answers():
    rng = np.random.default_rng(3)
    rough = ndimage.gaussian_filter(rng.normal(size=(256, 256)), 4.0)
    other = ndimage.gaussian_filter(rng.normal(size=(256, 256)), 4.0)
    same = align_heightmaps(rough[20:220, 20:220], rough[27:227, 16:216], spacing=(2.0, 2.0))
    sq = float(np.std(rough))
    assert same["residual_rms_um"] < 0.02 * sq
    assert same["overlap_fraction"] == pytest.approx((200 - 7) * (200 - 4) / 200**2, abs=0.01)
    a, b = rough[20:220, 20:220], other[20:220, 20:220]
    apart = align_heightmaps(a, b, spacing=(2.0, 2.0))
    # unrelated surfaces: the residual is that of two independent maps, sqrt(Sq1^2 + Sq2^2)
    expected = float(np.hypot(np.std(a), np.std(b)))
    assert apart["residual_rms_um"] == pytest.approx(expected, rel=0.15)


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_dropouts_add_up_to_what_was_not_measured(after_run):
    q = after_run["m"]["quality"]
    assert sum(q["dropouts"].values()) == pytest.approx(1 - q["surface_coverage"], abs=1e-12)
    assert 0.5 < q["otsu_separability"] <= 1 and q["median_surface_cnr"] > 5
    mesh = q["mesh"]
    assert mesh["triangles"] == after_run["m"]["n_surface_triangles"]
    assert mesh["holes"] == 0 and mesh["boundary_loops"] == 1
    # the isosurface lies on the height map: half a z-step apart at most, on the median
    dz = after_run["case"].spacing[0]
    err = q["mesh_vs_heightmap_um"]
    assert err["median_abs"] < dz / 2 and err["median_abs"] <= err["p95_abs"] <= err["max_abs"]
    # the mesh's developed area ratio is the height map's Sdr, measured independently
    sdr = after_run["m"]["Sdr_percent"] / 100
    assert mesh["developed_area_ratio"] == pytest.approx(1 + sdr, rel=0.02)


# --------------------------------------------------------------------------- the pages


def _sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_report(after_run):
    out, m = after_run["out"], after_run["m"]
    page = (out / "report.html").read_text(encoding="utf-8")
    sha = _sha256(after_run["path"])
    assert m["inputs"][0]["sha256"] == sha and sha in page
    assert m["software"]["version"] in page
    for key, (what, unit) in METRICS.items():
        assert html.escape(what) in page and key in page, key
        assert f"<td>{html.escape(unit)}</td>" in page, key
    for text in ("surface coverage", "Otsu separability", "mesh holes", "deepest slice"):
        assert text in page, text
    assert "Nothing was flagged." in page
    assert page.count("<img ") == 4 and 'src="data:image/png;base64,' in page
    assert "<details>" in page  # provenance folded
    assert problems(out / "report.html") == []


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_report(compared, mpm_pair):
    out, report = compared["out"], compared["report"]
    page = (out / "report.html").read_text(encoding="utf-8")
    for side in ("before", "after"):
        assert _sha256(mpm_pair[side][0]) in page
        assert (out / side / "report.html").is_file()
    assert [r["sha256"] for r in report["inputs"]] == [
        _sha256(mpm_pair[s][0]) for s in ("before", "after")
    ]
    assert "residual after alignment" in page
    assert f"{report['alignment']['residual_rms_um']:.4g}" in page
    # different folds before and after: the page says the alignment did not match
    assert "the surfaces do not match" in page and "skipped: open3d" in page
    assert page.count("<img ") == 3  # the comparison and each side's height map
    assert problems(out / "report.html") == []


def test_warnings_are_flagged_in_metrics_and_report(mpm_small, tmp_path, capsys):
    case = mpm_small[1]
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, case.stack[:, 1], photometric="minisblack", metadata=None)
    out = tmp_path / "out"

    assert cli("analyze", plain, "--out", out, "--no-surface", "--no-figures", "-q") == 0
    assert "warning" in capsys.readouterr().err  # still shown on the command line
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    (warning,) = m["warnings"]
    assert "no voxel spacing" in warning
    page = (out / "report.html").read_text(encoding="utf-8")
    assert html.escape(warning) in page and "Nothing was flagged." not in page


def test_warnings_are_shown_when_the_analysis_then_fails(mpm_small, tmp_path, capsys):
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, mpm_small[1].stack[:, 1], photometric="minisblack", metadata=None)
    args = ("--no-surface", "--no-figures", "-q", "--threshold", "1e9")
    assert cli("analyze", plain, "--out", tmp_path / "out", *args) == 2
    warning, error = capsys.readouterr().err.splitlines()
    assert warning.startswith("mpm3d analyze: warning: ") and "no voxel spacing" in warning
    assert error.startswith("mpm3d analyze: error: ") and "no surface found" in error


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_report_shows_the_icp_residual(compared, tmp_path):
    """The page of a comparison refined by ICP (open3d) lists its fitness and residual."""
    from mpm3d.report import write_comparison_report

    report = json.loads((compared["out"] / "compare.json").read_text(encoding="utf-8"))
    report["alignment"]["icp"] = {
        "translation_um": [1.5, -2.0, 0.25],
        "rotation_deg": 0.125,
        "fitness": 0.375,
        "inlier_rmse_um": 3.625,
        "matched": False,
    }
    page = write_comparison_report(tmp_path, report).read_text(encoding="utf-8")
    assert "ICP fitness (share of points paired)</td><td>0.375<" in page
    assert "ICP residual: inlier RMSE (µm)</td><td>3.625<" in page
    assert "1.5, -2, 0.25; 0.125" in page
    assert "ICP: fitness below 0.5" in page  # flagged
    assert problems(tmp_path / "report.html") == []
