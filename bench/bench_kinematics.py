"""Speed of the vectorized strain computation against a per-triangle loop.

Prints the time of ``surface_strain.compute_strain`` (F, E, nodal averages) on a
dense 2D grid over many frames, the time of a straightforward Python loop over
frames and triangles doing the same per-triangle algebra (the baseline), and
their ratio.  Both run in this script on the same data.

    python bench/bench_kinematics.py [--grid 50] [--frames 100]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from surface_strain import compute_strain, delaunay_triangles


def loop_baseline(ref, cur, tri):
    T, M = cur.shape[0], len(tri)
    E = np.empty((T, M, 2, 2))
    for t in range(T):
        for m, (a, b, c) in enumerate(tri):
            G = np.column_stack([ref[b] - ref[a], ref[c] - ref[a]])
            d = np.column_stack([cur[t, b] - cur[t, a], cur[t, c] - cur[t, a]])
            F = d @ np.linalg.inv(G)
            E[t, m] = 0.5 * (F.T @ F - np.eye(2))
    return E


def best_of(fn, repeat):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=50, help="points per side (default 50)")
    parser.add_argument("--frames", type=int, default=100, help="frames (default 100)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    g = np.linspace(0, 800, args.grid)
    ref = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    tri = delaunay_triangles(ref)
    s = np.linspace(1, 1.5, args.frames)[:, None, None]
    cur = 400 + (ref - 400) * s + rng.normal(scale=0.05, size=(args.frames, len(ref), 2))
    t_vec, field = best_of(lambda: compute_strain(ref, cur, tri), 3)
    t_loop, E_loop = best_of(lambda: loop_baseline(ref, cur, tri), 1)
    assert np.allclose(field.E, E_loop, atol=1e-12)
    n = args.frames * len(tri)
    print(f"{len(ref)} points, {len(tri)} triangles, {args.frames} frames ({n} triangle-frames)")
    print(
        f"compute_strain (vectorized, incl. nodal averages): {t_vec:8.4f} s "
        f"({n / t_vec:,.0f} triangle-frames/s)"
    )
    print(
        f"per-triangle Python loop (E only, baseline):       {t_loop:8.4f} s "
        f"({n / t_loop:,.0f} triangle-frames/s)"
    )
    print(f"speed-up: {t_loop / t_vec:.0f}x")


if __name__ == "__main__":
    main()
