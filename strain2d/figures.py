"""Figures of a 2D run: the tracked grid and strain contour maps.

Built on :class:`matplotlib.figure.Figure` directly, so importing or calling
this module never changes the global pyplot state or backend.  Axes are in
pixels with y pointing down, as in the images.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from matplotlib.tri import Triangulation

from strain2d.tracks import Tracks
from surface_strain import StrainField, nodal_scalars

__all__ = ["plot_strain_errors", "plot_strain_maps", "plot_tracked_grid"]

_LABELS = {
    "Exx": r"$E_{xx}$",
    "Eyy": r"$E_{yy}$",
    "Exy": r"$E_{xy}$",
    "E1": r"$E_1$",
    "E2": r"$E_2$",
    "max_shear": r"$(E_1 - E_2)/2$",
}


def _show_image(ax, image: np.ndarray) -> None:
    ax.imshow(image, cmap="gray", interpolation="nearest", origin="upper")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")


def plot_tracked_grid(
    path: str | os.PathLike,
    first: np.ndarray,
    last: np.ndarray,
    tracks: Tracks,
    triangles: np.ndarray,
    *,
    last_index: int | None = None,
    dpi: int = 120,
) -> None:
    """Save the tracked grid and mesh over the reference and the last frame.

    Lost points on the last frame are drawn as red crosses.
    """
    last_index = tracks.n_frames - 1 if last_index is None else last_index
    fig = Figure(figsize=(11, 5.4), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, image, k, title in (
        (axes[0], first, 0, "frame 0 (reference)"),
        (axes[1], last, last_index, f"frame {last_index}"),
    ):
        _show_image(ax, image)
        pos = tracks.positions[k]
        vis = tracks.visible[k]
        ok_tri = np.all(vis[triangles], axis=1)
        if ok_tri.any():
            tri = Triangulation(pos[:, 0], pos[:, 1], triangles[ok_tri])
            ax.triplot(tri, color="#00c8ff", lw=0.8)
        ax.plot(pos[vis, 0], pos[vis, 1], "o", ms=4, mfc="#ffd000", mec="k", mew=0.5)
        if (~vis).any():
            ax.plot(pos[~vis, 0], pos[~vis, 1], "x", ms=7, color="red", mew=2, label="lost")
            ax.legend(loc="upper right", fontsize=8)
        ax.set_title(f"{title}: {int(vis.sum())}/{len(vis)} points tracked")
    fig.savefig(path, dpi=dpi, bbox_inches="tight")


def _limits(values: np.ndarray, min_span: float) -> tuple[float, float]:
    """This frame's range, widened about its middle to at least ``min_span``."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return -0.5 * min_span, 0.5 * min_span
    lo, hi = float(finite.min()), float(finite.max())
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
    return lo, hi


def plot_strain_maps(
    path: str | os.PathLike,
    image: np.ndarray,
    field: StrainField,
    frame: int,
    *,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    limits: dict[str, tuple[float, float]] | None = None,
    min_span: float = 0.01,
    alpha: float = 0.75,
    dpi: int = 120,
) -> None:
    """Save contour maps of nodal strain components on the deformed configuration.

    Parameters
    ----------
    path : path
        Output image (PNG, SVG or PDF by suffix).
    image : (H, W) float
        The frame shown underneath.
    field : StrainField
    frame : int
    components : keyword-only
        Names from :func:`surface_strain.nodal_scalars`.
    limits : dict, keyword-only
        Colour limits per component (default: this frame's range).
    min_span : float, keyword-only
        Smallest colour range, so that a uniform field with tracking noise of
        a few 1e-4 does not fill the whole colour scale.
    """
    scalars = nodal_scalars(field)
    unknown = [c for c in components if c not in scalars]
    if unknown:
        raise ValueError(f"unknown strain component(s) {unknown}; choose from {list(scalars)}")
    pos = field.points[frame]
    valid = field.element_valid[frame]
    fig = Figure(figsize=(5.2 * len(components), 5.0), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(components)))
    for ax, comp in zip(axes, components, strict=True):
        _show_image(ax, image)
        values = scalars[comp][frame]
        good = valid & np.all(np.isfinite(values[field.triangles]), axis=1)
        used = values[np.unique(field.triangles[good])] if good.any() else values[:0]
        lo, hi = (limits or {}).get(comp) or _limits(used, min_span)
        if good.any():
            tri = Triangulation(pos[:, 0], pos[:, 1], field.triangles[good])
            levels = np.linspace(lo, hi, 21)
            cs = ax.tricontourf(
                tri,
                np.nan_to_num(values),
                levels=levels,
                cmap="RdBu_r",
                alpha=alpha,
                extend="both",
            )
            ax.triplot(tri, color="k", lw=0.3, alpha=0.4)
            ticks = MaxNLocator(6).tick_values(lo, hi)
            ticks = ticks[(ticks >= lo - 1e-12) & (ticks <= hi + 1e-12)]
            cbar = fig.colorbar(cs, ax=ax, shrink=0.85, ticks=ticks)
            cbar.set_label(f"{_LABELS.get(comp, comp)} (Green-Lagrange, -)")
        ax.set_title(f"{_LABELS.get(comp, comp)}, frame {frame}")
        ax.set_xlim(-0.5, image.shape[1] - 0.5)
        ax.set_ylim(image.shape[0] - 0.5, -0.5)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")


def plot_strain_errors(
    path: str | os.PathLike,
    image: np.ndarray,
    field: StrainField,
    frame: int,
    errors: np.ndarray,
    *,
    title: str = "",
    dpi: int = 100,
) -> None:
    """Save contour maps of the signed nodal strain error (cf. the source paper's Figs. 5-9).

    Parameters
    ----------
    errors : (N, 2, 2) float
        Measured minus true nodal strain on ``frame``.

    Each panel uses symmetric colour limits and states the component's RMSE.
    """
    pos = field.points[frame]
    valid = field.element_valid[frame]
    fig = Figure(figsize=(15.6, 5.0), layout="constrained")
    axes = fig.subplots(1, 3)
    for ax, (name, (i, j)) in zip(
        axes, (("Exx", (0, 0)), ("Eyy", (1, 1)), ("Exy", (0, 1))), strict=True
    ):
        _show_image(ax, image)
        values = errors[:, i, j]
        good = valid & np.all(np.isfinite(values[field.triangles]), axis=1)
        finite = values[np.isfinite(values)]
        rmse = float(np.sqrt(np.mean(finite**2))) if finite.size else float("nan")
        if good.any():
            bound = max(float(np.abs(finite).max()), 1e-4)
            tri = Triangulation(pos[:, 0], pos[:, 1], field.triangles[good])
            cs = ax.tricontourf(
                tri,
                np.nan_to_num(values),
                levels=np.linspace(-bound, bound, 21),
                cmap="PuOr_r",
                alpha=0.8,
            )
            ax.plot(pos[:, 0], pos[:, 1], ".", ms=2, color="k")
            ticks = MaxNLocator(6, symmetric=True).tick_values(-bound, bound)
            ticks = ticks[np.abs(ticks) <= bound + 1e-15]
            fig.colorbar(cs, ax=ax, shrink=0.85, ticks=ticks, label=f"error in {_LABELS[name]} (-)")
        ax.set_title(f"{_LABELS[name]} error, RMSE {rmse:.2g}")
        ax.set_xlim(-0.5, image.shape[1] - 0.5)
        ax.set_ylim(image.shape[0] - 0.5, -0.5)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
