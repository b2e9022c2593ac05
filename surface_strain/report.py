"""The quality of a 3D strain measurement, and the run folder's ``report.html``.

:func:`measurement_quality` says how much of a run can be trusted, from the
strain field alone: the mesh (triangle count, radius-ratio quality, triangles
left out), the points still tracked on each frame, the fraction of the
reference surface area whose triangles have a valid strain on each frame,
triangles turned inside out, and the per-point quality column the input
brought (stereo's reprojection error).  :func:`write_run_report` turns a run
folder's ``summary.json`` content and its figures into a self-contained
``report.html`` (:class:`tissue_core.html.HtmlReport`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from surface_strain.field import StrainField, nodal_scalars
from surface_strain.streamed import iter_blocks

__all__ = [
    "POINT_QUALITY_COLUMNS",
    "SLIVER_QUALITY",
    "measurement_quality",
    "quality_flags",
    "strain_statistics",
    "write_run_report",
]

#: Triangles of a smaller radius ratio ``2 r_in / r_circ`` are slivers (the Delaunay filter's
#: default threshold): their strain magnifies tracking noise.
SLIVER_QUALITY = 0.1
#: A frame whose surface coverage falls below this fraction is flagged.
MIN_COVERAGE = 0.9
#: Per-point quality columns a points file may carry: name -> (what it is, unit, worse when).
POINT_QUALITY_COLUMNS = {
    "reproj_error": ("reprojection error", "px", "higher"),
    "quality": ("tracking quality", "tracker's scale", "lower"),
}
#: Rows of the per-frame table in the report; longer runs are summarised.
PER_FRAME_ROWS = 12
_COMPONENTS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J")


def _float(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def _inverted(field: StrainField) -> np.ndarray:
    """(T, M) bool: valid triangles whose orientation reversed from the reference."""
    ref = field.reference[field.triangles]
    cur = field.points[:, field.triangles]  # (T, M, 3, d)
    d1, d2 = ref[:, 1] - ref[:, 0], ref[:, 2] - ref[:, 0]
    c1, c2 = cur[:, :, 1] - cur[:, :, 0], cur[:, :, 2] - cur[:, :, 0]
    if field.reference.shape[1] == 2:
        sign = (d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])[None] * (
            c1[..., 0] * c2[..., 1] - c1[..., 1] * c2[..., 0]
        )
    else:
        sign = np.einsum("mk,tmk->tm", np.cross(d1, d2), np.cross(c1, c2))
    with np.errstate(invalid="ignore"):
        return field.element_valid & (sign < 0)


def measurement_quality(
    field: StrainField,
    *,
    n_mesh_triangles: int | None = None,
    point_quality: Mapping[str, np.ndarray] | None = None,
) -> dict:
    """How much of a strain measurement can be trusted, frame by frame.

    Parameters
    ----------
    field : StrainField
    n_mesh_triangles : int, optional, keyword-only
        Triangles of the chosen mesh before those with a vertex lost on the
        reference frame were left out (default: none were).
    point_quality : mapping of str to (T, N) float, optional, keyword-only
        Per-point columns of the input (see :data:`POINT_QUALITY_COLUMNS`),
        summarised over the visible points.

    Returns
    -------
    dict
        JSON-ready: ``mesh`` (``n_triangles``, ``excluded``, ``quality_min``,
        ``quality_median``, ``slivers``), and per frame (lists of T values)
        ``visible_fraction`` (of all N points), ``surface_coverage`` (the
        fraction of the meshed reference area whose triangles have a valid
        strain) and ``inverted_triangles`` (valid triangles whose orientation
        reversed from the reference: folded or tangled tracking), plus
        ``point_quality`` with ``median``, ``tail``, ``worst`` over all frames
        and ``median_per_frame`` for each column (``tail``: the 95th percentile, or
        the 5th for a quality that is worse when lower).

    Examples
    --------
    >>> from surface_strain import compute_strain
    >>> ref = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    >>> tri = np.array([[0, 1, 2], [1, 3, 2]])
    >>> visible = np.array([[True] * 4, [True, True, True, False]])
    >>> q = measurement_quality(compute_strain(ref, np.stack([ref, ref]), tri, visible=visible))
    >>> q["visible_fraction"], q["surface_coverage"]
    ([1.0, 0.75], [1.0, 0.5])
    """
    from surface_strain.mesh import triangle_quality

    M = field.n_triangles
    q = triangle_quality(field.reference, field.triangles) if M else np.zeros(0)
    areas = np.asarray(field.reference_areas, dtype=float)
    total = areas.sum()
    coverage, inverted = [], []
    for _, block in iter_blocks(field):  # a streamed field a block of frames at a time
        valid = block.element_valid & np.isfinite(block.E).all(axis=(2, 3))
        covered = (valid * areas).sum(axis=1) / total if total > 0 else np.zeros(block.n_frames)
        coverage.extend(float(c) for c in covered)
        inverted.extend(int(n) for n in _inverted(block).sum(axis=1))
    out = {
        "mesh": {
            "n_triangles": M,
            "excluded": int(n_mesh_triangles - M) if n_mesh_triangles is not None else 0,
            "quality_measure": "radius ratio 2 r_in / r_circ (1 equilateral, 0 degenerate)",
            "quality_min": _float(q.min()) if q.size else None,
            "quality_median": _float(np.median(q)) if q.size else None,
            "slivers": int((q < SLIVER_QUALITY).sum()),
            "sliver_threshold": SLIVER_QUALITY,
            "reference_area": _float(total),
        },
        "visible_fraction": [float(v) for v in field.visible.mean(axis=1)],
        "surface_coverage": coverage,
        "inverted_triangles": inverted,
    }
    columns = {}
    for name, values in (point_quality or {}).items():
        v = np.where(field.visible, np.asarray(values, dtype=float), np.nan)
        seen = v[np.isfinite(v)]
        what, unit, worse = POINT_QUALITY_COLUMNS.get(name, (name, "input's scale", "higher"))
        with warnings.catch_warnings():  # a frame without a visible point: NaN, no warning
            warnings.simplefilter("ignore", RuntimeWarning)
            per_frame = np.nanmedian(v, axis=1)
        columns[name] = {
            "what": what,
            "unit": unit,
            "worse": worse,
            "n": int(seen.size),
            "median": _float(np.median(seen)) if seen.size else None,
            "tail_percentile": 95 if worse == "higher" else 5,
            "tail": _float(np.percentile(seen, 95 if worse == "higher" else 5))
            if seen.size
            else None,
            "worst": _float(seen.max() if worse == "higher" else seen.min()) if seen.size else None,
            "median_per_frame": [_float(x) for x in per_frame],
        }
    if columns:
        out["point_quality"] = columns
    return out


def strain_statistics(field: StrainField, frame: int = -1) -> dict:
    """Mean, SD, min, max and count over the nodes of each strain component at ``frame``.

    Also the displacement magnitude ``|u|`` (in the points' unit).  JSON-ready
    (None where no node has a value).
    """
    t = field.n_frames - 1 if frame < 0 else frame
    node = nodal_scalars(field)
    values = {k: node[k][t] for k in _COMPONENTS if k in node}
    values["|u|"] = np.linalg.norm(field.points[t] - field.reference, axis=1)
    out = {}
    for key, v in values.items():
        v = v[np.isfinite(v)]
        out[key] = {
            "mean": _float(v.mean()) if v.size else None,
            "sd": _float(v.std(ddof=1)) if v.size > 1 else None,
            "min": _float(v.min()) if v.size else None,
            "max": _float(v.max()) if v.size else None,
            "n": int(v.size),
        }
    return out


def quality_flags(summary: Mapping) -> list[str]:
    """Sentences for what a run's ``summary.json`` content says a reader should know."""
    flags = []
    quality = summary.get("quality") or {}
    times = _times(summary)
    lost = summary.get("lost_on_reference") or 0
    if lost:
        flags.append(
            f"{lost} of {summary.get('points')} points are lost on the reference frame: they "
            "and their triangles are left out of the mesh."
        )
    if summary.get("unit_source") == "unknown":
        flags.append(
            "The coordinates' unit is unknown (no --unit and no stereo summary.json beside "
            "the points): lengths are in input units. Strain is dimensionless and unaffected."
        )
    mesh = quality.get("mesh") or {}
    if mesh.get("slivers"):
        flags.append(
            f"{mesh['slivers']} of {mesh['n_triangles']} triangles are slivers (radius ratio "
            f"below {mesh['sliver_threshold']}): their strain magnifies tracking noise."
        )
    cover = np.asarray(quality.get("surface_coverage") or [], dtype=float)
    if cover.size and cover.min() < MIN_COVERAGE:
        t = int(np.argmin(cover))
        flags.append(
            f"Surface coverage falls to {100 * cover[t]:.1f} % ({_when(t, times)}): "
            f"{np.count_nonzero(cover < MIN_COVERAGE)} of {cover.size} frames have valid strain "
            f"on less than {100 * MIN_COVERAGE:.0f} % of the reference surface."
        )
    inverted = np.asarray(quality.get("inverted_triangles") or [], dtype=int)
    if inverted.size and inverted.max() > 0:
        t = int(np.argmax(inverted))
        n = np.count_nonzero(inverted)
        flags.append(
            f"Triangles turn inside out on {n} frame{'s' if n > 1 else ''} (up to "
            f"{inverted[t]}, {_when(t, times)}): the tracked surface folds or points were "
            "mismatched there."
        )
    return flags


def _times(summary: Mapping) -> np.ndarray | None:
    fps = (summary.get("time_axis") or {}).get("fps")
    return np.arange(int(summary.get("frames") or 0)) / fps if fps else None


def _when(t: int, times) -> str:
    return f"frame {t}, t = {times[t]:.4g} s" if times is not None else f"frame {t}"


def _directions_text(directions: str) -> str:
    kind = directions.split(":")[0].lower()
    if kind == "xy":
        return "xy: global X and Y, projected onto each triangle's tangent plane"
    if kind == "vectors":
        return f"{directions}: the two given directions, projected onto each tangent plane"
    if kind == "cylinder":
        return f"{directions}: x axial, y circumferential about the axis through P along A"
    if kind == "sphere":
        return f"{directions}: x meridional, y circumferential about the axis through P along A"
    return directions


def _percent(x) -> float | None:
    return None if x is None else 100 * float(x)


def _frame_rows(summary: Mapping, times) -> list[dict]:
    q = summary["quality"]
    T = len(q["visible_fraction"])
    pq = q.get("point_quality") or {}
    rows = []
    for t in range(T):
        row = {"frame": t}
        if times is not None:
            row["time (s)"] = float(times[t])
        row["points visible (%)"] = _percent(q["visible_fraction"][t])
        row["surface coverage (%)"] = _percent(q["surface_coverage"][t])
        row["inverted triangles"] = q["inverted_triangles"][t]
        for info in pq.values():
            row[f"median {info['what']} ({info['unit']})"] = info["median_per_frame"][t]
        rows.append(row)
    return rows


def _over_frames(name: str, values, times, *, worse: str = "lower", scale: float = 1.0) -> dict:
    v = np.asarray([np.nan if x is None else x for x in values], dtype=float) * scale
    ok = np.isfinite(v)
    if not ok.any():
        return {"quantity": name}
    t = int(np.nanargmin(v) if worse == "lower" else np.nanargmax(v))
    return {
        "quantity": name,
        "reference frame": float(v[0]),
        "last frame": float(v[-1]),
        "median over frames": float(np.nanmedian(v)),
        "worst": float(v[t]),
        "worst at": _when(t, times) if np.nanmax(v) > np.nanmin(v) else "every frame alike",
    }


def _figures(folder: Path, summary: Mapping, *, quality: bool) -> list[dict]:
    """The figures of ``summary["figures"]`` in the quality section (or not) whose PNG exists."""
    return [
        f
        for f in summary.get("figures") or []
        if (f.get("section") == "quality") == quality
        and f.get("files")
        and (folder / f["files"][0]).is_file()
    ]


def write_run_report(folder: str | os.PathLike, summary: Mapping) -> Path:
    """Write ``report.html`` into a 3D run folder from its ``summary.json`` content.

    The report holds the inputs with their SHA-256, the parameters, the
    strain at the last frame with units, what was flagged, the quality of the
    measurement (mesh, points lost and surface coverage per frame, the
    input's per-point quality), the figures listed in ``summary["figures"]``
    (embedded: the file needs no other to be read) and ``summary`` itself,
    folded away.  Returns the report's path.
    """
    from tissue_core.html import HtmlReport

    folder = Path(folder)
    software = summary.get("software", {})
    unit = summary.get("unit") or "input units"
    times = _times(summary)
    fps = (summary.get("time_axis") or {}).get("fps")
    doc = HtmlReport(
        f"Surface strain: {summary.get('input') or folder.name}",
        subtitle=f"{software.get('name', 'surface_strain')} {software.get('version', '?')}, "
        f"created {summary.get('created', '?')}",
    )
    doc.heading("Inputs")
    records = [r for r in summary.get("input_files") or [] if r.get("sha256")]
    if records:
        doc.inputs(records)
    else:
        doc.paragraph(f"{summary.get('input') or '?'} (no checksum recorded by the caller).")

    doc.heading("Parameters")
    unknown = summary.get("unit_source") == "unknown"
    unit_text = "input units (not known: pass --unit)" if unknown else unit
    mesh = summary.get("mesh") or {}
    doc.key_values(
        {
            "points": summary.get("points"),
            "frames": summary.get("frames"),
            "time axis": f"{fps:g} frames per second (times in s)"
            if fps
            else "frames (no frame rate known: pass --fps)",
            "mesh": mesh.get("method"),
            "triangles": mesh.get("n_triangles"),
            "directions of Exx, Eyy, Exy": _directions_text(str(summary.get("directions"))),
            "strain": summary.get("strain"),
            "unit of X, Y, Z and displacements": unit_text,
            "command": " ".join(summary.get("command") or []) or "(called from Python)",
        }
    )

    stats = summary.get("last_frame_statistics") or {}
    if stats:
        last = int(summary.get("frames") or 1) - 1
        doc.heading(f"Strain on the last frame ({_when(last, times)})")
        units = {"J": "(-), area ratio", "|u|": unit, "max_shear": "(-)"}
        rows = [
            {"quantity": k, "unit": units.get(k, "(-)"), **{c: v[c] for c in v}}
            for k, v in stats.items()
        ]
        doc.table(rows, columns=["quantity", "unit", "mean", "sd", "min", "max", "n"],
                  headers=["quantity", "unit", "mean", "SD", "min", "max", "nodes"])  # fmt: skip
        doc.paragraph(
            "Green-Lagrange strain, dimensionless (-), averaged at the nodes over their "
            "triangles (area-weighted); J is the area ratio; |u| is the displacement from the "
            f"reference frame in {unit}. Mean and SD are over the nodes with a value."
        )

    peak = summary.get("peak_statistics")
    if peak:
        frame = int(peak["frame"])
        doc.heading(f"Strain at the peak of cycle {peak['cycle']}, the largest "
                    f"({_when(frame, times)})")  # fmt: skip
        units = {"J": "(-), area ratio", "|u|": unit, "max_shear": "(-)"}
        rows = [
            {"quantity": k, "unit": units.get(k, "(-)"), **{c: v[c] for c in v}}
            for k, v in peak.items()
            if isinstance(v, dict)
        ]
        doc.table(rows, columns=["quantity", "unit", "mean", "sd", "min", "max", "n"],
                  headers=["quantity", "unit", "mean", "SD", "min", "max", "nodes"])  # fmt: skip
    cycles = summary.get("cycles")
    if cycles:
        doc.heading("Repeated contractions" if cycles.get("repeated", True) else "Contraction")
        doc.paragraph(
            f"{len(cycles['cycles'])} cycle(s) found in the mean {cycles['component']} (peaks "
            f"rising at least {cycles['min_prominence']:.2g} above their valleys). Strains "
            "are the mean nodal values at each peak; cycles.csv and cycles_nodes.csv hold "
            "them."
        )
        doc.table(
            [
                {
                    "cycle": c["cycle"], "onset": c["onset"], "peak": c["peak"],
                    "end": c["end"], "time to peak": c.get("time_to_peak"),
                    "50 % relaxation": c.get("rt50"), "rise": c.get("amplitude"),
                    **{f"{k} at peak": (c.get("peak_mean") or {}).get(k)
                       for k in ("Exx", "Eyy", "Exy")},
                }
                for c in cycles["cycles"]
            ]
        )  # fmt: skip

    doc.heading("Flagged")
    doc.flags(summary.get("flagged") or [])

    quality = summary.get("quality")
    if quality:
        doc.heading("Quality of the measurement")
        m = quality["mesh"]
        doc.key_values(
            {
                "triangles": m["n_triangles"],
                "triangles left out (a vertex lost on the reference frame)": m["excluded"],
                "triangle quality, min / median": f"{m['quality_min']:.3g} / "
                f"{m['quality_median']:.3g} (radius ratio 2 r_in / r_circ: 1 equilateral, "
                "0.83 half a square, 0 degenerate)",
                f"slivers (quality below {m['sliver_threshold']})": m["slivers"],
                f"reference surface area ({unit}²)": m.get("reference_area"),
            },
            digits=4,
        )
        rows = [
            _over_frames("points visible (%)", quality["visible_fraction"], times, scale=100),
            _over_frames("surface coverage (%)", quality["surface_coverage"], times, scale=100),
            _over_frames(
                "inverted triangles", quality["inverted_triangles"], times, worse="higher"
            ),
        ]
        for info in (quality.get("point_quality") or {}).values():
            rows.append(
                _over_frames(
                    f"median {info['what']} ({info['unit']})",
                    info["median_per_frame"],
                    times,
                    worse=info["worse"],
                )
            )
        doc.table(rows, columns=["quantity", "reference frame", "last frame",
                                 "median over frames", "worst", "worst at"])  # fmt: skip
        doc.paragraph(
            "Points visible: of all the input's points. Surface coverage: the fraction of the "
            "meshed reference surface area whose triangles have a valid strain (all three "
            "points tracked). Inverted triangles: valid triangles whose orientation reversed "
            "from the reference frame (the surface folds, or points were mismatched)."
        )
        for info in (quality.get("point_quality") or {}).values():
            if info["n"]:
                doc.paragraph(
                    f"The input's {info['what']} over all {info['n']} visible point positions: "
                    f"median {info['median']:.3g} {info['unit']}, {info['tail_percentile']}th "
                    f"percentile {info['tail']:.3g} {info['unit']}, worst {info['worst']:.3g} "
                    f"{info['unit']}."
                )
        if len(quality["visible_fraction"]) <= PER_FRAME_ROWS:
            doc.table(_frame_rows(summary, times))
        else:
            doc.paragraph(
                f"{len(quality['visible_fraction'])} frames: the per-frame values are in "
                "summary.json (quality) and in the figure below."
            )
    for item in _figures(folder, summary, quality=True):
        doc.media(folder / item["files"][0], item["caption"])
    figures = _figures(folder, summary, quality=False)
    if figures:
        doc.heading("Figures")
        for item in figures:
            doc.media(folder / item["files"][0], item["caption"])
    doc.provenance(dict(summary))
    out = folder / "report.html"
    doc.write(out)
    return out
