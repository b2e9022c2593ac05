"""mpm3d analyze on a microscope mosaic against the whole stack: time, peak memory, metrics.

Renders the folded "after" stack (``--size`` px, 2.5 um pixels, 4 um z-step), cuts it
into a 3 x 3 mosaic with 10 % overlap and stage errors (``sample_data_synth stack
--tiles``), then runs, each in a process of its own, ``mpm3d analyze tiles.csv
--memory-limit LIMIT`` (read a band at a time) and ``mpm3d analyze after.tif`` (in
memory), and prints each run's time and peak resident memory, their ratios, and whether
every metric of metrics.json is equal (all but the inputs and the memory path's record).
The numbers docs/mpm3d_mosaics.md and the README quote.

    python bench/bench_mosaic.py [--size 1024] [--limit 1.3GiB] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mpm3d_memory import REPO, run_analyze  # the same peak-RSS launcher

#: what may differ between the mosaic's run and the stack's: what was read, and how
ABOUT_INPUT = {"inputs", "input", "input_path", "parameters", "command", "warnings"}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=1024, help="stack side in px (1024)")
    parser.add_argument("--limit", default="1.3GiB", help="the mosaic run's memory limit")
    parser.add_argument("--keep", help="render into this folder and keep it")
    args = parser.parse_args()
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_mosaic_"))
    try:
        data = folder / "data"
        subprocess.run(
            [sys.executable, "-m", "sample_data_synth", "stack", "--case", "after", "--size",
             str(args.size), "--tiles", "3x3", "--overlap", "0.1", "--out", str(data), "-q",
             "--overwrite"],
            cwd=REPO, check=True,
        )  # fmt: skip
        t_mosaic, peak_mosaic = run_analyze(
            data / "after_tiles" / "tiles.csv", folder / "run_tiles", "--memory-limit",
            args.limit, "-q", "--overwrite",
        )  # fmt: skip
        t_whole, peak_whole = run_analyze(
            data / "after.tif", folder / "run_whole", "-q", "--overwrite"
        )
        a = json.loads((folder / "run_tiles" / "metrics.json").read_text(encoding="utf-8"))
        b = json.loads((folder / "run_whole" / "metrics.json").read_text(encoding="utf-8"))
        keys = [k for k in a if k not in ABOUT_INPUT]
        differ = [k for k in keys if a[k] != b.get(k)]
        gib = 2**30
        print(f"3 x 3 mosaic of a {args.size} x {args.size} px folded stack")
        limit = f"--memory-limit {args.limit}"
        print(f"  mosaic, {limit}: {t_mosaic:.1f} s, peak {peak_mosaic / gib:.2f} GiB")
        print(f"  whole stack, in memory: {t_whole:.1f} s, peak {peak_whole / gib:.2f} GiB")
        print(
            f"  mosaic / stack: time {t_mosaic / t_whole:.2f}, peak {peak_mosaic / peak_whole:.2f}"
        )
        print(f"  metrics equal: {len(keys) - len(differ)} of {len(keys)}"
              + (f" (differ: {', '.join(differ)})" if differ else ""))  # fmt: skip
        return 1 if differ else 0
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
