"""The IC-GN kernel alone on 1, 2, 4... threads: what a second thread can give gdic and dic.

Tracks the first 12 frames of the dense speckle grid (equibiaxial, 800 px,
50 x 50 points) with gdic, keeps the compiled kernel's inputs of its last
all-points call, and times that one call (the best of ``--repeats``) on each
thread count the machine has, for each of numba's parallel chunk sizes
(``--chunks``; 0 is numba's default, the range split evenly). Prints a
Markdown table: milliseconds per count and the speed-ups from one thread.

    python bench/bench_icgn_threads.py [--counts 1,2,4,8,16] [--chunks 0,1,4,16,64]
                                       [--repeats 4]

Wall-clock on a machine that may be shared: compare the counts of one run.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", default="1,2,4,8,16", help="thread counts (1,2,4,8,16)")
    parser.add_argument("--chunks", default="0,1,4,16,64", help="numba chunk sizes")
    parser.add_argument("--repeats", type=int, default=4, help="timings per count (4)")
    args = parser.parse_args(argv)

    import numba

    import strain2d.trackers._icgn_kernel as kernel
    from sample_data_synth import make_case
    from strain2d import track

    video = make_case("equibiaxial", size=800, n_frames=12, rng=0)
    points = video.truth.grid((50, 50))
    calls = []
    icgn = kernel.icgn

    def spy(*inputs):
        if len(inputs[1]) == len(points):
            calls[:] = [inputs]
        return icgn(*inputs)

    kernel.icgn = spy
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            track(video.frames, points, tracker="gdic")
    finally:
        kernel.icgn = icgn
    inputs = calls[0]
    most = numba.config.NUMBA_NUM_THREADS
    counts = [n for n in (int(c) for c in args.counts.split(",")) if n <= most]

    def best(n: int, chunk: int) -> float:
        numba.set_num_threads(n)
        fastest = float("inf")
        for _ in range(max(args.repeats, 1)):
            with numba.parallel_chunksize(chunk):
                start = time.perf_counter()
                icgn(*inputs)
                fastest = min(fastest, time.perf_counter() - start)
        return fastest

    print(
        f"IC-GN kernel, one frame of {len(points)} points (gdic's inputs), best of "
        f"{args.repeats}; numba threading layer {numba.threading_layer()}\n"
    )
    head = " | ".join(f"{n} thr. (ms)" for n in counts)
    ups = " | ".join(f"{n}/1" for n in counts[1:])
    print(f"| chunk | {head} | {ups} |")
    print("|---|" + "---|" * (2 * len(counts) - 1))
    for chunk in (int(c) for c in args.chunks.split(",")):
        times = [best(n, chunk) for n in counts]
        cells = " | ".join(f"{t * 1000:.0f}" for t in times)
        speedups = " | ".join(f"{times[0] / t:.2f}" for t in times[1:])
        print(f"| {chunk} | {cells} | {speedups} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
