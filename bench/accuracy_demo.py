"""Accuracy of the demo's z-stack and stereo results against the synthetic truth.

Run after ``make demo``; prints the numbers the mpm3d and stereo guides (docs/)
tables quote:

    python bench/accuracy_demo.py [--demo demo_output]

* mpm3d: fold wavelength, median and max fold height, orientation (from each
  ``metrics.json``), the height map's RMS error and the surface mesh's RMS
  distance to the true surface (from ``heightmap.tif`` and ``surface.vtp``);
  the quality each report shows (coverage, separability, mesh holes, mesh vs
  height map, height ranges) and the comparison's alignment.
* stereo: calibration RMS and baseline error, matching and tracking errors,
  reprojection RMS, 3D RMSE (raw and after one rigid alignment) and the
  membrane strain RMSE (principal strains) against the analytic field.
* study: each synthetic specimen's detected contraction endpoint and its
  mean Exx, Eyy there against the truth, and each group's verdict against the
  design (``study_truth.json``).
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import numpy as np


def _rows(path: Path) -> list[dict]:
    return list(csv.DictReader(path.read_text().splitlines()))


def mpm3d_accuracy(demo: Path) -> None:
    import pyvista as pv
    import tifffile

    from mpm3d.surface import heightmap_mesh

    print("mpm3d (demo pair):")
    for case in ("before", "after"):
        run = demo / "mpm3d_compare" / case
        m = json.loads((run / "metrics.json").read_text())
        truth = json.loads((demo / "stacks" / f"{case}_truth.json").read_text())
        npz = np.load(demo / "stacks" / f"{case}_truth.npz")
        height = tifffile.imread(run / "heightmap.tif")[0]
        hm_rms = float(np.sqrt(np.mean((height - npz["height_um"]) ** 2)))
        dz, dy, dx = truth["spacing_um"]
        mesh = pv.read(run / "surface.vtp")
        true_mesh = heightmap_mesh(npz["depth_um"], spacing=(dz, dy, dx))
        dist = np.asarray(mesh.compute_implicit_distance(true_mesh)["implicit_distance"])
        span = (np.array(npz["depth_um"].shape[::-1]) - 1) * np.array([dx, dy])
        inner = np.all((mesh.points[:, :2] > 10) & (mesh.points[:, :2] < span - 10), axis=1)
        print(
            f"  {case}: wavelength {m['fold_wavelength_um']:.1f} um (truth "
            f"{truth['wavelength_um']:.0f}), median fold height {m['fold_height_um']:.1f} "
            f"(truth {truth['median_fold_height_um']:.1f}), max {m['max_fold_height_um']:.1f} "
            f"(truth {truth['max_fold_height_um']:.1f}), orientation "
            f"{m['fold_orientation_deg']:.2f} deg (truth {truth['orientation_deg']:.0f}), "
            f"height map RMS {hm_rms:.2f} um, mesh RMS distance "
            f"{np.sqrt(np.mean(dist[inner] ** 2)):.2f} um"
        )
        q = m["quality"]
        mesh_q, diff = q["mesh"], q["mesh_vs_heightmap_um"]
        lo, hi = m["height_range_um"]
        print(
            f"    quality: coverage {100 * q['surface_coverage']:.2f} %, separability "
            f"{q['otsu_separability']:.3f}, mesh {mesh_q['triangles']} triangles, "
            f"{mesh_q['holes']} holes, area ratio {mesh_q['developed_area_ratio']:.3f} "
            f"(1 + Sdr {1 + m['Sdr_percent'] / 100:.3f}), mesh vs height map median "
            f"{diff['median_abs']:.2f} / p95 {diff['p95_abs']:.2f} / max {diff['max_abs']:.1f} "
            f"um, heights {lo:.1f}-{hi:.1f} um, colour range "
            f"{m['height_colour_range_um'][0]:.1f}-{m['height_colour_range_um'][1]:.1f} um"
        )
    align = json.loads((demo / "mpm3d_compare" / "compare.json").read_text())["alignment"]
    print(
        f"  compare: correlation {align['overlap_correlation']:.2f}, residual RMS "
        f"{align['residual_rms_um']:.0f} um over {100 * align['overlap_fraction']:.1f} % overlap"
    )


def _kabsch_rmse(A: np.ndarray, B: np.ndarray) -> tuple[float, float]:
    """RMSE after the best rigid motion of A onto B, and that motion's angle (deg)."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    moved = (A - ca) @ R.T + cb
    angle = np.degrees(np.arccos(min(1.0, (np.trace(R) - 1) / 2)))
    return float(np.sqrt(np.mean(np.sum((moved - B) ** 2, axis=1)))), float(angle)


def stereo_accuracy(demo: Path) -> None:
    from sample_data_synth.stereo import load_stereo_scene
    from strain2d.tracks import read_tracks

    print("stereo (demo dome):")
    calib = json.loads((demo / "stereo_calib.json").read_text())
    rig = json.loads((demo / "stereo_targets" / "calibration" / "rig.json").read_text())
    true_baseline = float(np.linalg.norm(rig["T"]))
    print(
        f"  calibration RMS {calib['rms_px']:.3f} px (left {calib['rms_left_px']:.3f}, right "
        f"{calib['rms_right_px']:.3f}); baseline {calib['baseline']:.3f} "
        f"(truth {true_baseline:.3f}, {100 * (calib['baseline'] / true_baseline - 1):+.3f} %)"
    )
    rec = demo / "stereo_dome"
    scene = load_stereo_scene(demo / "stereo_scene" / "dome")
    left = read_tracks(rec / "tracks_left.csv")
    right = read_tracks(rec / "tracks_right.csv")
    T, N = left.positions.shape[:2]
    material = scene.material_from_left_pixel(left.positions[0], 0)
    truth = np.stack([scene.positions(material, t) for t in range(T)])
    px = {c: np.stack([scene.pixels(material, t, camera=c) for t in range(T)]) for c in
          ("left", "right")}  # fmt: skip

    def rms(a, b):
        return np.sqrt(np.nanmean(np.sum((a - b) ** 2, axis=-1), axis=-1))

    er, el = rms(right.positions, px["right"]), rms(left.positions, px["left"])
    X = np.array([[float(r[k]) for k in "XYZ"] for r in _rows(rec / "points3d.csv")])
    raw = float(np.sqrt(np.mean(np.sum((X - truth.reshape(-1, 3)) ** 2, axis=1))))
    aligned, angle = _kabsch_rmse(X, truth.reshape(-1, 3))
    summary = json.loads((rec / "summary.json").read_text())
    print(
        f"  matching {er[0]:.3f} px RMS; tracking at the last frame {el[-1]:.3f} / "
        f"{er[-1]:.3f} px (left / right); reprojection RMS "
        f"{summary['reprojection_rms_px']:.3f} px"
    )
    print(
        f"  3D RMSE {raw:.2f} mm, {aligned:.3f} mm after one rigid alignment "
        f"(a {angle:.3f} deg turn of the world frame)"
    )
    from surface_strain import compute_strain, nodal_scalars
    from surface_strain.mesh import grid_triangles

    nodes = _rows(rec / "strain" / "strain_nodes.csv")
    w = np.linalg.eigvalsh(np.stack([scene.strain(material, t) for t in range(T)]))
    cols, rows = summary["points"]["grid"]
    exact = nodal_scalars(compute_strain(truth[0], truth, grid_triangles(rows, cols)))
    for key, true in (("E1", w[..., 1]), ("E2", w[..., 0])):
        got = np.array([float(r[key]) for r in nodes]).reshape(T, N)
        err, mesh_err = got - true, exact[key] - true
        print(
            f"  {key} RMSE {np.sqrt(np.nanmean(err[-1] ** 2)):.4f} at the last frame, "
            f"{np.sqrt(np.nanmean(err**2)):.4f} over all frames; the same mesh on the exact "
            f"positions: {np.sqrt(np.nanmean(mesh_err[-1] ** 2)):.4f} at the last frame"
        )


def study_accuracy(demo: Path) -> None:
    truth = json.loads((demo / "study_data" / "study_truth.json").read_text())
    stats = json.loads((demo / "study_batch" / "study" / "statistics.json").read_text())
    exact = {s["specimen"]: s for s in truth["specimens"]}
    print("study (demo, 8 synthetic specimens):")
    hits, errors = 0, []
    for r in stats["specimens"]:
        e = exact[r["specimen"]]
        hits += r["endpoint"] == e["endpoint"]
        errors += [r["mean_Exx"] - e["Exx"], r["mean_Eyy"] - e["Eyy"]]
    print(
        f"  contraction endpoint detected exactly in {hits} of {len(stats['specimens'])} "
        f"specimens; specimen mean Exx, Eyy at the endpoint within "
        f"{np.abs(errors).max():.5f} of the truth"
    )
    for name, group in truth["groups"].items():
        level = stats["specimen_level"][name]
        verdict = "Exx differs from Eyy" if level["t_p"] < stats["alpha"] else "no difference"
        print(
            f"  {name}: Exx - Eyy {level['mean_difference']:+.4f} (truth "
            f"{group['difference_mean']:+.4f}), paired t-test on specimen means "
            f"p = {level['t_p']:.4f} -> {verdict} (designed: {group['expected']})"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--demo", default="demo_output", help="the demo's output folder")
    args = parser.parse_args()
    demo = Path(args.demo)
    if not (demo / "stereo_dome").is_dir() or not (demo / "mpm3d_compare").is_dir():
        raise SystemExit(f"no demo results in {demo}: run `make demo` first")
    mpm3d_accuracy(demo)
    stereo_accuracy(demo)
    study_accuracy(demo)


if __name__ == "__main__":
    main()
