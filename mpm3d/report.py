"""``report.html`` for an analysis folder and for a comparison folder.

Both pages are built with :class:`tissue_core.html.HtmlReport` from what the
folder's JSON holds (``metrics.json``, ``compare.json``), so a page can be
rebuilt from the files alone.  Sections: inputs with their SHA-256,
parameters, results with units, the quality of the measurement (surface
coverage, segmentation, mesh, and for a comparison the alignment), the
figures (embedded), what was flagged, and the provenance folded away.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from tissue_core.html import HtmlReport

__all__ = ["METRICS", "analysis_flags", "write_analysis_report", "write_comparison_report"]

#: every result in metrics.json that the reports show: key -> (what it is, unit)
METRICS = {
    "fold_wavelength_um": ("fold wavelength (spectral peak)", "µm"),
    "fold_height_um": ("fold height (median crest-to-trough)", "µm"),
    "max_fold_height_um": ("highest fold (median crest-to-trough)", "µm"),
    "n_folds": ("folds found", "count"),
    "fold_periods_in_view": ("fold periods across the field", "count"),
    "fold_orientation_deg": ("crest orientation, from x towards y", "°"),
    "fold_coherency": ("orientation coherency (0 none, 1 parallel)", "1"),
    "spectral_orientation_deg": ("crest orientation from the spectrum", "°"),
    "Sa_um": ("Sa, arithmetic mean height", "µm"),
    "Sq_um": ("Sq, root mean square height", "µm"),
    "Ssk": ("Ssk, skewness", "1"),
    "Sku": ("Sku, kurtosis", "1"),
    "Sp_um": ("Sp, highest peak", "µm"),
    "Sv_um": ("Sv, deepest pit", "µm"),
    "Sz_um": ("Sz, peak to pit", "µm"),
    "Sdr_percent": ("Sdr, developed interfacial area ratio", "%"),
}

#: below these the report flags the measurement
LOW_COVERAGE = 0.9
LOW_SEPARABILITY = 0.7


def _number(value, digits: int = 4) -> str:
    if value is None:
        return "n/a"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            return "n/a"
        return f"{value:.{digits}g}"
    return str(value)


def _percent(value) -> str:
    return "n/a" if value is None else f"{100 * value:.1f} %"


def _result_rows(metrics: dict) -> list[dict]:
    rows = []
    for key, (what, unit) in METRICS.items():
        if key in metrics:
            rows.append({"result": what, "value": _number(metrics[key]), "unit": unit, "key": key})
    return rows


def _parameters(metrics: dict) -> dict:
    spacing = metrics.get("spacing_um", {})
    params = metrics.get("parameters", {})
    quality = metrics.get("quality", {})
    smooth = params.get("smooth_um")
    mosaic = params.get("mosaic")
    tiles = (
        {
            "mosaic": f"{mosaic['tiles']} tiles, {100 * mosaic['covered_fraction']:.1f} % of "
            f"the extent covered, stage positions rounded by up to "
            f"{mosaic['max_position_rounding_px']:.2f} px; overlaps from the nearest tile centre"
        }
        if mosaic
        else {}
    )
    return {
        "voxel spacing z, y, x (µm)": f"{_number(spacing.get('z'))}, "
        f"{_number(spacing.get('y'))}, {_number(spacing.get('x'))}"
        f" (from {metrics.get('spacing_source', '?')})",
        "stack shape (Z, C, Y, X)": " x ".join(str(n) for n in metrics.get("shape_zcyx", [])),
        **tiles,
        "channel": metrics.get("channel"),
        "surface threshold (grey value)": f"{_number(metrics.get('threshold'), 6)}, "
        f"{quality.get('threshold_method', '?')}",
        "peak window below the first crossing (µm)": _number(params.get("peak_window_um")),
        "least contrast-to-noise of a measured column": _number(params.get("min_cnr")),
        "outlier limit (µm off the 3 x 3 median)": _number(params.get("outlier_um")),
        "height-map smoothing sigma (µm)": _number(smooth),
        "least fold height (µm)": _number(metrics.get("min_fold_height_um"))
        + ("" if params.get("min_fold_height_um") is not None else " (a fifth of the range)"),
        "isosurface": "off (--no-surface)"
        if not params.get("surface", True)
        else f"band {_number(params.get('band_um'))} µm around the height map, "
        f"lateral bin {_number((quality.get('mesh') or {}).get('lateral_bin'))}, "
        f"decimate {_number(params.get('decimate'))}",
        "height datum": f"{metrics.get('height_datum', {}).get('datum', '?')} "
        f"({_number(metrics.get('height_datum', {}).get('depth_below_first_slice_um'))} µm "
        "below the first slice)",
        "command": " ".join(metrics.get("command") or []),
    }


def _quality_rows(metrics: dict) -> list[dict]:
    q = metrics.get("quality", {})
    drop = q.get("dropouts", {})
    rows = [
        {
            "quantity": "surface coverage (columns where a surface was measured)",
            "value": _percent(q.get("surface_coverage")),
        },
        {
            "quantity": "not measured: never reached the threshold / above the stack / "
            "faint / outlier",
            "value": " / ".join(
                _percent(drop.get(k)) for k in ("no_crossing", "above_stack", "faint", "outlier")
            ),
        },
        {
            "quantity": "lumen background, noise (grey values, robust SD)",
            "value": f"{_number(q.get('background'))}, {_number(q.get('background_noise'))}",
        },
        {
            "quantity": "Otsu separability at the threshold (between-class share of the "
            "variance; 1 = two distinct levels)",
            "value": _number(q.get("otsu_separability"), 3),
        },
        {
            "quantity": "median contrast-to-noise of the surface layer (measured columns)",
            "value": _number(q.get("median_surface_cnr"), 3),
        },
    ]
    mesh = q.get("mesh")
    if mesh:
        rows += [
            {
                "quantity": "mesh triangles, points",
                "value": f"{mesh['triangles']}, {mesh['points']}",
            },
            {
                "quantity": "mesh holes (closed boundary loops inside the field)",
                "value": str(mesh["holes"]),
            },
            {
                "quantity": "mesh boundary loops, non-manifold edges, degenerate triangles",
                "value": f"{mesh['boundary_loops']}, {mesh['non_manifold_edges']}, "
                f"{mesh['degenerate_triangles']}",
            },
            {
                "quantity": "mesh area over its projected area (1 + Sdr of the mesh)",
                "value": _number(mesh.get("developed_area_ratio"), 4),
            },
        ]
    err = q.get("mesh_vs_heightmap_um")
    if err:
        rows.append(
            {
                "quantity": "mesh depth - height-map depth at the same (x, y): median, "
                "95th percentile, maximum of |difference| (µm)",
                "value": f"{_number(err['median_abs'], 3)}, {_number(err['p95_abs'], 3)}, "
                f"{_number(err.get('max_abs'), 3)}",
            }
        )
    return rows


def analysis_flags(metrics: dict) -> list[str]:
    """What a reader should know before trusting the numbers, one sentence each."""
    flags = list(metrics.get("warnings") or [])
    q = metrics.get("quality", {})
    coverage = q.get("surface_coverage")
    if coverage is not None and coverage < LOW_COVERAGE:
        flags.append(
            f"The surface was measured in {_percent(coverage)} of the columns only "
            f"(below {_percent(LOW_COVERAGE)}); the rest of the height map is filled in "
            "from the neighbours."
        )
    sep = q.get("otsu_separability")
    if isinstance(sep, float) and math.isfinite(sep) and sep < LOW_SEPARABILITY:
        flags.append(
            f"The grey levels separate poorly at the threshold (Otsu separability "
            f"{sep:.2f} < {LOW_SEPARABILITY}): check --threshold and --channel."
        )
    if metrics.get("fold_wavelength_note"):
        flags.append(f"Fold wavelength: {metrics['fold_wavelength_note']}.")
    mesh = q.get("mesh")
    if mesh and mesh["holes"]:
        flags.append(f"The surface mesh has {mesh['holes']} hole(s) inside the field of view.")
    if mesh and mesh["non_manifold_edges"]:
        flags.append(f"The surface mesh has {mesh['non_manifold_edges']} non-manifold edge(s).")
    return flags


def _figures(doc: HtmlReport, folder: Path, figures: list[dict], prefix: str = "") -> None:
    for item in figures:
        path = folder / item["file"]
        if path.is_file():
            doc.media(path, f"{prefix}{item['caption']} ({item['file']})")


def write_analysis_report(folder: str | os.PathLike, metrics: dict) -> Path:
    """Write ``folder/report.html`` for an ``analyze`` folder from its ``metrics.json``."""
    folder = Path(folder)
    software = metrics.get("software", {})
    doc = HtmlReport(
        f"Lumen surface and folds: {metrics.get('input', folder.name)}",
        subtitle=f"mpm3d {software.get('version', '?')}: python -m mpm3d analyze",
    )
    doc.heading("Input")
    doc.inputs(metrics.get("inputs") or [{"path": metrics.get("input_path")}])
    doc.heading("Parameters")
    doc.key_values(_parameters(metrics))
    doc.heading("Results")
    doc.paragraph(
        "Heights are measured above the stack's deepest slice (the datum of the height "
        "map, both height figures and the mesh's height_um array); fold heights are "
        "crest-to-trough and the ISO 25178-2 parameters use the height map with its "
        "least-squares plane removed, so neither depends on the datum. Unit 1: "
        "dimensionless."
    )
    doc.table(_result_rows(metrics), columns=["result", "value", "unit", "key"])
    doc.key_values(
        {
            "height range of the height map (µm above the datum)": metrics.get("height_range_um"),
            "height range of the mesh (µm above the datum)": metrics.get("mesh_height_range_um")
            or "no mesh (--no-surface)",
            "colour range of both height figures (µm)": metrics.get("height_colour_range_um"),
        },
        digits=4,
    )
    doc.heading("Quality of the measurement")
    doc.table(_quality_rows(metrics), columns=["quantity", "value"])
    doc.heading("Flagged")
    doc.flags(analysis_flags(metrics))
    if metrics.get("figures"):
        doc.heading("Figures")
        _figures(doc, folder, metrics["figures"])
    doc.provenance(
        {k: v for k, v in metrics.items() if k != "figures"}, "Everything in metrics.json"
    )
    out = folder / "report.html"
    doc.write(out)
    return out


def _alignment_rows(alignment: dict) -> list[dict]:
    rows = [
        {
            "quantity": "lateral shift of the after stack, x, y (µm)",
            "value": f"{_number(alignment.get('shift_x_um'))}, "
            f"{_number(alignment.get('shift_y_um'))}",
        },
        {
            "quantity": "overlap of the aligned height maps",
            "value": _percent(alignment.get("overlap_fraction")),
        },
        {
            "quantity": "correlation of the aligned, form-removed height maps",
            "value": _number(alignment.get("overlap_correlation"), 3),
        },
        {
            "quantity": "residual after alignment: RMS of the height difference, form removed (µm)",
            "value": _number(alignment.get("residual_rms_um"), 4),
        },
        {
            "quantity": "the surfaces match (correlation >= 0.5)",
            "value": _number(alignment.get("matched")),
        },
    ]
    icp = alignment.get("icp")
    if isinstance(icp, dict):
        rows += [
            {
                "quantity": "ICP fitness (share of points paired)",
                "value": _number(icp["fitness"], 3),
            },
            {
                "quantity": "ICP residual: inlier RMSE (µm)",
                "value": _number(icp["inlier_rmse_um"], 4),
            },
            {
                "quantity": "ICP translation x, y, z (µm); rotation (°)",
                "value": f"{', '.join(_number(v) for v in icp['translation_um'])}; "
                f"{_number(icp['rotation_deg'], 3)}",
            },
        ]
    elif icp:
        rows.append({"quantity": "ICP refinement", "value": str(icp)})
    return rows


def write_comparison_report(folder: str | os.PathLike, report: dict) -> Path:
    """Write ``folder/report.html`` for a ``compare`` folder from its ``compare.json``."""
    folder = Path(folder)
    before, after = report["before"], report["after"]
    software = report.get("software", {})
    doc = HtmlReport(
        f"Before / after: {before.get('input')} and {after.get('input')}",
        subtitle=f"mpm3d {software.get('version', '?')}: python -m mpm3d compare",
    )
    doc.heading("Inputs")
    doc.inputs(report.get("inputs") or [])
    doc.heading("Parameters")
    doc.paragraph(
        "Both stacks are analysed with the same options; each side's own page "
        "(before/report.html, after/report.html) lists its parameters in full."
    )
    doc.table(
        [
            {"parameter": k, "before": _parameters(before)[k], "after": _parameters(after)[k]}
            for k in (
                "voxel spacing z, y, x (µm)",
                "stack shape (Z, C, Y, X)",
                "channel",
                "surface threshold (grey value)",
                "height-map smoothing sigma (µm)",
                "least fold height (µm)",
                "isosurface",
            )
        ],
        columns=["parameter", "before", "after"],
    )
    doc.heading("Changes")
    units = {k: u for k, (_, u) in METRICS.items()}
    names = {k: w for k, (w, _) in METRICS.items()}
    rows = [
        {
            "result": names.get(r["metric"], r["metric"]),
            "unit": units.get(r["metric"], ""),
            "before": r["before"],
            "after": r["after"],
            "change (after - before)": r["change"],
            "ratio": r["ratio"],
        }
        for r in report.get("changes", [])
    ]
    doc.table(
        rows, columns=["result", "unit", "before", "after", "change (after - before)", "ratio"]
    )
    doc.paragraph("Orientation changes are axial: they lie in (-90, 90] degrees.")
    doc.heading("Quality of the measurement")
    doc.heading("Alignment", level=3)
    alignment = report.get("alignment", {})
    doc.table(_alignment_rows(alignment), columns=["quantity", "value"])
    if alignment.get("note"):
        doc.paragraph(alignment["note"])
    doc.heading("Each stack", level=3)
    qb, qa = _quality_rows(before), _quality_rows(after)
    doc.table(
        [
            {"quantity": b["quantity"], "before": b["value"], "after": a["value"]}
            for b, a in zip(qb, qa, strict=False)
        ],
        columns=["quantity", "before", "after"],
    )
    doc.heading("Flagged")
    flags = [f"before: {f}" for f in analysis_flags(before)]
    flags += [f"after: {f}" for f in analysis_flags(after)]
    if alignment and not alignment.get("matched", True):
        flags.append(f"Alignment: {alignment.get('note')}")
    if isinstance(alignment.get("icp"), str):
        flags.append(f"ICP: {alignment['icp']}")
    elif isinstance(alignment.get("icp"), dict) and not alignment["icp"].get("matched"):
        flags.append(
            "ICP: fitness below 0.5; the surfaces do not correspond and its "
            "transform means nothing."
        )
    doc.flags(flags)
    figures = report.get("figures") or []
    side_figures = [
        (side, item)
        for side in ("before", "after")
        for item in report[side].get("figures") or []
        if item["file"].endswith(("heightmap.png", "surface3d.png"))
    ]
    if figures or side_figures:
        doc.heading("Figures")
        _figures(doc, folder, figures)
        for side, item in side_figures:
            _figures(doc, folder / side, [item], prefix=f"{side.capitalize()}: ")
    doc.provenance(
        {k: v for k, v in report.items() if k != "figures"}, "Everything in compare.json"
    )
    out = folder / "report.html"
    doc.write(out)
    return out
