"""An 8-specimen batch run one specimen after the other, then on a local Dask cluster.

Renders the synthetic study of the demo (``sample_data_synth study``: 8
specimens of 352 x 352 px, 25 frames, two groups) and runs
``strain2d batch`` on it twice in this script: ``--workers 1`` (every run in
one process, one after the other: the baseline) and ``--workers 2`` (a local
Dask cluster of two worker processes).  Each batch analyzes every specimen
(7 x 7 grid, the default tracker, figures, report and animation) and then
builds the study.  Prints the wall time of each, its CPU time (every process
of the batch: Dask's workers, ffmpeg), the cores it kept busy on average, the
speedup, the most the one-process batch's own parallelism leaves for the
cores there are, and whether the
two batch folders hold the same results (``tissue_core.batch.differences``:
every table, figure and ParaView file byte for byte, the JSON results without
time stamps and run times).

    python bench/bench_batch.py [--workers 2] [--specimens-per-group 4] [--frames N] [--keep DIR]
"""

from __future__ import annotations

import argparse
import csv
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from tissue_core.batch import differences


def _run(argv: list[str]) -> tuple[float, float]:
    """Run ``python -m ARGV``; its wall time and the CPU time of it and every process it waited
    for (Dask's workers, ffmpeg), in seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", *argv], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        sys.exit(f"{' '.join(argv)} failed:\n{done.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return seconds, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2, help="local cluster size (2)")
    parser.add_argument("--specimens-per-group", type=int, default=4, help="(4: 8 specimens)")
    parser.add_argument("--frames", type=int, default=25, help="frames per video (25)")
    parser.add_argument("--keep", help="keep the data and both batch folders here")
    args = parser.parse_args()
    root = Path(args.keep or tempfile.mkdtemp(prefix="bench_batch_"))
    root.mkdir(parents=True, exist_ok=True)
    try:
        data = root / "data"
        shutil.rmtree(data, ignore_errors=True)
        _run(["sample_data_synth", "-q", "study", "--per-group", str(args.specimens_per_group),
              "--frames", str(args.frames), "--out", str(data)])  # fmt: skip
        with open(data / "manifest.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        roi = rows[0]["roi"]
        common = [str(data / "manifest.csv"), "--grid", "7x7", "--roi", roi, "--fps", "10"]
        times, cpu = {}, {}
        for label, workers in (("sequential", 1), ("cluster", args.workers)):
            out = root / label
            shutil.rmtree(out, ignore_errors=True)
            times[label], cpu[label] = _run(["strain2d", "-q", "batch", *common, "--workers",
                                             str(workers), "--out", str(out)])  # fmt: skip
        diff = differences(root / "sequential", root / "cluster")
        cores = os.cpu_count() or 1
        print(
            f"{len(rows)} specimens (sample_data_synth study: 352x352 px, {args.frames} frames), "
            f"{cores} cores"
        )
        print()
        print("| batch | workers | wall (s) | CPU (s) | cores busy | speedup |")
        print("|---|---|---|---|---|---|")
        busy = {label: cpu[label] / times[label] for label in times}
        print(f"| one process, one run after the other | 1 | {times['sequential']:.1f} | "
              f"{cpu['sequential']:.1f} | {busy['sequential']:.2f} | 1.00 |")  # fmt: skip
        speedup = times["sequential"] / times["cluster"]
        print(f"| local Dask cluster | {args.workers} | {times['cluster']:.1f} | "
              f"{cpu['cluster']:.1f} | {busy['cluster']:.2f} | {speedup:.2f} |")  # fmt: skip
        print()
        # the one-process batch is not one core's work: ffmpeg encodes each animation beside the
        # process drawing it, and the tracker's kernels and BLAS use every core
        print(f"the one-process batch keeps {busy['sequential']:.2f} cores busy, so {cores} cores "
              f"allow at most {cores / busy['sequential']:.2f}x; the cluster used "
              f"{busy['cluster'] / cores:.0%} of the cores")  # fmt: skip
        if diff:
            print(f"results DIFFER in {len(diff)} files: {'; '.join(diff[:5])}")
        else:
            print("results identical: every run and the study (tissue_core.batch.differences)")
    finally:
        if not args.keep:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
