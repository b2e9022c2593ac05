"""Command line: ``python -m surface_strain compute POINTS3D.csv --out DIR``.

Reads 3D point tracks (``frame,point,X,Y,Z[,visible]``: the output of
``python -m stereo reconstruct`` as it is), meshes the reference points,
computes membrane strain per triangle and node for every frame, and writes
``strain_nodes.csv``, ``strain_elements.csv``, ``summary.json``, the
ParaView series ``strain.pvd`` and figures.  Errors a user can cause end
with one line on stderr and exit status 2.
"""

from __future__ import annotations

import json
import warnings
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

__all__ = ["main"]


class UsageError(ValueError):
    """A bad option or input, reported as one line."""


def _vector(text: str, what: str) -> np.ndarray:
    try:
        v = np.array([float(t) for t in text.split(",")])
    except ValueError:
        raise UsageError(f"{what} must be three numbers X,Y,Z, got {text!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all():
        raise UsageError(f"{what} must be three finite numbers X,Y,Z, got {text!r}")
    return v


def parse_directions(text: str) -> dict:
    """Keyword arguments of :func:`compute_strain` for ``--directions``.

    ``xy`` (default): global X and Y.  ``vectors:AX,AY,AZ:BX,BY,BZ``: two
    constant directions.  ``cylinder:PX,PY,PZ:AX,AY,AZ``: axial and
    circumferential about the axis through P along A.
    ``sphere:PX,PY,PZ:AX,AY,AZ``: meridional and circumferential about it.
    """
    parts = text.split(":")
    kind = parts[0].lower()
    usage = (
        "--directions must be xy, vectors:AX,AY,AZ:BX,BY,BZ, cylinder:PX,PY,PZ:AX,AY,AZ "
        f"or sphere:PX,PY,PZ:AX,AY,AZ, got {text!r}"
    )
    if kind == "xy" and len(parts) == 1:
        return {}
    if kind not in ("vectors", "cylinder", "sphere") or len(parts) != 3:
        raise UsageError(usage)
    a, b = _vector(parts[1], f"{kind} first vector"), _vector(parts[2], f"{kind} second vector")
    if kind == "vectors":
        return {"directions": np.stack([a, b])}
    return {"directions": "cylindrical" if kind == "cylinder" else "spherical", "axis": (a, b)}


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
    p.add_argument("--fps", type=float, help="frame rate, for times in the ParaView series")
    p.add_argument("--unit", help="unit of X, Y, Z (default: from summary.json, else mm)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    return cli


def _stereo_summary(points_path: Path) -> dict:
    path = points_path.parent / "summary.json"
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError):
        return {}


def mesh_for(
    points: np.ndarray, visible: np.ndarray, args, summary: dict
) -> tuple[np.ndarray, str]:
    """Triangles for the reference points and how they were made."""
    from surface_strain.io import read_triangles
    from surface_strain.mesh import delaunay_triangles, grid_triangles

    n = points.shape[1]
    given = [flag for flag, value in (("--triangles", args.triangles), ("--grid", args.grid),
             ("--projection", getattr(args, "projection", None))) if value]  # fmt: skip
    if len(given) > 1:
        raise UsageError(
            f"{' and '.join(given)} each choose the mesh: give one of them "
            "(--projection applies to the Delaunay mesh of scattered points)"
        )
    if args.triangles:
        return read_triangles(args.triangles, n), f"given ({Path(args.triangles).name})"
    grid = None
    if args.grid:
        try:
            cols, rows = (int(v) for v in args.grid.lower().split("x"))
        except ValueError:
            raise UsageError(f"--grid must be COLSxROWS, got {args.grid!r}") from None
        grid = (cols, rows)
    elif not getattr(args, "projection", None):  # an explicit --projection asks for Delaunay
        info = summary.get("points") if isinstance(summary, dict) else None
        given = info.get("grid") if isinstance(info, dict) else None
        if isinstance(given, list) and len(given) == 2:
            try:
                grid = (int(given[0]), int(given[1]))
            except (TypeError, ValueError):
                grid = None
    if grid is not None:
        cols, rows = grid
        if cols < 2 or rows < 2:
            raise UsageError(f"a grid needs at least 2 x 2 points, got {cols}x{rows}")
        if cols * rows != n:
            raise UsageError(f"a {cols}x{rows} grid has {cols * rows} points, the file has {n}")
        return grid_triangles(rows, cols), f"grid {cols}x{rows}, alternating diagonals"
    ref = points[0]
    ok = visible[0]
    if ok.sum() < 3:
        raise UsageError("fewer than 3 points are visible on the reference frame")
    projection = getattr(args, "projection", None) or "plane"
    try:
        tri_ok = delaunay_triangles(ref[ok], projection=projection)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    index = np.flatnonzero(ok)
    return index[tri_ok], f"Delaunay on the best-fit {projection}"


def write_strain_folder(
    folder: Path,
    points: np.ndarray,
    visible: np.ndarray,
    triangles: np.ndarray,
    *,
    mesh_method: str,
    directions: str = "xy",
    unit: str = "mm",
    fps: float | None = None,
    figures: bool = True,
    source: str = "",
):
    """Compute strain on 3D tracks and write every result file into ``folder`` (exists).

    Used by ``python -m surface_strain compute`` and ``python -m stereo
    reconstruct --strain``.  Returns the :class:`StrainField`.
    """
    from surface_strain import __version__
    from surface_strain.export import write_elements_csv, write_nodes_csv, write_pvd
    from surface_strain.field import compute_strain, nodal_scalars

    # points lost on the reference frame have no reference position: their triangles go,
    # they keep a placeholder position (tied to no triangle) and stay lost in every frame
    lost = ~(visible[0] & np.isfinite(points[0]).all(axis=1))
    triangles = np.asarray(triangles)[~lost[np.asarray(triangles)].any(axis=1)]
    if len(triangles) == 0:
        raise UsageError("no triangle has all three points visible on the reference frame")
    if lost.any():
        index = np.flatnonzero(lost)
        named = ", ".join(str(i) for i in index[:5]) + (" ..." if index.size > 5 else "")
        warnings.warn(
            f"{index.size} of {lost.size} points are lost (not visible, or NaN) on the "
            f"reference frame and are left out of the mesh: point(s) {named}",
            UserWarning,
            stacklevel=2,
        )
    reference = points[0].copy()
    if lost.any():
        reference[lost] = reference[~lost].mean(axis=0)
        visible = visible & ~lost[None, :]
    try:
        field = compute_strain(
            reference, points, triangles, visible=visible, **parse_directions(directions)
        )
    except ValueError as exc:
        if isinstance(exc, UsageError):
            raise
        raise UsageError(str(exc)) from None
    times = np.arange(field.n_frames) / fps if fps else np.arange(field.n_frames, dtype=float)
    if not np.isfinite(times).all():
        raise UsageError(f"--fps {fps} gives non-finite times")
    node = nodal_scalars(field)
    write_nodes_csv(folder / "strain_nodes.csv", field)
    write_elements_csv(folder / "strain_elements.csv", field)
    write_pvd(folder, field, name="strain", times=times)
    last = field.n_frames - 1
    if figures:
        from surface_strain.figures import plot_strain_curves, plot_strain_violins, render_strain

        (folder / "figures").mkdir()
        for key in ("E1", "E2", "Exx", "Eyy"):
            render_strain(field, folder / "figures" / f"{key}_frame{last:04d}.png", key=key,
                          frame=last, unit=unit)  # fmt: skip
        plot_strain_curves(field, times=times, fps=fps).savefig(
            folder / "figures" / "strain_over_time.png"
        )
        plot_strain_violins(field).savefig(folder / "figures" / f"violins_frame{last:04d}.png")
    mean = {k: [float(np.nanmean(v[t])) if np.isfinite(v[t]).any() else None
                for t in range(field.n_frames)] for k, v in node.items()}  # fmt: skip
    summary = {
        "software": {"name": "surface_strain", "version": __version__},
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "input": source,
        "unit": unit,
        "frames": field.n_frames,
        "points": field.n_points,
        "mesh": {"method": mesh_method, "n_triangles": field.n_triangles},
        "directions": directions,
        "strain": "Green-Lagrange membrane strain; Exx, Eyy, Exy in the directions' frame",
        "nodal_mean_per_frame": mean,
    }
    with open(folder / "summary.json", "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=2, allow_nan=False, default=str)
        f.write("\n")
    return field


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
        raise UsageError(f"--fps must be a positive number, got {args.fps}")
    parse_directions(args.directions)  # fail before the work
    say = Progress(quiet=args.quiet)
    points, visible = read_points3d(args.points)
    say(f"{args.points}: {points.shape[1]} points over {points.shape[0]} frames")
    summary_in = _stereo_summary(Path(args.points))
    unit = args.unit or summary_in.get("unit") or "mm"
    triangles, how = mesh_for(points, visible, args, summary_in)
    with atomic_dir(args.out, overwrite=args.overwrite, inputs=_inputs(args)) as tmp:
        field = write_strain_folder(
            tmp,
            points,
            visible,
            triangles,
            mesh_method=how,
            directions=args.directions,
            unit=unit,
            fps=args.fps,
            figures=not args.no_figures,
            source=Path(args.points).name,
        )
    e1 = nodal_scalars(field)["E1"][-1]
    e1_mean = f"{np.nanmean(e1):.4f}" if np.isfinite(e1).any() else "- (no valid node)"
    say(
        f"{field.n_points} points, {field.n_triangles} triangles ({how}), "
        f"{field.n_frames} frames; last frame E1 mean {e1_mean}"
    )
    say(f"results in {args.out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    from surface_strain.io import PointsError
    from tissue_core.cli import run_command

    return run_command("surface_strain", _build_parser(), argv, errors=(UsageError, PointsError))


def entry() -> None:
    """The console script ``surface-strain``: like ``python -m surface_strain``."""
    from tissue_core.cli import run_module

    run_module(__name__)
