"""Memory of ``strain2d analyze`` on long videos: 3,000 frames against 300.

Writes two synthetic films of a lab's kind (512 x 512 px speckle, 30 fps, a
periodic equibiaxial contraction of up to 10 % with a 2 s period, sensor
noise drawn afresh for every frame) of 300 and 3,000 frames, frame by frame
with OpenCV's VideoWriter (one period is rendered with sample_data_synth and
reused, so the script never holds the video).  Then runs, as a user would,
``python -m strain2d analyze VIDEO --grid G --tracker NAME --out DIR`` (the
default figures, MP4 animation and report) on each, and prints each run's
peak resident memory (the child's own, from ``os.wait4``), the ratio of the
3,000-frame run to the 300-frame one, and wall times.  The target of issue 17
is a ratio of at most 1 (within a few MiB of noise).

The default (klt, 7x7 grid, every output) takes about two minutes on 2
cores (the 3,000-frame run about one, most of it the animation); ``--trackers gdic,klt --grids
7x7,15x15`` is the whole matrix (over an hour), ``--animation none`` leaves
the animation out of a sweep.

    python bench/bench_long_video.py [--quick] [--frames 300,3000]
        [--grids 7x7,15x15] [--trackers gdic,klt] [--animation none] [--size 512]
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FPS = 30.0
PERIOD_S = 2.0
STRETCH = 0.9  # smallest stretch of the contraction (x and y)


def write_film(path: Path, n_frames: int, size: int, *, rng: int = 0) -> None:
    """A periodic contraction film, written one frame at a time (FFV1 AVI, lossless)."""
    import cv2

    from sample_data_synth.deformations import Homogeneous
    from sample_data_synth.render import add_sensor_noise, render_speckle
    from sample_data_synth.speckle import speckle_pattern

    period = round(PERIOD_S * FPS)
    c = (size - 1) / 2
    pattern = speckle_pattern((-20, -20, size + 20, size + 20), radius=2.0, rng=rng)
    deformation = Homogeneous("stretch", (c, c), lx=STRETCH, ly=STRETCH)
    # one period, rendered once: frame k shows phase k % period (t in [0, 1])
    phase = [(1 - np.cos(2 * np.pi * k / period)) / 2 for k in range(period)]
    cycle = [render_speckle(pattern, deformation, t, (size, size)) for t in phase]
    writer = cv2.VideoWriter(
        str(path), cv2.VideoWriter_fourcc(*"FFV1"), FPS, (size, size), isColor=False
    )
    if not writer.isOpened():
        raise OSError(f"OpenCV cannot write {path}")
    noise = np.random.default_rng(rng + 1)
    try:
        for k in range(n_frames):
            writer.write(add_sensor_noise(cycle[k % period], rng=noise))
    finally:
        writer.release()


def run_analyze(argv: list[str]) -> tuple[float, float]:
    """Run ``python -m strain2d analyze ...``: (peak RSS in MiB, wall time in s)."""
    start = time.perf_counter()
    child = subprocess.Popen([sys.executable, "-m", "strain2d", "-q", "analyze", *argv])
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    seconds = time.perf_counter() - start
    if child.returncode != 0:
        raise SystemExit(f"strain2d analyze {' '.join(argv)} failed ({child.returncode})")
    return usage.ru_maxrss / 1024, seconds  # KiB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", default="300,3000", help="two lengths (default 300,3000)")
    parser.add_argument("--grids", default="7x7", help="comma-separated, e.g. 7x7,15x15 (7x7)")
    parser.add_argument(
        "--trackers", default="klt", help="comma-separated, e.g. gdic,klt (klt; gdic is slower)"
    )
    parser.add_argument(
        "--animation", default="mp4", help="analyze's --animation (mp4; none for quick sweeps)"
    )
    parser.add_argument("--size", type=int, default=512, help="frame side in px (512)")
    parser.add_argument(
        "--quick", action="store_true", help="200 and 1,000 frames (about 4 minutes on 2 cores)"
    )
    args = parser.parse_args()
    if args.quick:
        args.frames = "200,1000"
    lengths = [int(v) for v in args.frames.split(",")]
    if len(lengths) != 2:
        parser.error("--frames takes two lengths, e.g. 300,3000")
    print(
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores; "
        f"{args.size}x{args.size} px at {FPS:g} fps, periodic contraction to {STRETCH:g}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        videos = {}
        for n in lengths:
            videos[n] = folder / f"film_{n}.avi"
            t0 = time.perf_counter()
            write_film(videos[n], n, args.size)
            print(f"wrote {n} frames in {time.perf_counter() - t0:.0f} s")
        short, long = lengths
        print(
            f"| tracker | grid | peak RSS {short} (MiB) | peak RSS {long} (MiB) | "
            f"ratio {long}/{short} | wall {short} (s) | wall {long} (s) |"
        )
        print("|---|---|---|---|---|---|---|")
        for tracker in args.trackers.split(","):
            for grid in args.grids.split(","):
                peaks, walls = {}, {}
                for n in lengths:
                    out = folder / f"run_{tracker}_{grid}_{n}"
                    argv = [str(videos[n]), "--grid", grid, "--tracker", tracker, "--fps", "30"]
                    argv += ["--animation", args.animation, "--out", str(out)]
                    peaks[n], walls[n] = run_analyze(argv)
                print(
                    f"| {tracker} | {grid} | {peaks[short]:.0f} | {peaks[long]:.0f} | "
                    f"{peaks[long] / peaks[short]:.2f} | {walls[short]:.0f} | {walls[long]:.0f} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
