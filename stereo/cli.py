"""Command line: ``python -m stereo {calibrate,import-calib,match,reconstruct}``.

* ``calibrate --left GLOB --right GLOB --board SPEC --out calib.json``
* ``import-calib INTRINSICS.yml [EXTRINSICS.yml] --out calib.json`` (OpenCV files)
* ``match LEFT_IMAGE RIGHT_IMAGE --points POINTS.csv [--calib calib.json] --out MATCHES.csv``
* ``reconstruct --calib calib.json --left SRC --right SRC --grid 7x7 --out DIR``

Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import csv
import glob
import json
import re
import sys
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from strain2d.errors import InputError, SourceError

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:
        self.exit(2, f"{self.prog}: error: {message}\n")


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


def _read_gray(path: str) -> np.ndarray:
    import cv2

    image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise SourceError(f"cannot read the image {path}")
    return image


def _say(args):
    start = time.perf_counter()

    def say(message: str) -> None:
        if not args.quiet:
            print(f"[{time.perf_counter() - start:6.1f} s] {message}", file=sys.stderr, flush=True)

    return say


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="stereo", description="Stereo calibration and 3D point tracks.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    p = sub.add_parser("calibrate", help="calibrate a camera pair from target images")
    p.add_argument("--left", required=True, help="left images: a glob pattern or a folder")
    p.add_argument("--right", required=True, help="right images: a glob pattern or a folder")
    p.add_argument(
        "--board",
        required=True,
        help="checkerboard:COLSxROWS:SQUARE (inner corners) or "
        "charuco:COLSxROWS:SQUARE:MARKER:DICTIONARY (squares), sizes in --unit",
    )
    p.add_argument("--unit", default="mm", help="unit of the square size (default mm)")
    p.add_argument(
        "--free-k3", action="store_true", help="also estimate the k3 distortion term (fixed at 0)"
    )
    p.add_argument("--out", required=True, help="calibration JSON to write")
    _common(p)
    p.set_defaults(handler=_cmd_calibrate)

    p = sub.add_parser("import-calib", help="convert OpenCV YAML/XML calibration files to JSON")
    p.add_argument(
        "files", nargs="+", help="OpenCV FileStorage files (e.g. intrinsics, extrinsics)"
    )
    p.add_argument("--unit", default="mm", help="unit of T (default mm)")
    p.add_argument("--out", required=True, help="calibration JSON to write")
    _common(p)
    p.set_defaults(handler=_cmd_import)

    p = sub.add_parser("match", help="find points of the left image in the right image")
    p.add_argument("left_image")
    p.add_argument("right_image")
    p.add_argument("--points", required=True, help="CSV with columns x,y (left image, px)")
    p.add_argument("--calib", nargs="+", help="calibration (JSON, or OpenCV YAML files)")
    _match_args(p)
    p.add_argument("--out", required=True, help="CSV to write")
    _common(p)
    p.set_defaults(handler=_cmd_match)

    p = sub.add_parser("reconstruct", help="track a grid in both videos and triangulate it")
    p.add_argument("--calib", nargs="+", required=True, help="calibration (JSON or OpenCV YAML)")
    p.add_argument("--left", nargs="+", required=True, help="left video, TIFF, folder or images")
    p.add_argument("--right", nargs="+", required=True, help="right video, TIFF, folder or images")
    p.add_argument("--grid", default="7x7", help="grid COLSxROWS (default 7x7)")
    p.add_argument("--roi", help="grid region X0,Y0,X1,Y1 in left-image pixels")
    p.add_argument("--points", help="CSV with columns x,y instead of a grid")
    p.add_argument("--tracker", default="dic", help="2D tracker: dic, klt (default dic)")
    p.add_argument("--subset", type=int, help="dic subset side in px (default 31)")
    p.add_argument(
        "--shape-function",
        choices=["affine", "quadratic"],
        default="quadratic",
        help="dic subset warp (default quadratic: curved surfaces seen in perspective)",
    )
    p.add_argument("--max-reproj", type=float, default=1.0, help="px; worse points are dropped")
    p.add_argument(
        "--strain",
        action="store_true",
        help="also compute membrane strain on the 3D tracks into DIR/strain/",
    )
    p.add_argument(
        "--directions",
        default="xy",
        help="with --strain: frame of Exx, Eyy, Exy (xy, vectors:..., cylinder:..., sphere:...)",
    )
    _match_args(p)
    p.add_argument("--out", required=True, help="output folder")
    _common(p)
    p.set_defaults(handler=_cmd_reconstruct)
    return parser


def _match_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--match-subset", type=int, default=41, help="subset side for the cross-view match (41)"
    )
    p.add_argument(
        "--max-epipolar", type=float, default=1.0, help="px from the epipolar line allowed (1.0)"
    )


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress messages")
    p.add_argument("-v", "--verbose", action="store_true", help="log details")


def _cmd_calibrate(args) -> int:
    from stereo.calibration import calibrate_stereo, parse_board
    from tissue_core.outputs import atomic_file, check_writable

    board = parse_board(args.board)
    left, right = _expand(args.left, "left"), _expand(args.right, "right")
    if len(left) != len(right):
        raise InputError(f"unequal image counts: {len(left)} left and {len(right)} right")
    check_writable(args.out, overwrite=args.overwrite, kind="file", inputs=left + right)
    say = _say(args)
    names = [f"{Path(a).name} / {Path(b).name}" for a, b in zip(left, right, strict=True)]
    calib = calibrate_stereo(
        [_read_gray(f) for f in left],
        [_read_gray(f) for f in right],
        board,
        names=names,
        unit=args.unit,
        fix_k3=not args.free_k3,
        progress=say,
    )
    with atomic_file(args.out, overwrite=args.overwrite, inputs=left + right) as tmp:
        calib.save(tmp)
    if not args.quiet:
        for r in calib.extra["rejected"]:
            print(f"rejected {r['image']}: {r['reason']}", file=sys.stderr)
        kept = len(calib.extra["views"])
        print(
            f"calibrated on {kept} of {len(left)} pairs: RMS {calib.rms_px:.3f} px "
            f"(left {calib.extra['rms_left_px']:.3f}, right {calib.extra['rms_right_px']:.3f}), "
            f"baseline {calib.baseline:.2f} {calib.unit}; written to {args.out}",
            file=sys.stderr,
        )
    return 0


def _cmd_import(args) -> int:
    from stereo.calibration import load_calibration
    from tissue_core.outputs import atomic_file

    calib = load_calibration(*args.files)
    calib.unit = args.unit
    calib.extra["imported_from"] = [Path(f).name for f in args.files]
    with atomic_file(args.out, overwrite=args.overwrite, inputs=args.files) as tmp:
        calib.save(tmp)
    return 0


def _load_calib(paths):
    from stereo.calibration import load_calibration

    return load_calibration(*paths) if paths else None


def _cmd_match(args) -> int:
    from stereo.match import match_views
    from strain2d.grid import read_points_csv
    from tissue_core.outputs import atomic_file, check_writable

    inputs = [args.left_image, args.right_image, args.points, *(args.calib or [])]
    check_writable(args.out, overwrite=args.overwrite, kind="file", inputs=inputs)
    calib = _load_calib(args.calib)
    left, right = _read_gray(args.left_image), _read_gray(args.right_image)
    points = read_points_csv(args.points)
    m = match_views(
        left,
        right,
        points,
        calib=calib,
        subset=args.match_subset,
        max_epipolar_px=args.max_epipolar,
    )
    with atomic_file(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(
                ["point", "x_left", "y_left", "x_right", "y_right", "quality", "visible",
                 "epipolar_px"]
            )  # fmt: skip
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
    if not args.quiet:
        print(
            f"matched {int(m.visible.sum())} of {len(points)} points; written to {args.out}",
            file=sys.stderr,
        )
    return 0


def _cmd_reconstruct(args) -> int:
    from stereo.reconstruct import reconstruct
    from strain2d import __version__
    from strain2d.frames import open_frames
    from strain2d.grid import make_grid, parse_grid, parse_roi, read_points_csv
    from tissue_core.outputs import atomic_dir, check_writable

    inputs = [*args.left, *args.right, *args.calib] + ([args.points] if args.points else [])
    check_writable(args.out, overwrite=args.overwrite, inputs=inputs)
    if not (np.isfinite(args.max_reproj) and args.max_reproj > 0):
        raise InputError(f"--max-reproj must be a positive number, got {args.max_reproj}")
    calib = _load_calib(args.calib)
    left, right = open_frames(args.left), open_frames(args.right)
    if args.points:
        points = read_points_csv(args.points)
        point_info = {"source": Path(args.points).name}
    else:
        shape = parse_grid(args.grid)
        roi = parse_roi(args.roi) if args.roi else None
        points = make_grid(left.shape, shape=shape, roi=roi)
        point_info = {"grid": list(shape), "roi": list(roi) if roi else None}
    if args.strain:
        from surface_strain.cli import parse_directions

        parse_directions(args.directions)  # fail before the work
    say = _say(args)
    options = {}
    if args.tracker == "dic":
        options["shape_function"] = args.shape_function
        if args.subset:
            options["subset"] = args.subset
    elif args.subset:
        raise InputError("--subset is an option of the dic tracker")
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
    from strain2d.tracks import Tracks, write_tracks_csv

    with atomic_dir(args.out, overwrite=args.overwrite, inputs=inputs) as tmp:
        with open(tmp / "points3d.csv", "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow(["frame", "point", "X", "Y", "Z", "reproj_error", "visible"])
            for t in range(rec.n_frames):
                for i in range(rec.n_points):
                    X = rec.points[t, i]
                    w.writerow(
                        [t, i, *(f"{v:.6f}" for v in X), f"{rec.reproj_error[t, i]:.4f}",
                         int(rec.visible[t, i])]
                    )  # fmt: skip
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
        from stereo.figures import plot_points3d, plot_views

        (tmp / "figures").mkdir()
        plot_views(left.first(), right.first(), rec).savefig(tmp / "figures" / "views.png")
        plot_points3d(rec, unit=calib.unit).savefig(tmp / "figures" / "points3d.png")
        err = rec.reproj_error[rec.visible]
        summary = {
            "software": {"name": "stereo", "version": __version__},
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "inputs": {"left": left.names, "right": right.names, "calib": args.calib},
            "unit": calib.unit,
            "frames": rec.n_frames,
            "points": {"n": rec.n_points, **point_info},
            "visible_fraction": float(rec.visible.mean()),
            "reprojection_rms_px": float(np.sqrt(np.mean(err**2))) if err.size else None,
            "reprojection_max_px": float(err.max()) if err.size else None,
            "parameters": {
                "tracker": args.tracker,
                "subset": args.subset,
                "shape_function": args.shape_function if args.tracker == "dic" else None,
                "match_subset": args.match_subset,
                "max_epipolar_px": args.max_epipolar,
                "max_reproj_px": args.max_reproj,
            },
            "match": rec.meta["match"],
        }
        with open(tmp / "summary.json", "w", encoding="utf-8") as f:
            json.dump(summary, f, indent=2)
            f.write("\n")
        if args.strain:
            from surface_strain.cli import write_strain_folder
            from surface_strain.mesh import delaunay_triangles, grid_triangles

            say("computing strain")
            if not args.points:
                cols, rows = point_info["grid"]
                triangles, how = grid_triangles(rows, cols), f"grid {cols}x{rows}"
            else:
                triangles, how = delaunay_triangles(rec.points[0]), "Delaunay"
            (tmp / "strain").mkdir()
            write_strain_folder(
                tmp / "strain",
                rec.points,
                rec.visible,
                triangles,
                mesh_method=how,
                directions=args.directions,
                unit=calib.unit,
                source="points3d.csv",
            )
    if not args.quiet:
        rms = summary["reprojection_rms_px"]
        print(
            f"{rec.n_points} points x {rec.n_frames} frames, "
            f"{100 * summary['visible_fraction']:.1f} % visible, reprojection RMS "
            f"{'-' if rms is None else f'{rms:.3f}'} px; results in {args.out}",
            file=sys.stderr,
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from surface_strain.cli import UsageError
    from surface_strain.io import PointsError
    from tissue_core.cli import run_command

    return run_command("stereo", _build_parser(), argv, errors=(UsageError, PointsError))
