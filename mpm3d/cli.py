"""Command line: ``python -m mpm3d {analyze,stitch,compare,batch}``.

``analyze STACK.tif --out DIR`` measures one stack (see
:mod:`mpm3d.analyze` for the files it writes; ``--memory-limit 1.5GiB``
bounds its memory: a larger stack is read in bands, see :mod:`mpm3d.tiled`); ``compare BEFORE.tif
AFTER.tif --out DIR`` measures two and reports the change of every metric
(see :mod:`mpm3d.compare`).  Errors a user can cause end with one line on
stderr and exit status 2.
"""

from __future__ import annotations

import argparse

from mpm3d.errors import InputError
from tissue_core.cli import CommandLine

__all__ = ["main"]


def _number(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def _spacing(text: str):
    from mpm3d.io import parse_spacing

    try:
        return parse_spacing(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _memory(text: str) -> int:
    from mpm3d.tiled import parse_memory

    try:
        return parse_memory(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--memory-limit ")) from None


def _channel(text: str) -> int | str:
    return int(text) if text.isdigit() else text


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, help="output folder (must not exist, see --overwrite)")
    _stack_options(p)
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")


def _stack_options(p) -> None:
    """The options of analyze and compare but the inputs and the output (shared with batch)."""
    p.add_argument(
        "--channel",
        type=_channel,
        help="channel index or name (default: all channels, each scaled, combined by maximum)",
    )
    p.add_argument(
        "--spacing", type=_spacing, help="voxel spacing Z,Y,X in um (overrides metadata)"
    )
    p.add_argument(
        "--threshold", type=_number, help="surface detection level in grey values (default Otsu)"
    )
    p.add_argument(
        "--smooth", type=_number, metavar="UM", help="height-map smoothing sigma, um (1 pixel)"
    )
    p.add_argument(
        "--min-fold-height",
        type=_number,
        metavar="UM",
        help="least crest-to-trough height of a fold, um (a fifth of the height range)",
    )
    p.add_argument(
        "--iso-bin",
        type=int,
        metavar="N",
        help="average N x N pixels before the isosurface (default: voxels near cubic)",
    )
    p.add_argument(
        "--decimate",
        type=_number,
        default=0.0,
        metavar="F",
        help="fraction of the surface's triangles to remove (0)",
    )
    p.add_argument("--no-surface", action="store_true", help="skip the isosurface mesh")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")


def _memory_args(p) -> None:
    """How analyze may use memory (its results do not depend on it)."""
    p.add_argument(
        "--memory-limit",
        type=_memory,
        metavar="SIZE",
        help="memory the analysis may use, e.g. 1.5GiB, 800MB (default: half the memory "
        "available); a stack that would need more is read and analysed in bands of rows, "
        "with the same results",
    )
    p.add_argument(
        "--lazy", action="store_true", help="read and analyse the stack in bands even if it fits"
    )
    p.add_argument(
        "--tile-rows",
        type=int,
        metavar="N",
        help="rows of pixels per band (implies --lazy; default: as many as the limit allows)",
    )


def _build_parser() -> CommandLine:
    cli = CommandLine("mpm3d", "Multiphoton z-stacks to the lumen surface and its folds.")
    p = cli.command(
        "analyze", _cmd_analyze, help="measure the lumen surface and folds of one stack"
    )
    p.add_argument(
        "stack",
        help="z-stack: ImageJ hyperstack, OME-TIFF or multi-page TIFF; or a mosaic's tile "
        "list, a CSV file,x_um,y_um (each tile's stack and the stage position of its pixel "
        "(0, 0)), read as one stack a band at a time",
    )
    _common(p)
    _memory_args(p)
    p = cli.command(
        "stitch",
        _cmd_stitch,
        help="write a mosaic's tiles as one stack",
        description="Write the z-stack tiles listed in TILES (a CSV file,x_um,y_um: each "
        "tile's stack, relative to the CSV, and the stage position in um of its pixel (0, 0)) "
        "as one ImageJ TIFF stack, a plane at a time. Positions are rounded to the nearest "
        "pixel; where tiles overlap, each pixel comes from the tile whose centre is nearest. "
        "`mpm3d analyze TILES` reads the same stack without writing it.",
    )
    p.add_argument("tiles", help="the tile list (CSV file,x_um,y_um)")
    p.add_argument("--out", required=True, help="the stitched stack (.tif)")
    p.add_argument(
        "--spacing", type=_spacing, help="voxel spacing Z,Y,X in um (overrides the tiles')"
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing output file")
    p = cli.command("compare", _cmd_compare, help="compare two stacks (before / after)")
    p.add_argument("before", help="the first stack (e.g. before contraction)")
    p.add_argument("after", help="the second stack")
    p.add_argument(
        "--icp",
        choices=("auto", "on", "off"),
        default="auto",
        help="refine the alignment by ICP with open3d (auto: when installed)",
    )
    _common(p)

    p = cli.command(
        "batch",
        _cmd_batch,
        help="analyze many stacks as a batch (on a Dask cluster), with a table of their metrics",
        description="Analyze every stack named (or listed in a manifest CSV with a column "
        "stack, optionally name, and any analyze option by name, e.g. channel, spacing) into "
        "OUT/runs/NAME, each as one task on a local Dask cluster or a running scheduler, and "
        "list the headline metrics of every stack in OUT/metrics.csv. A failing stack is "
        "reported and the others go on; a rerun keeps the runs that are complete with the "
        "same parameters and makes the rest. Options given here apply to every run; a "
        "manifest column of the same name wins.",
        allow_abbrev=False,
    )
    p.add_argument("inputs", nargs="+", metavar="STACK", help="the stacks, or one manifest CSV")
    p.add_argument("--out", required=True, help="batch folder: runs/, metrics.csv, batch.log")
    from tissue_core.batch import RunOptions, add_batch_arguments

    add_batch_arguments(p, what="analyses", tables=["metrics.csv"])
    options = RunOptions(p, "analyze options, for every run")
    _stack_options(options)
    _memory_args(options)
    p.set_defaults(run_options=options)
    return cli


#: analyze's options that change how much memory it uses, never its results
_HOW_NOT_WHAT = ("--memory-limit=", "--lazy", "--tile-rows=")


def _cmd_batch(args) -> int:
    from pathlib import Path

    from mpm3d.batch import stack_rows, write_metrics_table
    from tissue_core.batch import (
        batch_folder,
        check_workers,
        manifest_jobs,
        raise_if_failed,
        run_batch,
    )

    rows = stack_rows(args.inputs)
    out = Path(args.out).resolve()
    jobs, _, unused = manifest_jobs(
        rows,
        out,
        args.run_options,
        args,
        module="mpm3d.cli",
        command="analyze",
        sources=[("stack", None)],
        name_column="name",
        summary="metrics.json",
        neutral=_HOW_NOT_WHAT,
    )
    workers = check_workers(args.workers, args.scheduler, len(jobs))
    if args.scheduler is None and workers > 1 and getattr(args, "memory_limit", None) is None:
        # analyze's default (half the memory available) is for one run on the machine
        from mpm3d.tiled import format_bytes
        from tissue_core.resources import available_memory

        share = format_bytes(int(available_memory() * 0.8 / workers))
        jobs = [job.with_options("--memory-limit", share) for job in jobs]
    folder = batch_folder(args.out)
    say = _progress(args)
    notes = [f"manifest columns not used: {', '.join(unused)}"] if unused else []
    outcomes = run_batch(
        jobs,
        folder,
        workers=workers,
        scheduler=args.scheduler,
        overwrite=args.overwrite,
        say=say,
        notes=notes,
    )
    n = write_metrics_table(out / "metrics.csv", outcomes, overwrite=args.overwrite)
    if n is not None:
        say(f"metrics of {n} stacks in {Path(args.out) / 'metrics.csv'}")
    raise_if_failed(outcomes, args.out)
    say(f"results in {args.out}")
    return 0


def _options(args) -> dict:
    if args.iso_bin is not None and args.iso_bin < 1:
        raise InputError(f"--iso-bin must be >= 1, got {args.iso_bin}")
    if not 0 <= args.decimate < 1:
        raise InputError(f"--decimate must be in [0, 1), got {args.decimate}")
    if args.no_surface:
        given = [o for o, v in (("--iso-bin", args.iso_bin), ("--decimate", args.decimate)) if v]
        if given:
            raise InputError(f"{' and '.join(given)} shape the isosurface that --no-surface skips")
    for name in ("smooth", "min_fold_height"):
        value = getattr(args, name)
        if value is not None and value < 0:
            raise InputError(f"--{name.replace('_', '-')} must be >= 0, got {value}")
    return {
        "channel": args.channel,
        "spacing": args.spacing,
        "threshold": args.threshold,
        "smooth_um": args.smooth,
        "min_fold_height_um": args.min_fold_height,
        "surface": not args.no_surface,
        "iso_bin": args.iso_bin,
        "decimate": args.decimate,
    }


def _memory_options(args) -> dict:
    if args.tile_rows is not None and args.tile_rows < 1:
        raise InputError(f"--tile-rows must be >= 1, got {args.tile_rows}")
    return {"memory_limit": args.memory_limit, "lazy": args.lazy, "tile_rows": args.tile_rows}


def _progress(args):
    from tissue_core.progress import Progress

    return Progress(quiet=args.quiet)


def _summary(metrics: dict) -> str:
    def fmt(key: str, unit: str) -> str:
        value = metrics.get(key)
        return "-" if value is None else f"{value:.1f}{unit}"

    return (
        f"folds: wavelength {fmt('fold_wavelength_um', ' um')}, "
        f"height {fmt('fold_height_um', ' um')} (max {fmt('max_fold_height_um', ' um')}), "
        f"crests at {fmt('fold_orientation_deg', ' deg')}, "
        f"coherency {metrics['fold_coherency']:.2f}; "
        f"Sa {fmt('Sa_um', ' um')}, Sq {fmt('Sq_um', ' um')}, Sdr {fmt('Sdr_percent', ' %')}"
    )


def _cmd_analyze(args) -> int:
    from mpm3d.analyze import analyze_stack, write_analysis
    from tissue_core.outputs import atomic_dir

    say = _progress(args)
    inputs = _input_files(args.stack)
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        analysis = analyze_stack(
            args.stack, progress=say, **_options(args), **_memory_options(args)
        )
        say("writing results")
        write_analysis(analysis, tmp, figures=not args.no_figures)
    say(f"{args.stack}: {_summary(analysis.metrics)}")
    say(f"results in {args.out}")
    return 0


def _input_files(path: str) -> list[str]:
    """The stack, or a mosaic's tile list and its tiles: what an output must not replace."""
    from mpm3d.mosaic import is_tile_list

    if not is_tile_list(path):
        return [path]
    from tissue_core.tables import read_tile_list

    return [path, *(str(tile.path) for tile in read_tile_list(path))]


def _cmd_stitch(args) -> int:
    from mpm3d.mosaic import write_stitched

    say = _progress(args)
    if not str(args.out).lower().endswith((".tif", ".tiff")):
        raise InputError(f"--out {args.out}: the stitched stack is a TIFF (.tif)")
    with say.task("stitching", unit="plane") as progress:
        record = write_stitched(
            args.tiles, args.out, spacing=args.spacing, overwrite=args.overwrite,
            progress=progress,
        )  # fmt: skip
    ny, nx = record["shape_yx"]
    say(
        f"{record['tiles']} tiles, {nx} x {ny} px, {100 * record['covered_fraction']:.1f} % "
        f"covered (stage positions rounded by up to {record['max_position_rounding_px']:.2f} px)"
    )
    say(f"stitched stack in {args.out}")
    return 0


def _cmd_compare(args) -> int:
    from mpm3d.compare import compare_stacks, write_comparison
    from tissue_core.outputs import atomic_dir

    say = _progress(args)
    icp = {"auto": None, "on": True, "off": False}[args.icp]
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=[args.before, args.after]) as tmp:
        report, first, second = compare_stacks(
            args.before, args.after, icp=icp, progress=say, **_options(args)
        )
        say("writing results")
        write_comparison(report, first, second, tmp, figures=not args.no_figures)
    shown = ("fold_wavelength_um", "fold_height_um", "max_fold_height_um", "Sq_um")
    for row in report["changes"]:
        if row["change"] is not None and row["metric"] in shown:
            say(f"{row['metric']}: {row['before']:.1f} -> {row['after']:.1f}")
    say(f"results in {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from tissue_core.cli import run_command

    return run_command("mpm3d", _build_parser(), argv)


def entry() -> None:
    """The console script ``mpm3d``: like ``python -m mpm3d``."""
    from tissue_core.cli import run_module

    run_module(__name__)
