"""What the figures cost: ``strain2d analyze`` against ``strain2d track`` on the same input.

Renders the paper's equibiaxial case (800 x 800 px, 31 frames) to a lossless
AVI, then runs, as a user would, ``python -m strain2d track`` and ``python -m
strain2d analyze`` (default figures: maps, curves, violins, the MP4 animation,
the report) with the same grid and tracker, and prints each command's wall
time, their ratio, and where analyze's time went (from its summary.json's
``runtime_s``: tracking, strain, the tables and ParaView series, the
animation, when the last figure was done (the figures are drawn by worker
processes meanwhile), the summary and report, and all the writing).
The targets: ``analyze`` at most 1.3 times ``track`` with the default
tracker, at most 2 times with ``klt``.

    python bench/bench_analyze.py [--grid 13] [--trackers gdic,dic,klt] [--frames 31]
                                  [--repeat 1]

With ``--repeat N`` each command runs N times and the fastest run counts (on
a shared machine the others measure the neighbours).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sample_data_synth import make_case, write_video


def _run(argv: list[str]) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "strain2d", "-q", *argv], check=True)
    return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=13, help="points per side (default 13)")
    parser.add_argument("--frames", type=int, default=31, help="frames (default 31)")
    parser.add_argument("--trackers", default="gdic,klt", help="comma-separated (gdic,dic,klt)")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each command (default 1)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        video = folder / "equibiaxial.avi"
        write_video(make_case("equibiaxial", size=800, n_frames=args.frames, rng=0).frames, video)
        grid = ["--grid", f"{args.grid}x{args.grid}"]
        _run(["track", str(video), *grid, "--tracker", "klt", "--out", str(folder / "w.csv")])
        print(
            f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
            f"{args.grid}x{args.grid} grid, {args.frames} frames of 800x800 px"
        )
        parts = ("tracking", "strain", "tables", "animation", "figures", "report", "outputs")
        print(f"| tracker | track (s) | analyze (s) | analyze / track | {', '.join(parts)} (s) |")
        print("|---|---|---|---|---|")
        for tracker in args.trackers.split(","):
            options = [*grid, "--tracker", tracker, "--overwrite"]
            t_track = t_analyze = float("inf")
            for _ in range(args.repeat):
                tracks = folder / f"{tracker}.csv"
                t_track = min(t_track, _run(["track", str(video), *options, "--out", str(tracks)]))
                out = folder / f"run_{tracker}"
                took = _run(["analyze", str(video), *options, "--out", str(out)])
                if took < t_analyze:
                    t_analyze = took
                    runtime = json.loads((out / "summary.json").read_text())["runtime_s"]
            spent = ", ".join(f"{runtime.get(part, float('nan')):.2f}" for part in parts)
            print(
                f"| {tracker} | {t_track:.1f} | {t_analyze:.1f} | {t_analyze / t_track:.2f} | "
                f"{spent} |"
            )


if __name__ == "__main__":
    main()
