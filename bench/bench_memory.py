"""Peak memory of dic and gdic on a dense grid (10,000 points by default).

Tracks a 100 x 100 grid over the paper's equibiaxial case (800 x 800 px,
4 frames) and prints each tracker's peak Python-heap allocation (tracemalloc,
which sees NumPy's buffers) and its ratio to dic's in the same run.

    python bench/bench_memory.py [--grid 100] [--frames 4]
"""

from __future__ import annotations

import argparse
import time
import tracemalloc

import numpy as np

from sample_data_synth import make_case
from strain2d import track


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=100, help="points per side (default 100)")
    parser.add_argument("--frames", type=int, default=4, help="frames (default 4)")
    args = parser.parse_args()
    video = make_case("equibiaxial", size=800, n_frames=args.frames, rng=0)
    points = video.truth.grid((args.grid, args.grid))
    truth = video.truth.positions(points, args.frames - 1)
    print(f"{len(points)} points x {args.frames} frames of 800x800 px")
    peaks = {}
    for name in ("dic", "gdic"):
        track(video.frames[:2], points[::211], tracker=name)  # compile, warm caches
        tracemalloc.start()
        t0 = time.perf_counter()
        tracks = track(video.frames, points, tracker=name)
        seconds = time.perf_counter() - t0
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        peaks[name] = peak
        rmse = np.sqrt(np.mean(np.sum((tracks.positions[-1] - truth) ** 2, axis=1)))
        print(
            f"{name:5s} peak {peak / 2**20:8.0f} MiB  ({peak / len(points) / 1024:6.1f} KiB per "
            f"point)  {seconds:6.1f} s  final RMSE {rmse:.4f} px"
        )
    print(f"gdic uses {peaks['gdic'] / peaks['dic']:.2f}x the memory of dic")


if __name__ == "__main__":
    main()
