"""Run folders of strain on surfaces: the mesh choice, and writing a run.

:func:`choose_mesh` is the one place where the toolkit decides how tracked
points are meshed (given triangles, a grid's topology, or Delaunay), for the
2D pipeline (:mod:`strain2d`), ``surface_strain compute`` and ``stereo
reconstruct --strain``.  :func:`write_run` computes the strain of 3D point
tracks and writes a whole run folder (``strain_nodes.csv``,
``strain_elements.csv``, ``strain.pvd``, ``summary.json``, figures);
:func:`strain2d.load_run` reads it back, as it reads 2D runs.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np

from tissue_core.errors import InputError

__all__ = ["RUN_SCHEMA", "Mesh", "choose_mesh", "parse_directions", "write_run"]

#: Version of the run folder's layout (``summary.json`` ``schema``); 2D and 3D runs share it.
RUN_SCHEMA = 1


class Mesh(NamedTuple):
    """Triangles of the reference points and how they were made."""

    triangles: np.ndarray
    """(M, 3) int, indices into the points."""
    method: Literal["given", "grid", "delaunay"]
    description: str
    """In words, for summaries: ``"grid 7x7, alternating diagonals"``."""


def choose_mesh(
    reference: np.ndarray,
    visible: np.ndarray | None = None,
    *,
    triangles: np.ndarray | None = None,
    grid: tuple[int, int] | None = None,
    projection: Literal["plane", "sphere", "cylinder"] | None = None,
    min_quality: float = 0.1,
    source: str = "given",
) -> Mesh:
    """Mesh reference points: given triangles, a grid's topology, or Delaunay.

    Parameters
    ----------
    reference : (N, 2) or (N, 3) float
        Reference positions (NaN allowed where ``visible`` is False).
    visible : (N,) bool, optional
        Points usable on the reference frame; Delaunay meshes only these.
        Default: all.
    triangles : (M, 3) int, keyword-only
        A mesh to use as is (``source`` names it in the description).
    grid : (n_cols, n_rows), keyword-only
        The points form a row-major grid: each cell is split along
        alternating diagonals (:func:`surface_strain.grid_triangles`), which
        is symmetric, unlike a Delaunay mesh of a square grid.
    projection : {"plane", "sphere", "cylinder"}, keyword-only
        Delaunay of 3D points in their best-fit plane (default) or on the
        best-fit sphere or cylinder (:func:`surface_strain.delaunay_triangles`).
    min_quality : float, keyword-only
        Delaunay drops triangles with a smaller radius ratio.

    Raises
    ------
    InputError
        More than one of ``triangles``, ``grid``, ``projection``; a grid that
        does not fit the points; fewer than 3 usable points.
    """
    from surface_strain.mesh import delaunay_triangles, grid_triangles

    reference = np.asarray(reference, dtype=float)
    n = reference.shape[0]
    chosen = [name for name, value in (("triangles", triangles), ("grid", grid),
              ("projection", projection)) if value is not None]  # fmt: skip
    if len(chosen) > 1:
        raise InputError(
            f"{' and '.join(chosen)} each choose the mesh: give one of them "
            "(projection applies to the Delaunay mesh of scattered points)"
        )
    if triangles is not None:
        return Mesh(np.asarray(triangles, dtype=np.int64), "given", f"given ({source})")
    if grid is not None:
        cols, rows = (int(v) for v in grid)
        if cols < 2 or rows < 2:
            raise InputError(f"a grid needs at least 2 x 2 points, got {cols}x{rows}")
        if cols * rows != n:
            raise InputError(f"a {cols}x{rows} grid has {cols * rows} points, got {n}")
        # grid_triangles takes (rows, cols); the toolkit's grids are (cols, rows), as --grid
        return Mesh(
            grid_triangles(rows, cols), "grid", f"grid {cols}x{rows}, alternating diagonals"
        )
    ok = np.ones(n, bool) if visible is None else np.asarray(visible, bool)
    if ok.sum() < 3:
        raise InputError("fewer than 3 points are visible on the reference frame")
    try:
        if reference.shape[1] == 2:
            tri = delaunay_triangles(reference[ok], min_quality=min_quality)
            how = "Delaunay"
        else:
            tri = delaunay_triangles(
                reference[ok], min_quality=min_quality, projection=projection or "plane"
            )
            how = f"Delaunay on the best-fit {projection or 'plane'}"
    except ValueError as exc:
        raise InputError(str(exc)) from None
    return Mesh(np.flatnonzero(ok)[tri], "delaunay", how)


def _vector(text: str, what: str) -> np.ndarray:
    try:
        v = np.array([float(t) for t in text.split(",")])
    except ValueError:
        raise InputError(f"{what} must be three numbers X,Y,Z, got {text!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all():
        raise InputError(f"{what} must be three finite numbers X,Y,Z, got {text!r}")
    return v


def parse_directions(text: str) -> dict:
    """Keyword arguments of :func:`surface_strain.compute_strain` for ``--directions``.

    ``xy`` (default): global X and Y.  ``vectors:AX,AY,AZ:BX,BY,BZ``: two
    constant directions.  ``cylinder:PX,PY,PZ:AX,AY,AZ``: axial and
    circumferential about the axis through P along A.
    ``sphere:PX,PY,PZ:AX,AY,AZ``: meridional and circumferential about it.

    Examples
    --------
    >>> parse_directions("xy")
    {}
    >>> parse_directions("cylinder:0,0,0:0,0,1")["directions"]
    'cylindrical'
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
        raise InputError(usage)
    a, b = _vector(parts[1], f"{kind} first vector"), _vector(parts[2], f"{kind} second vector")
    # what no surface can fix is refused now, not after the tracking and meshing
    if kind == "vectors":
        for which, v in (("first", a), ("second", b)):
            if not np.linalg.norm(v) > 0:
                raise InputError(f"--directions {text}: the {which} vector has zero length")
        if np.linalg.norm(np.cross(a, b)) <= 1e-9 * np.linalg.norm(a) * np.linalg.norm(b):
            raise InputError(
                f"--directions {text}: the two vectors are parallel; give two directions "
                "that span a plane"
            )
        return {"directions": np.stack([a, b])}
    if not np.linalg.norm(b) > 0:
        raise InputError(f"--directions {text}: the axis A has zero length")
    return {"directions": "cylindrical" if kind == "cylinder" else "spherical", "axis": (a, b)}


def write_run(
    folder: str | os.PathLike,
    points: np.ndarray,
    visible: np.ndarray,
    mesh: Mesh,
    *,
    directions: str = "xy",
    unit: str | None = "mm",
    fps: float | None = None,
    figures: bool = True,
    source: str = "",
    inputs: Sequence[str | os.PathLike] = (),
    point_quality: Mapping[str, np.ndarray] | None = None,
):
    """Compute membrane strain on 3D tracks and write a run folder into ``folder`` (exists).

    The folder's files are those of ``python -m surface_strain compute``, which
    calls this, as ``python -m stereo reconstruct --strain`` does (write into
    a temporary folder, as :func:`tissue_core.outputs.atomic_dir` gives):
    the tables, the ParaView series, ``summary.json``, the figures and a
    self-contained ``report.html`` (:func:`surface_strain.write_run_report`)
    with the quality of the measurement (:func:`surface_strain.measurement_quality`).

    Parameters
    ----------
    folder : path
        An existing, empty folder.
    points : (T, N, 3) float
        Tracked positions in ``unit``, NaN where lost.
    visible : (T, N) bool
    mesh : Mesh
        From :func:`choose_mesh`.
    directions : str, keyword-only
        The frame of Exx, Eyy, Exy (see :func:`parse_directions`).
    unit : str or None, keyword-only
        Unit of the positions; None when it is not known (recorded and shown
        as "input units", and flagged).
    fps : float, keyword-only
        Frame rate: times in seconds in the ParaView series and the summary.
    figures : bool, keyword-only
        Also render the strain maps, curves and violins.
    source : str, keyword-only
        The input's name, for the summary.
    inputs : sequence of path, keyword-only
        The files the points came from: recorded with their SHA-256 in
        ``summary.json`` (``input_files``) and the report.
    point_quality : mapping of str to (T, N) float, keyword-only
        Per-point columns of the input (``reproj_error`` in px, ``quality``),
        summarised in the report.

    Returns
    -------
    StrainField
    """
    from surface_strain import __version__
    from surface_strain.export import write_elements_csv, write_nodes_csv, write_pvd
    from surface_strain.field import compute_strain, nodal_scalars
    from surface_strain.report import (
        measurement_quality,
        quality_flags,
        strain_statistics,
        write_run_report,
    )
    from tissue_core.html import input_records
    from tissue_core.jsonio import write_json
    from tissue_core.outputs import recorded_command

    folder = Path(folder)
    unit_source = "given" if unit else "unknown"
    unit = unit or "input units"
    n_mesh_triangles = len(mesh.triangles)
    # points lost on the reference frame have no reference position: their triangles go,
    # they keep a placeholder position (tied to no triangle) and stay lost in every frame
    lost = ~(visible[0] & np.isfinite(points[0]).all(axis=1))
    triangles = np.asarray(mesh.triangles)
    triangles = triangles[~lost[triangles].any(axis=1)]
    if len(triangles) == 0:
        raise InputError("no triangle has all three points visible on the reference frame")
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
        if isinstance(exc, InputError):
            raise
        raise InputError(str(exc)) from None
    times = np.arange(field.n_frames) / fps if fps else np.arange(field.n_frames, dtype=float)
    if not np.isfinite(times).all():
        raise InputError(f"--fps {fps} gives non-finite times")
    write_nodes_csv(folder / "strain_nodes.csv", field)
    write_elements_csv(folder / "strain_elements.csv", field)
    write_pvd(
        folder,
        field,
        name="strain",
        times=times,
        time_unit="s" if fps else "frame",
        length_unit=unit,
    )
    last = field.n_frames - 1
    node = nodal_scalars(field)
    mean = {k: [float(np.nanmean(v[t])) if np.isfinite(v[t]).any() else None
                for t in range(field.n_frames)] for k, v in node.items()}  # fmt: skip
    # contraction cycles, as 2D runs find them; repeated ones put the peak of the largest
    # beside the last frame (its maps and statistics)
    from surface_strain.cycles import CYCLE_COMPONENTS, find_run_cycles, write_cycles_csv

    curves = np.array([[np.nan if v is None else v for v in mean[c]] for c in CYCLE_COMPONENTS]).T
    cycles = find_run_cycles(curves, times)
    peak = None
    if cycles is not None:
        write_cycles_csv(folder, cycles, field, node=node)
        if cycles["repeated"] and cycles["largest"] is not None:
            cycles["chosen"] = cycles["largest"]
            peak = int(cycles["cycles"][cycles["largest"]]["peak"])
    quality = measurement_quality(
        field, n_mesh_triangles=n_mesh_triangles, point_quality=point_quality
    )
    figure_list = []
    if figures:
        from surface_strain.figures import (
            plot_strain_curves,
            plot_strain_violins,
            plot_tracking_quality,
            render_strain,
        )

        (folder / "figures").mkdir()

        def figure(name: str, caption: str, section: str = "figures") -> Path:
            # strain2d's layout of summary["figures"], and where the report shows it
            figure_list.append(
                {"files": [f"figures/{name}"], "caption": caption, "section": section}
            )
            return folder / "figures" / name

        when = f"t = {times[last]:.4g} s, frame {last}" if fps else f"frame {last}"
        for key, what in (
            ("E1", "first principal strain E1"),
            ("E2", "second principal strain E2"),
            ("Exx", "Exx"),
            ("Eyy", "Eyy"),
        ):
            path = figure(
                f"{key}_frame{last:04d}.png",
                f"Nodal {what} (Green-Lagrange, dimensionless) on the deformed surface on the "
                f"last frame ({when}); grey: no valid value. Axes in {unit}.",
            )
            render_strain(field, path, key=key, frame=last, unit=unit, fps=fps)
        if peak is not None and peak != last:
            n = cycles["largest"] + 1
            at = f"t = {times[peak]:.4g} s, frame {peak}" if fps else f"frame {peak}"
            for key in ("E1", "E2"):
                path = figure(
                    f"{key}_frame{peak:04d}.png",
                    f"Nodal {key} on the deformed surface at the peak of cycle {n}, the "
                    f"largest of the repeated contractions ({at}); grey: no valid value. "
                    f"Axes in {unit}.",
                )
                render_strain(field, path, key=key, frame=peak, unit=unit, fps=fps)
        path = figure(
            "strain_over_time.png",
            "Mean nodal strain of each component over time, with a band of +/- one spatial "
            "SD over the nodes.",
        )
        plot_strain_curves(field, times=times, fps=fps).savefig(path)
        path = figure(
            f"violins_frame{last:04d}.png",
            f"Distribution over the nodes of each component on the last frame ({when}).",
        )
        plot_strain_violins(field, fps=fps).savefig(path)
        path = figure(
            "quality_over_time.png",
            "Points still tracked (of all the input's points) and the reference surface area "
            "whose triangles have a valid strain, per frame.",
            section="quality",
        )
        visible, coverage = quality["visible_fraction"], quality["surface_coverage"]
        plot_tracking_quality(visible, coverage, times=times, fps=fps).savefig(path)
    summary = {
        "schema": RUN_SCHEMA,
        "software": {"name": "surface_strain", "version": __version__},
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": recorded_command.get(),
        "input": source,
        "input_files": input_records(inputs),
        "unit": unit,
        "unit_source": unit_source,
        "frames": field.n_frames,
        "points": field.n_points,
        "mesh": {"method": mesh.description, "n_triangles": field.n_triangles},
        "lost_on_reference": int(lost.sum()),
        "directions": directions,
        "time_axis": {"fps": fps, "unit": "s" if fps else "frame"},
        "strain": "Green-Lagrange membrane strain; Exx, Eyy, Exy in the directions' frame",
        "nodal_mean_per_frame": mean,
        **({"cycles": {k: v for k, v in cycles.items() if k != "curves"}} if cycles else {}),
        "last_frame_statistics": strain_statistics(field, last),
        **(
            {
                "peak_statistics": {
                    "frame": peak,
                    "cycle": cycles["largest"] + 1,
                    **strain_statistics(field, peak),
                }
            }
            if peak is not None
            else {}
        ),
        "quality": quality,
        "figures": figure_list,
        "report": "report.html",
    }
    summary["flagged"] = quality_flags(summary)
    write_json(folder / "summary.json", summary)
    write_run_report(folder, summary)
    return field
