"""Command line: ``python -m surface_strain compute POINTS3D.csv --out DIR``.

Reads 3D point tracks (``frame,point,X,Y,Z[,visible]``: the output of
``python -m stereo reconstruct`` as it is), meshes the reference points,
computes membrane strain per triangle and node for every frame, and writes
``strain_nodes.csv``, ``strain_elements.csv``, ``summary.json``, the
ParaView series ``strain.pvd``, figures and a self-contained ``report.html``
(inputs with checksums, parameters, results with units, the quality of the
measurement, what was flagged).  Errors a user can cause end
with one line on stderr and exit status 2.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from surface_strain.run import parse_directions, write_run
from tissue_core.errors import InputError

__all__ = ["main"]


def _build_parser():
    from tissue_core.cli import CommandLine

    cli = CommandLine("surface_strain", "Membrane strain on tracked surfaces.")
    p = cli.command(
        "compute", _cmd_compute, help="strain per triangle and node from 3D point tracks"
    )
    p.add_argument(
        "points", help="CSV with frame,point,X,Y,Z[,visible] (e.g. stereo's points3d.csv)"
    )
    p.add_argument("--triangles", help="CSV of p0,p1,p2 point indices (default: see --grid)")
    p.add_argument(
        "--grid",
        help="the points form a COLSxROWS grid (row by row): mesh it by its topology; by "
        "default taken from a stereo summary.json beside the points, else Delaunay",
    )
    p.add_argument("--directions", default="xy", help="frame of Exx, Eyy, Exy (default xy)")
    p.add_argument(
        "--projection",
        choices=["plane", "sphere", "cylinder"],
        default=None,
        help="Delaunay meshing of scattered points: in their best-fit plane (default), or "
        "on the best-fit sphere or cylinder for caps and tubes too curved for one plane",
    )
    p.add_argument(
        "--fps",
        type=float,
        help="frame rate: times in seconds in the figures, the report and the ParaView series "
        "(default: from a stereo summary.json beside the points, else frames)",
    )
    p.add_argument(
        "--unit", help="unit of X, Y, Z (default: from summary.json, else 'input units')"
    )
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    return cli


def _stereo_summary(points_path: Path) -> dict:
    path = points_path.parent / "summary.json"
    if not path.is_file():
        return {}
    try:
        summary = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        return {}
    return summary if isinstance(summary, dict) else {}


def _grid(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--grid must be COLSxROWS, got {text!r}") from None
    return cols, rows


def _mesh(points: np.ndarray, visible: np.ndarray, args, summary: dict):
    """The mesh --triangles, --grid or --projection ask for; else the grid stereo recorded,
    else Delaunay."""
    from surface_strain.io import read_triangles
    from surface_strain.run import choose_mesh

    flags = [flag for flag, value in (("--triangles", args.triangles), ("--grid", args.grid),
             ("--projection", args.projection)) if value]  # fmt: skip
    if len(flags) > 1:
        raise InputError(
            f"{' and '.join(flags)} each choose the mesh: give one of them "
            "(--projection applies to the Delaunay mesh of scattered points)"
        )
    if args.triangles:
        triangles = read_triangles(args.triangles, points.shape[1])
        return choose_mesh(points[0], triangles=triangles, source=Path(args.triangles).name)
    grid = _grid(args.grid) if args.grid else None
    if grid is None and not args.projection:  # an explicit --projection asks for Delaunay
        info = summary.get("points") if isinstance(summary, dict) else None
        given = info.get("grid") if isinstance(info, dict) else None
        if isinstance(given, list) and len(given) == 2:
            try:
                grid = (int(given[0]), int(given[1]))
            except (TypeError, ValueError):
                grid = None
    return choose_mesh(points[0], visible[0], grid=grid, projection=args.projection)


def _summary_fps(summary: dict) -> float | None:
    """A frame rate the stereo summary records (``fps``, or ``time_axis.fps``), if any."""
    axis = summary.get("time_axis")
    fps = summary.get("fps") or (axis.get("fps") if isinstance(axis, dict) else None)
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        return None
    return fps if np.isfinite(fps) and fps > 0 else None


def _point_quality(path: Path) -> dict[str, np.ndarray]:
    """The per-point quality columns of the points file (stereo's ``reproj_error``), if any."""
    from surface_strain.report import POINT_QUALITY_COLUMNS
    from tissue_core.tables import read_long_table

    with open(path, newline="", encoding="utf-8-sig") as f:
        header = [h.strip().lower() for h in next(csv.reader(f), [])]
    names = [c for c in POINT_QUALITY_COLUMNS if c in header]
    if not names:
        return {}
    table = read_long_table(path, required=names)
    return {c: table[c] for c in names}


def _inputs(args) -> list[Path]:
    """Every file compute reads: the points, --triangles, and stereo's summary beside them."""
    files = [Path(args.points), Path(args.points).parent / "summary.json"]
    return files + ([Path(args.triangles)] if args.triangles else [])


def _cmd_compute(args) -> int:
    from surface_strain.field import nodal_scalars
    from surface_strain.io import read_points3d
    from tissue_core.outputs import atomic_dir, check_writable
    from tissue_core.progress import Progress

    check_writable(args.out, overwrite=args.overwrite, inputs=_inputs(args))
    if args.fps is not None and not (np.isfinite(args.fps) and args.fps > 0):
        raise InputError(f"--fps must be a positive number, got {args.fps}")
    parse_directions(args.directions)  # fail before the work
    say = Progress(quiet=args.quiet)
    tracks = read_points3d(args.points)
    points, visible = tracks.positions, tracks.visible
    say(f"{args.points}: {points.shape[1]} points over {points.shape[0]} frames")
    summary_in = _stereo_summary(Path(args.points))
    given = summary_in.get("unit")
    unit = args.unit or (given if isinstance(given, str) and given.strip() else None)
    fps = args.fps if args.fps is not None else _summary_fps(summary_in)
    mesh = _mesh(points, visible, args, summary_in)
    quality = _point_quality(Path(args.points))
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=_inputs(args)) as tmp:
        field = write_run(
            tmp,
            points,
            visible,
            mesh,
            directions=args.directions,
            unit=unit,
            fps=fps,
            figures=not args.no_figures,
            source=Path(args.points).name,
            inputs=[p for p in _inputs(args) if p.is_file()],
            point_quality=quality,
        )
    e1 = nodal_scalars(field)["E1"][-1]
    e1_mean = f"{np.nanmean(e1):.4f}" if np.isfinite(e1).any() else "- (no valid node)"
    say(
        f"{field.n_points} points, {field.n_triangles} triangles ({mesh.description}), "
        f"{field.n_frames} frames; last frame E1 mean {e1_mean}"
    )
    say(f"results in {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from tissue_core.cli import run_command

    return run_command("surface_strain", _build_parser(), argv)


def entry() -> None:
    """The console script ``surface-strain``: like ``python -m surface_strain``."""
    from tissue_core.cli import run_module

    run_module(__name__)
