"""mpm3d analyze on a stack 4x larger than its memory limit: peak memory and equal metrics.

1. Equal metrics: a rendered 256 x 256 px two-channel stack (small enough for
   both paths) analysed in memory and in bands of 16 rows (``--tile-rows
   16``); every value of metrics.json (but the path record), the height map
   and the mesh must be equal.  Prints the time of each and their ratio.
2. Bounded memory: a stack of ``--size`` (6 GiB by default) written page by
   page into a temporary folder (a rendered 1024 x 1024 px folded surface,
   its deepest slices repeated below to make up the size: never in memory
   whole), then ``mpm3d analyze --memory-limit LIMIT`` (1.5 GiB by default)
   in a subprocess; its peak resident memory (``wait4``'s ``ru_maxrss`` of
   that process) against the limit and the stack's size; with ``--baseline``
   also the in-memory path's on the same stack (peak and time ratios).

3. A wide field of view: a one-channel 8-bit stack of 240 x 4096 x 4096 px
   (3.75 GiB; ``--wide``), a rendered 1024 px surface mirrored tile by tile,
   then ``mpm3d analyze --memory-limit 1GiB`` (``--wide-limit``), figures and
   the isosurface included (some 20 million triangles, streamed through files):
   its peak resident memory, and with ``--baseline`` the in-memory run's,
   whose metrics.json, height map, surface intensity and mesh (surface.ply,
   byte for byte) must be equal.

    python bench/bench_mpm3d_memory.py [--size 6GiB] [--limit 1.5GiB] [--keep DIR] [--baseline]
        [--wide 240x4096x4096] [--wide-limit 1GiB] [--only equal|bounded|wide]
"""

from __future__ import annotations

import argparse
import filecmp
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: the record of the path taken: the only part of metrics.json the paths may differ in
PATH_RECORD = ("parameters", "memory")


#: runs ``python -m mpm3d analyze ARGS...`` and prints its peak RSS: a small process of its own,
#: since a child's ru_maxrss also counts the memory of the process it was forked from
LAUNCHER = """
import os, subprocess, sys
proc = subprocess.Popen([sys.executable, "-m", "mpm3d", "analyze", *sys.argv[1:]],
                        stdout=subprocess.DEVNULL)
_, status, usage = os.wait4(proc.pid, 0)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss * 1024)
"""


def run_analyze(stack: Path, out: Path, *options: str) -> tuple[float, int]:
    """``python -m mpm3d analyze``: (seconds, peak RSS bytes of that process)."""
    argv = [sys.executable, "-c", LAUNCHER, str(stack), "--out", str(out), *options]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    t0 = time.perf_counter()
    done = subprocess.run(argv, cwd=REPO, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - t0
    status, peak = (int(v) for v in done.stdout.split())
    if status != 0:
        raise SystemExit(f"mpm3d analyze failed ({status}):\n{done.stderr}")
    return seconds, peak


def without_path_record(metrics: dict) -> dict:
    out = json.loads(json.dumps(metrics))
    out[PATH_RECORD[0]].pop(PATH_RECORD[1])
    out.pop("command", None)
    return out


def equal_metrics(folder: Path) -> None:
    import tifffile

    from sample_data_synth import make_stack_case, write_stack

    case = make_stack_case("before", size=256, spacing=(4.0, 2.5, 2.5), rng=3)
    stack = folder / "small.tif"
    write_stack(stack, case)
    size = stack.stat().st_size
    print(f"equal metrics: {case.stack.shape} (Z, C, Y, X) uint16 stack, {size / 2**20:.0f} MiB")
    runs = {}
    for name, options in (("in-memory", ()), ("tiled", ("--tile-rows", "16"))):
        out = folder / f"small_{name}"
        seconds, peak = run_analyze(stack, out, "--no-figures", *options)
        metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
        runs[name] = (out, metrics, seconds)
        record = metrics["parameters"]["memory"]
        bands = f", {record['tile_rows']} rows a band" if name == "tiled" else ""
        print(
            f"  {name:9s} {seconds:6.1f} s  peak RSS {peak / 2**20:6.0f} MiB  "
            f"(path {record['path']}{bands})"
        )
    (a, ma, ta), (b, mb, tb) = runs["in-memory"], runs["tiled"]
    same = without_path_record(ma) == without_path_record(mb)
    differing = [k for k in ma if ma[k] != mb[k]]
    read = tifffile.imread
    maps = np.array_equal(read(a / "heightmap.tif"), read(b / "heightmap.tif"))
    import pyvista as pv

    sa, sb = pv.read(a / "surface.vtp"), pv.read(b / "surface.vtp")
    mesh = sa.n_points == sb.n_points and np.array_equal(sa.points, sb.points)
    mesh = mesh and np.array_equal(sa.regular_faces, sb.regular_faces)
    print(
        f"  metrics.json equal (all but {'.'.join(PATH_RECORD)}): {same}"
        f"{'' if same else f' (differ: {differing})'}; height maps equal: {maps}; "
        f"meshes equal ({sa.n_points} points, {sa.n_cells} triangles): {mesh}"
    )
    print(f"  tiled / in-memory time: {tb / ta:.2f}")
    if not (same and maps and mesh):
        raise SystemExit("the tiled path's results differ from the in-memory path's")


def _empty_stack(path: Path, shape, dtype, axes: str, spacing) -> int:
    """Write the header of an empty contiguous ImageJ stack; the data's offset. tifffile
    writes the header only; the slices are then written at their offsets (no memory map:
    the stack is never in this process's memory)."""
    import tifffile

    with warnings.catch_warnings():  # over 4 GiB ImageJ files have one IFD: as ImageJ writes them
        warnings.filterwarnings("ignore", ".*truncating ImageJ file", UserWarning)
        mm = tifffile.memmap(
            path,
            shape=shape,
            dtype=dtype,
            imagej=True,
            resolution=(1 / spacing[2], 1 / spacing[1]),
            metadata={"axes": axes, "spacing": spacing[0], "unit": "um"},
        )
        offset = mm.offset
        del mm  # the header is written here
    return offset


def _slice(base: np.ndarray, z: int) -> np.ndarray:
    """Slice ``z`` of a rendered stack made deeper: its deepest 16 slices repeated below."""
    if z < base.shape[0]:
        return base[z]
    tail = base[-16:]
    return tail[(z - base.shape[0]) % len(tail)]


def write_big_stack(path: Path, target_bytes: int, *, size: int = 1024) -> tuple[int, ...]:
    """A two-channel ImageJ stack of about ``target_bytes``, written page by page
    (:func:`_empty_stack`).

    A folded surface rendered with its natural depth (sample_data_synth),
    then its deepest 16 slices repeated below: tissue, as deep as the size
    asks.
    """
    from sample_data_synth import make_stack_case

    spacing = (4.0, 2.5, 2.5)
    case = make_stack_case("before", size=size, spacing=spacing, rng=5)
    base = case.stack
    nz = max(base.shape[0], math.ceil(target_bytes / (2 * size * size * 2)))
    shape = (nz, 2, size, size)
    offset = _empty_stack(path, shape, np.uint16, "ZCYX", spacing)
    with open(path, "r+b") as f:
        for z in range(nz):
            page = _slice(base, z)
            data = np.ascontiguousarray(page, "<u2").tobytes()
            os.pwrite(f.fileno(), data, offset + z * len(data))
    return shape


def bounded_memory(folder: Path, size_text: str, limit_text: str, *, baseline: bool) -> None:
    from mpm3d.tiled import parse_memory

    target, limit = parse_memory(size_text), parse_memory(limit_text)
    stack = folder / "big.tif"
    t0 = time.perf_counter()
    shape = write_big_stack(stack, target)
    written = stack.stat().st_size
    print(
        f"bounded memory: {shape} (Z, C, Y, X) uint16 stack, {written / 2**30:.2f} GiB "
        f"written in {time.perf_counter() - t0:.0f} s"
    )
    out = folder / "big_out"
    seconds, peak = run_analyze(stack, out, "--memory-limit", limit_text)
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    record = metrics["parameters"]["memory"]
    print(
        f"  mpm3d analyze --memory-limit {limit_text}: {seconds:.0f} s, path {record['path']}, "
        f"{record.get('tile_rows')} rows a band (height map), "
        f"{record.get('surface_tile_rows')} binned rows a band (isosurface)"
    )
    print(
        f"  stack {written / 2**30:.2f} GiB = {written / limit:.2f}x the limit "
        f"{limit / 2**30:.2f} GiB; peak RSS {peak / 2**30:.2f} GiB = {peak / limit:.2f}x the limit "
        f"(model's estimate {record.get('estimated_peak_bytes', 0) / 2**30:.2f} GiB)"
    )
    print(
        f"  fold wavelength {metrics['fold_wavelength_um']:.1f} um, fold height "
        f"{metrics['fold_height_um']:.1f} um, {metrics['n_surface_triangles']} triangles"
    )
    if baseline:
        whole = folder / "big_in_memory"
        seconds0, peak0 = run_analyze(stack, whole, "--memory-limit", "1TiB")
        metrics0 = json.loads((whole / "metrics.json").read_text(encoding="utf-8"))
        same = without_path_record(metrics0) == without_path_record(metrics)
        print(f"  metrics.json of the two paths equal (all but {'.'.join(PATH_RECORD)}): {same}")
        print(
            f"  baseline, the same stack in memory: {seconds0:.0f} s, peak RSS "
            f"{peak0 / 2**30:.2f} GiB; banded / in-memory: peak {peak / peak0:.2f}, "
            f"time {seconds / seconds0:.2f}"
        )
        if not same:
            raise SystemExit("the tiled path's metrics differ from the in-memory path's")
    if peak > limit:
        raise SystemExit("peak memory over the limit")


def write_wide_stack(path: Path, shape: tuple[int, int, int], *, size: int = 1024) -> None:
    """A one-channel 8-bit stack of ``shape`` (Z, Y, X), written page by page: the
    urothelium channel of a folded surface rendered at ``size`` px, mirrored tile by tile
    across the field (the folds run on across each seam), its deepest 16 slices repeated
    below to make up the slices."""

    from sample_data_synth import make_stack_case

    nz, ny, nx = shape
    spacing = (4.0, 2.5, 2.5)
    case = make_stack_case("before", size=size, spacing=spacing, rng=5)
    base = case.stack[:, 1]  # the urothelium, whose top is the lumen's surface
    base = (base.astype(np.float32) * (255.0 / max(1, int(base.max())))).astype(np.uint8)
    tiles_y, tiles_x = math.ceil(ny / size), math.ceil(nx / size)
    offset = _empty_stack(path, shape, np.uint8, "ZYX", spacing)
    with open(path, "r+b") as f:
        for z in range(nz):
            page = _slice(base, z)
            row = np.concatenate([page if j % 2 == 0 else page[:, ::-1] for j in range(tiles_x)], 1)
            plane = np.concatenate([row if i % 2 == 0 else row[::-1] for i in range(tiles_y)])
            plane = plane[:ny, :nx]
            data = np.ascontiguousarray(plane).tobytes()
            os.pwrite(f.fileno(), data, offset + z * len(data))


def wide_field(folder: Path, shape_text: str, limit_text: str, *, baseline: bool) -> None:
    """A wide field of view (4096 x 4096 px by default) within the limit: the (Y, X) maps'
    work on disk and in bands (mpm3d.diskmaps), the mesh through files
    (mpm3d.meshstream)."""
    from mpm3d.tiled import parse_memory

    shape = tuple(int(n) for n in shape_text.lower().split("x"))
    if len(shape) != 3:
        raise SystemExit(f"--wide must be ZxYxX, got {shape_text!r}")
    limit = parse_memory(limit_text)
    stack = folder / "wide.tif"
    t0 = time.perf_counter()
    write_wide_stack(stack, shape)
    written = stack.stat().st_size
    print(
        f"wide field: {shape} (Z, Y, X) uint8 stack, {written / 2**30:.2f} GiB written in "
        f"{time.perf_counter() - t0:.0f} s"
    )
    out = folder / "wide_out"
    seconds, peak = run_analyze(stack, out, "--memory-limit", limit_text)
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    record = metrics["parameters"]["memory"]
    print(
        f"  mpm3d analyze --memory-limit {limit_text}: {seconds:.1f} s, path "
        f"{record['path']}, {record.get('tile_rows')} rows a band (height map), "
        f"{record.get('surface_tile_rows')} binned rows a band and "
        f"{record.get('mesh_piece_rows')} a piece (mesh), "
        f"{metrics['n_surface_triangles']:,} triangles; peak RSS "
        f"{peak / 2**30:.2f} GiB = {peak / limit:.2f}x the limit (model's estimate "
        f"{record.get('estimated_peak_bytes', 0) / 2**30:.2f} GiB)"
    )
    if baseline:
        import tifffile

        whole = folder / "wide_in_memory"
        seconds0, peak0 = run_analyze(stack, whole, "--memory-limit", "1TiB")
        metrics0 = json.loads((whole / "metrics.json").read_text(encoding="utf-8"))
        same = without_path_record(metrics0) == without_path_record(metrics)
        maps = all(
            np.array_equal(tifffile.imread(out / f), tifffile.imread(whole / f), equal_nan=True)
            for f in ("heightmap.tif", "surface_intensity.tif")
        )
        mesh = filecmp.cmp(out / "surface.ply", whole / "surface.ply", shallow=False)
        print(
            f"  in memory: {seconds0:.1f} s, peak RSS {peak0 / 2**30:.2f} GiB; banded / in "
            f"memory: peak {peak / peak0:.2f}, time {seconds / seconds0:.2f}; metrics.json "
            f"equal (all but {'.'.join(PATH_RECORD)}): {same}; height map and intensity "
            f"equal: {maps}; mesh equal (surface.ply): {mesh}"
        )
        if not (same and maps and mesh):
            raise SystemExit("the banded path's results differ from the in-memory path's")
    if peak > limit:
        raise SystemExit("peak memory over the limit")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="6GiB", help="size of the large stack (6GiB)")
    parser.add_argument("--limit", default="1.5GiB", help="memory limit for it (1.5GiB)")
    parser.add_argument("--keep", metavar="DIR", help="work in DIR and keep the files")
    parser.add_argument(
        "--baseline",
        action="store_true",
        help="also analyse the large stack in memory (needs some 2.5x its size of free memory)",
    )
    parser.add_argument(
        "--wide",
        default="240x4096x4096",
        help="Z x Y x X of the wide one-channel 8-bit stack (240x4096x4096; 0 skips it)",
    )
    parser.add_argument("--wide-limit", default="1GiB", help="memory limit for it (1GiB)")
    parser.add_argument("--only", choices=("equal", "bounded", "wide"), help="run one part alone")
    args = parser.parse_args()
    folder = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_mpm3d_mem_"))
    folder.mkdir(parents=True, exist_ok=True)
    try:
        if args.only in (None, "equal"):
            equal_metrics(folder)
        if args.only in (None, "bounded"):
            bounded_memory(folder, args.size, args.limit, baseline=args.baseline)
        if args.only in (None, "wide") and args.wide != "0":
            wide_field(folder, args.wide, args.wide_limit, baseline=args.baseline)
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
