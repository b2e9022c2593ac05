"""Figures over a video frame: strain contour maps, the tracked grid and strain error maps.

Image axes are in pixels with y pointing down (x = column, y = row, the
centre of the top-left pixel at (0, 0)); with a pixel size (``length``, a
:class:`strain2d.scale.PixelScale`) they are labelled in its unit, at round
values of that unit, with the same origin.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from matplotlib.tri import Triangulation

from strain2d.errors import InputError
from strain2d.figures._checks import _check_2d, _check_image, _frame_index, _scalars
from strain2d.figures._save import save_figure
from strain2d.figures._style import (
    _LABELS,
    _colorbar,
    _colour_scale,
    _frame_limits,
    _label,
    _Scale,
    _unit_label,
    completed_limits,
)
from strain2d.tracks import Tracks
from surface_strain import StrainField

__all__ = [
    "plot_strain_errors",
    "plot_strain_maps",
    "plot_strain_maps_at",
    "plot_tracked_grid",
    "strain_maps_figure",
]


def _length_axes(ax, shape: tuple[int, int], length=None) -> None:
    """Axis labels in px, or in ``length``'s unit at round values (the data stay in px)."""
    if length is None:
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
        return
    from matplotlib.ticker import FixedLocator, FuncFormatter

    per_px, unit = float(length.per_px), length.unit
    for axis, n in ((ax.xaxis, shape[1]), (ax.yaxis, shape[0])):
        lo, hi = -0.5 * per_px, (n - 0.5) * per_px
        ticks = MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]).tick_values(lo, hi)
        ticks = ticks[(ticks >= lo) & (ticks <= hi)]
        axis.set_major_locator(FixedLocator(ticks / per_px))
        axis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v * per_px:.6g}"))
    ax.set_xlabel(f"x ({unit})")
    ax.set_ylabel(f"y ({unit})")


def _show_image(ax, image: np.ndarray, *, vmin=None, vmax=None, length=None):
    # nearest samples coloured after sampling ("data"), not before: the same pixels, without
    # colouring every pixel of a large frame first (three 1080p frames at 150 dpi: 0.08 s
    # against 0.41-0.74 s)
    artist = ax.imshow(
        image,
        cmap="gray",
        interpolation="nearest",
        interpolation_stage="data",
        origin="upper",
        vmin=vmin,
        vmax=vmax,
    )
    _length_axes(ax, image.shape[:2], length)
    ax.set_xlim(-0.5, image.shape[1] - 0.5)
    ax.set_ylim(image.shape[0] - 0.5, -0.5)
    return artist


def _triangulation(field: StrainField, frame: int, values: np.ndarray | None):
    """The valid triangles of ``frame`` (with finite ``values`` at their nodes), or None."""
    good = field.element_valid[frame].copy()
    if values is not None:
        good &= np.all(np.isfinite(values[field.triangles]), axis=1)
    if not good.any():
        return None
    pos = field.points[frame]
    pos = np.where(np.isfinite(pos), pos, 0.0)  # lost nodes belong to no used triangle
    return Triangulation(pos[:, 0], pos[:, 1], field.triangles[good])


def _draw_contours(ax, tri, values: np.ndarray, scale: _Scale, alpha: float):
    return ax.tricontourf(
        tri,
        np.nan_to_num(values),
        levels=scale.levels,
        cmap=scale.cmap,
        norm=scale.norm,
        alpha=alpha,
        extend="both",
    )


def _figsize_for_image(image: np.ndarray, n_panels: int, panel_width: float = 5.2):
    h, w = image.shape[:2]
    return panel_width * n_panels, max(2.5, (panel_width - 1.2) * h / w + 1.0)


def strain_maps_figure(
    image: np.ndarray,
    field: StrainField,
    frame: int,
    *,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    limits: Mapping[str, tuple[float, float]] | None = None,
    min_span: float = 0.01,
    alpha: float = 0.75,
    title: str | None = None,
    length=None,
) -> Figure:
    """Contour maps of nodal strain components on the deformed configuration.

    Parameters
    ----------
    image : (H, W) float or uint8
        The frame shown underneath, in gray.
    field : StrainField
        A 2D field.
    frame : int
        Frame index (negative counts from the end).
    components : sequence of str, keyword-only
        Names from :func:`surface_strain.nodal_scalars`; one panel each.
    limits : dict, keyword-only
        Colour limits per component, e.g. from :func:`strain_limits` so that
        maps at several frames share one scale; components not in it use
        this frame's range.
    min_span : float, keyword-only
        Smallest colour range of a component without given limits.
    alpha : float, keyword-only
        Opacity of the contours over the image.
    title : str, keyword-only
        Figure title above the panels.
    length : PixelScale, keyword-only
        The pixel size: axes in its unit instead of pixels.

    Returns
    -------
    matplotlib.figure.Figure
        One panel per component, each with a labelled colour bar.
    """
    image = _check_image(image)
    _check_2d(field)
    k = _frame_index(field, frame)
    scalars = _scalars(field, components)
    fig = Figure(figsize=_figsize_for_image(image, len(components)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(components)))
    for ax, comp in zip(axes, components, strict=True):
        _show_image(ax, image, length=length)
        values = scalars[comp][k]
        tri = _triangulation(field, k, values)
        used = values[np.unique(tri.triangles)] if tri is not None else values[:0]
        lo, hi = (limits or {}).get(comp) or _frame_limits(used, min_span)
        scale = _colour_scale(comp, float(lo), float(hi))
        if tri is not None:
            _draw_contours(ax, tri, values, scale, alpha)
            ax.triplot(tri, color="k", lw=0.3, alpha=0.4)
        _colorbar(fig, ax, scale, _unit_label(comp), alpha=alpha, shrink=0.85)
        ax.set_title(f"{_label(comp)}, frame {k}")
    if title:
        fig.suptitle(title)
    return fig


def plot_strain_maps(
    path: str | os.PathLike,
    image: np.ndarray,
    field: StrainField,
    frame: int,
    *,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    limits: Mapping[str, tuple[float, float]] | None = None,
    min_span: float = 0.01,
    alpha: float = 0.75,
    dpi: int = 120,
    title: str | None = None,
    formats: str | Sequence[str] | None = None,
) -> list[Path]:
    """Save contour maps of nodal strain components on the deformed configuration.

    The figure of :func:`strain_maps_figure`, cropped to its content.

    Parameters
    ----------
    path : path
        Output image; its suffix gives the format (PNG, SVG, PDF) unless
        ``formats`` is given (see :func:`save_figure`).
    image : (H, W) float
        The frame shown underneath.
    field : StrainField
    frame : int
    components, limits, min_span, alpha, title : keyword-only
        As for :func:`strain_maps_figure`.  Without ``limits`` each component
        uses this frame's range; pass :func:`strain_limits` to share one
        scale between frames.

    Returns
    -------
    list of Path
        The written files.
    """
    fig = strain_maps_figure(
        image,
        field,
        frame,
        components=components,
        limits=limits,
        min_span=min_span,
        alpha=alpha,
        title=title,
    )
    return save_figure(fig, path, formats, dpi=dpi, tight=True)


def plot_strain_maps_at(
    path_stem: str | os.PathLike,
    images: Mapping[int, np.ndarray],
    field: StrainField,
    frames: Sequence[int] | None = None,
    *,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    limits: Mapping[str, tuple[float, float]] | None = None,
    formats: str | Sequence[str] = ("png",),
    dpi: int = 120,
    titles: Mapping[int, str] | None = None,
) -> dict[int, list[Path]]:
    """Save strain maps at several frames on one shared colour scale.

    Parameters
    ----------
    path_stem : path
        Output name without suffix; frame ``k`` is written to
        ``{path_stem}_frame{k:04d}.{format}``, e.g. ``figures/strain`` ->
        ``figures/strain_frame0030.png``.
    images : dict
        ``{frame: (H, W) image}``, the video frame under each map.
    field : StrainField
    frames : sequence of int
        The frames to draw (negative counts from the end); default: the keys
        of ``images``, in increasing order.  Each must have an image.
    components : sequence of str, keyword-only
    limits : dict, keyword-only
        Colour limits per component; default :func:`strain_limits` over
        every frame of the field, so that these maps and an animation of the
        same field share one scale.
    formats : str or sequence of str, keyword-only
        Formats of each map (see :func:`save_figure`).
    titles : dict, keyword-only
        ``{frame: title}``, e.g. the time or "contraction endpoint".

    Returns
    -------
    dict
        ``{frame: [written paths]}`` with frames as non-negative indices.
    """
    if frames is None:
        frames = sorted(images)
    picked = {}
    for f in frames:
        k = _frame_index(field, f, "frames entry")
        if f in images:
            picked[k] = images[f]
        elif k in images:
            picked[k] = images[k]
        else:
            raise InputError(f"no image given for frame {f}; images has frames {sorted(images)}")
    limits = completed_limits(field, components, limits)
    stem = Path(path_stem)
    written = {}
    for k, image in picked.items():
        fig = strain_maps_figure(
            image,
            field,
            k,
            components=components,
            limits=limits,
            title=(titles or {}).get(k),
        )
        written[k] = save_figure(
            fig, stem.with_name(f"{stem.name}_frame{k:04d}"), formats, dpi=dpi, tight=True
        )
    return written


def plot_tracked_grid(
    path: str | os.PathLike,
    first: np.ndarray,
    last: np.ndarray,
    tracks: Tracks,
    triangles: np.ndarray,
    *,
    last_index: int | None = None,
    dpi: int = 120,
    formats: str | Sequence[str] | None = None,
    length=None,
    outline: Sequence[np.ndarray] = (),
) -> list[Path]:
    """Save the tracked grid and mesh over the reference and the last frame.

    Lost points on the last frame are drawn as red crosses.  Returns the
    written files (see :func:`save_figure` for ``path`` and ``formats``).
    ``length`` (a :class:`~strain2d.scale.PixelScale`) labels the axes in its unit;
    ``outline``, polylines ``(K, 2)`` of ``(x, y)`` px (a tissue mask's,
    :meth:`tissue_core.masks.Mask.outline`), is drawn on the reference frame.
    """
    last_index = tracks.n_frames - 1 if last_index is None else last_index
    fig = Figure(figsize=(11, 5.4), layout="constrained")
    axes = fig.subplots(1, 2)
    for ax, image, k, title in (
        (axes[0], first, 0, "frame 0 (reference)"),
        (axes[1], last, last_index, f"frame {last_index}"),
    ):
        _show_image(ax, image, length=length)
        if k == 0:
            for n, line in enumerate(outline):
                line = np.asarray(line, dtype=float)
                ax.plot(line[:, 0], line[:, 1], "--", color="#ff40ff", lw=1.2,
                        label="tissue mask" if n == 0 else None)  # fmt: skip
            if len(outline):
                ax.legend(loc="upper right", fontsize=8)
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
    return save_figure(fig, path, formats, dpi=dpi, tight=True)


def plot_strain_errors(
    path: str | os.PathLike,
    image: np.ndarray,
    field: StrainField,
    frame: int,
    errors: np.ndarray,
    *,
    title: str = "",
    dpi: int = 100,
    formats: str | Sequence[str] | None = None,
) -> list[Path]:
    """Save contour maps of the signed nodal strain error (cf. the source paper's Figs. 5-9).

    Each panel uses symmetric colour limits and states the component's RMSE.

    Parameters
    ----------
    errors : (N, 2, 2) float
        Measured minus true nodal strain on ``frame``.

    Returns
    -------
    list of Path
        The written files (see :func:`save_figure`).
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
    return save_figure(fig, path, formats, dpi=dpi, tight=True)
