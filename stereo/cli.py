"""Command line: ``python -m stereo {calibrate,import-calib,match,reconstruct}``.

* ``calibrate --left GLOB --right GLOB --board SPEC --out calib.json``
* ``import-calib INTRINSICS.yml [EXTRINSICS.yml] [--image-size WxH] --out calib.json``
  (OpenCV files), or ``import-calib CAL.xml --out calib.json`` (VIC-3D or DICe)
* ``match LEFT_IMAGE RIGHT_IMAGE --points POINTS.csv [--calib calib.json] --out MATCHES.csv``
* ``reconstruct --calib calib.json --left SRC --right SRC --grid 7x7 --out DIR`` (3D points,
  each view's tracks, the per-frame quality, figures, ``summary.json`` and ``report.html``)

Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import glob
import math
import re
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from tissue_core.cli import CommandLine
from tissue_core.csvtext import csv_writer
from tissue_core.errors import InputError, SourceError

__all__ = ["main"]

#: the header of the CSV ``stereo match`` writes
MATCH_COLUMNS = (
    "point", "x_left", "y_left", "x_right", "y_right", "quality", "visible", "epipolar_px"
)  # fmt: skip
#: the grid ``reconstruct`` places without --points or --grid
_DEFAULT_GRID = "7x7"


def _natural(path: str) -> list:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", path)]


def _expand(pattern: str, side: str) -> list[str]:
    """Files matching a glob pattern (or a folder's image files), in natural order."""
    p = Path(pattern)
    if p.is_dir():
        files = [str(f) for f in p.iterdir() if f.suffix.lower() in _IMAGE_SUFFIXES]
    else:
        files = glob.glob(pattern)
    if not files:
        raise SourceError(f"--{side} {pattern!r} matches no image files")
    return sorted(files, key=_natural)


_IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp"}


def _check_unit(unit: str) -> None:
    if not unit.strip():
        raise InputError(f"--unit must be the name of a length unit, e.g. mm, got {unit!r}")


def _check_match_options(args) -> None:
    """--match-subset and --max-epipolar, before anything is read."""
    subset = args.match_subset
    if subset < 7 or subset % 2 == 0:
        raise InputError(f"--match-subset must be an odd number >= 7, got {subset}")
    tolerance = args.max_epipolar
    if not (math.isfinite(tolerance) and tolerance > 0):
        raise InputError(f"--max-epipolar must be a positive number of pixels, got {tolerance}")


def _check_subset_fits(option: str, subset: int, shape: tuple[int, int], what: str) -> None:
    h, w = shape
    if subset >= min(h, w):
        raise InputError(f"{option} {subset} is larger than the {w}x{h} {what}")


def _check_calibration_size(calib, calib_paths, shape: tuple[int, int], source: str) -> None:
    """The calibration must be for images of the size the command reads."""
    h, w = shape
    cw, ch = calib.image_size
    if (cw, ch) != (w, h):
        name = " + ".join(Path(p).name for p in calib_paths)
        raise InputError(
            f"{name} is for {cw}x{ch} images, {source} is {w}x{h}: "
            "use the calibration of the cameras and resolution that took these images"
        )


#: the least distance, px, between a target's corners or dots at which a detector finds them
MIN_FEATURE_SPACING_PX = 4


def _check_board_fits(spec: str, counts: tuple[int, int], shape: tuple[int, int]) -> None:
    """Refuse a board with more corners or dots than the images can show (its arrays, sized by
    the counts, would be allocated for nothing)."""
    most = sorted(max(1, n // MIN_FEATURE_SPACING_PX) for n in shape)
    if sorted(counts)[0] > most[0] or sorted(counts)[1] > most[1]:
        h, w = shape
        raise InputError(
            f"--board {spec}: {counts[0]}x{counts[1]} is more than {w}x{h} px images can show "
            f"(at most {most[1]}x{most[0]}, {MIN_FEATURE_SPACING_PX} px apart: the least a "
            "detector finds); give the board's own counts"
        )


def _read_points(path: str, shape: tuple[int, int], *, for_strain: bool) -> np.ndarray:
    """Points (N, 2) of a CSV file with columns x,y, checked against the image; errors name
    the file.  ``for_strain``: the points must also carry a mesh (3 or more, not collinear)."""
    from strain2d import read_points_csv, validate_points

    points = read_points_csv(path)
    if len(points) == 0:
        raise InputError(f"{path} holds no points (a header x,y and one row per point)")
    bad = np.flatnonzero(~np.isfinite(points).all(axis=1))
    if bad.size:
        i = int(bad[0])
        raise InputError(
            f"{path}: point {i} ({points[i, 0]:g}, {points[i, 1]:g}) is not finite; "
            "give numbers for x and y"
        )
    _, first = np.unique(points, axis=0, return_index=True)
    if len(first) < len(points):
        i = sorted(set(range(len(points))) - set(first.tolist()))[0]
        raise InputError(f"{path}: point {i} ({points[i, 0]:g}, {points[i, 1]:g}) is given twice")
    h, w = shape
    outside = (points < 0).any(axis=1) | (points[:, 0] > w - 1) | (points[:, 1] > h - 1)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise InputError(
            f"{path}: point {i} ({points[i, 0]:g}, {points[i, 1]:g}) lies outside the "
            f"{w}x{h} px left image"
        )
    if for_strain:
        try:
            validate_points(points, (h, w))
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None
    return points


def _say(args):
    from tissue_core.progress import Progress

    return Progress(quiet=args.quiet)


_CALIB_HELP = (
    "calibration: the JSON of stereo calibrate or import-calib, OpenCV YAML/XML files "
    "(intrinsics, extrinsics), or one VIC-3D or DICe XML; a file without the image size "
    "is taken to be for the size of the images read"
)


def _build_parser() -> CommandLine:
    cli = CommandLine("stereo", "Stereo calibration and 3D point tracks.")

    p = cli.command("calibrate", _cmd_calibrate, help="calibrate a camera pair from target images")
    p.add_argument("--left", required=True, help="left images: a glob pattern or a folder")
    p.add_argument("--right", required=True, help="right images: a glob pattern or a folder")
    p.add_argument(
        "--board",
        required=True,
        help="checkerboard:COLSxROWS:SQUARE (inner corners), "
        "charuco:COLSxROWS:SQUARE:MARKER:DICTIONARY (squares), or a dot grid "
        "circles:COLSxROWS:SPACING (acircles: for OpenCV's asymmetric grid), sizes in --unit",
    )
    p.add_argument("--unit", default="mm", help="unit of the square size (default mm)")
    p.add_argument(
        "--free-k3", action="store_true", help="also estimate the k3 distortion term (fixed at 0)"
    )
    p.add_argument("--out", required=True, help="calibration JSON to write")
    _common(p)

    p = cli.command(
        "import-calib",
        _cmd_import,
        help="convert a calibration (OpenCV YAML/XML, VIC-3D or DICe XML) to JSON",
    )
    p.add_argument(
        "files",
        nargs="+",
        help="OpenCV FileStorage files (e.g. intrinsics.yml extrinsics.yml), or one VIC-3D "
        "calibration XML, or one DICe cal.xml",
    )
    p.add_argument(
        "--image-size",
        help="WIDTHxHEIGHT px, for files that hold no image size (OpenCV's stereo_calib "
        "sample, VIC-3D .cal files)",
    )
    p.add_argument("--unit", default="mm", help="unit of T (default mm)")
    p.add_argument("--out", required=True, help="calibration JSON to write")
    _common(p)

    p = cli.command("match", _cmd_match, help="find points of the left image in the right image")
    p.add_argument("left_image")
    p.add_argument("right_image")
    p.add_argument("--points", required=True, help="CSV with columns x,y (left image, px)")
    p.add_argument("--calib", nargs="+", help=_CALIB_HELP)
    _match_args(p)
    p.add_argument("--out", required=True, help="CSV to write")
    _common(p)

    p = cli.command(
        "reconstruct",
        _cmd_reconstruct,
        later=_tracker_flags,
        help="track a grid in both videos and triangulate it",
    )
    p.add_argument("--calib", nargs="+", required=True, help=_CALIB_HELP)
    p.add_argument("--left", nargs="+", required=True, help="left video, TIFF, folder or images")
    p.add_argument("--right", nargs="+", required=True, help="right video, TIFF, folder or images")
    _add_reconstruct_options(p)
    p.add_argument("--out", required=True, help="output folder")
    _common(p)

    p = cli.command(
        "batch",
        _cmd_batch,
        later=lambda p: _tracker_flags(_batch_run_options(p)),
        help="reconstruct the specimens of a manifest as a batch (on a Dask cluster)",
        description="Reconstruct every specimen of a manifest CSV (columns left, right, "
        "optionally calib, specimen, and any reconstruct option by name, e.g. grid, roi, fps) "
        "into OUT/runs/SPECIMEN, each as one task on a local Dask cluster or a running "
        "scheduler. A failing specimen is reported and the others go on; a rerun keeps the "
        "runs that are complete with the same parameters and makes the rest. Options given "
        "here apply to every run; a manifest column of the same name wins.",
        allow_abbrev=False,
    )
    p.add_argument("manifest", metavar="MANIFEST", help="CSV: one row per specimen")
    p.add_argument("--out", required=True, help="batch folder: runs/, batch.log, batch.json")
    from tissue_core.batch import add_batch_arguments

    add_batch_arguments(p, what="reconstructions")
    options = _batch_run_options(p)
    options.add_argument(
        "--calib",
        nargs="+",
        help="the calibration of every specimen (a manifest column calib names one file "
        "per specimen instead)",
    )
    _add_reconstruct_options(options)
    p.set_defaults(run_options=options)
    return cli


_RUN_OPTIONS: dict[int, object] = {}


def _batch_run_options(p):
    """The batch parser's record of the reconstruct options it passes on (one per parser)."""
    from tissue_core.batch import RunOptions

    if id(p) not in _RUN_OPTIONS:
        _RUN_OPTIONS[id(p)] = RunOptions(p, "reconstruct options, for every run")
    return _RUN_OPTIONS[id(p)]


def _add_reconstruct_options(p) -> None:
    """``reconstruct``'s options but the inputs and the output (shared with ``batch``)."""
    p.add_argument("--grid", help=f"grid COLSxROWS (default {_DEFAULT_GRID})")
    p.add_argument("--roi", help="grid region X0,Y0,X1,Y1 in left-image pixels")
    p.add_argument("--points", help="CSV with columns x,y instead of a grid (--grid, --roi)")
    p.add_argument(
        "--mask",
        metavar="FILE",
        help="where the tissue is on the left view's reference frame: an image of its size "
        "(PNG/TIFF, not 0 is tissue), an ImageJ ROI (.roi, .zip) or a polygon CSV (x,y); the "
        "grid fills it and points and triangles off the tissue are left out",
    )
    p.add_argument(
        "--tracker",
        default="dic",
        help="2D tracker that follows the points through each video: dic, klt, or another "
        "that tracks frames (default dic); dic's warp is quadratic here (curved surfaces "
        "seen in perspective)",
    )
    p.add_argument("--max-reproj", type=float, default=1.0, help="px; worse points are dropped")
    p.add_argument(
        "--fps",
        type=float,
        default=None,
        help="frame rate of the videos: time axes in seconds (default: the frame index)",
    )
    p.add_argument(
        "--strain",
        action="store_true",
        help="also compute membrane strain on the 3D tracks into DIR/strain/",
    )
    p.add_argument(
        "--directions",
        help="with --strain: frame of Exx, Eyy, Exy (xy, vectors:..., cylinder:..., sphere:...; "
        "default xy)",
    )
    _match_args(p)


def _cmd_batch(args) -> int:
    from tissue_core.batch import (
        batch_folder,
        check_workers,
        manifest_jobs,
        manifest_rows,
        raise_if_failed,
        run_batch,
    )

    first = manifest_rows(args.manifest, required=("left", "right"))[0]
    if "calib" not in first and not getattr(args, "calib", None):
        raise InputError(
            "give the calibration: --calib for every specimen, or a calib column in the manifest"
        )
    out = Path(args.out).resolve()
    jobs, _, unused = manifest_jobs(
        args.manifest,
        out,
        args.run_options,
        args,
        module="stereo.cli",
        command="reconstruct",
        sources=[("left", "--left"), ("right", "--right")],
    )
    workers = check_workers(args.workers, args.scheduler, len(jobs))
    folder = batch_folder(args.out)
    say = _say(args)
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
    raise_if_failed(outcomes, args.out)
    say(f"results in {args.out}")
    return 0


def _match_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--match-subset",
        type=int,
        default=41,
        help="subset side for the cross-view match (41); that match always uses the quadratic "
        "warp, which follows the perspective between the views",
    )
    p.add_argument(
        "--max-epipolar",
        type=float,
        default=1.0,
        help="px from the epipolar line allowed for a match (1.0); the feature matches that "
        "relate the views are kept within 3 times this",
    )


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")


def _folders(*patterns: str) -> list[str]:
    """The patterns that name folders: inputs an output may not go into."""
    return [p for p in patterns if Path(p).is_dir()]


def _cmd_calibrate(args) -> int:
    from stereo.calibration import calibrate_stereo, parse_board
    from tissue_core.images import read_gray
    from tissue_core.outputs import atomic_file, check_writable

    board = parse_board(args.board)
    _check_unit(args.unit)
    left, right = _expand(args.left, "left"), _expand(args.right, "right")
    both = sorted({Path(f).resolve() for f in left} & {Path(f).resolve() for f in right})
    if both:
        more = f" and {len(both) - 1} more" if len(both) > 1 else ""
        raise InputError(
            f"--left {args.left} and --right {args.right} name the same images ({both[0]}"
            f"{more}): a stereo calibration needs each camera's own views of the target"
        )
    if len(left) != len(right):
        raise InputError(f"unequal image counts: {len(left)} left and {len(right)} right")
    inputs = [*left, *right, *_folders(args.left, args.right)]
    writing = {"overwrite": args.overwrite, "inputs": inputs}
    check_writable(args.out, kind="file", **writing)
    say = _say(args)
    names = [f"{Path(a).name} / {Path(b).name}" for a, b in zip(left, right, strict=True)]
    left_images, right_images = [read_gray(f) for f in left], [read_gray(f) for f in right]
    _check_board_fits(args.board, (board.cols, board.rows), left_images[0].shape)
    calib = calibrate_stereo(
        left_images,
        right_images,
        board,
        names=names,
        unit=args.unit,
        fix_k3=not args.free_k3,
        progress=say,
    )
    with atomic_file(args.out, **writing) as tmp:
        calib.save(tmp)
    for r in calib.extra["rejected"]:
        say(f"rejected {r['image']}: {r['reason']}")
    kept = len(calib.extra["views"])
    say(
        f"calibrated on {kept} of {len(left)} pairs: RMS {calib.rms_px:.3f} px "
        f"(left {calib.extra['rms_left_px']:.3f}, right {calib.extra['rms_right_px']:.3f}), "
        f"baseline {calib.baseline:.2f} {calib.unit}; written to {args.out}"
    )
    return 0


def _cmd_import(args) -> int:
    from stereo.calib_formats import parse_image_size
    from stereo.calibration import load_calibration
    from tissue_core.outputs import atomic_file, check_writable
    from tissue_core.version import __version__

    _check_unit(args.unit)
    size = parse_image_size(args.image_size) if args.image_size is not None else None
    writing = {"overwrite": args.overwrite, "inputs": args.files}
    check_writable(args.out, kind="file", **writing)
    calib = load_calibration(*args.files, image_size=size, unit=args.unit)
    calib.extra["imported_from"] = [Path(f).name for f in args.files]
    calib.extra["import_options"] = {"image_size": args.image_size, "unit": args.unit}
    calib.extra["software"] = {
        "package": "tissue-strain",
        "module": "stereo",
        "version": __version__,
    }
    with atomic_file(args.out, **writing) as tmp:
        calib.save(tmp)
    say = _say(args)
    for note in calib.extra.get("notes", []):
        say(f"note: {note}")
    say(
        f"{calib.extra.get('imported_format', 'JSON')} calibration of {' and '.join(args.files)} "
        f"written to {args.out}"
    )
    return 0


def _load_calib(paths, shape: tuple[int, int], say) -> tuple:
    """The calibration in ``paths`` (None without) and where its image size comes from.

    A file that holds no image size (OpenCV's stereo_calib sample, VIC-3D
    ``.cal`` files) is for images of ``shape`` (H, W), those the command reads:
    ``"frames"``, said through ``say``; otherwise ``"calibration"``.
    """
    from stereo.calib_formats import ImageSizeMissing
    from stereo.calibration import load_calibration

    if not paths:
        return None, None
    try:
        return load_calibration(*paths), "calibration"
    except ImageSizeMissing:
        h, w = shape
        calib = load_calibration(*paths, image_size=(w, h))
        calib.extra["image_size_from"] = "frames"
        names = " + ".join(Path(p).name for p in paths)
        say(f"note: {names} holds no image size: taken from the images, {w}x{h} px")
        return calib, "frames"


def _cmd_match(args) -> int:
    from stereo.match import match_views
    from tissue_core.images import read_gray
    from tissue_core.outputs import atomic_file, check_writable

    _check_match_options(args)
    inputs = [args.left_image, args.right_image, args.points, *(args.calib or [])]
    writing = {"overwrite": args.overwrite, "inputs": inputs}
    check_writable(args.out, kind="file", **writing)
    left, right = read_gray(args.left_image), read_gray(args.right_image)
    if left.shape != right.shape:
        raise InputError(
            f"the views differ in size: {args.left_image} is {left.shape[1]}x{left.shape[0]}, "
            f"{args.right_image} is {right.shape[1]}x{right.shape[0]}"
        )
    calib, _ = _load_calib(args.calib, left.shape, _say(args))
    if calib is not None:
        _check_calibration_size(calib, args.calib, left.shape, args.left_image)
    _check_subset_fits("--match-subset", args.match_subset, left.shape, "images")
    points = _read_points(args.points, left.shape, for_strain=False)
    m = match_views(
        left,
        right,
        points,
        calib=calib,
        subset=args.match_subset,
        max_epipolar_px=args.max_epipolar,
    )
    with atomic_file(args.out, **writing) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            w = csv_writer(f)
            w.writerow(MATCH_COLUMNS)
            for i in range(len(points)):
                w.writerow(
                    [
                        i,
                        f"{m.left[i, 0]:.4f}",
                        f"{m.left[i, 1]:.4f}",
                        f"{m.right[i, 0]:.4f}",
                        f"{m.right[i, 1]:.4f}",
                        f"{m.quality[i]:.4f}",
                        int(m.visible[i]),
                        f"{m.epipolar_px[i]:.4f}",
                    ]
                )
    _say(args)(f"matched {int(m.visible.sum())} of {len(points)} points; written to {args.out}")
    return 0


def _tracker_flags(p: argparse.ArgumentParser) -> None:
    """The options of the trackers reconstruct can use, as the registry declares them (built
    when the command runs: it imports the trackers)."""
    from stereo.report import WARP_NOISE_NOTE
    from strain2d import add_tracker_arguments

    # the trade-off of reconstruct's own default warp, told where the warp is chosen
    note = (
        f"For dic, reconstruct defaults to quadratic: {WARP_NOISE_NOTE}; give "
        "--shape-function affine for flat specimens"
    )
    add_tracker_arguments(
        p, _frame_trackers(), defaults=_TRACKER_DEFAULTS, notes={"--shape-function": note}
    )


#: reconstruct's own tracker defaults: curved surfaces seen in perspective need dic's
#: second-order warp
_TRACKER_DEFAULTS = {"dic": {"shape_function": "quadratic"}}


def _frame_trackers() -> list[str]:
    """The trackers reconstruct can use: those that track frames."""
    from strain2d import available_trackers

    return [name for name, spec in available_trackers().items() if spec.needs_frames]


def _tracker_options(args) -> dict:
    from strain2d import tracker_options

    options = tracker_options(args, args.tracker, defaults=_TRACKER_DEFAULTS)
    subset = options.get("subset")
    if args.tracker == "dic" and subset is not None and (subset < 7 or subset % 2 == 0):
        raise InputError(f"--subset must be an odd number >= 7, got {subset}")
    return options


def _check_reconstruct_options(args) -> None:
    """Every option of ``reconstruct`` that can be judged before anything is read."""
    from strain2d import available_trackers

    if args.points and (args.grid is not None or args.roi is not None):
        raise InputError("give either --points or --grid/--roi, not both")
    if args.fps is not None and not (np.isfinite(args.fps) and args.fps > 0):
        raise InputError(f"--fps must be a positive number, got {args.fps}")
    if args.directions is not None and not args.strain:
        raise InputError("--directions sets the frame of the strain: it needs --strain")
    usable = _frame_trackers()
    if args.tracker not in usable:
        what = "reads tracks made elsewhere" if args.tracker in available_trackers() else None
        reason = (
            f"the {args.tracker} tracker {what}; reconstruct tracks both videos itself"
            if what
            else f"unknown tracker {args.tracker!r}"
        )
        raise InputError(f"--tracker {args.tracker}: {reason}: use one of {', '.join(usable)}")
    _tracker_options(args)
    if not (math.isfinite(args.max_reproj) and args.max_reproj > 0):
        raise InputError(f"--max-reproj must be a positive number of pixels, got {args.max_reproj}")
    _check_match_options(args)
    if args.strain:
        from surface_strain import parse_directions

        parse_directions(args.directions or "xy")


def _grid_points(args, shape: tuple[int, int]) -> tuple[np.ndarray, dict]:
    from strain2d import make_grid, parse_grid, parse_roi

    text = args.grid or _DEFAULT_GRID
    cols, rows = parse_grid(text)
    roi = parse_roi(args.roi) if args.roi else None
    if roi is not None and not all(math.isfinite(v) for v in roi):
        raise InputError(f"--roi must be four finite numbers X0,Y0,X1,Y1, got {args.roi!r}")
    points = make_grid(shape, shape=(cols, rows), roi=roi)
    return points, {"grid": [cols, rows], "roi": list(roi) if roi else None}


def _masked_grid_points(args, mask, shape: tuple[int, int]):
    """The grid in ``--mask`` (:func:`strain2d.grid.masked_grid`): points, triangles, info."""
    from strain2d import masked_grid, parse_grid, parse_roi

    cols, rows = parse_grid(args.grid or _DEFAULT_GRID)
    roi = parse_roi(args.roi) if args.roi else None
    if roi is not None and not all(math.isfinite(v) for v in roi):
        raise InputError(f"--roi must be four finite numbers X0,Y0,X1,Y1, got {args.roi!r}")
    points, triangles, counts = masked_grid(shape, mask, shape=(cols, rows), roi=roi)
    info = {
        "grid": [cols, rows],
        "roi": list(roi) if roi else list(mask.bounds()),
        "mask": {**mask.summary(), **counts},
    }
    return points, triangles, info


def _source_name(source) -> str:
    return source.names[0] if len(source.names) == 1 else f"{source.names[0]} ..."


_VIEWS_CAPTION = (
    "The reference frames of both views with the points (circles) and where the points "
    "with a 3D position are on the last frame (crosses)."
)
_POINTS_CAPTION = (
    "The triangulated points in the left camera's frame ({unit}), on the reference frame "
    "(grey) and the last frame (coloured by reprojection error)."
)
_QUALITY_CAPTION = (
    "Per frame: the reprojection error of the triangulated points (median and 95th "
    "percentile), the median tracking quality of each view against its reference frame, "
    "and the share of the points with a 3D position."
)


def _write_frame_quality(path: Path, per_frame: dict) -> None:
    """``quality_per_frame.csv``: one row per frame (:func:`stereo.report.frame_quality`)."""
    from stereo.report import FRAME_COLUMNS

    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv_writer(f)
        w.writerow(FRAME_COLUMNS)
        for t in range(len(per_frame["frame"])):
            row = []
            for c in FRAME_COLUMNS:
                v = per_frame[c][t]
                row.append(int(v) if c in ("frame", "points_3d", "lost") else f"{v:.4f}")
            w.writerow(row)


def _results(rec) -> dict:
    """The reconstruction's results in the calibration's unit, for the summary."""
    p0 = rec.points[0][np.isfinite(rec.points[0]).all(axis=1)]
    moved = np.linalg.norm(rec.points[-1] - rec.points[0], axis=1)
    moved = moved[np.isfinite(moved)]
    return {
        "extent": np.ptp(p0, axis=0).tolist() if len(p0) else None,
        "mean_depth": float(p0[:, 2].mean()) if len(p0) else None,
        "displacement_median": float(np.median(moved)) if moved.size else None,
        "displacement_max": float(moved.max()) if moved.size else None,
    }


def _strain_summary(field, mesh) -> dict:
    """Nodal strain statistics on the last frame, for the summary and the report."""
    from surface_strain import nodal_scalars

    node = nodal_scalars(field)
    last = {}
    for key in ("Exx", "Eyy", "Exy", "E1", "E2"):
        v = node[key][-1]
        v = v[np.isfinite(v)]
        last[key] = {
            "mean": float(v.mean()) if v.size else None,
            "sd": float(v.std(ddof=1)) if v.size > 1 else None,
            "min": float(v.min()) if v.size else None,
            "max": float(v.max()) if v.size else None,
            "n": int(v.size),
        }
    return {
        "folder": "strain",
        "definition": "Green-Lagrange membrane strain",
        "mesh": mesh.description,
        "last_frame": last,
    }


def _quality_summary(summary: dict, rec, calib, per_frame: dict, field, args) -> None:
    """Add the measurement's quality and what it flags to the summary."""
    from stereo.report import (
        calibration_quality,
        flatness,
        match_quality,
        mesh_quality,
        quality_flags,
    )

    err = rec.reproj_error[rec.visible]
    quality = {
        "calibration": calibration_quality(calib),
        "matching": match_quality(rec),
        "reprojection": {
            "median_px": float(np.median(err)) if err.size else None,
            "p95_px": float(np.percentile(err, 95)) if err.size else None,
            "max_px": float(err.max()) if err.size else None,
        },
        "tracking_quality": rec.meta["tracking_quality"],
        "per_frame": "quality_per_frame.csv",
        "surface": flatness(rec.points),
    }
    if field is not None:
        quality["mesh"] = mesh_quality(field)
    summary["quality"] = quality
    summary["flags"] = quality_flags(
        per_frame,
        quality["calibration"],
        quality["matching"],
        max_reproj_px=args.max_reproj,
        quality_name=rec.meta["tracking_quality"],
        warp=summary["parameters"]["shape_function"],
        surface=quality["surface"],
        mesh=quality.get("mesh"),
    )


def _cmd_reconstruct(args) -> int:
    from stereo.reconstruct import reconstruct
    from strain2d import open_frames
    from tissue_core.html import input_records
    from tissue_core.jsonio import write_json
    from tissue_core.outputs import atomic_dir, check_writable, recorded_command
    from tissue_core.version import __version__

    _check_reconstruct_options(args)
    from strain2d import tracker_inputs

    inputs = [*args.left, *args.right, *args.calib] + ([args.points] if args.points else [])
    inputs += [args.mask] if args.mask else []
    inputs += tracker_inputs(args)
    check_writable(args.out, overwrite=args.overwrite, inputs=inputs)
    say = _say(args)
    left, right = open_frames(args.left), open_frames(args.right)
    if len(left) != len(right):
        raise InputError(
            f"the views have different frame counts: {len(left)} in {_source_name(left)}, "
            f"{len(right)} in {_source_name(right)}"
        )
    calib, size_from = _load_calib(args.calib, left.shape, say)
    _check_calibration_size(calib, args.calib, left.shape, _source_name(left))
    _check_calibration_size(calib, args.calib, right.shape, _source_name(right))
    _check_subset_fits("--match-subset", args.match_subset, left.shape, "frames")
    options = _tracker_options(args)
    if isinstance(options.get("subset"), int):
        _check_subset_fits("--subset", options["subset"], left.shape, "frames")
    mask = None
    if args.mask:
        from tissue_core.masks import read_mask

        mask = read_mask(args.mask, left.shape)
    masked_triangles = None  # a grid in the mask: its triangles on the tissue
    if args.points:
        points = _read_points(args.points, left.shape, for_strain=True)
        point_info = {"source": Path(args.points).name}
        if mask is not None:
            from strain2d import points_on_tissue

            on = points_on_tissue(points, mask, source=args.points)
            point_info["mask"] = {**mask.summary(), "points_off_tissue": int((~on).sum())}
            points = points[on]
    elif mask is not None:
        points, masked_triangles, point_info = _masked_grid_points(args, mask, left.shape)
    else:
        points, point_info = _grid_points(args, left.shape)
    from strain2d import check_tracks_fit

    check_tracks_fit(
        len(points), len(left), views=2, remedy="use fewer points (--grid, --points) or frames"
    )
    directions = args.directions or "xy"
    rec = reconstruct(
        left,
        right,
        calib,
        points,
        tracker=args.tracker,
        options=options,
        match_options={"subset": args.match_subset, "max_epipolar_px": args.max_epipolar},
        max_reproj_px=args.max_reproj,
        progress=say,
    )
    from strain2d import Tracks, write_tracks_csv
    from tissue_core.tables import write_long_table

    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        write_long_table(
            tmp / "points3d.csv",
            {
                **{axis: (rec.points[..., k], "%.6f") for k, axis in enumerate("XYZ")},
                "reproj_error": (rec.reproj_error, "%.4f"),
                "visible": (rec.visible, "%d"),
            },
        )
        for side, pos in (("left", rec.left), ("right", rec.right)):
            seen = np.isfinite(pos).all(axis=2)
            write_tracks_csv(
                tmp / f"tracks_{side}.csv",
                Tracks(
                    positions=np.where(seen[..., None], pos, np.nan),
                    visible=seen,
                    quality=np.where(rec.visible, 1.0, 0.0),
                ),
            )
        from stereo.figures import plot_points3d, plot_quality, plot_views
        from stereo.report import frame_quality

        (tmp / "figures").mkdir()
        plot_views(left.first(), right.first(), rec).savefig(tmp / "figures" / "views.png")
        plot_points3d(rec, unit=calib.unit).savefig(tmp / "figures" / "points3d.png")
        per_frame = frame_quality(rec)
        _write_frame_quality(tmp / "quality_per_frame.csv", per_frame)
        plot_quality(
            per_frame,
            max_reproj_px=args.max_reproj,
            quality_name=rec.meta["tracking_quality"],
            fps=args.fps,
        ).savefig(tmp / "figures" / "quality.png")
        err = rec.reproj_error[rec.visible]
        summary = {
            "software": {"name": "stereo", "version": __version__},
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "command": recorded_command.get(),
            "inputs": {"left": left.names, "right": right.names, "calib": args.calib},
            "input_files": input_records(inputs),
            "unit": calib.unit,
            "calibration": {
                "image_size": list(calib.image_size),
                # "frames": the calibration file holds none; it is that of the frames
                "image_size_from": size_from,
                "baseline": calib.baseline,
                "rms_px": calib.rms_px,  # NaN (null) for a calibration made elsewhere
            },
            "frames": rec.n_frames,
            # surface_strain compute reads the frame rate from here for points3d.csv
            "time_axis": {"fps": args.fps, "unit": "s" if args.fps else "frame"},
            "points": {"n": rec.n_points, **point_info},
            "visible_fraction": float(rec.visible.mean()),
            "reprojection_rms_px": float(np.sqrt(np.mean(err**2))) if err.size else None,
            "reprojection_max_px": float(err.max()) if err.size else None,
            "parameters": {
                "tracker": args.tracker,
                "subset": options.get("subset"),
                "shape_function": options.get("shape_function"),
                "tracker_options": options,
                "match_subset": args.match_subset,
                "max_epipolar_px": args.max_epipolar,
                "max_reproj_px": args.max_reproj,
                "directions": directions if args.strain else None,
            },
            "match": rec.meta["match"],
            "results": _results(rec),
        }
        field = None
        if args.strain:
            from surface_strain import choose_mesh, write_run

            say("computing strain")
            usable = rec.visible[0] & np.isfinite(rec.points[0]).all(axis=1)
            if masked_triangles is not None:
                from surface_strain import Mesh

                cols, rows = point_info["grid"]
                how = f"grid {cols}x{rows} on the mask's tissue, alternating diagonals"
                mesh = Mesh(masked_triangles, "grid", how)
            else:
                grid = None if args.points else tuple(point_info["grid"])
                mesh = choose_mesh(rec.points[0], usable, grid=grid)
                if mask is not None:  # Delaunay of the points on the tissue: its triangles on it
                    from strain2d import mask_triangles

                    kept = mask_triangles(points, mesh.triangles, mask)
                    point_info["mask"]["triangles_off_tissue"] = len(mesh.triangles) - len(kept)
                    mesh = mesh._replace(triangles=kept)
            (tmp / "strain").mkdir()
            field = write_run(
                tmp / "strain",
                rec.points,
                rec.visible,
                mesh,
                directions=directions,
                unit=calib.unit,
                source="points3d.csv",
                point_quality={"reproj_error": rec.reproj_error},
                fps=args.fps,
            )
            summary["strain"] = _strain_summary(field, mesh)
        _quality_summary(summary, rec, calib, per_frame, field, args)
        figures = [
            {"file": "figures/views.png", "caption": _VIEWS_CAPTION},
            {"file": "figures/points3d.png", "caption": _POINTS_CAPTION.format(unit=calib.unit)},
            {"file": "figures/quality.png", "caption": _QUALITY_CAPTION},
        ]
        if args.strain:
            from stereo.report import strain_figures

            figures += strain_figures(tmp)
        summary["figures"] = [item["file"] for item in figures]
        write_json(tmp / "summary.json", summary)
        from stereo.report import write_report

        write_report(tmp, summary, per_frame, figures=figures)
    rms = summary["reprojection_rms_px"]
    say(
        f"{rec.n_points} points x {rec.n_frames} frames, "
        f"{100 * summary['visible_fraction']:.1f} % visible, reprojection RMS "
        f"{'-' if rms is None else f'{rms:.3f}'} px"
    )
    say(f"results in {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from tissue_core.cli import run_command

    return run_command("stereo", _build_parser(), argv)


def entry() -> None:
    """The console script ``stereo``: like ``python -m stereo``."""
    from tissue_core.cli import run_module

    run_module(__name__)
