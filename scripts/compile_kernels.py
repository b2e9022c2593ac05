"""Compile the toolkit's numba kernels once, into their on-disk cache (``make setup`` runs it).

The kernels (the trackers' IC-GN, B-spline prefilter and field residual, mpm3d's
surface detection, binning and channel merging) are compiled on first use and
cached beside their modules. Without this step the first commands after an
install each spend 10-20 s compiling, and processes started together (a test
run on several workers, a batch on a cluster) compile the same kernels at the
same time. This script calls each kernel with the argument types the toolkit
passes, on tiny synthetic inputs, and prints how long it took.

    python scripts/compile_kernels.py
"""

from __future__ import annotations

import time
import warnings


def _trackers() -> None:
    import numpy as np

    from sample_data_synth import make_case
    from strain2d import track
    from strain2d.trackers._lattice import LatticeSolver

    video = make_case("equibiaxial", size=160, n_frames=3, rng=1)
    points = video.truth.grid((5, 5))
    for name in ("dic", "gdic"):  # IC-GN (affine and quadratic), prefilter, threads
        track(video.frames, points, tracker=name)
    track(video.frames, points, tracker="dic", options={"shape_function": "quadratic"})
    # the field's residual and gradient kernels (gdic calls them only where matches fail)
    reference = np.asarray(video.frames[0], np.float64)
    solver = LatticeSolver(reference, points)
    state, _ = solver.coarse(np.asarray(video.frames[1], np.float64), solver.state)
    solver.refine(np.asarray(video.frames[1], np.float64), state)


def _mpm3d() -> None:
    import tempfile
    from pathlib import Path

    from mpm3d import analyze_stack, read_stack
    from sample_data_synth import make_stack_case, write_stack

    case = make_stack_case("before", size=48, spacing=(4.0, 5.0, 5.0), rng=1)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "small.tif"
        write_stack(path, case)
        # the channels combined (one kernel), the surface (another), the isosurface's
        # binning (a third); in memory and in bands
        analyze_stack(read_stack(path), iso_bin=2)
        analyze_stack(read_stack(path), iso_bin=2, lazy=True, tile_rows=16)


def main() -> None:
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _trackers()
        _mpm3d()
    print(f"numba kernels compiled and cached in {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
