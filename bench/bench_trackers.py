"""Tracking throughput of dic, gdic and klt on the same video and the same dense grid.

Renders the paper's equibiaxial case (800 x 800 px, 31 frames) once, tracks a
dense grid with each tracker (best of 3 runs, after one warm-up run that also
compiles dic's kernel), and prints point-frames per second, the ratio, and each
tracker's final tracking RMSE against the exact ground truth.

    python bench/bench_trackers.py [--grid 40] [--subset 31]
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from sample_data_synth import make_case
from strain2d import track


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=40, help="points per side (default 40)")
    parser.add_argument("--subset", type=int, default=31, help="dic subset / klt window (31)")
    # gdic runs with its defaults, as a user gets it
    args = parser.parse_args()
    video = make_case("equibiaxial", size=800, n_frames=31, rng=0)
    points = video.truth.grid((args.grid, args.grid))
    truth = video.truth.positions(points, video.truth.n_frames - 1)
    n = len(points) * video.truth.n_frames
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"{len(points)} points x {video.truth.n_frames} frames of 800x800 px, "
        f"{args.subset} px subsets/windows (gdic: its own choice, auto)"
    )
    options = {
        "dic": {"subset": args.subset},
        "gdic": {},  # its default: subsets sized per point (31 px on this speckle)
        "klt": {"window": args.subset},
    }
    speed = {}
    for name in ("klt", "dic", "gdic"):
        track(video.frames[:3], points[::97], tracker=name, options=options[name])  # warm-up
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            tracks = track(video.frames, points, tracker=name, options=options[name])
            best = min(best, time.perf_counter() - t0)
        rmse = np.sqrt(np.mean(np.sum((tracks.positions[-1] - truth) ** 2, axis=1)))
        speed[name] = n / best
        print(
            f"{name:4s} {best:7.3f} s  {n / best:10,.0f} point-frames/s  "
            f"final RMSE {rmse:.4f} px  lost {int((~tracks.visible[-1]).sum())}"
        )
    print(f"dic takes {speed['klt'] / speed['dic']:.2f}x the time of klt")
    print(f"gdic takes {speed['klt'] / speed['gdic']:.2f}x the time of klt")


if __name__ == "__main__":
    main()
