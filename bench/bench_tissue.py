"""Trackers side by side on the speckle-free tissue suite (sample_data_synth.tissue).

For every case (800 x 800 px, 21 frames; the 20-degree rotation 5 frames) the
case's grid is tracked by each tracker and compared with the exact truth on
the final frame: tracking RMSE and maximum over the points the tracker kept,
points lost among those in view, nodal strain RMSE (Exx, Eyy, Exy together)
and, as the floor of that grid, the strain RMSE of the exact positions; the
strain RMSE against the exact positions' strain on the same mesh (what the
tracking alone costs, the grid's own error taken out); run
time, and for trackers that report an uncertainty the fraction of
per-coordinate errors (all frames) within 2 sigma.

    python bench/bench_tissue.py [--size 800] [--cases a,b] [--trackers dic,gdic,klt]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from sample_data_synth.tissue import TISSUE_CASES, make_tissue_case
from strain2d import track
from strain2d.pipeline import strain_from_tracks
from strain2d.tracks import Tracks
from tissue_core.errors import InputError


def _strain_rmse(tracks: Tracks, truth, points, grid, reference=None) -> float:
    """Nodal strain RMSE on the final frame against the analytic strain, or against
    ``reference`` (the nodal strain of the exact positions on the same mesh)."""
    last = truth.n_frames - 1
    try:
        field = strain_from_tracks(tracks, grid_shape=grid)
    except InputError:  # too few points left to mesh
        return float("nan")
    expected = truth.strain(points, last) if reference is None else reference
    error = field.nodal_E[last] - expected
    parts = np.stack([error[:, 0, 0], error[:, 1, 1], error[:, 0, 1]])
    parts = parts[:, np.all(np.isfinite(parts), axis=0)]
    return float(np.sqrt(np.mean(parts**2))) if parts.size else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=800)
    parser.add_argument("--cases", default=",".join(TISSUE_CASES))
    parser.add_argument("--trackers", default="dic,gdic,klt")
    args = parser.parse_args()
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"{args.size}x{args.size} px"
    )
    print()
    print("| case (kind) | tracker | final RMSE / max (px) | lost in view | strain RMSE "
          "(grid floor) | tracking's strain RMSE | within 2 sigma | time (s) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for case in args.cases.split(","):
        video = make_tissue_case(case, size=args.size, rng=0)
        truth = video.truth
        grid = tuple(truth.params["grid"])
        points = truth.grid(grid)
        true = truth.positions(points)
        H, W = video.frames.shape[1:]
        in_view = (true[..., 0] >= 0) & (true[..., 0] <= W - 1)
        in_view &= (true[..., 1] >= 0) & (true[..., 1] <= H - 1)
        ones = np.ones(true.shape[:2])
        exact = Tracks(true, ones.astype(bool), ones)
        floor = _strain_rmse(exact, truth, points, grid)
        exact_E = strain_from_tracks(exact, grid_shape=grid).nodal_E[-1]
        for name in args.trackers.split(","):
            t0 = time.perf_counter()
            tracks = track(video.frames, points, tracker=name)
            seconds = time.perf_counter() - t0
            kept = tracks.visible[-1]
            error = np.linalg.norm(tracks.positions[-1] - true[-1], axis=1)[kept]
            rmse = np.sqrt(np.mean(error**2)) if error.size else float("nan")
            worst = error.max() if error.size else float("nan")
            lost = int((in_view[-1] & ~kept).sum())
            covered = "-"
            if tracks.uncertainty is not None:
                seen = tracks.visible[1:]
                d = np.abs(tracks.positions - true)[1:][seen]
                s = tracks.uncertainty[1:][seen][:, None]
                covered = f"{np.mean(d <= 2 * s):.2f}"
            strain = _strain_rmse(tracks, truth, points, grid)
            tracking_part = _strain_rmse(tracks, truth, points, grid, exact_E)
            print(
                f"| {case} ({truth.params['kind']}) | {name} | {rmse:.3f} / {worst:.2f} | "
                f"{lost}/{int(in_view[-1].sum())} | {strain:.4f} ({floor:.4f}) | "
                f"{tracking_part:.4f} | {covered} | "
                f"{seconds:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
