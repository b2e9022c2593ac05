"""What the figures cost: ``strain2d analyze`` against ``strain2d track`` on the same input.

Renders the paper's equibiaxial case (800 x 800 px, 31 frames) to a lossless
AVI, then runs, as a user would, ``python -m strain2d track`` and ``python -m
strain2d analyze`` (default figures: maps, curves, violins, the MP4 animation,
the report) with the same grid and tracker, and prints each command's wall
time, their ratio, and where analyze's time went (from its summary.json).
The target of issue 16 is a ratio of at most 2.

    python bench/bench_analyze.py [--grid 13] [--trackers gdic,klt] [--frames 31]
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
    parser.add_argument("--trackers", default="gdic,klt", help="comma-separated (gdic,klt)")
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
        print("| tracker | track (s) | analyze (s) | analyze / track | tracking, figures (s) |")
        print("|---|---|---|---|---|")
        for tracker in args.trackers.split(","):
            options = [*grid, "--tracker", tracker]
            t_track = _run(["track", str(video), *options, "--out", str(folder / f"{tracker}.csv")])
            out = folder / f"run_{tracker}"
            t_analyze = _run(["analyze", str(video), *options, "--out", str(out)])
            runtime = json.loads((out / "summary.json").read_text())["runtime_s"]
            print(
                f"| {tracker} | {t_track:.1f} | {t_analyze:.1f} | {t_analyze / t_track:.2f} | "
                f"{runtime['tracking']:.1f}, {runtime['figures']:.1f} |"
            )


if __name__ == "__main__":
    main()
