"""What the figures cost: ``strain2d analyze`` against ``strain2d track`` on the same input.

Renders the paper's equibiaxial case (800 x 800 px, 31 frames, a 13 x 13
grid) and, with ``--sheet``, the full-HD muscle sheet
(:mod:`sample_data_synth.sheet`: 1920 x 1080 px, 41 frames, its 29 x 15 grid)
to lossless AVIs, then runs, as a user would, ``python -m strain2d track`` and ``python -m
strain2d analyze`` (default figures: maps, curves, violins, the MP4 animation,
the report) with the same grid and tracker, and prints each command's wall
time, their ratio, and where analyze's time went (from its summary.json's
``runtime_s``: tracking, strain, the tables and ParaView series, the
animation, when the last figure was done (the figures are drawn by worker
processes meanwhile), the summary and report, and all the writing).
The targets: ``analyze`` at most 1.3 times ``track`` with the default
tracker, at most 2 times with ``klt``.

    python bench/bench_analyze.py [--grid 13] [--trackers gdic,dic,klt] [--frames 31]
                                  [--repeat 1] [--sheet]

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


def _cases(folder: Path, args) -> list[tuple[str, Path, list[str]]]:
    """(name, video, grid options) of each case, rendered into ``folder``."""
    video = folder / "equibiaxial.avi"
    write_video(make_case("equibiaxial", size=800, n_frames=args.frames, rng=0).frames, video)
    cases = [
        (
            f"equibiaxial 800x800, {args.frames} frames, {args.grid}x{args.grid} grid",
            video,
            ["--grid", f"{args.grid}x{args.grid}"],
        )
    ]
    if args.sheet:
        from sample_data_synth.sheet import SHEET_GRID, make_muscle_sheet

        sheet = make_muscle_sheet(rng=0)
        path = folder / "sheet.avi"
        write_video(sheet.frames, path)
        x0, y0, x1, y1 = (round(v) for v in sheet.truth.roi)
        nx, ny = SHEET_GRID
        cases.append(
            (
                f"muscle sheet 1920x1080, {len(sheet.frames)} frames, {nx}x{ny} grid",
                path,
                ["--grid", f"{nx}x{ny}", "--roi", f"{x0},{y0},{x1},{y1}"],
            )
        )
        del sheet
    return cases


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=13, help="points per side (default 13)")
    parser.add_argument("--frames", type=int, default=31, help="frames (default 31)")
    parser.add_argument("--trackers", default="gdic,klt", help="comma-separated (gdic,dic,klt)")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each command (default 1)")
    parser.add_argument(
        "--sheet", action="store_true", help="the full-HD muscle sheet too (about a minute more)"
    )
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cases = _cases(folder, args)
        _run(["track", str(cases[0][1]), *cases[0][2], "--tracker", "klt", "--out",
              str(folder / "w.csv")])  # fmt: skip
        print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores")
        parts = ("tracking", "strain", "tables", "animation", "figures", "report", "outputs")
        print(
            f"| case | tracker | track (s) | analyze (s) | analyze / track | "
            f"{', '.join(parts)} (s) |"
        )
        print("|---|---|---|---|---|---|")
        for name, video, grid in cases:
            for tracker in args.trackers.split(","):
                options = [*grid, "--tracker", tracker, "--overwrite"]
                t_track = t_analyze = float("inf")
                for _ in range(args.repeat):
                    tracks = folder / f"{tracker}.csv"
                    t_track = min(
                        t_track, _run(["track", str(video), *options, "--out", str(tracks)])
                    )
                    out = folder / f"run_{tracker}"
                    took = _run(["analyze", str(video), *options, "--out", str(out)])
                    if took < t_analyze:
                        t_analyze = took
                        runtime = json.loads((out / "summary.json").read_text())["runtime_s"]
                spent = ", ".join(f"{runtime.get(part, float('nan')):.2f}" for part in parts)
                print(
                    f"| {name} | {tracker} | {t_track:.1f} | {t_analyze:.1f} | "
                    f"{t_analyze / t_track:.2f} | {spent} |"
                )


if __name__ == "__main__":
    main()
