"""``python -m mpm3d analyze``: the files it writes against the synthetic stacks' truth,
its input formats, and every error a user can cause (exit 2, one line, no traceback)."""

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import tifffile

from sample_data_synth import make_stack_case, write_stack
from tests.mpm3d.helpers import TABLES, axis_diff, cli, listing, rel_err
from tests.tolerances import MPM_FOLD_RELATIVE, MPM_ORIENTATION_DEG, MPM_SURFACE_RMS_ZSTEPS
from tissue_core.outputs import MARKER

REPO = Path(__file__).resolve().parents[2]

#: every file of a full ``analyze`` and, for the PNGs, their size (rows, columns)
FIGURES = {
    "figures/heightmap.png": (572, 704),  # 6.4 x 5.2 in at 110 dpi
    "figures/profiles.png": (440, 770),  # 7.0 x 4.0 in
    "figures/spectrum.png": (528, 616),  # 5.6 x 4.8 in
    "figures/surface3d.png": (800, 1000),  # the render window
}
#: options for a quick, quiet run
FAST = ("--no-surface", "--no-figures", "-q")
FULL = TABLES | {"surface.vtp", "surface.ply", "figures", MARKER} | set(FIGURES)


def read_csv(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def assert_metrics_match(metrics: dict, case) -> None:
    info = case.info
    assert rel_err(metrics["fold_wavelength_um"], info["wavelength_um"]) < MPM_FOLD_RELATIVE
    assert rel_err(metrics["fold_height_um"], info["median_fold_height_um"]) < MPM_FOLD_RELATIVE
    assert rel_err(metrics["max_fold_height_um"], info["max_fold_height_um"]) < MPM_FOLD_RELATIVE
    assert axis_diff(metrics["fold_orientation_deg"], info["orientation_deg"]) < (
        MPM_ORIENTATION_DEG
    )


def assert_one_error_line(captured, *fragments: str, command: str = "analyze") -> str:
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert line.startswith(f"mpm3d {command}: error: "), line
    for fragment in fragments:
        assert fragment in line
    return line


# --------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A 96 x 96 px "before" stack as OME-TIFF, as a plain multipage TIFF, and its case."""
    folder = tmp_path_factory.mktemp("small")
    case = make_stack_case("before", size=96, spacing=(4.0, 5.0, 5.0), rng=1)
    ome = folder / "small.ome.tif"
    write_stack(ome, case, format="ome")
    plain = folder / "plain.tif"  # the urothelium channel, no metadata at all
    tifffile.imwrite(plain, case.stack[:, 1], photometric="minisblack")
    return {"case": case, "ome": ome, "plain": plain}


# --------------------------------------------------------------------------- analyze, full


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_writes_every_file_and_reports(after_run):
    out = after_run["out"]
    assert after_run["status"] == 0
    assert listing(out) == FULL
    # the scratch folder became the output: nothing left beside it
    assert [p.name for p in out.parent.iterdir()] == [out.name]
    err = after_run["stderr"].splitlines()
    assert "warning" not in after_run["stderr"] and "error" not in after_run["stderr"]
    assert err[-1].endswith(f"] results in {out}")
    assert f"] {after_run['path']}: folds: wavelength" in err[-2]
    assert all(line.startswith("[") for line in err)  # timestamped progress messages


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_metrics_match_the_truth(after_run):
    m, case = after_run["m"], after_run["case"]
    assert m["command"][:2] == ["mpm3d", "analyze"]  # the recorded command
    for key in (
        "fold_wavelength_um",
        "fold_height_um",
        "max_fold_height_um",
        "fold_orientation_deg",
        "fold_coherency",
        "Sa_um",
        "Sq_um",
        "Sz_um",
        "Sdr_percent",
        "spacing_um",
        "input",
        "software",
        "parameters",
    ):
        assert key in m, key
    assert m["input"] == "after.tif"
    assert m["software"]["version"]
    assert m["parameters"]["surface"] is True
    assert m["spacing_um"] == dict(zip("zyx", case.spacing, strict=True))
    assert m["spacing_source"] == "imagej"
    assert m["shape_zcyx"] == list(case.stack.shape)
    assert_metrics_match(m, case)
    assert m["n_folds"] == case.info["n_folds_in_view"]
    assert 0.9 < m["fold_coherency"] <= 1.0
    assert 0 < m["Sa_um"] < m["Sq_um"] < m["Sz_um"]
    assert m["Sdr_percent"] > 0


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_folds_match_the_true_folds(after_run):
    """folds.csv's ``offset_um`` and the truth's ``crest_offset_um`` share one convention:
    distance from the map centre along ``n = (-sin t, cos t)``, t the crest direction
    (mpm3d.metrics.fold_profiles and sample_data_synth.stacks.fold_height_field), so a
    fold matches the true crest nearest to it in signed offset."""
    case = after_run["case"]
    wavelength = case.info["wavelength_um"]
    truth = [f for f in case.info["folds"] if f["in_view"]]
    true_offsets = np.array([f["crest_offset_um"] for f in truth])
    rows = read_csv(after_run["out"] / "folds.csv")
    assert list(rows[0]) == [
        "fold",
        "offset_um",
        "x_um",
        "y_um",
        "n_profiles",
        "height_um",
        "height_max_um",
        "width_um",
    ]
    assert len(rows) == len(truth) == after_run["m"]["n_folds"]
    matched = []
    for row in rows:
        k = int(np.argmin(np.abs(true_offsets - float(row["offset_um"]))))
        assert abs(true_offsets[k] - float(row["offset_um"])) < MPM_FOLD_RELATIVE * wavelength
        assert rel_err(float(row["height_um"]), truth[k]["crest_height_um"]) < MPM_FOLD_RELATIVE
        matched.append(k)
    assert sorted(matched) == list(range(len(truth)))  # every true fold, once
    # the crest table: every crest lies on a true crest line
    crests = read_csv(after_run["out"] / "crests.csv")
    assert set(crests[0]) == {
        "profile",
        "x_um",
        "y_um",
        "offset_um",
        "height_um",
        "width_um",
        "sides",
    }
    assert len(crests) > len(rows)
    offsets = np.array([float(c["offset_um"]) for c in crests])
    assert np.all(np.abs(offsets[:, None] - true_offsets).min(axis=1) < 0.1 * wavelength)


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_heightmap_tiff(after_run):
    case = after_run["case"]
    dz, dy, dx = case.spacing
    with tifffile.TiffFile(after_run["out"] / "heightmap.tif") as tif:
        data = tif.asarray()
        ij = tif.imagej_metadata
        page = tif.pages[0]
        xres = page.tags["XResolution"].value
        yres = page.tags["YResolution"].value
    assert data.shape == (2, *case.depth_um.shape) and data.dtype == np.float32
    assert ij["unit"] == "um" and ij["Labels"] == ["height_um", "measured"]
    assert xres[1] / xres[0] == pytest.approx(dx) and yres[1] / yres[0] == pytest.approx(dy)
    true_height = (case.stack.shape[0] - 1) * dz - case.depth_um
    rms = float(np.sqrt(np.mean((data[0] - true_height) ** 2)))
    assert rms < MPM_SURFACE_RMS_ZSTEPS * dz
    measured = data[1]
    assert set(np.unique(measured)) <= {0.0, 1.0}
    assert measured.mean() == pytest.approx(after_run["m"]["surface_coverage"])


@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_surface_meshes(after_run):
    import pyvista as pv

    case = after_run["case"]
    dz, dy, dx = case.spacing
    vtp = pv.read(after_run["out"] / "surface.vtp")
    ply = pv.read(after_run["out"] / "surface.ply")
    assert vtp.n_cells > 1000 and vtp.is_all_triangles
    assert vtp.n_cells == after_run["m"]["n_surface_triangles"] == ply.n_cells
    np.testing.assert_allclose(ply.points, vtp.points, atol=1e-3)
    # points (x, y, depth) in um, inside the stack, spanning the true depths
    ny, nx = case.depth_um.shape
    lo, hi = np.asarray(vtp.bounds).reshape(3, 2).T
    assert lo[0] >= -dx and hi[0] <= nx * dx and lo[1] >= -dy and hi[1] <= ny * dy
    assert lo[2] >= 0 and hi[2] <= (case.stack.shape[0] - 1) * dz + 0.01  # float32 points
    depth = np.asarray(vtp.points[:, 2])
    assert depth.min() < case.depth_um.min() + 2 * dz
    assert depth.max() > case.depth_um.max() - 2 * dz
    low, high = np.percentile(depth, [0.5, 99.5])
    assert case.depth_um.min() - 2 * dz < low and high < case.depth_um.max() + 2 * dz


@pytest.mark.parametrize("name", sorted(FIGURES))
@pytest.mark.xdist_group("mpm3d_after_run")  # the session's analyze made once
def test_analyze_figures_are_drawn(after_run, name):
    from matplotlib.image import imread

    image = imread(after_run["out"] / name)
    assert image.shape[:2] == FIGURES[name]
    assert float(np.std(image[..., :3])) > 0.05  # not blank


# --------------------------------------------------------------------------- analyze, options


def test_analyze_without_surface_and_figures(mpm_pair, tmp_path, capsys):
    path, case = mpm_pair["before"]
    out = tmp_path / "before_out"
    assert cli("analyze", path, "--out", out, "--no-surface", "--no-figures") == 0
    assert listing(out) == TABLES | {MARKER}
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert m["input"] == "before.tif"
    assert m["n_surface_triangles"] is None and m["parameters"]["surface"] is False
    assert m["spacing_um"] == dict(zip("zyx", case.spacing, strict=True))
    assert_metrics_match(m, case)
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert lines[-1].endswith(f"] results in {out}")
    assert all(line.startswith("[") for line in lines)  # timestamped steps, then the summary
    assert "warning" not in captured.err


def test_analyze_ome_tiff(small, tmp_path, capsys):
    case = small["case"]
    out = tmp_path / "ome_out"
    assert cli("analyze", small["ome"], "--out", out, "--channel", "urothelium", *FAST) == 0
    assert capsys.readouterr().err == ""
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert m["spacing_source"] == "ome"
    assert m["spacing_um"] == dict(zip("zyx", case.spacing, strict=True))
    assert m["channel"] == "urothelium"  # the OME channel names are read
    assert m["input"] == "small.ome.tif"
    assert rel_err(m["fold_wavelength_um"], case.info["wavelength_um"]) < MPM_FOLD_RELATIVE


def test_plain_tiff_warns_once_about_the_spacing(small, tmp_path, capsys):
    out = tmp_path / "plain_out"
    assert cli("analyze", small["plain"], "--out", out, *FAST) == 0
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("mpm3d analyze: warning: ")
    assert "--spacing" in lines[0]
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert m["spacing_source"] == "none"
    assert m["spacing_um"] == {"z": 1.0, "y": 1.0, "x": 1.0}


def test_plain_tiff_with_spacing(small, tmp_path, capsys):
    case = small["case"]
    out = tmp_path / "plain_out"
    assert cli("analyze", small["plain"], "--out", out, "--spacing", "4,5,5", *FAST) == 0
    assert capsys.readouterr().err == ""
    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert m["spacing_source"] == "user"
    assert m["spacing_um"] == {"z": 4.0, "y": 5.0, "x": 5.0}
    assert m["channel"] == "0"
    assert rel_err(m["fold_wavelength_um"], case.info["wavelength_um"]) < MPM_FOLD_RELATIVE


def test_overwrite_replaces_an_earlier_result(small, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli("analyze", small["ome"], "--out", out, "--no-surface", "-q") == 0
    assert "figures" in listing(out)
    assert cli("analyze", small["ome"], "--out", out, "--overwrite", *FAST) == 0
    assert capsys.readouterr().err == ""
    assert listing(out) == TABLES | {MARKER}
    assert [p.name for p in tmp_path.iterdir()] == ["out"]  # no scratch or replaced folder


# --------------------------------------------------------------------------- errors


def _not_tiff(folder: Path) -> Path:
    path = folder / "notes.tif"
    path.write_text("not an image\n")
    return path


def _single_page(folder: Path) -> Path:
    path = folder / "slice.tif"
    tifffile.imwrite(path, np.arange(64, dtype=np.uint16).reshape(8, 8))
    return path


ERRORS = {
    # id: (stack maker, extra arguments, fragments of the one error line)
    "missing-file": (lambda f, s: f / "missing.tif", (), ("not found", "missing.tif")),
    "not-a-tiff": (lambda f, s: _not_tiff(f), (), ("cannot read", "notes.tif")),
    "2d-image": (lambda f, s: _single_page(f), (), ("2D image", "not a z-stack")),
    "channel-name": (
        lambda f, s: s["ome"],
        ("--channel", "nuclei"),
        ("'nuclei' not found", "collagen, urothelium"),
    ),
    "channel-index": (lambda f, s: s["ome"], ("--channel", "5"), ("channel 5 out of range",)),
    "no-surface": (lambda f, s: s["ome"], ("--threshold", "65535"), ("no surface found",)),
    "spacing": (lambda f, s: s["ome"], ("--spacing", "4,5"), ("--spacing", "'4,5'")),
    "decimate": (lambda f, s: s["ome"], ("--decimate", "1.5"), ("--decimate", "1.5")),
    "iso-bin": (lambda f, s: s["ome"], ("--iso-bin", "0"), ("--iso-bin", ">= 1")),
}


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_user_errors_give_one_line_and_exit_2(small, tmp_path, capsys, case):
    make, extra, fragments = ERRORS[case]
    stack = make(tmp_path, small)
    before = listing(tmp_path)
    out = tmp_path / "out"
    assert cli("analyze", stack, "--out", out, "-q", *extra) == 2
    assert_one_error_line(capsys.readouterr(), *fragments)
    assert listing(tmp_path) == before  # no output, no scratch folder left behind


def test_progress_then_one_error_line_without_quiet(small, tmp_path, capsys):
    assert cli("analyze", small["ome"], "--out", tmp_path / "out", "--threshold", "65535") == 2
    captured = capsys.readouterr()
    *progress, last = captured.err.splitlines()
    assert last.startswith(f"mpm3d analyze: error: {small['ome']}: no surface found")
    assert progress and all(line.startswith("[") for line in progress)
    assert "Traceback" not in captured.err


def test_existing_output_is_left_untouched(small, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    for flags in ([], ["--overwrite"]):  # not a result of the toolkit: never replaced
        assert cli("analyze", small["ome"], "--out", out, "-q", *flags) == 2
        assert_one_error_line(capsys.readouterr(), "not a result of this toolkit")
        assert listing(tmp_path) == {"out", "out/keep.txt"}
        assert (out / "keep.txt").read_text() == "mine"


@pytest.mark.parametrize("overwrite", [False, True])
@pytest.mark.parametrize("target", ["folder", "file"])
def test_output_never_replaces_the_input(small, tmp_path, capsys, target, overwrite):
    stack = tmp_path / "data" / "stack.ome.tif"
    stack.parent.mkdir()
    stack.write_bytes(small["ome"].read_bytes())
    out = stack.parent if target == "folder" else stack
    flags = ["--overwrite"] if overwrite else []
    assert cli("analyze", stack, "--out", out, "-q", *flags) == 2
    line = assert_one_error_line(capsys.readouterr())
    assert "would replace the input" in line
    assert listing(tmp_path) == {"data", "data/stack.ome.tif"}
    assert stack.read_bytes() == small["ome"].read_bytes()


def test_python_m_mpm3d_without_arguments():
    done = subprocess.run(
        [sys.executable, "-m", "mpm3d"], cwd=REPO, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 2
    assert done.stdout == ""
    assert done.stderr.strip().splitlines()[-1].startswith("mpm3d: error:")
    assert "Traceback" not in done.stderr


def test_finite_numbers_only(small, tmp_path, capsys):
    out = tmp_path / "out"
    assert cli("analyze", small["ome"], "--out", out, "--smooth", "nan") == 2
    assert_one_error_line(capsys.readouterr(), "--smooth", "finite")
    assert not out.exists()


def test_output_beside_the_stack_is_allowed(small, tmp_path, capsys):
    """The stack's folder is not an input folder: results may go next to the stack."""
    folder = tmp_path / "data"
    folder.mkdir()
    stack = folder / "stack.ome.tif"
    stack.write_bytes(small["ome"].read_bytes())
    out = folder / "stack_results"
    assert cli("analyze", stack, "--out", out, *FAST) == 0
    assert capsys.readouterr().err == ""
    assert (out / "metrics.json").is_file()
    assert stack.read_bytes() == small["ome"].read_bytes()
