"""Speed and memory of ``mpm3d analyze`` against scikit-image's marching cubes.

Renders a synthetic two-channel MPM stack (240 x 1024 x 1024 voxels per
channel by default, 1.24 um pixels and a 4 um z-step as in the source
paper, folds with known geometry), writes it as an ImageJ hyperstack, then
in two fresh processes:

1. the whole ``python -m mpm3d analyze`` (read, surface, metrics,
   isosurface, every output file and figure), timed end to end;
2. ``skimage.measure.marching_cubes`` alone on the same volume (the channel
   combination ``analyze`` uses, already in memory, at the same grey level),
   the baseline.

Prints both times, their ratio, each process's peak resident memory against
the stack's size on disk, and the accuracy of the analysis against the
truth.

    python bench/bench_mpm3d.py [--size 1024] [--slices 240] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

from sample_data_synth import make_stack_case, write_stack

CHILD = textwrap.dedent(
    """
    import json, resource, sys, time
    what, stack, out = sys.argv[1:4]
    t0 = time.perf_counter()
    if what == "analyze":
        from mpm3d.cli import main
        code = main(["analyze", stack, "--out", out, "-q", "--overwrite"])
        assert code == 0, code
        seconds = time.perf_counter() - t0
    else:
        from skimage.measure import marching_cubes
        from mpm3d.io import read_stack, select_channel
        level = float(sys.argv[4])
        st = read_stack(stack)
        volume, _ = select_channel(st)
        t0 = time.perf_counter()
        verts, faces, _, _ = marching_cubes(volume, level, spacing=st.spacing)
        seconds = time.perf_counter() - t0
        out = len(faces)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"seconds": seconds, "peak_bytes": peak, "extra": out}))
    """
)


def _child(*args: str) -> dict:
    res = subprocess.run(
        [sys.executable, "-c", CHILD, *args], capture_output=True, text=True, check=False
    )
    if res.returncode != 0:
        raise SystemExit(f"{args[0]} failed:\n{res.stderr}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=1024, help="pixels per side (1024)")
    parser.add_argument("--slices", type=int, default=240, help="z slices (240)")
    parser.add_argument("--keep", help="keep the stack and the analysis in this folder")
    args = parser.parse_args()

    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_mpm3d-"))
    work.mkdir(parents=True, exist_ok=True)
    stack_path = work / "after.tif"
    t0 = time.perf_counter()
    case = make_stack_case(
        "after",
        size=args.size,
        spacing=(4.0, 1.24 * 1024 / args.size, 1.24 * 1024 / args.size),
        n_slices=args.slices,
        fold_height_range_um=(500.0, 750.0),
        rng=0,
    )
    write_stack(stack_path, case)
    nbytes = stack_path.stat().st_size
    del case.stack
    print(
        f"stack: {args.slices} x {args.size} x {args.size} voxels x 2 channels (uint16), "
        f"{nbytes / 2**20:.0f} MiB, rendered in {time.perf_counter() - t0:.0f} s"
    )

    # warm the numba cache and the page cache so neither run pays for them
    _child("analyze", str(stack_path), str(work / "warmup"))
    analysis = _child("analyze", str(stack_path), str(work / "analysis"))
    metrics = json.loads((work / "analysis" / "metrics.json").read_text())
    mc = _child("skimage", str(stack_path), "-", str(metrics["surface_level"]))

    ratio = analysis["seconds"] / mc["seconds"]
    print("\n| step | time (s) | peak memory | peak / stack size |")
    print("|---|---|---|---|")
    for label, r in (
        ("skimage marching_cubes alone (baseline)", mc),
        ("mpm3d analyze, whole (read, surface, metrics, mesh, files, figures)", analysis),
    ):
        print(
            f"| {label} | {r['seconds']:.1f} | {r['peak_bytes'] / 2**30:.2f} GiB | "
            f"{r['peak_bytes'] / nbytes:.2f} |"
        )
    print(f"\nanalyze / marching_cubes time ratio: {ratio:.2f} (bar: <= 0.5)")
    print(
        f"marching cubes made {mc['extra']:,} triangles; "
        f"analyze's surface has {metrics['n_surface_triangles']:,}"
    )
    truth = case.info
    print(
        "accuracy: wavelength {:.1f} um (truth {:.1f}), median fold height {:.1f} um "
        "(truth {:.1f}), max {:.1f} (truth {:.1f}), orientation {:.2f} deg (truth {:.1f})".format(
            metrics["fold_wavelength_um"],
            truth["wavelength_um"],
            metrics["fold_height_um"],
            truth["median_fold_height_um"],
            metrics["max_fold_height_um"],
            truth["max_fold_height_um"],
            metrics["fold_orientation_deg"],
            truth["orientation_deg"],
        )
    )
    import tifffile

    height = tifffile.imread(work / "analysis" / "heightmap.tif")[0]
    err = height - case.height_um
    print(f"height map RMS error {np.sqrt(np.mean(err**2)):.2f} um (z-step 4 um)")
    if not args.keep:
        import shutil

        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
