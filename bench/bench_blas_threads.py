"""BLAS inside the trackers: gdic with BLAS on one thread (as it runs) against BLAS on every core.

Since commit 5ee5547 the trackers run BLAS on one thread
(:func:`strain2d.trackers._threads.using_threads`); this script times gdic
as it runs ("new") and with that limit replaced by a no-op in the same
process ("old": OpenBLAS's own thread per core), alternating, then dic, on
the speed cases of ``bench/bench_default_tracker.py``: the muscle sheet, the
four weak-texture cases and the dense speckle grid.  It prints each time,
old / new, gdic new / dic, and whether the tracks are identical.  The
difference grows with the cores (docs/tracker_scenes.md, "One BLAS thread
inside the trackers": 3.3x on the vessels case on 16 cores, 1.7x on 2).

    python bench/bench_blas_threads.py [--cases sheet,vessels]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages

CASES = ("sheet", "closeup-gaussian", "vessels-contraction", "fur-gaussian",
         "retina-contraction", "speckle50")  # fmt: skip


def _case(name: str):
    from sample_data_synth import make_case
    from sample_data_synth.sheet import SHEET_GRID, make_muscle_sheet
    from sample_data_synth.tissue import make_tissue_case

    if name == "sheet":
        video, grid = make_muscle_sheet(n_frames=41, rng=0), SHEET_GRID
    elif name == "speckle50":
        video, grid = make_case("equibiaxial", size=800, n_frames=31, rng=0), (50, 50)
    else:
        video = make_tissue_case(name, size=800, rng=0)
        grid = tuple(video.truth.params["grid"])
    points = video.truth.grid(grid)
    return video.frames, points


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES), help=f"of {', '.join(CASES)}")
    args = parser.parse_args(argv)
    import scipy.linalg  # noqa: F401  (its BLAS loaded, as the trackers load it)
    import threadpoolctl

    from sample_data_synth import make_case
    from strain2d import track

    warnings.simplefilter("ignore")
    real = threadpoolctl.threadpool_limits
    warm = make_case("equibiaxial", size=160, n_frames=3, rng=1)
    for tracker in ("gdic", "dic"):
        track(warm.frames, warm.truth.grid((4, 4)), tracker=tracker)  # compile
    blas = [(i["internal_api"], i["num_threads"]) for i in threadpoolctl.threadpool_info()]
    print(f"{os.cpu_count()} cores; BLAS libraries and their threads: {blas}\n")
    print("| case | gdic new (s) | gdic old (s) | old / new | dic (s) | gdic new / dic | "
          "identical tracks |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name in args.cases.split(","):
        frames, points = _case(name)
        seconds, tracks = {}, {}
        for mode in ("new", "old", "dic"):
            threadpoolctl.threadpool_limits = (
                (lambda **_: contextlib.nullcontext()) if mode == "old" else real
            )
            try:
                start = time.perf_counter()
                tracks[mode] = track(frames, points, tracker="dic" if mode == "dic" else "gdic")
                seconds[mode] = time.perf_counter() - start
            finally:
                threadpoolctl.threadpool_limits = real
        same = np.array_equal(tracks["new"].positions, tracks["old"].positions, equal_nan=True)
        print(
            f"| {name}, {len(points)} x {len(frames)} | {seconds['new']:.2f} | "
            f"{seconds['old']:.2f} | {seconds['old'] / seconds['new']:.2f} | "
            f"{seconds['dic']:.2f} | {seconds['new'] / seconds['dic']:.2f} | "
            f"{'yes' if same else 'no'} |",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
