"""Command line: ``python -m strain2d {track,analyze,benchmark}``.

Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import time

from strain2d import __version__
from strain2d.errors import InputError, SourceError

log = logging.getLogger(__name__)

#: ``strain2d analyze`` keeps a video's frames (8-bit) while it tracks them if they fit this
#: many bytes (and an eighth of the memory available): short videos are then decoded once;
#: longer ones are decoded again for the animation, so memory stays bounded by this
KEEP_FRAMES_BYTES = 256 * 2**20


def _add_source_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "source",
        nargs="+",
        metavar="SOURCE",
        help="video file, multi-page TIFF, folder of images, or image files in order; "
        "the first frame is the reference",
    )
    _add_frame_range_args(p)


def _add_frame_range_args(p) -> None:
    p.add_argument("--start", type=int, default=0, help="first frame to use (default 0)")
    p.add_argument("--stop", type=int, default=None, help="frame to stop before (default: end)")
    p.add_argument("--step", type=int, default=1, help="use every STEP-th frame (default 1)")


def _add_tracker_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--tracker",
        default="gdic",
        help="tracker name: gdic, dic, klt, cotracker3, imported (default gdic: global and "
        "local correlation, for weak natural texture as well as speckle)",
    )


def _tracker_flags(p: argparse.ArgumentParser) -> None:
    """Each tracker's options, as the registry declares them (built when the command runs:
    it imports the trackers)."""
    from strain2d.trackers import add_tracker_arguments

    add_tracker_arguments(p)


def _add_points_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--points", help="CSV file of reference points with columns x,y (pixels)")
    p.add_argument(
        "--grid",
        help="regular grid COLSxROWS over the ROI (default 7x7; with --tracker "
        "imported and no --grid, every imported point)",
    )
    p.add_argument("--roi", help="grid region X0,Y0,X1,Y1 in pixels (default: central 70%%)")
    p.add_argument(
        "--spacing",
        type=float,
        metavar="PX",
        help="a grid of points PX pixels apart over the region (the ROI, or the mask's "
        "bounds), centred in it, instead of --grid's count",
    )
    p.add_argument(
        "--mask",
        metavar="FILE",
        help="where the tissue is on the reference frame: an image of the frame's size "
        "(PNG/TIFF, binary or labelled: not 0 is tissue), an ImageJ ROI (.roi, .zip) or a "
        "polygon CSV (x,y); the grid fills it (over its bounds, or --roi) and points and "
        "triangles off the tissue are left out",
    )


def _add_analyze_options(p) -> None:
    """``analyze``'s options but the source and the output (shared with ``batch``)."""
    _add_points_args(p)
    _add_tracker_args(p)
    p.add_argument(
        "--min-triangle-quality",
        type=float,
        default=0.1,
        help="Delaunay meshes (with --points or imported tracks) drop triangles whose "
        "radius ratio is below this (default 0.1); grids are meshed cell by cell",
    )
    p.add_argument(
        "--fps",
        type=float,
        default=None,
        help="frame rate for time axes in seconds (default: the frame index)",
    )
    scale = p.add_mutually_exclusive_group()
    scale.add_argument(
        "--scale",
        metavar="SIZE",
        help="pixel size on the specimen, e.g. 0.012mm/px or 83.3px/mm (nm, um, mm, cm, m), "
        "or 'auto': the one a TIFF records (ImageJ/Fiji, OME); tables gain positions and "
        "displacements in that unit (x_mm, u_mm...), figure axes and the ParaView files "
        "are in it (default: pixels; strain is dimensionless)",
    )
    scale.add_argument(
        "--scale-ruler",
        metavar="X0,Y0,X1,Y1:LENGTH",
        help="measure the pixel size on the first frame: two pixel positions on a ruler, "
        "scale bar or target and the length between them, e.g. 100,400,600,400:6mm",
    )
    g = p.add_argument_group("figures, statistics and report")
    g.add_argument(
        "--endpoint",
        type=int,
        metavar="FRAME",
        help="contraction endpoint frame (default: detected, where the strain rate falls "
        "below --endpoint-tolerance and stays there; with repeated contractions, the peak of "
        "the largest cycle)",
    )
    g.add_argument(
        "--signals",
        metavar="FILE",
        help="CSV of the lab's signals beside the video (stimulus, force, pressure...): a "
        "frame column (the video's frame numbers) or a time column (time, t, time_s, time_ms; "
        "needs --fps), then one column per signal; aligned to the frames into signals.csv, "
        "a figure and the report",
    )
    g.add_argument(
        "--trigger",
        metavar="NAME",
        help="the --signals column whose pulses start each contraction cycle (a stimulus)",
    )
    g.add_argument(
        "--cycle",
        type=int,
        metavar="N",
        help="with repeated contractions: the cycle (1, 2, ...) whose peak is the endpoint "
        "(default: the largest)",
    )
    g.add_argument(
        "--endpoint-tolerance",
        type=float,
        default=0.05,
        metavar="FRACTION",
        help="endpoint detection: rate of the mean strains, as a fraction of its largest "
        "value, below which the tissue counts as still (default 0.05)",
    )
    g.add_argument(
        "--maps-at",
        metavar="FRAMES",
        help="comma-separated frames that also get contour maps (the endpoint and the last "
        "frame always do); 'peaks': every cycle's peak too",
    )
    g.add_argument(
        "--animation",
        choices=["mp4", "gif", "none"],
        default="mp4",
        help="animation of the strain field on the video (default mp4)",
    )
    g.add_argument(
        "--figure-format",
        default="png",
        metavar="FORMATS",
        help="comma-separated figure formats among png, svg, pdf (default png; png is "
        "always written, the report embeds it)",
    )


def _build_parser():
    from tissue_core.cli import CommandLine

    cli = CommandLine(
        "strain2d", "Track virtual grid points in a video and compute the strain field."
    )
    p = cli.command(
        "track", _cmd_track, later=_tracker_flags, help="track points and write TRACKS.csv"
    )
    _add_source_args(p)
    _add_points_args(p)
    _add_tracker_args(p)
    p.add_argument("--out", required=True, help="output CSV: frame,point,x,y,visible,quality")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")

    p = cli.command(
        "analyze",
        _cmd_analyze,
        later=_tracker_flags,
        help="track a grid and write strain tables, figures, VTK",
    )
    _add_source_args(p)
    _add_analyze_options(p)
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")

    p = cli.command(
        "study",
        _cmd_study,
        help="combine analyze runs (specimens) into study figures, tests and a report",
        description="Combine analyze output folders: Fig. 14/15-style panels for all "
        "specimens, specimen-level paired tests, a mixed-effects model with the specimen as "
        "random effect, a plain-language summary and report.html.",
    )
    p.add_argument("runs", nargs="*", metavar="RUN_DIR", help="analyze output folders")
    p.add_argument(
        "--manifest",
        metavar="CSV",
        help="CSV with columns run (folder, relative to the CSV), and optionally specimen, "
        "group and endpoint (a frame overriding the run's contraction endpoint)",
    )
    p.add_argument(
        "--compare",
        default="Exx,Eyy",
        metavar="A,B",
        help="the two nodal components compared (default Exx,Eyy)",
    )
    p.add_argument("--alpha", type=float, default=0.05, help="significance level (default 0.05)")
    p.add_argument(
        "--figure-format", default="png", metavar="FORMATS", help="as for analyze (default png)"
    )
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")

    p = cli.command(
        "batch",
        _cmd_batch,
        later=lambda p: _tracker_flags(_batch_run_options(p)),
        help="analyze the videos of a manifest as a batch (on a Dask cluster), then the study",
        description="Analyze every video of a manifest CSV (columns video, specimen, group, "
        "and any analyze option by name, e.g. grid, roi, fps) into OUT/runs/SPECIMEN, each as "
        "one task on a local Dask cluster or a running scheduler, then combine the runs in "
        "OUT/study. A failing video is reported and the others go on; a rerun keeps the runs "
        "that are complete with the same parameters and makes the rest. Analyze options "
        "given here apply to every run; a manifest column of the same name wins.",
        allow_abbrev=False,
    )
    p.add_argument("manifest", metavar="MANIFEST", help="CSV: one row per specimen")
    p.add_argument("--out", required=True, help="batch folder: runs/, study/, batch.log")
    from tissue_core.batch import add_batch_arguments

    add_batch_arguments(p, what="runs", tables=["study_manifest.csv"])
    g = p.add_argument_group("the study")
    g.add_argument("--no-study", action="store_true", help="analyze only; no study")
    g.add_argument("--compare", default="Exx,Eyy", metavar="A,B", help="as for study (Exx,Eyy)")
    g.add_argument("--alpha", type=float, default=0.05, help="as for study (default 0.05)")
    options = _batch_run_options(p)
    _add_frame_range_args(options)
    _add_analyze_options(options)
    p.set_defaults(run_options=options)

    p = cli.command(
        "benchmark", _cmd_benchmark, help="reproduce the paper's Table 1 on synthetic videos"
    )
    p.add_argument("--quick", action="store_true", help="400x400 px, 11 frames (for tests)")
    p.add_argument(
        "--cases",
        help="comma-separated subset of equibiaxial,rotation,shear,tissue (the paper's) "
        "and gaussian,sinusoid,fold (heterogeneous); default all",
    )
    p.add_argument("--trackers", help="comma-separated tracker names (default: all)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the synthetic videos")
    p.add_argument("--grid", default="7x7", help="grid COLSxROWS on each case's region (7x7)")
    p.add_argument("--no-figures", action="store_true", help="skip the error-contour figures")
    p.add_argument(
        "--sweep",
        help="also run sweeps, comma-separated: grid, subset, noise, contrast, density "
        "(writes sweep_KIND.json and .md)",
    )
    p.add_argument("--out", required=True, help="output folder (benchmark.json, benchmark.md)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    return cli


_RUN_OPTIONS: dict[int, object] = {}


def _batch_run_options(p):
    """The batch parser's record of the analyze options it passes on (one per parser)."""
    from tissue_core.batch import RunOptions

    if id(p) not in _RUN_OPTIONS:
        _RUN_OPTIONS[id(p)] = RunOptions(p, "analyze options, for every run")
    return _RUN_OPTIONS[id(p)]


def _cmd_batch(args) -> int:
    from strain2d.batch import analyze_jobs, run_study, study_job, write_study_manifest
    from tissue_core.batch import batch_folder, check_workers, raise_if_failed, run_batch

    options = args.run_options
    say = _progress(args)
    if not args.no_study:
        from strain2d.report import parse_formats

        parse_formats(getattr(args, "figure_format", None) or "png")
        if not 0 < args.alpha < 1:
            raise InputError(f"--alpha must lie between 0 and 1, got {args.alpha}")
        if len([c for c in args.compare.split(",") if c.strip()]) != 2:
            raise InputError(f"--compare takes two components A,B, got {args.compare!r}")
    # the manifest is read whole and checked before the folder is made or anything runs
    from pathlib import Path

    out = Path(args.out).resolve()
    jobs, rows, unused = analyze_jobs(args.manifest, out, options, args)
    workers = check_workers(args.workers, args.scheduler, len(jobs))
    folder = batch_folder(args.out)
    notes = [f"manifest columns not used: {', '.join(unused)}"] if unused else []
    studied = []

    def study(outcomes, run) -> None:  # on the batch's workers, before they are let go
        ok = {o.name for o in outcomes if o.status != "failed"}
        if ok:
            changed = any(o.status == "done" for o in outcomes)
            path = out / "study_manifest.csv"
            changed |= write_study_manifest(path, jobs, rows, ok, overwrite=args.overwrite)
            studied.append((len(ok), run_study(study_job(out, args), changed, run)))

    outcomes = run_batch(
        jobs,
        folder,
        workers=workers,
        scheduler=args.scheduler,
        overwrite=args.overwrite,
        say=say,
        notes=notes,
        then=None if args.no_study else study,
    )
    for specimens, made in studied:
        if made is not None:
            say(f"study of {specimens} specimens")
        if made is not None and made.status == "failed":
            raise InputError(f"the study failed: {made.reason}")
    raise_if_failed(outcomes, args.out)
    say(f"results in {args.out}")
    return 0


def _progress(args, *, record: bool = False):
    from tissue_core.progress import Progress

    return Progress(quiet=args.quiet, record=record)


def _tracker_options(args) -> dict:
    from strain2d.trackers import tracker_options

    return tracker_options(args, args.tracker)


def _reference_points(args, source):
    """The points to track, what the summary says of them, their mesh when the mask chose
    it (else None: the grid's, or Delaunay's, made after the tracking), and the mask."""
    from strain2d.grid import make_grid, parse_grid, parse_roi, read_points_csv, validate_points

    imported = args.tracker == "imported" and args.grid is None and args.roi is None
    if imported and not args.points and getattr(args, "mask", None):
        raise InputError(
            "--mask with --tracker imported needs --grid or --points: the points of the "
            "imported file are not a grid to fill the mask with"
        )
    spacing = getattr(args, "spacing", None)
    if spacing is not None and args.grid:
        raise InputError("give either --grid (a count) or --spacing (a distance), not both")
    mask = _mask(args, source.shape)
    if args.points:
        if args.roi or args.grid or spacing is not None:
            raise InputError("give either --points or --grid/--roi/--spacing, not both")
        points = validate_points(read_points_csv(args.points), source.shape)
        info = {"points_file": args.points}
        if mask is None:
            return points, info, None, None
        return (*_masked_points(args, points, mask, info), mask)
    if imported and spacing is None:
        return None, {"points": "all points of the imported file"}, None, None
    shape = parse_grid(args.grid or "7x7")
    roi = parse_roi(args.roi) if args.roi else None
    if spacing is not None:
        from strain2d.grid import default_roi, grid_at_spacing

        region = roi or (mask.bounds() if mask is not None else default_roi(source.shape))
        shape, roi = grid_at_spacing(region, spacing)
    if mask is not None:
        from strain2d.grid import masked_grid
        from surface_strain import Mesh

        points, triangles, counts = masked_grid(source.shape, mask, shape=shape, roi=roi)
        x0, y0, x1, y1 = mask.bounds() if roi is None else roi
        info = {
            "grid": f"{shape[0]}x{shape[1]}",
            **({"spacing_px": spacing} if spacing is not None else {}),
            "roi": [x0, y0, x1, y1],
            "mask": {**mask.summary(), **counts},
        }
        how = f"grid {shape[0]}x{shape[1]} on the mask's tissue, alternating diagonals"
        return points, info, Mesh(triangles, "grid", how), mask
    points = make_grid(source.shape, shape=shape, roi=roi)
    x0, y0 = points.min(axis=0)
    x1, y1 = points.max(axis=0)
    info = {"grid": f"{shape[0]}x{shape[1]}", "grid_shape": shape, "roi": [x0, y0, x1, y1]}
    if spacing is not None:
        info["spacing_px"] = spacing
    return points, info, None, None


def _mask(args, shape):
    """``--mask``, read for frames of ``shape``, or None."""
    if not getattr(args, "mask", None):
        return None
    from tissue_core.masks import read_mask

    return read_mask(args.mask, shape)


def _masked_points(args, points, mask, info):
    """``--points`` in a mask: those on the tissue, their Delaunay triangles on it."""
    import numpy as np

    from strain2d.grid import mask_triangles, points_on_tissue
    from surface_strain import Mesh, choose_mesh

    on = points_on_tissue(points, mask, source=args.points)
    points = points[on]
    mesh = choose_mesh(points, min_quality=args.min_triangle_quality)
    triangles = mask_triangles(points, mesh.triangles, mask)
    used = np.unique(triangles)
    if used.size < 3:
        raise InputError(
            f"--mask {mask.source}: no triangle of the points of {args.points} lies on the tissue"
        )
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    counts = {
        "points_off_tissue": int(len(on) - used.size),
        "triangles_off_tissue": int(len(mesh.triangles) - len(triangles)),
    }
    info = {**info, "mask": {**mask.summary(), **counts}}
    how = f"{mesh.description}, on the mask's tissue"
    return points[used], info, Mesh(renumber[triangles], mesh.method, how)


def _inputs(args) -> list[str]:
    """Every file the command reads, so no output may replace one."""
    from strain2d.trackers import tracker_inputs

    return [
        *args.source,
        *([args.points] if args.points else []),
        *([args.mask] if getattr(args, "mask", None) else []),
        *([args.signals] if getattr(args, "signals", None) else []),
        *tracker_inputs(args),
    ]


def _open(args):
    from strain2d.frames import open_frames

    return open_frames(args.source, start=args.start, stop=args.stop, step=args.step)


def _track_source(args, options: dict, say, check=None, keep_bytes: int = 0):
    """Open the frames, place the points and track them: (source, point_info, tracks,
    (mesh, mask)), the mesh and the tissue mask None where no mask chose them.

    ``check(n_frames, (H, W))`` runs once the frames are counted, before tracking.
    ``source`` is an :class:`~strain2d.frames.EndFrames` wrapper, so the first and
    last frames need not be decoded again afterwards (nor the others, when 8-bit
    and within ``keep_bytes``)."""
    from strain2d.frames import EndFrames
    from strain2d.pipeline import track

    # keeps the first and last frames for the figures
    source = EndFrames(_open(args), keep_bytes=keep_bytes)
    h, w = source.shape
    say(f"{source.names[0]}: {len(source)} frames of {w}x{h} px ({source.kind})")
    if check is not None:
        check(len(source), (h, w))
    points, point_info, mesh, mask = _reference_points(args, source)
    n = "the imported" if points is None else str(len(points))
    with say.task(f"tracking {n} points ({args.tracker})") as update:
        tracks = track(source, points, tracker=args.tracker, options=options, progress=update)
    if tracks.n_frames != len(source):
        raise SourceError(
            f"{source.names[0]}: {tracks.n_frames} frames were tracked but the source has "
            f"{len(source)}"
        )
    lost = int((~tracks.visible[-1]).sum())
    say(f"{tracks.n_points} points over {tracks.n_frames} frames, {lost} lost on the last one")
    return source, point_info, tracks, (mesh, mask)


def _cmd_track(args) -> int:
    from strain2d.tracks import write_tracks_csv
    from tissue_core.outputs import atomic_file, check_writable

    options = _tracker_options(args)  # bad tracker options fail before anything is read
    kwargs = {"overwrite": args.overwrite, "inputs": _inputs(args)}
    check_writable(args.out, kind="file", **kwargs)
    say = _progress(args)
    _, _, tracks, _ = _track_source(args, options, say)
    with atomic_file(args.out, **kwargs) as tmp:
        write_tracks_csv(tmp, tracks)
    say(f"tracks in {args.out}")
    return 0


def _cmd_analyze(args) -> int:
    from strain2d.figures._pool import FigurePool
    from strain2d.pipeline import analysis_of
    from strain2d.run import check_run_options, write_run
    from tissue_core.outputs import check_writable
    from tissue_core.resources import available_memory

    t_start = time.perf_counter()
    peaks = bool(args.maps_at) and "peaks" in [v.strip() for v in args.maps_at.split(",")]
    listed = ",".join(v for v in (args.maps_at or "").split(",") if v.strip() != "peaks")
    map_frames = _frame_list(listed, "--maps-at")
    if args.cycle is not None and args.cycle < 1:
        raise InputError(f"--cycle counts cycles from 1, got {args.cycle}")
    if args.cycle is not None and args.endpoint is not None:
        raise InputError("give either --endpoint or --cycle: each chooses the endpoint")
    if args.trigger and not args.signals:
        raise InputError("--trigger names a column of --signals: give the signals file")
    signals = None
    options = {
        "fps": args.fps,
        "endpoint": args.endpoint,
        "endpoint_tolerance": args.endpoint_tolerance,
        "maps_at": map_frames,
        "animation": args.animation,
        "figure_format": args.figure_format,
    }
    check_run_options(**options, min_triangle_quality=args.min_triangle_quality)
    scale = _scale_option(args)
    tracker_options = _tracker_options(args)  # bad ones fail before anything is read
    check_writable(args.out, overwrite=args.overwrite, inputs=_inputs(args))
    say = _progress(args, record=True)  # its lines go into the run's run.log

    def frames_exist(n: int) -> None:
        for flag, frames in (("--endpoint", [args.endpoint]), ("--maps-at", map_frames)):
            bad = [k for k in frames if k is not None and k >= n]
            if bad:
                raise InputError(f"{flag} {bad[0]} is outside the frames 0..{n - 1}")

    def check(n: int, shape: tuple[int, int]) -> None:
        nonlocal scale, signals
        frames_exist(n)
        if args.signals:  # aligned once the frames are counted, before any is tracked
            from strain2d.signals import read_signals

            signals = read_signals(args.signals, n, fps=args.fps, start=args.start,
                                   step=args.step)  # fmt: skip
            if args.trigger:
                from surface_strain import stimulus_pulses

                if stimulus_pulses(signals.column(args.trigger)).size == 0:
                    raise InputError(
                        f"--trigger {args.trigger}: the column holds no pulse over the run's "
                        "frames (it does not rise); cycles cannot start at it"
                    )
            say(f"signals {', '.join(signals.names)} aligned by {signals.aligned_by}")
        if args.scale_ruler:  # the ruler's points must be in the frame: known once it is open
            from strain2d.scale import scale_from_ruler

            scale = scale_from_ruler(args.scale_ruler, shape)
            say(f"pixel size {scale.per_px:.6g} {scale.unit} ({scale.source})")

    # the figures' workers start now, while this process has one thread, and load Matplotlib
    # while the points are tracked
    with FigurePool(warm=True) as pool:
        # the frames, 8-bit, while they fit KEEP_FRAMES_BYTES and an eighth of the memory
        # available: the animation then decodes none of them again
        keep = min(KEEP_FRAMES_BYTES, available_memory() // 8)
        source, point_info, tracks, (mesh, mask) = _track_source(
            args, tracker_options, say, check=check, keep_bytes=keep
        )
        t_tracked = time.perf_counter()
        analysis = analysis_of(
            tracks,
            tracker=args.tracker,
            grid_shape=point_info.get("grid_shape"),
            min_triangle_quality=args.min_triangle_quality,
            streamed=True,  # a block of frames at a time: memory does not grow with the video
            mesh=mesh,
        )
        t_strain = time.perf_counter()
        say(f"strain on {analysis.field.n_triangles} triangles")
        with say.task("figures and animation", unit="frame") as update:
            summary = write_run(
                args.out,
                analysis,
                source,
                **options,
                points_info=point_info,
                overwrite=args.overwrite,
                inputs=_inputs(args),
                progress=update,
                runtime_s={"tracking": t_tracked - t_start, "strain": t_strain - t_tracked},
                scale=scale,
                pool=pool,
                mask=mask,
                log=say.recorded,
                cycle=args.cycle,
                maps_at_peaks=peaks,
                signals=signals,
                trigger=args.trigger,
            )
    ep = summary["contraction_endpoint"]
    say(f"{ep['label']}: frame {ep['frame']} ({ep['source']})")
    say(f"results in {args.out}")
    return 0


def _scale_option(args):
    """``--scale`` parsed (before any work), or None; ``--scale-ruler`` is checked on the frame."""
    if args.scale_ruler:
        from strain2d.scale import scale_from_ruler

        scale_from_ruler(args.scale_ruler)  # the form, before the video is read
        return None
    if args.scale is not None and args.scale.strip().lower() == "auto":
        from strain2d.scale import scale_from_file

        return scale_from_file(args.source[0])
    if args.scale is not None:
        from strain2d.scale import parse_scale

        return parse_scale(args.scale)
    return None


def _frame_list(text: str | None, flag: str) -> list[int]:
    if not text:
        return []
    try:
        frames = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise InputError(f"{flag} takes comma-separated frame numbers, got {text!r}") from None
    for k in frames:
        _frame_number(k, flag)
    return frames


def _frame_number(k: int | None, flag: str) -> int | None:
    """Frames are counted from 0 (the reference) in every option, never from the end."""
    if k is not None and k < 0:
        raise InputError(f"{flag} takes frame numbers from 0 (the reference frame), got {k}")
    return k


def _cmd_study(args) -> int:
    from strain2d.report import parse_formats, write_study
    from strain2d.study import read_manifest
    from tissue_core.outputs import recorded_command

    say = _progress(args)
    formats = parse_formats(args.figure_format)
    if not 0 < args.alpha < 1:
        raise InputError(f"--alpha must lie between 0 and 1, got {args.alpha}")
    parts = [c.strip() for c in args.compare.split(",")]
    if len(parts) != 2:
        raise InputError(f"--compare takes two components A,B, got {args.compare!r}")
    if args.manifest and args.runs:
        raise InputError("give run folders or --manifest, not both")
    if not args.manifest and not args.runs:
        raise InputError("give the run folders to combine, or --manifest CSV")
    entries = read_manifest(args.manifest) if args.manifest else args.runs
    summary = write_study(
        args.out,
        entries,
        compare=(parts[0], parts[1]),
        alpha=args.alpha,
        formats=formats,
        overwrite=args.overwrite,
        manifest=args.manifest,
        command=recorded_command.get(),
    )
    if not args.quiet:
        for line in summary["plain_summary"]:
            print(line)
    say(f"results in {args.out}")
    return 0


def _cmd_benchmark(args) -> int:
    from strain2d.benchmark import (
        SWEEPS,
        benchmark_markdown,
        check_benchmark_grid,
        run_benchmark,
        run_sweep,
        sweep_markdown,
    )
    from tissue_core.jsonio import write_json
    from tissue_core.outputs import atomic_dir, check_writable

    if args.seed < 0:
        raise InputError(f"--seed must be a whole number >= 0, got {args.seed}")
    check_writable(args.out, overwrite=args.overwrite)
    from sample_data_synth import CASES

    cases = args.cases.split(",") if args.cases else None
    for c in cases or []:
        if c not in CASES:
            raise InputError(f"unknown case {c!r}; choose from {', '.join(CASES)}")
    trackers = args.trackers.split(",") if args.trackers else None
    if trackers:
        from strain2d.trackers import get_tracker

        for name in trackers:
            if not get_tracker(name).needs_frames:
                raise InputError(f"the {name} tracker reads files and cannot be benchmarked")

    say = _progress(args)
    from strain2d.grid import parse_grid

    grid = parse_grid(args.grid)
    check_benchmark_grid(grid, quick=args.quick, cases=cases)
    sweeps = [k.strip() for k in args.sweep.split(",")] if args.sweep else []
    for kind in sweeps:
        if kind not in SWEEPS:
            raise InputError(f"unknown sweep {kind!r}; choose from {', '.join(SWEEPS)}")
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        figures = None if args.no_figures else tmp / "figures"
        if figures:
            figures.mkdir()
        results = run_benchmark(
            quick=args.quick,
            cases=cases,
            trackers=trackers,
            seed=args.seed,
            grid=grid,
            figures=figures,
            progress=say,
        )
        results["software"] = {"name": "strain2d", "version": __version__}
        table = benchmark_markdown(results)
        write_json(tmp / "benchmark.json", results)
        (tmp / "benchmark.md").write_text(table)
        for kind in sweeps:
            sweep = run_sweep(
                kind, quick=args.quick, trackers=trackers, seed=args.seed, progress=say
            )
            sweep["software"] = results["software"]
            write_json(tmp / f"sweep_{kind}.json", sweep)
            (tmp / f"sweep_{kind}.md").write_text(sweep_markdown(sweep))
    if not args.quiet:
        print(table)
    say(f"results in {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from tissue_core.cli import run_command

    return run_command("strain2d", _build_parser(), argv)


def entry() -> None:
    """The console script ``strain2d``: like ``python -m strain2d``."""
    from tissue_core.cli import run_module

    run_module(__name__)
