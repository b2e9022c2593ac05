"""``surface_strain compute``'s report.html and the quality of the measurement, on tracks whose
losses, coverage, inverted triangles and reprojection errors are known by construction."""

import csv
import hashlib
import json
import math

import numpy as np
import pytest

from surface_strain import compute_strain, grid_triangles, measurement_quality
from surface_strain.cli import main
from surface_strain.figures import plot_strain_curves, plot_tracking_quality
from tests.report_browser import problems

#: radius ratio 2 r_in / r_circ of half a square (a right isosceles triangle)
HALF_SQUARE = 2 * math.sqrt(2) - 2
LAM = (1.0, 1.1, 1.2, 1.3)  # stretch along X per frame


def _sheet():
    """A flat 5x5 grid (spacing 2) stretched along X; row 0 lost on frame 2; mirrored on frame 3.

    The mirror x -> -x is a reflection after the stretch: C = F^T F is that of the stretch
    (Exx = (1.3^2 - 1) / 2, Eyy = Exy = 0) but every triangle is turned inside out.
    Reprojection error 0.01 (t + 1) + 0.001 i for point i on frame t.
    """
    u, v = np.meshgrid(np.arange(5) * 2.0, np.arange(5) * 2.0)
    ref = np.column_stack([u.ravel() - 4, v.ravel() - 4, np.full(25, 100.0)])
    points = np.stack([ref * [lam, 1, 1] for lam in LAM])
    points[3, :, 0] *= -1
    visible = np.ones((4, 25), bool)
    visible[2, :5] = False
    reproj = 0.01 * (np.arange(4)[:, None] + 1) + 0.001 * np.arange(25)[None, :]
    return ref, points, visible, reproj


def _write(path, points, visible, reproj):
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "point", "X", "Y", "Z", "reproj_error", "visible"])
        for t in range(points.shape[0]):
            for i in range(points.shape[1]):
                xyz = points[t, i] if visible[t, i] else ["", "", ""]
                w.writerow([t, i, *xyz, reproj[t, i], int(visible[t, i])])


def test_quality_of_a_sheet_with_known_losses_and_a_mirror_image():
    ref, points, visible, reproj = _sheet()
    tri = grid_triangles(5, 5)
    field = compute_strain(ref, points, tri, visible=visible)
    q = measurement_quality(field, n_mesh_triangles=34, point_quality={"reproj_error": reproj})
    m = q["mesh"]
    assert m["n_triangles"] == 32 and m["excluded"] == 2 and m["slivers"] == 0
    assert m["quality_min"] == pytest.approx(HALF_SQUARE, abs=1e-12)
    assert m["quality_median"] == pytest.approx(HALF_SQUARE, abs=1e-12)
    assert m["reference_area"] == pytest.approx(64.0, abs=1e-12)
    assert q["visible_fraction"] == [1.0, 1.0, 0.8, 1.0]
    # losing the first row of points takes its row of cells: 8 of 32 equal triangles
    assert q["surface_coverage"] == pytest.approx([1.0, 1.0, 0.75, 1.0], abs=1e-12)
    assert q["inverted_triangles"] == [0, 0, 0, 32]
    pq = q["point_quality"]["reproj_error"]
    # medians over the visible points: i = 12 (all), i = 14.5 on frame 2 (points 5..24)
    want = [0.01 * (t + 1) + 0.001 * (14.5 if t == 2 else 12) for t in range(4)]
    assert pq["median_per_frame"] == pytest.approx(want, abs=1e-12)
    assert pq["worst"] == pytest.approx(0.04 + 0.024, abs=1e-12) and pq["n"] == 95
    assert pq["unit"] == "px"


def test_time_axes_say_seconds_when_a_frame_rate_is_known():
    ref, points, *_ = _sheet()
    field = compute_strain(ref, points[:3], grid_triangles(5, 5))
    assert plot_strain_curves(field, fps=4).axes[0].get_xlabel() == "time (s)"
    assert plot_strain_curves(field, times=[0, 0.5, 1], time_unit="s").axes[0].get_xlabel() == (
        "time (s)"
    )
    assert plot_strain_curves(field).axes[0].get_xlabel() == "frame"
    fig = plot_tracking_quality([1, 1, 0.8], [1, 1, 0.75], fps=4)
    np.testing.assert_allclose(fig.axes[0].lines[0].get_xdata(), [0, 0.25, 0.5])
    assert fig.axes[0].get_xlabel() == "time (s)"
    with pytest.raises(ValueError, match="one value per frame"):
        plot_strain_curves(field, times=[0, 1])


def test_compute_writes_a_self_contained_report(tmp_path):
    _, points, visible, reproj = _sheet()
    rec = tmp_path / "rec"
    rec.mkdir()
    src = rec / "points3d.csv"
    _write(src, points, visible, reproj)
    (rec / "summary.json").write_text(json.dumps({"unit": "mm", "points": {"grid": [5, 5]}}))
    out = tmp_path / "out"
    assert main(["compute", str(src), "--fps", "4", "--out", str(out), "-q"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    files = {r["path"]: r for r in summary["input_files"]}
    assert files[str(src)]["sha256"] == hashlib.sha256(src.read_bytes()).hexdigest()
    assert str(rec / "summary.json") in files
    assert summary["unit"] == "mm" and summary["unit_source"] == "given"
    q = summary["quality"]
    assert q["surface_coverage"] == pytest.approx([1.0, 1.0, 0.75, 1.0], abs=1e-12)
    assert q["inverted_triangles"] == [0, 0, 0, 32]
    stats = summary["last_frame_statistics"]
    assert stats["Exx"]["mean"] == pytest.approx((1.3**2 - 1) / 2, abs=1e-12)
    assert stats["Eyy"]["max"] == pytest.approx(0.0, abs=1e-12)
    assert stats["|u|"]["max"] == pytest.approx(2.3 * 4, abs=1e-9)  # x -> -1.3 x from |x| = 4
    flagged = summary["flagged"]
    assert len(flagged) == 2
    assert "falls to 75.0 % (frame 2, t = 0.5 s)" in flagged[0]
    assert "inside out on 1 frame (up to 32, frame 3, t = 0.75 s)" in flagged[1]
    report = out / "report.html"
    text = report.read_text()
    assert files[str(src)]["sha256"] in text and "Nothing was flagged" not in text
    assert "10 frames per second" not in text and "4 frames per second" in text
    assert text.count("<img ") == 7 and text.count('class="note"') == 2
    assert "<details><summary>Parameters and provenance" in text
    assert 'src="figures' not in text  # self-contained: every figure embedded
    assert problems(report) == []


def test_report_of_a_long_run_with_no_unit_summarises_its_frames(tmp_path):
    ref, *_ = _sheet()
    T = 15  # a rigid translation: zero strain, nothing lost
    points = np.stack([ref + np.array([0.1, -0.2, 0.05]) * t for t in range(T)])
    src = tmp_path / "p.csv"
    _write(src, points, np.ones((T, 25), bool), np.zeros((T, 25)))
    (tmp_path / "summary.json").write_text(json.dumps({"fps": 5}))  # a frame rate, no unit
    out = tmp_path / "out"
    assert main(["compute", str(src), "--grid", "5x5", "--no-figures", "--out", str(out),
                 "-q"]) == 0  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    assert summary["unit"] == "input units" and summary["unit_source"] == "unknown"
    assert summary["time_axis"] == {"fps": 5.0, "unit": "s"}
    assert summary["figures"] == [] and summary["quality"]["surface_coverage"] == [1.0] * T
    assert abs(summary["last_frame_statistics"]["E1"]["max"]) < 1e-12
    assert len(summary["flagged"]) == 1 and "unit is unknown" in summary["flagged"][0]
    text = (out / "report.html").read_text()
    assert "input units (not known: pass --unit)" in text
    assert f"{T} frames: the per-frame values are in summary.json" in text
    assert "every frame alike" in text and "<img " not in text
