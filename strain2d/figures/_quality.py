"""The quality of a run's measurement over time: points tracked, area covered, match quality."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from strain2d.errors import InputError

__all__ = ["plot_run_quality", "run_quality"]


def run_quality(tracks, field) -> dict:
    """Per-frame quality of a run: lists of T values, JSON-ready.

    ``visible_pct`` of the points tracked and ``coverage_pct`` of the
    reference mesh area whose triangles have a valid strain, with ``mesh``
    (triangle count, radius ratios, slivers), all from
    :func:`surface_strain.measurement_quality`; ``quality_median`` and
    ``quality_p5``, the tracker's quality (dic, gdic: ZNCC; klt:
    forward-backward agreement, 1 = exact) over the visible points;
    ``uncertainty_median_px`` where the tracker measures its uncertainty
    (else None).
    """
    from surface_strain import measurement_quality

    measured = measurement_quality(field)
    vis = np.asarray(tracks.visible, bool)
    q = np.where(vis, np.asarray(tracks.quality, float), np.nan)
    out = {
        "visible_pct": [100 * v for v in measured["visible_fraction"]],
        "coverage_pct": [100 * c for c in measured["surface_coverage"]],
        "mesh": measured["mesh"],
        "quality_median": [],
        "quality_p5": [],
        "uncertainty_median_px": None,
    }
    for row in q:
        row = row[np.isfinite(row)]
        out["quality_median"].append(float(np.median(row)) if row.size else None)
        out["quality_p5"].append(float(np.percentile(row, 5)) if row.size else None)
    if tracks.uncertainty is not None:
        u = np.where(vis, np.asarray(tracks.uncertainty, float), np.nan)
        med = []
        for row in u:
            row = row[np.isfinite(row)]
            med.append(float(np.median(row)) if row.size else None)
        out["uncertainty_median_px"] = med
    return out


def _values(seq) -> np.ndarray:
    return np.array([np.nan if v is None else v for v in seq], dtype=float)


def plot_run_quality(
    quality: dict,
    times: Sequence[float],
    *,
    time_unit: str = "frame",
    tracker: str = "",
    length=None,
) -> Figure:
    """Two panels over time: % of points tracked and of area with strain; the tracker's quality.

    ``quality`` is :func:`run_quality`'s; the uncertainty, when measured, is
    drawn on a second axis of the lower panel, in ``length``'s unit when a
    pixel size is given.
    """
    t = np.asarray(times, dtype=float)
    vis = _values(quality["visible_pct"])
    if t.shape != vis.shape:
        raise InputError(f"times has {t.size} values for {vis.size} frames")
    fig = Figure(figsize=(7.5, 4.6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    dots = t.size <= 30
    top.plot(t, vis, "-o" if dots else "-", ms=3, lw=1.6, label="points tracked")
    top.plot(t, _values(quality["coverage_pct"]), "--s" if dots else "--", ms=3, lw=1.4,
             label="mesh area with valid strain")  # fmt: skip
    low = np.nanmin(np.concatenate([vis, _values(quality["coverage_pct"])]), initial=100)
    top.set_ylim(max(0.0, min(low - 5, 90.0)), 101)
    top.set_ylabel("% of the reference")
    top.legend(fontsize=8, loc="lower left")
    top.grid(alpha=0.3)
    med, p5 = _values(quality["quality_median"]), _values(quality["quality_p5"])
    what = {"dic": "ZNCC", "gdic": "ZNCC", "klt": "forward-backward agreement"}.get(tracker, "")
    bottom.plot(t, med, "-", color="C2", lw=1.6, label="median over points")
    bottom.fill_between(t, p5, med, color="C2", alpha=0.2, lw=0, label="5th percentile to median")
    bottom.set_ylabel(f"tracking quality{f' ({what})' if what else ''} (-)", fontsize=9)
    bottom.set_xlabel("frame" if time_unit == "frame" else f"time ({time_unit})")
    bottom.grid(alpha=0.3)
    handles, labels = bottom.get_legend_handles_labels()
    unc = quality.get("uncertainty_median_px")
    if unc is not None:
        factor, unit = (1.0, "px") if length is None else (length.per_px, length.unit)
        twin = bottom.twinx()
        (line,) = twin.plot(t, _values(unc) * factor, ":", color="C3", lw=1.6)
        twin.set_ylabel(f"uncertainty ({unit}, 1 sigma)", fontsize=9, color="C3")
        twin.set_ylim(bottom=0)
        handles.append(line)
        labels.append("median uncertainty")
    bottom.legend(handles, labels, fontsize=8, loc="best")
    return fig
