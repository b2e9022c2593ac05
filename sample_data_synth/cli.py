"""Command line: ``python -m sample_data_synth {video,stack,stereo,study,twitches,folds,list}``.

``video`` writes, for each case (the paper's, or the speckle-free tissue
suite of :mod:`sample_data_synth.tissue` with ``--case tissue-suite`` or one of
its names), ``CASE.avi`` (lossless FFV1) and/or
``CASE.tif`` / ``CASE.mp4``, ``CASE_truth.json`` (the analytic deformation,
from which any point's position, F and E at any frame follow; see
:func:`sample_data_synth.load_ground_truth`) and ``CASE_truth.npz`` (the case's
grid: ``grid`` (N, 2), ``positions`` (T, N, 2), ``F`` and ``E`` (T, N, 2, 2)).

``stack`` writes, for ``before``, ``after`` or both (``pair``), a two-channel
MPM z-stack ``CASE.tif`` (ImageJ hyperstack) or ``CASE.ome.tif`` (OME-TIFF),
``CASE_truth.json`` (fold geometry, per-fold heights, conventions) and
``CASE_truth.npz`` (``depth_um`` and ``height_um``, (Y, X) float32); see
:mod:`sample_data_synth.stacks`.

``stereo`` writes one folder per case: ``calibration/`` (``left/view_00.png``
..., ``right/view_00.png`` ..., ``rig.json`` with the true calibration and
``poses.json`` with the true board poses) and ``stretch/``, ``dome/``
(``left/frame_000.png`` ..., ``right/frame_000.png`` ..., ``rig.json``,
``truth.json`` and ``truth.npz``); see :mod:`sample_data_synth.stereo`.

``study`` writes a multi-specimen contraction study with known anisotropy:
``S01.avi`` ... (lossless FFV1), ``S01_truth.json`` and ``S01_truth.npz`` per
specimen, ``manifest.csv`` (``run,specimen,group,video,truth,true_lx,true_ly,true_endpoint,roi``:
what to pass to ``strain2d analyze VIDEO --grid 7x7 --roi ROI --out RUN``) and
``study_truth.json`` (exact mean nodal strains at each endpoint, the expected
verdict per group); see :mod:`sample_data_synth.specimens`.

``twitches`` writes a muscle sheet that twitches three times, of different sizes
(:mod:`sample_data_synth.twitches`): ``twitches.avi``, ``twitches_truth.json``
(the deformation and the twitches' onsets, peaks, ends and amplitudes),
``stimulus.csv`` (``frame,time_s,stimulus``: a pulse a frame before each
onset) and ``mask.png`` (the tissue, an ellipse).

``folds`` writes a lumen wall that folds as it contracts (:mod:`sample_data_synth.folds`;
``--case folding``, ``mixed`` or ``oblique``): the camera's ``video.avi``, the
microscope's height maps of a sub-region ``before_heightmap.tif`` and
``after_heightmap.tif`` (and with ``--stacks`` the z-stacks ``before_stack.tif`` and
``after_stack.tif`` to give ``mpm3d analyze``), ``landmarks.csv`` (pairs picked by
hand), ``transform.json`` (the exact camera-to-microscope similarity) and
``truth.json`` (the true membrane strain).

Every command writes into a temporary folder beside ``--out`` and renames it
only when everything is written.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from sample_data_synth.cases import CASES, make_case, write_video
from sample_data_synth.stacks import (
    STACK_CASES,
    make_stack_case,
    save_stack_truth,
    write_stack,
    write_stack_tiles,
)
from sample_data_synth.stereo import (
    STEREO_CASES,
    default_rig,
    parse_board,
    render_calibration_views,
    render_surface_scene,
    save_calibration_views,
    save_stereo_scene,
)
from sample_data_synth.tissue import TISSUE_CASES, make_tissue_case
from tissue_core.cli import CommandLine
from tissue_core.outputs import atomic_dir, check_writable
from tissue_core.progress import Progress
from tissue_core.resources import check_fits

#: working memory per pixel while a frame is rendered, bytes (the pattern's or the
#: photograph's coordinates and densities; 70 to 140 measured at 512 to 1024 px): a lower bound
RENDER_BYTES_PER_PIXEL = 64
#: working memory per pixel of a stereo image while it is ray-traced, bytes (140 to 150
#: measured at 1280 x 960 px, with 3 x 3 supersampling): a lower bound
RAYTRACE_BYTES_PER_PIXEL = 100
#: the least distance, px, between a target's corners or dots at which a detector finds them
MIN_FEATURE_SPACING_PX = 4
#: the least share of the raw bytes that lossless video (FFV1) and PNG keep of frames with
#: sensor noise: a bit per pixel
NOISY_LOSSLESS_FRACTION = 1 / 8


def _build_parser() -> CommandLine:
    cli = CommandLine("sample_data_synth", "Synthetic videos and z-stacks with ground truth.")
    p = cli.command("video", _cmd_video, help="render benchmark videos with ground truth")
    p.add_argument(
        "--case",
        default="equibiaxial",
        help=f"one of {', '.join(CASES)}, or 'all'; or a tissue-suite case "
        f"({', '.join(TISSUE_CASES)}), or 'tissue-suite' for all of them (default equibiaxial)",
    )
    p.add_argument("--size", type=int, default=800, help="frame width and height in px (800)")
    p.add_argument(
        "--frames",
        type=int,
        default=None,
        help="number of frames (31; tissue suite: 21, rotation-20: 5)",
    )
    p.add_argument("--formats", default="avi,tif", help="comma-separated: avi, tif, mp4 (avi,tif)")
    p.add_argument("--read-noise", type=float, default=1.0, help="read noise in gray levels (1.0)")
    p.add_argument(
        "--shot-gain", type=float, default=0.02, help="shot-noise variance per gray level (0.02)"
    )
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "stack", _cmd_stack, help="render MPM z-stacks of a folded lumen with ground truth"
    )
    p.add_argument(
        "--case",
        default="pair",
        help=f"one of {', '.join(STACK_CASES)}, or 'pair' for both (default pair)",
    )
    p.add_argument("--size", type=int, default=512, help="width and height in px (512)")
    p.add_argument(
        "--slices",
        type=int,
        default=None,
        help="number of slices (default: the fewest that fit the folds)",
    )
    p.add_argument("--spacing", default="4,2.5,2.5", help="DZ,DY,DX in um (4,2.5,2.5)")
    p.add_argument("--format", default="imagej", help="imagej or ome (imagej)")
    p.add_argument(
        "--tiles",
        type=_tiles,
        metavar="RxC",
        help="also cut each stack into a microscope mosaic of R x C overlapping tiles: "
        "CASE_tiles/ with the tiles and tiles.csv (their stage positions, for mpm3d analyze)",
    )
    p.add_argument(
        "--overlap",
        type=float,
        default=0.1,
        help="the mosaic's overlap, a fraction of a tile's side in [0, 0.5) (0.1)",
    )
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "stereo",
        _cmd_stereo,
        help="render stereo calibration views and deforming surfaces with ground truth",
    )
    p.add_argument(
        "--case",
        default="all",
        help=f"one of {', '.join(STEREO_CASES)}, or 'all' (default all)",
    )
    p.add_argument(
        "--board",
        default="checkerboard:9x6:10",
        help="checkerboard:COLSxROWS:SQUARE_MM, charuco:SXxSY:SQUARE_MM:MARKER_MM[:DICT], or a "
        "dot grid circles:COLSxROWS:SPACING_MM:DIAMETER_MM (acircles: for OpenCV's asymmetric "
        "grid) (checkerboard:9x6:10)",
    )
    p.add_argument("--views", type=int, default=15, help="calibration views (15)")
    p.add_argument("--frames", type=int, default=11, help="frames of the surface cases (11)")
    p.add_argument("--size", default="1024x768", help="image WIDTHxHEIGHT in px (1024x768)")
    p.add_argument("--noise", type=float, default=1.0, help="sensor noise in gray levels (1.0)")
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "study", _cmd_study, help="render a multi-specimen contraction study with known anisotropy"
    )
    p.add_argument("--size", type=int, default=352, help="frame width and height in px (352)")
    p.add_argument("--frames", type=int, default=25, help="frames per video (25)")
    p.add_argument("--per-group", type=int, default=4, help="specimens per group (4)")
    p.add_argument("--texture", default="tissue", help="tissue or speckle (tissue)")
    p.add_argument(
        "--heterogeneity",
        type=float,
        default=0.04,
        help="amplitude of the smooth strain heterogeneity, 0 to 0.2 (0.04)",
    )
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "twitches",
        _cmd_twitches,
        help="render a muscle sheet that twitches three times, with a stimulus and a tissue mask",
    )
    p.add_argument("--frames", type=int, default=48, help="frames (48; the twitches end at 44)")
    p.add_argument("--fps", type=float, default=10.0, help="frame rate of stimulus.csv (10)")
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "folds",
        _cmd_folds,
        help="render a wall that folds as it contracts: camera video, microscope height maps",
    )
    p.add_argument(
        "--case",
        choices=["folding", "mixed", "oblique"],
        default="mixed",
        help="all folding, a true contraction plus folding (default), oblique folds",
    )
    p.add_argument("--frames", type=int, default=11, help="frames of the video (11)")
    p.add_argument("--stacks", action="store_true", help="also the multiphoton z-stacks")
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    p = cli.command(
        "patch",
        _cmd_patch,
        help="a microscope's height map of a patch of a stereo scene, with 3D landmarks",
    )
    p.add_argument("scene", help="a stereo scene folder (sample_data_synth stereo: dome/)")
    p.add_argument("--frame", type=int, default=0, help="the scene's frame (0)")
    p.add_argument("--center", default="4,-3", help="the patch's centre, material mm X,Y (4,-3)")
    p.add_argument("--size-um", type=float, default=2000.0, help="side of the patch (2000)")
    p.add_argument("--pixel-um", type=float, default=5.0, help="pixel size (5)")
    p.add_argument("--angle", type=float, default=25.0, help="the microscope's turn, deg (25)")
    p.add_argument("--fold-um", type=float, default=15.0, help="folds peak to peak (15)")
    p.add_argument(
        "--landmark-mm", type=float, default=0.05, help="landmark picking error, mm (0.05)"
    )
    p.add_argument("--seed", type=_seed, default=0, help="random seed, a whole number >= 0 (0)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    cli.command("list", _cmd_list, help="list the cases")
    return cli


def _tiles(text: str) -> tuple[int, int]:
    parts = text.lower().replace(" ", "").split("x")
    if len(parts) != 2 or not all(p.isdigit() and int(p) >= 1 for p in parts):
        raise argparse.ArgumentTypeError(f"expected RxC with R, C >= 1, e.g. 3x3; got {text!r}")
    return int(parts[0]), int(parts[1])


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, got {text!r}")
    return value


def _cmd_video(args) -> int:
    cases = {"all": list(CASES), "tissue-suite": list(TISSUE_CASES)}.get(args.case, [args.case])
    if any(c not in CASES and c not in TISSUE_CASES for c in cases):
        raise ValueError(
            f"unknown case {args.case!r}; choose from {', '.join(CASES)}, all, "
            f"{', '.join(TISSUE_CASES)} or tissue-suite"
        )
    formats = [f.strip().lower() for f in args.formats.split(",") if f.strip()]
    bad = [f for f in formats if f not in ("avi", "tif", "mp4")]
    if bad or not formats:
        raise ValueError(f"--formats must list avi, tif or mp4, got {args.formats!r}")
    if (args.frames is not None and args.frames < 2) or args.size < 64:
        raise ValueError("--frames must be >= 2 and --size >= 64")
    for name in ("read_noise", "shot_gain"):
        value = getattr(args, name)
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"--{name.replace('_', '-')} must be a number >= 0, got {value}")
    _check_video_fits(args, cases, formats)
    say = Progress(quiet=args.quiet)
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        for case in cases:
            with say.task(f"rendering {case}") as progress:
                render = make_tissue_case if case in TISSUE_CASES else make_case
                frames = (
                    {}
                    if args.frames is None and case in TISSUE_CASES
                    else {"n_frames": 31 if args.frames is None else args.frames}
                )
                video = render(
                    case,
                    size=args.size,
                    read_noise=args.read_noise,
                    shot_gain=args.shot_gain,
                    rng=args.seed,
                    progress=progress,
                    **frames,
                )
            for fmt in formats:
                write_video(video.frames, tmp / f"{case}.{fmt}")
            truth = video.truth
            truth.save(tmp / f"{case}_truth.json")
            grid = truth.grid(tuple(truth.params.get("grid", (7, 7))))
            np.savez_compressed(
                tmp / f"{case}_truth.npz",
                grid=grid,
                positions=truth.positions(grid),
                F=np.stack([truth.gradient(grid, k) for k in range(truth.n_frames)]),
                E=np.stack([truth.strain(grid, k) for k in range(truth.n_frames)]),
            )
    say(f"results in {args.out}")
    return 0


def _check_video_fits(args, cases: list[str], formats: list[str]) -> None:
    """Refuse, before anything is written, videos that cannot fit the memory or the disk."""
    noisy = args.read_noise > 0 or args.shot_gain > 0
    kept = {"tif": 1.0, "avi": NOISY_LOSSLESS_FRACTION if noisy else 0.0, "mp4": 0.0}
    pixels = args.size**2
    memory = disk = 0
    for case in cases:
        default = TISSUE_CASES[case].n_frames if case in TISSUE_CASES else 31
        raw = (args.frames or default) * pixels  # the case's frames, uint8, held whole
        memory = max(memory, raw + RENDER_BYTES_PER_PIXEL * pixels)
        disk += raw * sum(kept[f] for f in formats)
    frames = f" --frames {args.frames}" if args.frames is not None else ""
    videos = f"{len(cases)} videos" if len(cases) > 1 else "a video"
    check_fits(
        f"--size {args.size}{frames} ({videos} of {args.size}x{args.size} px frames)",
        memory=memory,
        disk=disk,
        out=args.out,
        remedy="use a smaller --size or fewer --frames",
    )


def _parse_spacing(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) and v > 0 for v in values):
        raise ValueError(f"--spacing must be DZ,DY,DX: three numbers > 0 in um, got {text!r}")
    return values


def _cmd_stack(args) -> int:
    cases = list(STACK_CASES) if args.case == "pair" else [args.case]
    if any(c not in STACK_CASES for c in cases):
        raise ValueError(
            f"unknown case {args.case!r}; choose from {', '.join(STACK_CASES)} or pair"
        )
    if args.format not in ("imagej", "ome"):
        raise ValueError(f"--format must be imagej or ome, got {args.format!r}")
    spacing = _parse_spacing(args.spacing)
    if args.size < 16:
        raise ValueError(f"--size must be >= 16, got {args.size}")
    if args.slices is not None and args.slices < 2:
        raise ValueError(f"--slices must be >= 2, got {args.slices}")
    if not 0 <= args.overlap < 0.5:
        raise ValueError(f"--overlap must be in [0, 0.5), got {args.overlap}")
    _check_stack_fits(args, cases, spacing)
    suffix = ".tif" if args.format == "imagej" else ".ome.tif"
    say = Progress(quiet=args.quiet)
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        for case in cases:
            with say.task(f"rendering {case}", unit="slice") as progress:
                stack = make_stack_case(
                    case,
                    size=args.size,
                    spacing=spacing,
                    n_slices=args.slices,
                    rng=args.seed,
                    progress=progress,
                )
            write_stack(tmp / f"{case}{suffix}", stack, format=args.format)
            save_stack_truth(tmp / case, stack)
            if args.tiles is not None:
                (tmp / f"{case}_tiles").mkdir()
                write_stack_tiles(
                    tmp / f"{case}_tiles", stack, tiles=args.tiles, overlap=args.overlap,
                    format=args.format, rng=args.seed,
                )  # fmt: skip
            del stack
    say(f"results in {args.out}")
    return 0


def _check_stack_fits(args, cases: list[str], spacing: tuple[float, float, float]) -> None:
    """Refuse, before anything is written, stacks that cannot fit the memory or the disk."""
    import inspect

    if args.slices is not None:
        slices = args.slices
    else:  # the fewest the folds could need: the tissue above the crests and below the folds
        defaults = inspect.signature(make_stack_case).parameters
        depth = defaults["crest_depth_um"].default + defaults["tissue_below_um"].default
        slices = math.ceil(depth / spacing[0]) + 1
    pixels = args.size**2
    stack = 2 * 2 * slices * pixels  # two channels of uint16
    what = f"--size {args.size}" + (f" --slices {args.slices}" if args.slices else "")
    stacks = f"{len(cases)} stacks" if len(cases) > 1 else "a stack"
    check_fits(
        f"{what} ({stacks} of {slices} or more slices of {args.size}x{args.size} px)",
        memory=stack + 2 * 8 * pixels,  # and its depth and height maps, float64
        # the tiles repeat the stack, and their overlaps once more
        disk=len(cases) * stack * (1 if args.tiles is None else 2 + 2 * args.overlap),
        out=args.out,
        remedy="use a smaller --size or fewer --slices",
    )


def _parse_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        w = h = 0
    if w < 64 or h < 64:
        raise ValueError(f"--size must be WIDTHxHEIGHT, both >= 64 px, got {text!r}")
    return w, h


def _check_stereo_fits(args, cases: list[str], size: tuple[int, int], board) -> None:
    """Refuse, before anything is written, scenes that cannot fit the memory or the disk, and a
    board with more corners or dots than the images can show."""
    counts = (
        (board.squares_x, board.squares_y) if hasattr(board, "squares_x") else board.pattern_size
    )
    most = sorted(max(1, n // MIN_FEATURE_SPACING_PX) for n in size)
    if "calibration" in cases and (sorted(counts)[0] > most[0] or sorted(counts)[1] > most[1]):
        raise ValueError(
            f"--board {args.board}: {counts[0]}x{counts[1]} is more than {size[0]}x{size[1]} px "
            f"images can show (at most {most[1]}x{most[0]}, {MIN_FEATURE_SPACING_PX} px apart: "
            "the least a detector finds)"
        )
    pixels = size[0] * size[1]
    memory = disk = 0
    for case in cases:
        images = 2 * (args.views if case == "calibration" else args.frames)  # left and right
        memory = max(memory, images * pixels + RAYTRACE_BYTES_PER_PIXEL * pixels)
        disk += images * pixels * (NOISY_LOSSLESS_FRACTION if args.noise > 0 else 0.0)
    check_fits(
        f"--size {args.size} --views {args.views} --frames {args.frames}",
        memory=memory,
        disk=disk,
        out=args.out,
        remedy="use a smaller --size, or fewer --views or --frames",
    )


def _cmd_stereo(args) -> int:
    cases = list(STEREO_CASES) if args.case == "all" else [args.case]
    if any(c not in STEREO_CASES for c in cases):
        raise ValueError(
            f"unknown case {args.case!r}; choose from {', '.join(STEREO_CASES)} or all"
        )
    board = parse_board(args.board)
    if args.views < 1:
        raise ValueError(f"--views must be >= 1, got {args.views}")
    if args.frames < 2:
        raise ValueError(f"--frames must be >= 2, got {args.frames}")
    if not (np.isfinite(args.noise) and args.noise >= 0):
        raise ValueError(f"--noise must be a number >= 0, got {args.noise}")
    size = _parse_size(args.size)
    _check_stereo_fits(args, cases, size, board)
    rig = default_rig(image_size=size)
    say = Progress(quiet=args.quiet)
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        for case in cases:
            unit = "image"  # left and right views (or frames) together
            with say.task(f"rendering {case} (left and right)", unit=unit) as progress:
                if case == "calibration":
                    views = render_calibration_views(
                        rig,
                        board,
                        n_views=args.views,
                        rng=args.seed,
                        noise=args.noise,
                        progress=progress,
                    )
                else:
                    scene = render_surface_scene(
                        rig,
                        case,
                        n_frames=args.frames,
                        rng=args.seed,
                        noise=args.noise,
                        progress=progress,
                    )
            if case == "calibration":
                save_calibration_views(tmp / case, views)
            else:
                save_stereo_scene(tmp / case, scene)
    say(f"results in {args.out}")
    return 0


def _cmd_study(args) -> int:
    from dataclasses import replace

    from sample_data_synth.specimens import DEFAULT_DESIGN, make_study

    if args.per_group < 1:
        raise ValueError(f"--per-group must be >= 1, got {args.per_group}")
    if args.size < 64:
        raise ValueError(f"--size must be >= 64, got {args.size}")
    if args.frames < 3:
        raise ValueError(f"--frames must be >= 3, got {args.frames}")
    if args.texture not in ("tissue", "speckle"):
        raise ValueError(f"--texture must be tissue or speckle, got {args.texture!r}")
    if not (math.isfinite(args.heterogeneity) and 0 <= args.heterogeneity <= 0.2):
        raise ValueError(
            f"--heterogeneity must be a number from 0 to 0.2, got {args.heterogeneity}"
        )
    design = tuple(replace(g, n=args.per_group) for g in DEFAULT_DESIGN)
    n_specimens = sum(g.n for g in design)
    raw = args.frames * args.size**2  # a specimen's frames, uint8, held whole
    check_fits(
        f"--size {args.size} --frames {args.frames} --per-group {args.per_group} "
        f"({n_specimens} videos)",
        memory=raw + RENDER_BYTES_PER_PIXEL * args.size**2,
        disk=n_specimens * raw * NOISY_LOSSLESS_FRACTION,
        out=args.out,
        remedy="use a smaller --size, or fewer --frames or --per-group",
    )

    say = Progress(quiet=args.quiet)
    description = f"rendering {n_specimens} specimens x {args.frames} frames"
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp, say.task(description) as progress:
        make_study(
            tmp,
            design=design,
            size=args.size,
            n_frames=args.frames,
            heterogeneity=args.heterogeneity,
            texture=args.texture,
            rng=args.seed,
            progress=progress,
        )
    say(f"results in {args.out}")
    return 0


def _cmd_twitches(args) -> int:
    import cv2

    from sample_data_synth.twitches import make_repeated_twitches

    if not (math.isfinite(args.fps) and args.fps > 0):
        raise ValueError(f"--fps must be a positive number, got {args.fps}")
    if args.frames < 45:
        raise ValueError(f"--frames must be at least 45 (the last twitch ends at 44), got "
                         f"{args.frames}")  # fmt: skip
    say = Progress(quiet=args.quiet)
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        with say.task("rendering the twitching sheet") as progress:
            case = make_repeated_twitches(
                n_frames=args.frames, fps=args.fps, rng=args.seed, progress=progress
            )
        write_video(case.video.frames, tmp / "twitches.avi")
        case.video.truth.save(tmp / "twitches_truth.json")
        (tmp / "stimulus.csv").write_text(case.stimulus_csv())
        if not cv2.imwrite(str(tmp / "mask.png"), case.mask.astype(np.uint8) * 255):
            raise OSError(f"could not write {tmp / 'mask.png'}")
    say(f"twitches.avi, twitches_truth.json, stimulus.csv and mask.png in {args.out}")
    return 0


def _cmd_folds(args) -> int:
    from sample_data_synth.folds import (
        folding_wall_stacks,
        make_folding_wall,
        write_folding_wall,
    )
    from sample_data_synth.stacks import write_stack

    if not 2 <= args.frames <= 1000:
        raise ValueError(f"--frames must be 2 to 1000, got {args.frames}")
    say = Progress(quiet=args.quiet)
    with atomic_dir(args.out, overwrite=args.overwrite) as tmp:
        say(f"rendering the {args.case} wall: {args.frames} frames")
        case = make_folding_wall(args.case, n_frames=args.frames, rng=args.seed)
        write_folding_wall(case, tmp)
        if args.stacks:
            say("rendering the z-stacks before and after")
            for stack in folding_wall_stacks(case, rng=args.seed):
                write_stack(tmp / f"{stack.params['state']}_stack.tif", stack)
    say(f"video.avi, height maps, landmarks.csv, transform.json and truth.json in {args.out}")
    return 0


def _cmd_patch(args) -> int:
    from sample_data_synth.patch import microscope_patch, write_patch
    from sample_data_synth.stereo import load_stereo_scene

    try:
        center = tuple(float(v) for v in args.center.split(","))
    except ValueError:
        center = ()
    if len(center) != 2 or not all(math.isfinite(v) for v in center):
        raise ValueError(f"--center must be X,Y in mm, got {args.center!r}")
    for flag, value in (("--size-um", args.size_um), ("--pixel-um", args.pixel_um)):
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"{flag} must be a positive number, got {value}")
    if not 16 <= args.size_um / args.pixel_um <= 2000:
        raise ValueError("--size-um / --pixel-um must make 16 to 2000 pixels a side")
    for flag, value in (("--fold-um", args.fold_um), ("--landmark-mm", args.landmark_mm)):
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"{flag} must be 0 or more, got {value}")
    if args.fold_um > args.size_um / 4:
        raise ValueError(f"--fold-um must be at most a quarter of --size-um, got {args.fold_um}")
    if args.landmark_mm > 10:
        raise ValueError(f"--landmark-mm must be at most 10 (mm), got {args.landmark_mm}")
    if not math.isfinite(args.angle):
        raise ValueError(f"--angle must be a number, got {args.angle}")
    check_writable(args.out, overwrite=args.overwrite, inputs=[Path(args.scene)])
    say = Progress(quiet=args.quiet)
    if not (Path(args.scene) / "rig.json").is_file():
        raise ValueError(
            f"{args.scene}: not a stereo scene (no rig.json); give a case folder that "
            "sample_data_synth stereo wrote, such as dome/"
        )
    try:
        scene = load_stereo_scene(args.scene)
    except ValueError as exc:
        text = str(exc)
        raise ValueError(text if args.scene in text else f"{args.scene}: {text}") from None
    except Exception as exc:  # a scene folder changed by hand: any of its files unreadable
        raise ValueError(
            f"{args.scene}: not a readable stereo scene ({type(exc).__name__}: {exc})"
        ) from None
    if not 0 <= args.frame < scene.n_frames:
        raise ValueError(f"--frame must be 0 to {scene.n_frames - 1}, got {args.frame}")
    x0, y0, x1, y1 = scene.surface.texture_extent()
    reach = args.size_um * 1e-3 / math.sqrt(2) * 1.5  # the patch's corner, and a margin (mm)
    if not (x0 + reach <= center[0] <= x1 - reach and y0 + reach <= center[1] <= y1 - reach):
        raise ValueError(
            f"--center {args.center} with --size-um {args.size_um:g} does not lie on the "
            f"scene's surface (material mm {x0:g}..{x1:g}, {y0:g}..{y1:g})"
        )
    say(f"rendering a {args.size_um:g} um patch at {args.pixel_um:g} um pixels")
    patch = microscope_patch(
        scene, frame=args.frame, center=center, size_um=args.size_um, pixel_um=args.pixel_um,
        angle_deg=args.angle, fold_um=args.fold_um, landmark_mm=args.landmark_mm,
        rng=args.seed,
    )  # fmt: skip
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=[Path(args.scene)]) as tmp:
        write_patch(patch, tmp)
    say(f"heightmap.tif, landmarks3d.csv and truth.json in {args.out}")
    return 0


def _cmd_list(args) -> int:
    for name, spec in CASES.items():
        print(f"{name:12s} {spec.description}")
    for name, spec in STACK_CASES.items():
        print(f"{name:12s} {spec.description}")
    for name, spec in TISSUE_CASES.items():
        print(f"{name:12s} {spec.description} (tissue suite, {spec.kind})")
    for name, description in STEREO_CASES.items():
        print(f"{name:12s} {description} (stereo)")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from tissue_core.cli import run_command

    # the renderers check their own arguments with ValueError
    return run_command("sample_data_synth", _build_parser(), argv, errors=(ValueError,))


def entry() -> None:
    """The console script ``sample-data-synth``: like ``python -m sample_data_synth``."""
    from tissue_core.cli import run_module

    run_module(__name__)
