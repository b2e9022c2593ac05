"""The quality of a stereo reconstruction, and the ``report.html`` of ``stereo reconstruct``.

:func:`frame_quality` summarises every frame of a
:class:`~stereo.reconstruct.Reconstruction` (points with a 3D position,
reprojection error, the 2D trackers' correlation in each view);
:func:`calibration_quality`, :func:`match_quality`, :func:`mesh_quality` and
:func:`flatness` measure the other steps; :func:`quality_flags` turns them
into sentences for the reader; :func:`write_report` builds the self-contained
report from the run's ``summary.json`` content and the per-frame table.

The reprojection error of a triangulated point is the RMS over the two views
of the distance between the tracked pixel and the projection of the 3D point
(Hartley & Zisserman, Multiple View Geometry, 2nd ed. 2004, Sec. 12.1,
doi:10.1017/CBO9780511811685).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from stereo.calibration import POOR_RMS_PX
from tissue_core.html import HtmlReport

__all__ = [
    "CALIBRATION_RMS_PX",
    "FLAT_FRACTION",
    "LOW_TRACKING_QUALITY",
    "POOR_TRIANGLE",
    "WARP_NOISE_NOTE",
    "calibration_quality",
    "flatness",
    "frame_quality",
    "match_quality",
    "mesh_quality",
    "quality_flags",
    "strain_figures",
    "write_report",
]

#: a calibration's RMS reprojection error above this (px) is flagged (as stereo calibrate does)
CALIBRATION_RMS_PX = POOR_RMS_PX
#: a frame whose median tracking quality (ZNCC for dic) falls below this is flagged
LOW_TRACKING_QUALITY = 0.9
#: triangles with a smaller radius ratio 2 r_in / r_circ (1: equilateral) are flagged
POOR_TRIANGLE = 0.3
#: a surface whose RMS distance from its best-fit plane stays below this fraction of its
#: extent in every frame counts as flat (where the affine warp is the quieter choice)
FLAT_FRACTION = 0.005
#: the warp trade-off measured on flat real specimens, stated in the help and the report
WARP_NOISE_NOTE = (
    "the quadratic warp follows curved surfaces seen in perspective, but on flat real "
    "specimens it is about twice as noisy as the affine one (out-of-plane spatial SD "
    "0.0027 mm against 0.0018 mm)"
)

#: the per-frame table's columns (``quality_per_frame.csv``)
FRAME_COLUMNS = (
    "frame", "points_3d", "lost", "reproj_median_px", "reproj_p95_px",
    "quality_left_median", "quality_right_median",
)  # fmt: skip


def _nan_stat(values: np.ndarray, q: float) -> float:
    v = values[np.isfinite(values)]
    return float(np.percentile(v, q)) if v.size else float("nan")


def frame_quality(rec) -> dict[str, np.ndarray]:
    """Per-frame quality of a reconstruction.

    Parameters
    ----------
    rec : stereo.reconstruct.Reconstruction

    Returns
    -------
    dict of (T,) arrays, keyed as :data:`FRAME_COLUMNS`:
        ``points_3d`` (int) points with a 3D position; ``lost`` (int) the
        others of the N points placed (never matched, lost by a tracker, or
        over the reprojection limit); ``reproj_median_px``, ``reproj_p95_px``
        the median and 95th percentile of the reprojection error over the
        points with a 3D position (NaN where there is none);
        ``quality_left_median``, ``quality_right_median`` the median of the
        2D tracker's quality over the points tracked in that view (those
        matched between the views and not lost there: the points whose
        quality is not NaN; NaN without the qualities).
    """
    T, N = rec.visible.shape
    err = np.where(rec.visible, rec.reproj_error, np.nan)
    out = {
        "frame": np.arange(T),
        "points_3d": rec.visible.sum(axis=1).astype(int),
        "lost": N - rec.visible.sum(axis=1).astype(int),
        "reproj_median_px": np.array([_nan_stat(err[t], 50) for t in range(T)]),
        "reproj_p95_px": np.array([_nan_stat(err[t], 95) for t in range(T)]),
    }
    for side in ("left", "right"):
        q = getattr(rec, f"{side}_quality", None)
        out[f"quality_{side}_median"] = (
            np.full(T, np.nan)
            if q is None
            else np.array([_nan_stat(np.asarray(q[t], float), 50) for t in range(T)])
        )
    return out


def calibration_quality(calib) -> dict:
    """What the calibration records about its own quality (NaN where it records nothing).

    ``rms_px`` is the rig's RMS reprojection error over the calibration views
    as the calibration file states it (OpenCV files made elsewhere carry
    none); ``baseline`` is ``|T|`` in the calibration's unit.
    """
    extra = calib.extra or {}
    views = extra.get("views") or []
    return {
        "rms_px": float(calib.rms_px),
        "rms_left_px": float(extra.get("rms_left_px", float("nan"))),
        "rms_right_px": float(extra.get("rms_right_px", float("nan"))),
        "worst_view_rms_px": max(
            (max(v.get("rms_left_px", 0.0), v.get("rms_right_px", 0.0)) for v in views),
            default=float("nan"),
        ),
        "views_used": len(views) if views else None,
        "views_rejected": len(extra.get("rejected") or []) if views else None,
        "board": extra.get("board"),
        "imported_from": extra.get("imported_from"),
        "baseline": float(calib.baseline),
        "unit": calib.unit,
        "image_size": [int(v) for v in calib.image_size],
        # "frames" where the calibration file holds none (stereo reconstruct takes the frames')
        "image_size_from": extra.get("image_size_from", "calibration"),
    }


def match_quality(rec) -> dict:
    """The cross-view match of the reference frames: how many points, how well.

    ``zncc_*`` is the correlation of the matched subsets between the views,
    ``epipolar_*_px`` the matches' distance from their epipolar lines.
    """
    zncc = np.asarray(rec.meta.get("match_quality", []), float)
    epi = np.asarray(rec.meta.get("epipolar_px", []), float)
    matched = np.isfinite(rec.right[0]).all(axis=1)
    z, e = zncc[matched] if zncc.size else zncc, epi[matched] if epi.size else epi
    info = rec.meta.get("match", {})
    return {
        "points": int(rec.n_points),
        "matched": int(matched.sum()),
        "zncc_median": _nan_stat(z, 50),
        "zncc_min": float(np.nanmin(z)) if np.isfinite(z).any() else float("nan"),
        "epipolar_median_px": _nan_stat(e, 50),
        "epipolar_max_px": float(np.nanmax(e)) if np.isfinite(e).any() else float("nan"),
        "feature_matches": info.get("matches"),
        "feature_inliers": info.get("inliers"),
    }


def flatness(points: np.ndarray) -> dict:
    """How far the points stray from a plane, frame by frame.

    Parameters
    ----------
    points : (T, N, 3) float, NaN where lost

    Returns
    -------
    dict
        ``plane_rms`` the largest over the frames of the RMS distance from the
        frame's best-fit plane (length unit), ``extent`` the diagonal of the
        reference points' in-plane bounding box, ``fraction`` their ratio
        (NaN with fewer than 3 points), ``flat`` whether it is below
        :data:`FLAT_FRACTION`.
    """
    from surface_strain import best_fit_plane

    worst, extent = float("nan"), float("nan")
    for t in range(points.shape[0]):
        p = points[t][np.isfinite(points[t]).all(axis=1)]
        if len(p) < 3:
            continue
        centre, axes = best_fit_plane(p)
        normal = np.cross(axes[:, 0], axes[:, 1])
        rms = float(np.sqrt(np.mean(((p - centre) @ normal) ** 2)))
        worst = rms if not np.isfinite(worst) else max(worst, rms)
        if not np.isfinite(extent):
            extent = float(np.linalg.norm(np.ptp((p - centre) @ axes, axis=0)))
    fraction = worst / extent if np.isfinite(worst) and extent > 0 else float("nan")
    return {
        "plane_rms": worst,
        "extent": extent,
        "fraction": fraction,
        "flat": bool(fraction < FLAT_FRACTION),
    }


def mesh_quality(field) -> dict:
    """Quality of the strain mesh: triangle shapes on the reference, folds and losses later.

    Parameters
    ----------
    field : surface_strain.StrainField (3D)

    Returns
    -------
    dict
        ``triangles``; ``radius_ratio_min`` and ``_median`` (2 r_in / r_circ,
        1 for an equilateral triangle) and ``poor_triangles`` (below
        :data:`POOR_TRIANGLE`) on the reference; ``edge_median`` (length
        unit); ``folded_max`` the most triangles in a frame that face against
        the side most of the mesh faces then (area-weighted,
        :func:`surface_strain.folded_triangles`) and ``folded_frame`` where;
        ``lost_last_frame`` the triangles without strain on the last frame.
    """
    from surface_strain import edge_lengths, folded_triangles, triangle_quality

    tri = np.asarray(field.triangles)
    ratio = triangle_quality(field.reference, tri)
    edges = edge_lengths(field.reference, tri)
    folded = np.zeros(field.n_frames, int)
    for t in range(field.n_frames):
        ok = np.asarray(field.element_valid[t], bool)
        if not ok.any():
            continue
        p = np.where(np.isfinite(field.points[t]), field.points[t], 0.0)
        q = p[tri[ok]]
        # the area-weighted mean normal of the frame's triangles: the side most of the mesh faces
        normal = np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]).sum(axis=0)
        if np.linalg.norm(normal) > 0:
            folded[t] = int(folded_triangles(p, tri[ok], normal=normal).sum())
    return {
        "triangles": len(tri),
        "radius_ratio_min": float(ratio.min()),
        "radius_ratio_median": float(np.median(ratio)),
        "poor_triangles": int((ratio < POOR_TRIANGLE).sum()),
        "edge_median": float(np.median(edges)),
        "folded_max": int(folded.max()),
        "folded_frame": int(folded.argmax()),
        "lost_last_frame": int((~np.asarray(field.element_valid[-1], bool)).sum()),
    }


def _worst(values: np.ndarray, *, low: bool) -> tuple[float, int]:
    ok = np.flatnonzero(np.isfinite(values))
    if not ok.size:
        return float("nan"), -1
    k = ok[np.argmin(values[ok])] if low else ok[np.argmax(values[ok])]
    return float(values[k]), int(k)


def quality_flags(
    per_frame: dict,
    calibration: dict,
    matching: dict,
    *,
    max_reproj_px: float,
    quality_name: str = "ZNCC",
    warp: str | None = None,
    surface: dict | None = None,
    mesh: dict | None = None,
) -> list[str]:
    """Sentences for what a reader should know before trusting the result (empty: nothing)."""
    flags = []
    unit = calibration.get("unit", "")
    rms = calibration.get("rms_px", float("nan"))
    if not np.isfinite(rms):
        flags.append(
            "The calibration records no reprojection error (it was made elsewhere): its "
            "quality is unknown, and the 3D positions are only as good as it is."
        )
    elif rms > CALIBRATION_RMS_PX:
        flags.append(
            f"The calibration's RMS reprojection error is {rms:.3g} px, above "
            f"{CALIBRATION_RMS_PX:g} px: recalibrate with sharper, more varied target views."
        )
    n, matched = matching["points"], matching["matched"]
    if matched < n:
        flags.append(
            f"{n - matched} of {n} points were not found in the right view (correlation too "
            "low or too far from the epipolar line): they have no 3D position in any frame."
        )
    lost = np.asarray(per_frame["lost"])
    if lost.size and lost.max() > n - matched:
        k = int(lost.argmax())
        flags.append(
            f"Up to {int(lost[k])} of {n} points have no 3D position in a frame (first at "
            f"frame {k}): lost by a tracker or over the {max_reproj_px:g} px reprojection limit."
        )
    p95, k = _worst(np.asarray(per_frame["reproj_p95_px"], float), low=False)
    if np.isfinite(p95) and p95 > 0.5 * max_reproj_px:
        flags.append(
            f"The 95th percentile of the reprojection error reaches {p95:.3g} px at frame {k}, "
            f"more than half the {max_reproj_px:g} px limit: the views disagree there "
            "(tracking drift, or a calibration that no longer fits the rig)."
        )
    for side in ("left", "right"):
        q, k = _worst(np.asarray(per_frame[f"quality_{side}_median"], float), low=True)
        if np.isfinite(q) and q < LOW_TRACKING_QUALITY:
            flags.append(
                f"The median tracking {quality_name} of the {side} view falls to {q:.3g} at "
                f"frame {k} (below {LOW_TRACKING_QUALITY:g}): the pattern changes or blurs."
            )
    if warp == "quadratic" and surface and surface.get("flat"):
        flags.append(
            f"The surface stays within {surface['plane_rms']:.2g} {unit} RMS of a plane "
            f"({100 * surface['fraction']:.2g} % of its {surface['extent']:.3g} {unit} extent) "
            f"and the subset warp is quadratic: {WARP_NOISE_NOTE}. Consider "
            "--shape-function affine for such a surface."
        )
    if mesh:
        if mesh["poor_triangles"]:
            flags.append(
                f"{mesh['poor_triangles']} of {mesh['triangles']} triangles are thin (radius "
                f"ratio below {POOR_TRIANGLE:g}, lowest {mesh['radius_ratio_min']:.2g}): their "
                "strain amplifies the position noise."
            )
        if mesh["folded_max"]:
            flags.append(
                f"{mesh['folded_max']} triangles fold over (face against the rest of the mesh) "
                f"at frame {mesh['folded_frame']}: the strain there is not meaningful."
            )
        if mesh["lost_last_frame"]:
            flags.append(
                f"{mesh['lost_last_frame']} of {mesh['triangles']} triangles have no strain on "
                "the last frame (a corner point was lost)."
            )
    return flags


def _rows_to_show(per_frame: dict, limit: int = 15) -> list[int]:
    """All frames when few; else ``limit`` of them: the worst of each column, the first and
    the last, and evenly spaced ones between."""
    T = len(per_frame["frame"])
    if T <= limit:
        return list(range(T))
    worst = {int(np.asarray(per_frame["lost"]).argmax())}
    for key, low in (("reproj_p95_px", False), ("quality_left_median", True),
                     ("quality_right_median", True)):  # fmt: skip
        _, k = _worst(np.asarray(per_frame[key], float), low=low)
        if k >= 0:
            worst.add(k)
    picks = worst | {0, T - 1}
    candidates = np.linspace(0, T - 1, limit).round().astype(int)
    while len(picks) < limit:  # farthest from what is picked first: spread over the run
        chosen = np.array(sorted(picks))
        gaps = np.abs(candidates[:, None] - chosen[None, :]).min(axis=1)
        picks.add(int(candidates[gaps.argmax()]))
    return sorted(picks)


def _short(path: str) -> str:
    """``parent/name`` of a path, for titles."""
    p = Path(path)
    return f"{p.parent.name}/{p.name}" if p.parent.name else p.name


def _table(doc: HtmlReport, mapping: dict) -> None:
    """Key-value rows to 4 significant figures, leaving out what is unknown (None)."""
    doc.key_values({k: v for k, v in mapping.items() if v is not None}, digits=4)


def _finite(value):
    """``value`` if it is a finite number, else None (the row is left out)."""
    return value if isinstance(value, int | float) and np.isfinite(value) else None


def _pair(a, b):
    """Two numbers for one row, or None when neither is known."""
    return [a, b] if _finite(a) is not None or _finite(b) is not None else None


def _known(value):
    """A number for a table, or "not recorded" where the source gave none (None or NaN)."""
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "not recorded"
    return value


def _strain_caption(name: str) -> str:
    stem = Path(name).stem
    if stem == "strain_over_time":
        return "Mean nodal strain over the frames (strain/)."
    key, _, frame = stem.partition("_frame")
    frame_text = f" at frame {int(frame)}" if frame.isdigit() else ""
    if key == "violins":
        return f"Distribution of the nodal strain{frame_text} (strain/)."
    if key in ("E1", "E2", "Exx", "Eyy", "Exy"):
        return f"{key}{frame_text} on the 3D mesh (strain/)."
    return f"{stem} (strain/)."


def write_report(
    folder: str | os.PathLike,
    summary: dict,
    per_frame: dict,
    *,
    figures: Sequence[dict] = (),
) -> Path:
    """Write ``folder/report.html`` for a ``stereo reconstruct`` run.

    Parameters
    ----------
    folder : path
        The run folder (figures are read from it and embedded).
    summary : dict
        The run's ``summary.json`` content (with ``quality`` and, after
        ``--strain``, ``strain``).
    per_frame : dict
        :func:`frame_quality` of the reconstruction.
    figures : sequence of {"file", "caption"}
        Paths relative to ``folder`` of PNG figures to embed, in order.
    """
    folder = Path(folder)
    software = summary.get("software", {})
    unit = summary.get("unit", "")
    inputs = summary.get("inputs", {})
    names = [_short(p) for p in (inputs.get("left") or [])[:1] + (inputs.get("right") or [])[:1]]
    doc = HtmlReport(
        f"Stereo reconstruction: {' and '.join(names) or 'two views'}",
        subtitle=f"{software.get('name', 'stereo')} {software.get('version', '?')}, "
        f"created {summary.get('created', '?')}",
    )
    quality = summary.get("quality", {})
    flags = summary.get("flags", [])

    doc.heading("Inputs")
    doc.inputs(summary.get("input_files", []))

    doc.heading("Parameters")
    par = summary.get("parameters", {})
    points = summary.get("points", {})
    warp = par.get("shape_function")
    warp_text = warp or "(the tracker has none)"
    if warp:
        warp_text = f"{warp} ({WARP_NOISE_NOTE}; --shape-function affine or quadratic)"
    _table(
        doc,
        {
            "points": points.get("source")
            or (f"grid {points['grid'][0]}x{points['grid'][1]}" if points.get("grid") else None),
            "grid region (px, left image)": points.get("roi") or "default",
            "tracker": par.get("tracker"),
            "subset warp (shape function)": warp_text,
            "tracker options": par.get("tracker_options", {}),
            "cross-view match subset (px)": par.get("match_subset"),
            "epipolar tolerance (px)": par.get("max_epipolar_px"),
            "reprojection limit (px)": par.get("max_reproj_px"),
            "strain directions": par.get("directions") or "(no --strain)",
            "command": " ".join(summary.get("command") or []),
        },
    )

    doc.heading("Results")
    res = summary.get("results", {})
    _table(
        doc,
        {
            "frames": summary.get("frames"),
            "points placed": points.get("n"),
            "points with a 3D position, all frames (%)": 100
            * summary.get("visible_fraction", float("nan")),
            f"reference extent X, Y, Z ({unit})": res.get("extent"),
            f"mean depth Z on the reference ({unit})": res.get("mean_depth"),
            f"displacement on the last frame, median ({unit})": res.get("displacement_median"),
            f"displacement on the last frame, max ({unit})": res.get("displacement_max"),
            f"RMS distance from the best-fit plane, worst frame ({unit})": quality.get(
                "surface", {}
            ).get("plane_rms"),
        },
    )
    strain = summary.get("strain")
    if strain:
        doc.heading(f"Strain on the last frame (frame {summary.get('frames', 1) - 1})")
        doc.paragraph(
            f"{strain.get('definition', 'Green-Lagrange membrane strain')} (dimensionless), "
            f"nodal values over the mesh ({strain.get('mesh', '')}); all files in strain/."
        )
        rows = [{"component": k, **v} for k, v in strain.get("last_frame", {}).items()]
        doc.table(rows, columns=["component", "mean", "sd", "min", "max", "n"])

    doc.heading("Quality of the measurement")
    doc.heading("Calibration", 3)
    cal = quality.get("calibration", {})
    views = cal.get("views_used")
    _table(
        doc,
        {
            "RMS reprojection error, rig (px)": _known(cal.get("rms_px")),
            "RMS reprojection error, left / right camera (px)": _pair(
                cal.get("rms_left_px"), cal.get("rms_right_px")
            ),
            "worst target view (px)": _finite(cal.get("worst_view_rms_px")),
            "target views used / rejected": f"{views} / {cal.get('views_rejected')}"
            if views
            else None,
            "target": cal.get("board"),
            "imported from": cal.get("imported_from"),
            f"baseline ({unit})": cal.get("baseline"),
            "image size (px)": cal.get("image_size")
            if cal.get("image_size_from") != "frames"
            else f"{cal['image_size'][0]}x{cal['image_size'][1]}, the frames' (the "
            "calibration file holds none)",
        },
    )
    doc.heading("Matching the views (reference frames)", 3)
    m = quality.get("matching", {})
    _table(
        doc,
        {
            "points matched in the right view": f"{m.get('matched')} of {m.get('points')}",
            "ZNCC of the matched subsets, median / lowest": [
                m.get("zncc_median"),
                m.get("zncc_min"),
            ],
            "distance from the epipolar line, median / max (px)": [
                m.get("epipolar_median_px"),
                m.get("epipolar_max_px"),
            ],
            "feature matches relating the views (inliers)": f"{m.get('feature_matches')} "
            f"({m.get('feature_inliers')})",
        },
    )
    qname = quality.get("tracking_quality", "ZNCC")
    doc.heading("Triangulation and tracking, per frame", 3)
    overall = quality.get("reprojection", {})
    doc.paragraph(
        f"Reprojection error over all frames and points: median "
        f"{overall.get('median_px', float('nan')):.3g} px, 95th percentile "
        f"{overall.get('p95_px', float('nan')):.3g} px, largest "
        f"{overall.get('max_px', float('nan')):.3g} px. Tracking quality: {qname} of each "
        "point against the reference frame in its view (1 is best)."
    )
    shown = _rows_to_show(per_frame)
    rows = [{c: per_frame[c][t].item() for c in FRAME_COLUMNS} for t in shown]
    doc.table(
        rows,
        columns=list(FRAME_COLUMNS),
        headers=[
            "frame", "3D points", "lost", "reprojection median (px)", "reprojection p95 (px)",
            f"left {qname} median", f"right {qname} median",
        ],
    )  # fmt: skip
    if len(shown) < len(per_frame["frame"]):
        doc.paragraph(
            f"{len(shown)} of {len(per_frame['frame'])} frames shown (evenly spaced, and the "
            "worst of each column); every frame is in quality_per_frame.csv."
        )
    mq = quality.get("mesh")
    if mq:
        doc.heading("Strain mesh", 3)
        _table(
            doc,
            {
                "triangles": mq["triangles"],
                "radius ratio 2 r_in / r_circ, lowest / median (1: equilateral)": [
                    mq["radius_ratio_min"],
                    mq["radius_ratio_median"],
                ],
                f"thin triangles (radius ratio < {POOR_TRIANGLE:g})": mq["poor_triangles"],
                f"median edge length ({unit})": mq["edge_median"],
                "folded triangles, most in a frame": mq["folded_max"],
                "triangles without strain on the last frame": mq["lost_last_frame"],
            },
        )

    doc.heading("Flagged")
    doc.flags(flags)

    doc.heading("Figures")
    for item in figures:
        doc.media(folder / item["file"], item["caption"])
    if (folder / "strain" / "report.html").exists():
        doc.paragraph("The strain computation has its own report: strain/report.html.")
    doc.provenance(summary)
    out = folder / "report.html"
    doc.write(out)
    return out


def strain_figures(folder: str | os.PathLike) -> list[dict]:
    """The strain results' PNG figures in ``folder/strain/figures``, with captions.

    The mean strain over time, the maps and the violins of
    :func:`surface_strain.write_run`, in that order; other files there are
    left to the strain folder's own report.
    """
    folder = Path(folder)
    order = {"strain_over_time": 0, "E1": 1, "E2": 2, "Exx": 3, "Eyy": 4, "Exy": 5, "violins": 6}
    files = [
        p
        for p in (folder / "strain" / "figures").glob("*.png")
        if p.stem.partition("_frame")[0] in order
    ]
    files.sort(key=lambda p: (order[p.stem.partition("_frame")[0]], p.name))
    return [{"file": str(p.relative_to(folder)), "caption": _strain_caption(p.name)} for p in files]
