"""``python -m mpm3d compare`` and its parts: the report against the synthetic stacks' truth,
height-map alignment against known shifts, metric changes, and the optional ICP (open3d)."""

import json
import math
import sys

import numpy as np
import pytest
import tifffile
from scipy import ndimage

from mpm3d.compare import COMPARED, align_heightmaps, icp_refine, metric_changes
from mpm3d.errors import InputError
from tests.mpm3d.helpers import TABLES, axis_diff, cli, listing, rel_err
from tests.tolerances import MPM_FOLD_RELATIVE, MPM_ORIENTATION_DEG, MPM_SHIFT_PX
from tissue_core.outputs import MARKER

#: one side's analysis without the surface (the comparison needs only the height maps)
SIDE = TABLES | {"figures"} | {f"figures/{n}.png" for n in ("heightmap", "profiles", "spectrum")}


@pytest.fixture
def no_open3d(monkeypatch):
    """Make ``import open3d`` fail, whether or not it is installed."""
    monkeypatch.setitem(sys.modules, "open3d", None)


# --------------------------------------------------------------------------- compare command


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_writes_every_file(compared):
    out = compared["out"]
    assert compared["status"] == 0
    assert compared["stderr"] == ""  # -q: no progress, and no warning
    expected = {"compare.json", "changes.csv", "report.html", "figures"}
    expected.add("figures/compare_heightmaps.png")
    for side in ("before", "after"):
        expected |= {side} | {f"{side}/{name}" for name in SIDE}
    assert listing(out) == expected | {MARKER}
    assert [p.name for p in out.parent.iterdir()] == [out.name]


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_report_holds_both_analyses(compared, mpm_pair):
    report, out = compared["report"], compared["out"]
    assert {"before", "after", "alignment", "changes"} <= set(report)
    for side in ("before", "after"):
        saved = json.loads((out / side / "metrics.json").read_text(encoding="utf-8"))
        assert report[side] == saved
        assert saved["input"] == f"{side}.tif"
        case = mpm_pair[side][1]
        info = case.info
        assert rel_err(saved["fold_wavelength_um"], info["wavelength_um"]) < MPM_FOLD_RELATIVE
        assert rel_err(saved["fold_height_um"], info["median_fold_height_um"]) < (MPM_FOLD_RELATIVE)
        assert axis_diff(saved["fold_orientation_deg"], info["orientation_deg"]) < (
            MPM_ORIENTATION_DEG
        )
        assert saved["n_surface_triangles"] is None


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_changes_are_after_minus_before(compared):
    report, rows = compared["report"], compared["rows"]
    assert [row["metric"] for row in rows] == list(COMPARED)
    assert [row["metric"] for row in report["changes"]] == list(COMPARED)
    for row, entry in zip(rows, report["changes"], strict=True):
        key = row["metric"]
        before, after = report["before"][key], report["after"][key]
        assert entry["before"] == before and entry["after"] == after
        assert float(row["before"]) == before and float(row["after"]) == after
        change = after - before
        if key == "fold_orientation_deg":
            assert abs(change) < 90.0  # 85 -> 80 deg: no wrap here (see test_orientation_...)
            assert row["ratio"] == "" and entry["ratio"] is None
        else:
            assert float(row["ratio"]) == pytest.approx(after / before, rel=1e-12)
        assert float(row["change"]) == pytest.approx(change, rel=1e-12, abs=1e-12)
        assert entry["change"] == pytest.approx(change, rel=1e-12, abs=1e-12)
    by_key = {row["metric"]: float(row["change"]) for row in rows}
    assert by_key["fold_wavelength_um"] > 0 and by_key["fold_height_um"] > 0  # contracted
    assert by_key["n_folds"] == report["after"]["n_folds"] - report["before"]["n_folds"]


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_alignment_skips_icp_without_open3d(compared):
    alignment = compared["report"]["alignment"]
    assert set(alignment) == {
        "shift_x_um",
        "shift_y_um",
        "overlap_correlation",
        "overlap_fraction",
        "residual_rms_um",
        "icp",
        "matched",
        "note",
    }
    assert alignment["icp"].startswith("skipped") and "open3d" in alignment["icp"]
    assert all(math.isfinite(alignment[k]) for k in ("shift_x_um", "shift_y_um"))
    # different folds before and after: little in common
    assert -1.0 <= alignment["overlap_correlation"] < 0.5
    assert alignment["matched"] is False and "not meaningful" in alignment["note"]


@pytest.mark.xdist_group("mpm3d_compared")  # the session's compare made once
def test_compare_figure(compared):
    from matplotlib.image import imread

    image = imread(compared["out"] / "figures" / "compare_heightmaps.png")
    assert image.shape[:2] == (528, 1210)  # 11.0 x 4.8 in at 110 dpi
    assert float(np.std(image[..., :3])) > 0.05


def test_icp_on_without_open3d_fails_before_measuring(mpm_pair, tmp_path, capsys, no_open3d):
    out = tmp_path / "cmp"
    args = ("compare", mpm_pair["before"][0], mpm_pair["after"][0], "--out", out)
    assert cli(*args, "--icp", "on") == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    # no progress line either: it fails before the stacks are read
    assert captured.err.splitlines() == [
        "mpm3d compare: error: ICP refinement needs open3d: pip install "
        "'tissue-strain[3d]' (and the system library libusb-1.0-0)"
    ]
    assert list(tmp_path.iterdir()) == []


def test_icp_on_needs_the_surfaces(mpm_pair, tmp_path, capsys):
    out = tmp_path / "cmp"
    args = ("compare", mpm_pair["before"][0], mpm_pair["after"][0], "--out", out)
    assert cli(*args, "--icp", "on", "--no-surface") == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("mpm3d compare: error: ")
    assert "--no-surface" in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_icp_refine_names_the_extra(no_open3d):
    with pytest.raises(InputError, match=r"tissue-strain\[3d\]"):
        icp_refine(None, None, shift_xy_um=(0.0, 0.0))


def _uniform(folder):
    path = folder / "uniform.tif"
    metadata = {"axes": "ZCYX", "spacing": 4.0, "unit": "um"}
    tifffile.imwrite(
        path,
        np.full((8, 2, 16, 16), 7, np.uint16),
        imagej=True,
        resolution=(0.2, 0.2),
        metadata=metadata,
    )
    return path


def _truncated(folder, source):
    path = folder / "cut.tif"
    raw = source.read_bytes()
    path.write_bytes(raw[: int(0.6 * len(raw))])
    return path


def _flat_image(folder):
    path = folder / "slice.tif"
    tifffile.imwrite(path, np.zeros((16, 16), np.uint16))
    return path


#: id: (which side is bad, its maker, extra options, fragments of the error line)
SIDE_ERRORS = {
    "before-missing": ("before", lambda f, s: f / "gone.tif", (), ["not found"]),
    "after-missing": ("after", lambda f, s: f / "gone.tif", (), ["not found"]),
    "after-truncated": ("after", _truncated, (), ["truncated"]),
    "after-uniform": ("after", lambda f, s: _uniform(f), (), ["the stack is uniform"]),
    "after-2d": ("after", lambda f, s: _flat_image(f), (), ["2D image"]),
    "before-threshold": ("before", None, ("--threshold", "65535"), ["no surface found"]),
    "before-channel": ("before", None, ("--channel", "7"), ["channel 7 out of range"]),
}


@pytest.mark.parametrize("case", sorted(SIDE_ERRORS))
def test_compare_errors_name_the_stack(mpm_small, tmp_path, capsys, case):
    """The same options go to two stacks: an error must say which one it is about."""
    side, make, extra, fragments = SIDE_ERRORS[case]
    good = mpm_small[0]
    bad = good if make is None else make(tmp_path, good)
    before, after = (bad, good) if side == "before" else (good, bad)
    out = tmp_path / "cmp"
    assert (
        cli("compare", before, after, "--out", out, "--no-surface", "--no-figures", "-q", *extra)
        == 2
    )
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    line = lines[0]
    assert line.startswith(f"mpm3d compare: error: {side} stack"), line
    assert str(bad) in line, line
    for fragment in fragments:
        assert fragment in line, line
    assert not out.exists()


def test_compare_big_endian_with_itself(mpm_small, tmp_path, capsys):
    """A stack and its big-endian copy (ImageJ's default): the same surface, no change."""
    path, case = mpm_small
    dz, dy, dx = case.spacing
    big = tmp_path / "big-endian.tif"
    tifffile.imwrite(
        big,
        case.stack,
        imagej=True,
        byteorder=">",
        resolution=(1 / dx, 1 / dy),
        metadata={"axes": "ZCYX", "spacing": dz, "unit": "um"},
    )
    out = tmp_path / "cmp"
    assert cli("compare", path, big, "--out", out, "--no-surface", "--no-figures", "-q") == 0
    assert capsys.readouterr().err == ""
    report = json.loads((out / "compare.json").read_text(encoding="utf-8"))
    for row in report["changes"]:
        assert row["change"] in (0, None), row
    alignment = report["alignment"]
    assert alignment["shift_x_um"] == pytest.approx(0, abs=MPM_SHIFT_PX * dx)
    assert alignment["shift_y_um"] == pytest.approx(0, abs=MPM_SHIFT_PX * dy)
    assert alignment["overlap_correlation"] > 0.999


def test_compare_warnings_name_the_stack(mpm_small, tmp_path, capsys):
    path, case = mpm_small
    plain = tmp_path / "plain.tif"
    tifffile.imwrite(plain, case.stack[:, 1], photometric="minisblack", metadata=None)
    out = tmp_path / "cmp"
    args = ("compare", path, plain, "--out", out, "--channel", "0", "--no-surface", "--no-figures")
    assert cli(*args, "-q") == 0
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"mpm3d compare: warning: after stack: {plain}: no voxel spacing")


# --------------------------------------------------------------------------- alignment


def _rough(shape=(256, 256), sigma=4.0, seed=0):
    return ndimage.gaussian_filter(np.random.default_rng(seed).normal(size=shape), sigma)


@pytest.mark.parametrize("surface", ["before-truth", "after-truth", "rough"])
def test_align_recovers_an_integer_shift(mpm_pair, surface):
    if surface == "rough":
        height, spacing = _rough(), (3.0, 2.0)
    else:
        case = mpm_pair[surface.split("-")[0]][1]
        height, spacing = case.height_um, case.spacing[1:]
    # the "after" window starts 7 rows lower and 4 columns to the left, so the surface
    # in it appears 7 rows higher and 4 columns further right: moved by (-7, +4) px
    before = height[20:220, 20:220]
    after = height[27:227, 16:216]
    a = align_heightmaps(before, after, spacing=spacing)
    dy, dx = spacing
    assert a["shift_y_um"] == pytest.approx(-7 * dy, abs=MPM_SHIFT_PX * dy)
    assert a["shift_x_um"] == pytest.approx(4 * dx, abs=MPM_SHIFT_PX * dx)
    assert a["overlap_correlation"] > 0.95


@pytest.mark.parametrize("shift", [(2.3, -1.6), (-0.45, 0.8), (3.65, 3.15), (-2.85, -3.4)])
def test_align_recovers_a_subpixel_shift(shift):
    height = _rough(sigma=5.0)
    moved = ndimage.shift(height, shift, order=3, mode="nearest")
    inner = (slice(32, -32), slice(32, -32))
    spacing = (3.0, 2.0)
    a = align_heightmaps(height[inner], moved[inner], spacing=spacing)
    assert a["shift_y_um"] / spacing[0] == pytest.approx(shift[0], abs=MPM_SHIFT_PX)
    assert a["shift_x_um"] / spacing[1] == pytest.approx(shift[1], abs=MPM_SHIFT_PX)
    assert a["overlap_correlation"] > 0.99


def test_align_needs_maps_of_one_shape():
    with pytest.raises(InputError, match="differ in shape"):
        align_heightmaps(np.zeros((8, 8)), np.zeros((8, 9)), spacing=(1.0, 1.0))


# --------------------------------------------------------------------------- metric changes


def _row(rows, key):
    (row,) = [r for r in rows if r["metric"] == key]
    return row


@pytest.mark.parametrize(
    ("before", "after", "change"),
    [
        (170.0, 10.0, 20.0),
        (10.0, 170.0, -20.0),
        (85.0, 80.0, -5.0),
        (45.0, 45.0, 0.0),
        (0.0, 179.5, -0.5),
        (0.0, 90.0, 90.0),  # a quarter turn either way: (-90, 90] takes +90
        (100.0, 10.0, 90.0),
        (30.0, 110.0, 80.0),
    ],
)
def test_orientation_change_wraps(before, after, change):
    rows = metric_changes({"fold_orientation_deg": before}, {"fold_orientation_deg": after})
    row = _row(rows, "fold_orientation_deg")
    assert row["change"] == pytest.approx(change, abs=1e-9)
    assert -90.0 < row["change"] <= 90.0
    assert row["ratio"] is None  # an angle has no meaningful ratio


def test_metric_changes_on_hand_made_metrics():
    before = {"fold_wavelength_um": 200.0, "Sa_um": 0.0, "fold_height_um": None, "n_folds": 3}
    after = {"fold_wavelength_um": 450.0, "Sa_um": 5.0, "fold_height_um": 90.0, "n_folds": 5}
    rows = metric_changes(before, after)
    assert [r["metric"] for r in rows] == list(COMPARED)
    assert _row(rows, "fold_wavelength_um") == {
        "metric": "fold_wavelength_um",
        "before": 200.0,
        "after": 450.0,
        "change": 250.0,
        "ratio": 2.25,
    }
    sa = _row(rows, "Sa_um")
    assert sa["change"] == 5.0 and sa["ratio"] is None  # no ratio to zero
    height = _row(rows, "fold_height_um")
    assert height["before"] is None and height["after"] == 90.0  # None passes through
    assert height["change"] is None and height["ratio"] is None
    folds = _row(rows, "n_folds")
    assert folds["change"] == 2 and folds["ratio"] == pytest.approx(5 / 3)
    ssk = _row(rows, "Ssk")  # absent from both
    assert ssk == {"metric": "Ssk", "before": None, "after": None, "change": None, "ratio": None}
