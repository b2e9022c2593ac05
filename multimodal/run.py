"""A fold-aware run: the camera run's triangles measured along the microscope's surface."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from multimodal.geometry import (
    EDGES,
    Similarity,
    SurfaceMap,
    Tortuosity,
    directional_tortuosity,
    fold_aware_strain,
    tortuosity_correction,
)
from tissue_core.errors import InputError

__all__ = ["FoldStrain", "fold_strain_run", "write_fold_run"]

#: the components written per triangle, as (name, row, column) of the 2x2 tensor
COMPONENTS = (("Exx", 0, 0), ("Eyy", 1, 1), ("Exy", 0, 1))


@dataclass
class FoldStrain:
    """What :func:`fold_strain_run` measured (arrays per triangle)."""

    triangles: np.ndarray
    reference_px: np.ndarray
    current_px: np.ndarray
    surface: dict
    corrected: dict
    before: Tortuosity
    after: Tortuosity


def fold_strain_run(
    run,
    triangles: np.ndarray,
    frame: int,
    before: SurfaceMap,
    after: SurfaceMap,
    transform: Similarity,
    *,
    path: str = "geodesic",
    progress: Callable[[str], None] | None = None,
) -> FoldStrain:
    """The run's frame ``frame`` against frame 0, along the surface and corrected by the
    surfaces' tortuosity (the segments as long as the mesh's median edge).

    Every error the inputs can cause is raised before the edges are measured
    (the long step), which ``progress`` is told of first."""
    X = np.asarray(run.positions[0], float)
    x = np.where(run.visible[frame][:, None], run.positions[frame], np.nan)
    edges = np.concatenate([X[triangles[:, j]] - X[triangles[:, i]] for i, j in EDGES])
    segment = transform.scale * float(np.median(np.hypot(*edges.T)))
    pixel = max(*before.pixel_um, *after.pixel_um)
    if not segment >= pixel:
        raise InputError(
            f"the mesh's edges measure {segment:.3g} um on the height maps, under one of their "
            f"pixels ({pixel:.3g} um): are the transform's units right (um per camera pixel, "
            "or the run's units per um for a stereo run)?"
        )
    tortuosity = []
    for surface_map in (before, after):
        try:
            tortuosity.append(directional_tortuosity(surface_map, segment))
        except InputError as exc:
            raise InputError(f"{surface_map.source or 'a height map'}: {exc}") from None
    if progress is not None:
        progress(f"measuring {3 * len(triangles)} edges along the surfaces ({path} paths)")
    surface = fold_aware_strain(X, x, triangles, before, after, transform, path=path)
    corrected = tortuosity_correction(surface["F"], *tortuosity, transform)
    return FoldStrain(triangles, X, x, surface, corrected, *tortuosity)


def _means(E: np.ndarray, use: np.ndarray) -> dict:
    out = {}
    for name, i, j in COMPONENTS:
        values = E[use, i, j]
        values = values[np.isfinite(values)]
        out[name] = float(values.mean()) if values.size else None
    return out


def write_fold_run(
    folder: str | os.PathLike,
    result: FoldStrain,
    *,
    run,
    frame: int,
    before: SurfaceMap,
    after: SurfaceMap,
    transform: Similarity,
    residual: np.ndarray | None,
    path: str,
    inputs: list[Path],
    registration: dict | None = None,
) -> dict:
    """Write ``fold_strain.csv``, ``tortuosity.csv``, ``summary.json`` and
    ``figures/fold_strain.png`` into ``folder``; returns the summary.

    ``registration``: a stereo run's 3D registrations (its nodes were brought
    onto the microscope's plane, in micrometres, and ``transform`` is the
    identity), recorded in ``summary.json``."""
    from tissue_core.csvtext import number_cell
    from tissue_core.html import input_records
    from tissue_core.jsonio import write_json
    from tissue_core.version import __version__

    folder = Path(folder)
    E_s, E_p = result.surface["E"], result.surface["E_projected"]
    E_c, sd = result.corrected["E"], result.corrected["E_principal_sd"]
    on_maps = np.isfinite(E_s).all(axis=(1, 2))
    filled = result.surface["filled_share"]
    seen = np.isfinite(E_p).all(axis=(1, 2))
    header = ["triangle", "p0", "p1", "p2", "on_maps"]
    header += [f"{c}_projected" for c, _, _ in COMPONENTS]
    header += [f"{c}_surface" for c, _, _ in COMPONENTS]
    header += [f"{c}_corrected" for c, _, _ in COMPONENTS]
    header += ["E1_corrected_sd", "E2_corrected_sd", "filled_share"]
    lines = [",".join(header)]
    for k, tri in enumerate(result.triangles):
        cells = [str(k), *map(str, tri), str(int(on_maps[k]))]
        for E in (E_p, E_s, E_c):
            cells += [number_cell(float(E[k, i, j])) for _, i, j in COMPONENTS]
        cells += [number_cell(float(v)) for v in sd[k]]
        cells.append(number_cell(float(filled[k])))
        lines.append(",".join(cells))
    (folder / "fold_strain.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
    rows = ["angle_deg,before_mean,before_sd,after_mean,after_sd,before_segments,after_segments"]
    tb, ta = result.before, result.after
    for k, angle in enumerate(tb.angles_deg):
        values = (angle, tb.mean[k], tb.sd[k], ta.mean[k], ta.sd[k], tb.count[k], ta.count[k])
        rows.append(",".join(number_cell(float(v)) for v in values))
    (folder / "tortuosity.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    _nodes(folder / "strain_nodes.csv", result)
    (folder / "figures").mkdir()
    figure = _figure(folder / "figures" / "fold_strain.png", result, before, after, transform)
    paraview = _paraview(folder, result, before, after, transform, on_maps)
    means = {
        "projected": _means(E_p, on_maps),
        "fold_aware": _means(E_s, on_maps),
        "corrected": _means(E_c, seen),
        "projected_all": _means(E_p, seen),
    }
    folding = {}
    for name, _, _ in COMPONENTS:
        p, s = means["projected"][name], means["fold_aware"][name]
        folding[name] = None if p is None or s is None or abs(p) < 1e-3 else (p - s) / p
    summary = {
        "schema": 1,
        "software": {"name": "multimodal", "version": __version__},
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "run": str(run.path),
        "frames": {"reference": 0, "deformed": int(frame)},
        "height_maps": {
            name: {
                "source": m.source,
                "shape": list(m.shape),
                "pixel_um": list(m.pixel_um),
                "tiles": len(_tiles(m)),
            }
            for name, m in (("before", before), ("after", after))
        },
        "inputs": input_records(inputs),
        **({"registration_3d": registration} if registration is not None else {}),
        "transform": {
            **transform.as_dict(),
            "from": "landmarks"
            if residual is not None
            else ("the 3D registration" if registration is not None else "given"),
            **(
                {
                    "landmarks": len(residual),
                    "residual_um_rms": float(np.sqrt(np.mean(residual**2))),
                    "residual_um_max": float(residual.max()),
                }
                if residual is not None
                else {}
            ),
        },
        "parameters": {"path": path, "tortuosity_segment_um": result.before.segment_um},
        # what load_run (and so studies) read: frame 1 is the deformed state
        "source": {"frames_used": 2, "frames": [0, int(frame)]},
        "time_axis": {"fps": None, "unit": "frame"},
        "contraction_endpoint": {"frame": 1, "source": "given", "label": "the --after state"},
        "coverage": {
            "triangles": len(result.triangles),
            "on_maps": int(on_maps.sum()),
            "tracked": int(seen.sum()),
            # the share of an edge over heights the microscope's software filled in
            "filled_share_mean": float(filled[on_maps].mean()) if on_maps.any() else None,
            "over_10_percent_filled": int((filled[on_maps] > 0.1).sum()),
        },
        "mean_strain": means,
        "folding_share": folding,
        "tortuosity": {
            "before": {"x": float(tb.at(0.0)[0]), "y": float(tb.at(90.0)[0])},
            "after": {"x": float(ta.at(0.0)[0]), "y": float(ta.at(90.0)[0])},
            "directions": "the microscope's x and y",
        },
        "units": {
            "strain": "-",
            "lengths": "um",
            "camera": "px" if registration is None else "um (the microscope's plane)",
        },
        "definitions": {
            "projected": "the camera's 2D Green-Lagrange strain of each triangle"
            if registration is None
            else "the 2D Green-Lagrange strain of each triangle of the stereo run projected "
            "on the microscope's plane, in the microscope's x-y",
            "fold_aware": "membrane strain along the surface: each edge's length on the "
            "height maps (before and after), over the triangles both maps cover; frame of "
            "the reference surface, first axis over the "
            + ("camera's x" if registration is None else "microscope's x"),
            "corrected": "the projected principal stretches scaled by the surfaces' "
            "tortuosity along them (after / before), over every tracked triangle",
            "folding_share": "(projected - fold_aware) / projected of the means over the "
            "triangles on the maps: the share of the apparent strain that is folding",
        },
        "outputs": [
            "fold_strain.csv",
            "strain_nodes.csv",
            "tortuosity.csv",
            "summary.json",
            "report.html",
            *figure,
            *paraview,
        ],
    }
    summary["flags"] = _flags(summary)
    write_json(folder / "summary.json", summary)
    _report(folder, summary)
    return summary


def _nodes(path: Path, result: FoldStrain) -> None:
    """The surface strain averaged onto the nodes (area-weighted, triangles off the maps
    left out), as a two-frame run (the reference and the deformed state): what
    ``load_run`` reads, so studies take fold-aware runs beside 2D and stereo ones."""
    from surface_strain import nodal_average, scalar_fields, triangle_areas
    from tissue_core.tables import write_long_table

    n = len(result.reference_px)
    E = result.surface["E"]
    areas = triangle_areas(result.reference_px, result.triangles)
    nodal = nodal_average(E, result.triangles, n, weights=areas)
    nodal = np.stack([np.zeros_like(nodal), nodal])  # (2, N, 2, 2): the reference is 0
    fields = scalar_fields(nodal)
    C = 2 * nodal + np.eye(2)
    J = np.sqrt(np.maximum(C[..., 0, 0] * C[..., 1, 1] - C[..., 0, 1] ** 2, 0.0))
    J = np.where(np.isfinite(nodal).all(axis=(-2, -1)), J, np.nan)
    positions = np.stack([result.reference_px, result.current_px])
    visible = np.isfinite(positions).all(axis=-1) & np.isfinite(fields["Exx"])
    columns = {
        "x": (positions[..., 0], "%.6f"),
        "y": (positions[..., 1], "%.6f"),
        "visible": (visible, "%d"),
        **{c: (fields[c], "%.8g") for c in ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear")},
        "J": (J, "%.8g"),
    }
    write_long_table(path, columns)


def _flags(summary: dict) -> list[str]:
    """What a reader should know before trusting the numbers."""
    flags = []
    cover = summary["coverage"]
    if cover["on_maps"] == 0:
        flags.append(
            "No triangle lies on both height maps: only the statistics-only correction is "
            "measured (is the transform right? the microscope's field may miss the grid)"
        )
    elif cover["on_maps"] < cover["triangles"]:
        flags.append(
            f"{cover['triangles'] - cover['on_maps']} of {cover['triangles']} triangles leave a "
            "height map or cross a gap in it: they have the statistics-only correction alone"
        )
    if cover.get("over_10_percent_filled"):
        flags.append(
            f"{cover['over_10_percent_filled']} triangles have an edge more than 10 % over "
            "heights the microscope's software filled in rather than measured "
            "(filled_share in fold_strain.csv)"
        )
    seg = summary["parameters"]["tortuosity_segment_um"]
    pixel = max(max(m["pixel_um"]) for m in summary["height_maps"].values())
    if seg is not None and seg < 4 * pixel:
        flags.append(
            f"The mesh's edges ({seg:.3g} um) span under 4 pixels of the height maps "
            f"({pixel:.3g} um): the folds between the nodes are not resolved (are the "
            "transform's units um per camera pixel?)"
        )
    transform = summary["transform"]
    if transform.get("from") == "landmarks" and transform.get("landmarks", 0) < 3:
        flags.append("Two landmarks fix the transform exactly: its residual is not measured")
    rms = transform.get("residual_um_rms")
    if rms is not None and seg and rms > 0.05 * seg:
        flags.append(
            f"The registration's residual ({rms:.3g} um RMS) is over 5 % of a mesh edge "
            f"({seg:.3g} um): the edges may not lie where the height maps are read"
        )
    return flags


def _report(folder: Path, summary: dict) -> None:
    """``report.html``: inputs, the registration, the mean strains, figure, flags."""
    from tissue_core.html import HtmlReport

    doc = HtmlReport(
        "Fold-aware membrane strain",
        subtitle=f"{summary['run']}: frame {summary['frames']['deformed']} against frame 0",
    )
    doc.heading("Inputs")
    doc.inputs(summary["inputs"])
    doc.heading("Registration: camera pixels to microscope micrometres")
    doc.key_values(summary["transform"])
    doc.heading("Mean strain")
    means = summary["mean_strain"]
    rows = []
    for kind, label in (
        ("projected", "projected (the camera), over the triangles on the maps"),
        ("fold_aware", "along the surface (the height maps)"),
        ("corrected", "corrected by the tortuosity, every tracked triangle"),
    ):
        rows.append({"strain": label, **{c: means[kind][c] for c, _, _ in COMPONENTS}})
    doc.table(rows)
    doc.paragraph(
        "Share of the apparent strain that is folding, (projected - along the surface) / "
        "projected: " + ", ".join(
            f"{c} {v:.2f}" for c, v in summary["folding_share"].items() if v is not None
        )
    )  # fmt: skip
    doc.key_values(summary["coverage"])
    doc.heading("Figure")
    doc.media(
        folder / "figures" / "fold_strain.png",
        "Exx on the deformed mesh: as the camera sees it, along the microscope's surface, and "
        "corrected by the surfaces' tortuosity; dashed: the microscope's field of view.",
    )
    doc.heading("Tortuosity (surface length over projected length)")
    doc.key_values({f"{state} along {axis}": value
                    for state, d in summary["tortuosity"].items() if isinstance(d, dict)
                    for axis, value in d.items()})  # fmt: skip
    doc.heading("Flags")
    doc.flags(summary["flags"])
    doc.provenance(summary)
    doc.write(folder / "report.html")


#: the most vertices per side of a height map's mesh in the ParaView files
_SURFACE_SIDE = 240


def _surface_step(surface: SurfaceMap) -> int:
    """Every how many pixels :func:`_surface_mesh` takes a point."""
    return max(1, int(np.ceil(max(surface.shape) / _SURFACE_SIDE)))


def _surface_mesh(surface: SurfaceMap) -> tuple[np.ndarray, np.ndarray]:
    """The height map as a triangle mesh (um), every k-th pixel (:func:`_surface_step`), a
    point per pixel row by row (height 0 in a gap); no triangle over a gap."""
    Y, X = surface.shape
    k = _surface_step(surface)
    rows, cols = np.arange(0, Y, k), np.arange(0, X, k)
    (dy, dx), (x0, y0) = surface.pixel_um, surface.origin_um
    z = surface.height_um[np.ix_(rows, cols)]
    xx, yy = np.meshgrid(x0 + cols * dx, y0 + rows * dy)
    points = np.column_stack([xx.ravel(), yy.ravel(), np.nan_to_num(z).ravel()])
    n = len(cols)
    a = (np.arange(len(rows) - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    triangles = np.concatenate([np.column_stack([a, a + 1, a + n + 1]),
                                np.column_stack([a, a + n + 1, a + n])])  # fmt: skip
    finite = np.isfinite(z.ravel())
    return points, triangles[finite[triangles].all(axis=1)]


def _paraview(
    folder: Path,
    result: FoldStrain,
    before: SurfaceMap,
    after: SurfaceMap,
    transform: Similarity,
    on_maps: np.ndarray,
) -> list[str]:
    """The camera's mesh on the microscope's surfaces (um), with every triangle's strains,
    and the two surfaces: one ParaView scene, in the microscope's coordinates."""
    from tissue_core.vtkio import write_triangles

    cells = {"on_maps": on_maps}
    for label, E in (("surface", result.surface["E"]), ("projected", result.surface["E_projected"]),
                     ("corrected", result.corrected["E"])):  # fmt: skip
        for name, i, j in COMPONENTS:
            cells[f"{name}_{label}"] = E[:, i, j]
    units = {"units": ["coordinates um (the microscope's x, y and height)", "strain -"]}
    written = []
    for name, nodes, surface in (
        ("mesh_before.vtp", result.reference_px, before),
        ("mesh_after.vtp", result.current_px, after),
    ):
        xy = transform.apply(np.nan_to_num(nodes))
        z = surface.heights(xy)
        level = np.nanmean([np.nanmean(t.height_um) for t in _tiles(surface)])
        z = np.where(np.isfinite(z), z, float(level))
        write_triangles(folder / name, np.column_stack([xy, z]), result.triangles,
                        cell_data=cells, field_data=units)  # fmt: skip
        written.append(name)
    for name, surface in (("surface_before.vtp", before), ("surface_after.vtp", after)):
        meshes = [_surface_mesh(t) for t in _tiles(surface)]
        offsets = np.cumsum([0] + [len(p) for p, _ in meshes[:-1]])
        points = np.concatenate([p for p, _ in meshes])
        triangles = np.concatenate([t + o for (_, t), o in zip(meshes, offsets, strict=True)])
        write_triangles(folder / name, points, triangles,
                        point_data={"height_um": points[:, 2]}, field_data=units)  # fmt: skip
        written.append(name)
    return written


def _tiles(surface) -> list[SurfaceMap]:
    """A map's tiles: a mosaic's, or the map itself."""
    return list(getattr(surface, "tiles", [surface]))


def _figure(
    path: Path, result: FoldStrain, before: SurfaceMap, after: SurfaceMap, transform: Similarity
) -> list[str]:
    """Exx as the camera sees it, along the surface and corrected, on the deformed mesh,
    with the microscope's field of view."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.tri import Triangulation

    x = result.current_px
    panels = (
        ("projected (camera)", result.surface["E_projected"]),
        ("along the surface (microscope)", result.surface["E"]),
        ("corrected by tortuosity", result.corrected["E"]),
    )
    values = [E[:, 0, 0] for _, E in panels]
    finite = np.concatenate([v[np.isfinite(v)] for v in values])
    top = float(np.max(np.abs(finite))) if finite.size else 1.0
    fig = Figure(figsize=(13.5, 4.6), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, 3, sharex=True, sharey=True)
    ok = np.isfinite(x).all(axis=1)
    keep = ok[result.triangles].all(axis=1)
    tri = Triangulation(np.nan_to_num(x[:, 0]), np.nan_to_num(x[:, 1]), result.triangles[keep])
    outlines = []
    for tile in _tiles(after):
        x0, y0, x1, y1 = tile.bounds()
        box = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
        outlines.append(transform.inverse(box))
    shown = None
    for ax, (title, _), v in zip(axes, panels, values, strict=True):
        colours = np.ma.masked_invalid(v[keep])
        shown = ax.tripcolor(tri, facecolors=colours, cmap="RdBu_r", vmin=-top, vmax=top)
        ax.triplot(tri, color="0.6", lw=0.3)
        for corners in outlines:
            ax.plot(corners[:, 0], corners[:, 1], color="k", lw=1.0, ls="--")
        ax.set_title(title, fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x (px)")
    axes[0].set_ylabel("y (px)")
    axes[0].invert_yaxis()
    fig.colorbar(shown, ax=axes, shrink=0.85, label=r"$E_{xx}$ (-)")
    fig.suptitle("Exx on the deformed mesh; dashed: the microscope's field of view", fontsize=11)
    fig.savefig(path, dpi=110)
    return [f"figures/{path.name}"]
