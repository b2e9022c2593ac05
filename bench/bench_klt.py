"""Throughput of the klt tracker, with and without the window-bias correction.

Renders one synthetic equibiaxial video (800 x 800 px, 31 frames) and tracks
a grid on it twice: plain pyramidal LK (the baseline) and LK with the
window-deformation bias correction.  Prints point-frames per second, the
ratio of the two, and the final tracking RMSE of each against the exact
ground truth.

    python bench/bench_klt.py [--grid 15]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sample_data_synth import make_case
from strain2d import track


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=15, help="points per side (default 15)")
    args = parser.parse_args()
    video = make_case("equibiaxial", size=800, n_frames=31, rng=0)
    points = video.truth.grid((args.grid, args.grid))
    truth = video.truth.positions(points, video.truth.n_frames - 1)
    n = len(points) * video.truth.n_frames
    results = {}
    for label, correct in (("plain LK (baseline)", False), ("LK + bias correction", True)):
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            tracks = track(
                video.frames, points, tracker="klt", options={"affine_correction": correct}
            )
            best = min(best, time.perf_counter() - t0)
        rmse = np.sqrt(np.mean(np.sum((tracks.positions[-1] - truth) ** 2, axis=1)))
        results[label] = best
        print(
            f"{label:22s} {best:7.3f} s  {n / best:10,.0f} point-frames/s  final RMSE {rmse:.3f} px"
        )
    base, corr = results.values()
    print(f"correction costs {corr / base:.2f}x the baseline time")


if __name__ == "__main__":
    main()
