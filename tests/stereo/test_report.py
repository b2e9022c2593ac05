"""``stereo reconstruct`` writes a self-contained report.html with the quality of the
measurement; the quality numbers are checked against known answers."""

import hashlib
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from stereo.cli import main
from stereo.reconstruct import Reconstruction
from stereo.report import (
    CALIBRATION_RMS_PX,
    flatness,
    frame_quality,
    mesh_quality,
    quality_flags,
)
from strain2d import Tracks
from surface_strain import compute_strain, edge_lengths, triangle_quality
from tests.report_browser import problems
from tests.tolerances import EXACT, STEREO_POINT_RMSE_MM
from tissue_core.tables import read_long_table


def _sha256(paths) -> str:
    digest = hashlib.sha256()
    for p in paths:
        digest.update(Path(p).read_bytes())
    return digest.hexdigest()


def test_reconstruct_report_shows_inputs_quality_and_flags(small_stereo, tmp_path):
    """The stretching sheet, with a calibration that records a poor RMS error (0.8 px)."""
    s = small_stereo
    calib = json.loads(s.calib.read_text())
    calib["rms_px"] = 0.8
    calib_path = tmp_path / "calib.json"
    calib_path.write_text(json.dumps(calib))
    out = tmp_path / "rec"
    argv = ["reconstruct", "--calib", calib_path, "--left", s.left, "--right", s.right,
            "--points", s.points, "--strain", "--fps", 4, "--out", out, "-q"]  # fmt: skip
    assert main([str(a) for a in argv]) == 0
    summary = json.loads((out / "summary.json").read_text(), parse_constant=pytest.fail)
    # the frame rate reaches both time axes: the reconstruction's and its strain run's
    assert summary["time_axis"] == {"fps": 4.0, "unit": "s"}
    strain = json.loads((out / "strain" / "summary.json").read_text())
    assert strain["time_axis"] == {"fps": 4.0, "unit": "s"}

    # inputs with their checksums, in the summary and the report
    records = {Path(r["path"]).name: r for r in summary["input_files"]}
    assert records["calib.json"]["sha256"] == _sha256([calib_path])
    frames = sorted(s.left.glob("*.png"))
    assert records["left"]["files"] == len(frames) == 2
    assert records["left"]["sha256"] == _sha256(frames)
    assert records["points.csv"]["sha256"] == _sha256([s.points])

    # the per-frame quality is that of the points written to points3d.csv
    table = read_long_table(out / "points3d.csv", required=["reproj_error", "visible"])
    err, seen = table.columns["reproj_error"], table.columns["visible"] > 0
    per_frame = _csv_columns(out / "quality_per_frame.csv")
    for t in range(2):
        e = err[t][seen[t]]
        assert per_frame["points_3d"][t] == seen[t].sum() == 49
        # both files hold 4 decimals
        assert per_frame["reproj_median_px"][t] == pytest.approx(np.median(e), abs=1e-4)
        assert per_frame["reproj_p95_px"][t] == pytest.approx(np.percentile(e, 95), abs=1e-4)
    # frame 0 is each view's reference: its tracking correlation is exactly 1
    assert per_frame["quality_left_median"][0] == per_frame["quality_right_median"][0] == 1.0
    assert 0.9 < per_frame["quality_left_median"][1] < 1.0
    assert summary["quality"]["tracking_quality"] == "ZNCC"

    # results in mm against the rendered truth
    truth = s.truth["positions"]
    moved = np.linalg.norm(truth[1] - truth[0], axis=1)
    results = summary["results"]
    mm = STEREO_POINT_RMSE_MM
    assert results["displacement_median"] == pytest.approx(np.median(moved), abs=mm)
    assert results["mean_depth"] == pytest.approx(truth[0, :, 2].mean(), abs=mm)
    assert summary["quality"]["calibration"]["rms_px"] == 0.8
    # the mesh's quality is that of the same triangles on the true sheet
    elements = np.loadtxt(out / "strain" / "strain_elements.csv", delimiter=",", skiprows=1)
    tri = elements[elements[:, 0] == 0][:, 2:5].astype(int)
    mesh = summary["quality"]["mesh"]
    assert mesh["triangles"] == len(tri) > 0
    assert mesh["edge_median"] == pytest.approx(
        np.median(edge_lengths(truth[0], tri)), abs=STEREO_POINT_RMSE_MM
    )
    # the radius ratio is scale-free: a position error d changes it by about d / edge
    true_ratio = triangle_quality(truth[0], tri).min()
    assert mesh["radius_ratio_min"] == pytest.approx(true_ratio, abs=4 * mm / mesh["edge_median"])
    assert mesh["folded_max"] == mesh["poor_triangles"] == mesh["lost_last_frame"] == 0

    # flagged: the calibration's error, and the quadratic warp on a flat sheet
    flags = summary["flags"]
    assert len(flags) == 2, flags
    assert "0.8 px" in flags[0] and f"{CALIBRATION_RMS_PX:g} px" in flags[0]
    assert "quadratic" in flags[1] and "--shape-function affine" in flags[1]

    report = out / "report.html"
    assert problems(report) == []
    html = report.read_text(encoding="utf-8")
    sources = re.findall(r'src="([^"]*)"', html)
    assert len(sources) == len(summary["figures"]) >= 9  # views, 3D, quality, strain figures
    assert all(src.startswith("data:image/png;base64,") for src in sources)
    assert records["left"]["sha256"] in html and records["calib.json"]["sha256"] in html
    for text in ("Quality of the measurement", "reprojection p95 (px)", "left ZNCC median",
                 "baseline (mm)", "radius ratio", "0.0027 mm", "<details>"):  # fmt: skip
        assert text in html, text
    assert html.count('class="note"') == 2  # one box per flag


def _csv_columns(path) -> dict:
    lines = Path(path).read_text().splitlines()
    header = lines[0].split(",")
    rows = [[float(v) for v in line.split(",")] for line in lines[1:]]
    return {c: [r[k] for r in rows] for k, c in enumerate(header)}


def _reconstruction(err, visible, left_q, right_q) -> Reconstruction:
    T, N = visible.shape
    X = np.where(visible[..., None], 1.0, np.nan) * np.ones((T, N, 3))
    return Reconstruction(
        tracks=Tracks(X, visible, -err),
        reproj_error=err,
        left=np.zeros((T, N, 2)),
        right=np.zeros((T, N, 2)),
        left_quality=left_q,
        right_quality=right_q,
    )


def test_frame_quality_counts_and_percentiles():
    err = np.array([[0.1, 0.2, 0.3, 0.4, 0.5], [0.1, 0.2, 0.3, 5.0, np.nan]])
    visible = np.array([[1, 1, 1, 1, 1], [1, 1, 1, 0, 0]], bool)
    # as reconstruct stores them: point 4 was never matched (NaN in both views);
    # point 3 is tracked in both views in frame 1, only over the reprojection limit
    left_q = np.array([[1, 1, 1, 1, np.nan], [0.9, 0.8, 0.7, 0.6, np.nan]])
    right_q = np.array([[1, 1, 1, 1, np.nan], [0.95, 0.85, 0.75, 0.65, np.nan]])
    q = frame_quality(_reconstruction(err, visible, left_q, right_q))
    assert q["points_3d"].tolist() == [5, 3] and q["lost"].tolist() == [0, 2]
    assert q["reproj_median_px"] == pytest.approx([0.3, 0.2], abs=EXACT)
    # numpy's linear percentile: 0.4 + 0.8 * 0.1 and 0.2 + 0.9 * 0.1
    assert q["reproj_p95_px"] == pytest.approx([0.48, 0.29], abs=EXACT)
    # the medians over the 4 points tracked in each view: (0.7 + 0.8) / 2, (0.75 + 0.85) / 2
    assert q["quality_left_median"] == pytest.approx([1.0, 0.75], abs=EXACT)
    assert q["quality_right_median"] == pytest.approx([1.0, 0.8], abs=EXACT)


def test_tracking_quality_counts_only_points_tracked_in_that_view(small_stereo):
    """A grid larger than the sheet: the points off it are never matched, and the
    trackers lose some; a lost point's quality (the tracker's 0) is not the view's."""
    from stereo.calibration import load_calibration
    from stereo.reconstruct import reconstruct
    from strain2d import open_frames

    s = small_stereo
    x, y = np.meshgrid(np.linspace(60, 450, 6), np.linspace(60, 320, 5))
    left, right = open_frames([str(s.left)]), open_frames([str(s.right)])
    rec = reconstruct(
        left, right, load_calibration(s.calib), np.column_stack([x.ravel(), y.ravel()])
    )
    matched = np.isfinite(rec.right[0]).all(axis=1)
    assert 0 < matched.sum() < matched.size
    for q in (rec.left_quality, rec.right_quality):
        assert np.isnan(q[:, ~matched]).all()
        assert (q[np.isfinite(q)] > 0.5).all()  # no lost point's 0
    assert np.isfinite(rec.left_quality[:, rec.visible.any(axis=0)]).all()
    # the 2D tracks (tracks_left.csv, tracks_right.csv) hold no lost point at a stale place
    tracked = {side: np.isfinite(getattr(rec, side)).all(axis=2) for side in ("left", "right")}
    assert not tracked["left"][1].all()
    assert (np.isfinite(rec.left_quality) == tracked["left"] & matched).all()
    assert (np.isfinite(rec.right_quality) == tracked["right"]).all()
    per_frame = frame_quality(rec)
    for side in ("left", "right"):
        assert (per_frame[f"quality_{side}_median"] > 0.99).all(), side  # was 0 on the left


def test_mesh_quality_of_right_triangles_and_a_fold():
    """Two right isosceles triangles (radius ratio 2 sqrt 2 - 2); moving one corner across
    the diagonal folds one triangle over the other."""
    ref = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    folded = ref.copy()
    folded[3] = [2.0, 0.5, 0.0]
    tri = np.array([[0, 1, 2], [0, 2, 3]])
    q = mesh_quality(compute_strain(ref, np.stack([ref, ref, folded]), tri))
    assert q["triangles"] == 2
    assert q["radius_ratio_min"] == pytest.approx(2 * math.sqrt(2) - 2, abs=EXACT)
    assert q["poor_triangles"] == 0
    assert q["edge_median"] == pytest.approx(1.0, abs=EXACT)
    assert (q["folded_max"], q["folded_frame"]) == (1, 2)
    flat = mesh_quality(compute_strain(ref, np.stack([ref, 2 * ref]), tri))
    assert flat["folded_max"] == 0


def test_flatness_of_a_tilted_plane_and_a_dome():
    u, v = np.meshgrid(np.linspace(-10, 10, 9), np.linspace(-10, 10, 9))
    plane = np.column_stack([u.ravel(), v.ravel(), 0.3 * u.ravel() + 500.0])
    got = flatness(np.stack([plane, plane]))
    assert got["plane_rms"] < EXACT and got["flat"]
    assert got["extent"] == pytest.approx(math.hypot(20 * math.hypot(1, 0.3), 20), rel=1e-9)
    dome = plane.copy()
    dome[:, 2] -= 0.02 * (u.ravel() ** 2 + v.ravel() ** 2)  # sagitta 4 mm over 28 mm
    got = flatness(np.stack([plane, dome]))
    assert not got["flat"] and got["plane_rms"] > 0.5


def _clean():
    per_frame = {
        "lost": np.array([0, 0]),
        "reproj_p95_px": np.array([0.01, 0.02]),
        "quality_left_median": np.array([1.0, 0.99]),
        "quality_right_median": np.array([1.0, 0.98]),
    }
    calibration = {"rms_px": 0.1, "unit": "mm"}
    matching = {"points": 10, "matched": 10}
    return per_frame, calibration, matching


def test_a_clean_run_flags_nothing_and_each_problem_flags_once():
    per_frame, calibration, matching = _clean()
    assert quality_flags(per_frame, calibration, matching, max_reproj_px=1.0) == []
    flat = {"flat": True, "plane_rms": 0.01, "fraction": 1e-4, "extent": 50.0}
    assert quality_flags(per_frame, calibration, matching, max_reproj_px=1.0, warp="affine",
                         surface=flat) == []  # fmt: skip
    cases = [
        ({"calibration": {"rms_px": float("nan"), "unit": "mm"}}, "records no reprojection"),
        ({"matching": {"points": 10, "matched": 7}}, "3 of 10 points were not found"),
        ({"lost": np.array([0, 4])}, "Up to 4 of 10 points"),
        ({"reproj_p95_px": np.array([0.01, 0.7])}, "reaches 0.7 px at frame 1"),
        ({"quality_right_median": np.array([1.0, 0.5])}, "right view falls to 0.5 at frame 1"),
        ({"warp": "quadratic", "surface": flat}, "--shape-function affine"),
        ({"mesh": {"triangles": 8, "poor_triangles": 2, "radius_ratio_min": 0.1,
                   "folded_max": 0, "folded_frame": 0, "lost_last_frame": 0}},
         "2 of 8 triangles are thin"),
    ]  # fmt: skip
    for change, expected in cases:
        pf, cal, match = _clean()
        kwargs = {"max_reproj_px": 1.0}
        for key, value in change.items():
            if key in pf:
                pf[key] = value
            elif key == "calibration":
                cal = value
            elif key == "matching":
                match = value
            else:
                kwargs[key] = value
        flags = quality_flags(pf, cal, match, **kwargs)
        assert len(flags) == 1 and expected in flags[0], (expected, flags)


def test_the_warp_help_states_the_noise_trade_off(capsys):
    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--shape-function affine for flat specimens" in text
    assert "0.0027 mm against 0.0018 mm" in text


def test_a_long_run_is_summarised_in_a_table_that_fits_the_page(tmp_path):
    """200 frames: the table shows 15 of them, the worst included; the figure shows all."""
    from stereo.figures import plot_quality
    from stereo.report import write_report

    T = 200
    rng = np.random.default_rng(0)
    per_frame = {
        "frame": np.arange(T),
        "points_3d": np.full(T, 49),
        "lost": np.zeros(T, int),
        "reproj_median_px": rng.uniform(0.01, 0.02, T),
        "reproj_p95_px": rng.uniform(0.03, 0.04, T),
        "quality_left_median": rng.uniform(0.98, 0.99, T),
        "quality_right_median": rng.uniform(0.98, 0.99, T),
    }
    per_frame["reproj_p95_px"][137] = 0.5
    per_frame["lost"][61], per_frame["points_3d"][61] = 9, 40
    (tmp_path / "figures").mkdir()
    plot_quality(per_frame, max_reproj_px=1.0).savefig(tmp_path / "figures" / "quality.png")
    report = write_report(
        tmp_path,
        {"unit": "mm", "frames": T},
        per_frame,
        figures=[{"file": "figures/quality.png", "caption": "per frame"}],
    )
    html = report.read_text(encoding="utf-8")
    table = html[html.index("reprojection median (px)") :]
    table = table[: table.index("</table>")]
    shown = [int(m) for m in re.findall(r'<tr><td class="num">(\d+)</td>', table)]
    assert len(shown) == 15 and {0, 61, 137, T - 1} <= set(shown)
    assert "15 of 200 frames shown" in html
    assert problems(report) == []
