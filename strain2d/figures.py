"""Figures of 2D runs and studies: grids, strain maps, crosses, curves, violins, animations.

Per run (the source paper's Figs. 10-15 for one specimen): the tracked grid
(:func:`plot_tracked_grid`), contour maps of strain components on the
deformed configuration (:func:`plot_strain_maps`, :func:`plot_strain_maps_at`),
principal strain directions as crosses (:func:`plot_principal_crosses`), the
mean +/- spatial SD of each component over time (:func:`plot_strain_curves`),
violins of the nodal values at one frame (:func:`plot_strain_violins`) and an
MP4 or GIF of the strain field on the video (:func:`write_strain_animation`).
Per study (several specimens side by side): :func:`plot_study_curves`,
:func:`plot_study_violins` and the specimen-level paired plot
:func:`plot_specimen_means`.

Conventions
-----------
* Built on :class:`matplotlib.figure.Figure` directly, never pyplot, so
  importing or calling this module does not change the global matplotlib
  state or backend.  Functions named ``plot_*`` that take a path save and
  return the written paths; the others return the ``Figure`` and
  :func:`save_figure` writes it in any number of formats (PNG, SVG, PDF).
* Image axes are in pixels with y pointing down, as in the images (x =
  column, y = row, the centre of the top-left pixel at (0, 0)).
* Strain is Green-Lagrange, dimensionless.  Strain colour maps are diverging
  (``RdBu_r``: red = stretch, blue = shortening) with zero white: the colour
  of a value depends only on its sign and magnitude relative to the larger
  end of the range, so a range that does not reach zero uses one half of the
  map only, and a range such as (-0.3, 0.01) gives a barely pink top instead
  of a white middle at -0.15.
* :func:`strain_limits` gives colour limits shared by every frame, so maps at
  different frames and the animation can be compared by eye.
"""

from __future__ import annotations

import math
import operator
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Literal, NamedTuple

import numpy as np
from matplotlib import colormaps, rc_context
from matplotlib.cm import ScalarMappable
from matplotlib.collections import LineCollection
from matplotlib.colors import Colormap, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator
from matplotlib.tri import Triangulation

from strain2d.errors import InputError
from strain2d.tracks import Tracks
from surface_strain import (
    StrainField,
    element_principal_directions,
    element_scalars,
    nodal_principal_directions,
    nodal_scalars,
)
from tissue_core.outputs import replaced_on_success

__all__ = [
    "format_p",
    "mean_strain_curves",
    "plot_principal_crosses",
    "plot_specimen_means",
    "plot_strain_curves",
    "plot_strain_errors",
    "plot_strain_maps",
    "plot_strain_maps_at",
    "plot_strain_violins",
    "plot_study_curves",
    "plot_study_violins",
    "plot_tracked_grid",
    "save_figure",
    "strain_limits",
    "strain_maps_figure",
    "write_strain_animation",
]

_LABELS = {
    "Exx": r"$E_{xx}$",
    "Eyy": r"$E_{yy}$",
    "Exy": r"$E_{xy}$",
    "E1": r"$E_1$",
    "E2": r"$E_2$",
    "max_shear": r"$(E_1 - E_2)/2$",
    "theta1_deg": r"$\theta_1$",
    "J": r"$J$",
}

#: Colours of the components in curves and violins (Paul Tol's "vibrant", colour-blind safe).
_COLOURS = {
    "Exx": "#0077BB",
    "Eyy": "#EE7733",
    "Exy": "#009988",
    "E1": "#CC3311",
    "E2": "#33BBEE",
    "max_shear": "#EE3377",
    "J": "#555555",
    "theta1_deg": "#BBBBBB",
}
_STRETCH = "#b2182b"  # the red and blue ends of RdBu_r
_SHORTENING = "#2166ac"
_STRAIN_AXIS = "Green-Lagrange strain (-)"


def _label(comp: str) -> str:
    return _LABELS.get(comp, comp)


def _colour(comp: str, i: int) -> str:
    return _COLOURS.get(comp, f"C{i % 10}")


def _unit_label(comp: str) -> str:
    """Colour bar and axis label of a component, with its unit."""
    if comp == "J":
        return f"{_label(comp)} (area ratio, -)"
    if comp == "theta1_deg":
        return f"{_label(comp)}, direction of $E_1$ (deg)"
    return f"{_label(comp)} ({_STRAIN_AXIS})"


# --------------------------------------------------------------------------- saving


def save_figure(
    fig: Figure,
    path: str | os.PathLike,
    formats: str | Sequence[str] | None = None,
    *,
    dpi: float = 150,
    tight: bool = False,
) -> list[Path]:
    """Write a figure in one or more formats.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : path
        Output path, with or without a suffix.  A suffix that names an image
        format matplotlib writes (``.png``, ``.svg``, ``.pdf``, ...) is
        replaced by each of ``formats``; any other suffix is kept as part of
        the name (``run.v2`` -> ``run.v2.png``).
    formats : str or sequence of str, optional
        Formats to write, e.g. ``("png", "svg", "pdf")``.  Default: the
        suffix of ``path``, or PNG when it has none.
    dpi : float, keyword-only
        Resolution of raster formats; the image is ``figsize * dpi`` pixels
        unless ``tight``.
    tight : bool, keyword-only
        Crop to the drawn content (``bbox_inches="tight"``), which makes the
        pixel size depend on the content.

    Returns
    -------
    list of Path
        The written files, in the order of ``formats``.

    Each file is written under a temporary name and renamed when complete,
    so an interrupted call leaves no half-written figure.  SVG and PDF files
    carry no creation date, so the same figure gives the same bytes.
    """
    path = Path(path)
    supported = fig.canvas.get_supported_filetypes()
    suffix = path.suffix.lower().lstrip(".")
    stem = path.with_suffix("") if suffix in supported else path
    if formats is None:
        formats = (suffix,) if suffix in supported else ("png",)
    elif isinstance(formats, str):
        formats = (formats,)
    wanted = [str(f).lower().lstrip(".") for f in formats]
    if not wanted:
        raise InputError("formats is empty; give at least one, e.g. ('png',)")
    unknown = [f for f in wanted if f not in supported]
    if unknown:
        raise InputError(
            f"unknown figure format(s) {unknown}; choose from {', '.join(sorted(supported))}"
        )
    written = []
    for fmt in dict.fromkeys(wanted):
        out = stem.with_name(f"{stem.name}.{fmt}")
        metadata = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}.get(fmt)
        # a fixed salt makes SVG element ids, hence the file, reproducible
        with replaced_on_success(out) as tmp, rc_context({"svg.hashsalt": "strain2d"}):
            fig.savefig(
                tmp, format=fmt, dpi=dpi, bbox_inches="tight" if tight else None, metadata=metadata
            )
        written.append(out)
    return written


# --------------------------------------------------------------------------- checks


def _frame_index(field: StrainField, frame, name: str = "frame") -> int:
    T = field.n_frames
    try:
        k = operator.index(frame)
    except TypeError:
        raise InputError(f"{name} must be an integer frame index, got {frame!r}") from None
    if not -T <= k < T:
        raise InputError(f"{name} {k} is out of range for a field of {T} frames")
    return k % T


def _check_2d(field: StrainField) -> None:
    if field.points.shape[2] != 2:
        raise InputError(
            f"this figure draws 2D fields over images; the field has "
            f"{field.points.shape[2]}D points (see surface_strain.figures for 3D)"
        )


def _scalars(field: StrainField, components: Sequence[str]) -> dict[str, np.ndarray]:
    if isinstance(components, str):
        components = (components,)
    if len(components) == 0:
        raise InputError("components is empty; name at least one, e.g. ('Exx', 'Eyy')")
    scalars = nodal_scalars(field)
    unknown = [c for c in components if c not in scalars]
    if unknown:
        raise InputError(f"unknown strain component(s) {unknown}; choose from {list(scalars)}")
    return scalars


def _finite(values) -> np.ndarray:
    a = np.asarray(values, dtype=float).ravel()
    return a[np.isfinite(a)]


# --------------------------------------------------------------------------- colour scales


def strain_limits(
    field: StrainField,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    *,
    frames: Sequence[int] | None = None,
    min_span: float = 0.01,
    symmetric: bool = False,
    percentile: float = 0.5,
) -> dict[str, tuple[float, float]]:
    """Colour limits per component, shared by all frames.

    Parameters
    ----------
    field : StrainField
    components : sequence of str
        Names from :func:`surface_strain.nodal_scalars`.
    frames : sequence of int, keyword-only
        Frames whose nodal values set the limits (default: all frames).
    min_span : float, keyword-only
        Smallest range, widened about its middle, so that a uniform field
        with tracking noise of a few 1e-4 does not fill the whole colour scale.
    symmetric : bool, keyword-only
        Limits ``(-m, m)`` with ``m`` the larger magnitude of the two ends.
    percentile : float, keyword-only
        Percentage of the values left out at each end: the limits are the
        ``percentile`` and ``100 - percentile`` percentiles of the finite
        nodal values over the frames.  The default 0.5 keeps a spike of one
        node on a few frames (a tracking glitch) from washing out every map;
        values beyond the limits are drawn in the end colours and the colour
        bar shows arrows.  0 gives the full range.  A node that is wrong on
        every frame is more than 0.5 % of the values of a 7x7 grid; raise
        ``percentile`` (e.g. 2.5) or mask the node instead.

    Returns
    -------
    dict
        ``{component: (low, high)}`` as floats; ``(-min_span/2, min_span/2)``
        for a component without finite values.

    Examples
    --------
    >>> import numpy as np
    >>> from surface_strain import compute_strain, grid_triangles
    >>> X = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2)
    >>> f = compute_strain(X, np.stack([X, X * [1.0, 0.8]]), grid_triangles(3, 3))
    >>> strain_limits(f, ["Eyy"], percentile=0)
    {'Eyy': (-0.18, 0.0)}
    """
    if not (np.isfinite(min_span) and min_span >= 0):
        raise InputError(f"min_span must be a non-negative number, got {min_span}")
    if not 0 <= percentile < 50:
        raise InputError(f"percentile must be in [0, 50), got {percentile}")
    scalars = _scalars(field, components)
    if frames is None:
        idx = np.arange(field.n_frames)
    else:
        idx = np.array([_frame_index(field, f, "frames entry") for f in frames], dtype=int)
        if idx.size == 0:
            raise InputError("frames is empty; leave it out to use every frame")
    out = {}
    for comp in components:
        finite = _finite(scalars[comp][idx])
        if finite.size == 0:
            lo = hi = 0.0
        elif percentile > 0:
            lo, hi = (float(v) for v in np.percentile(finite, [percentile, 100 - percentile]))
        else:
            lo, hi = float(finite.min()), float(finite.max())
        if symmetric:
            m = max(abs(lo), abs(hi), 0.5 * min_span)
            lo, hi = -m, m
        elif hi - lo < min_span:
            mid = 0.5 * (lo + hi)
            lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
        out[comp] = (round(lo, 12) + 0.0, round(hi, 12) + 0.0)
    return out


def _frame_limits(values: np.ndarray, min_span: float) -> tuple[float, float]:
    """One frame's full range, widened about its middle to at least ``min_span``."""
    finite = _finite(values)
    if finite.size == 0:
        return -0.5 * min_span, 0.5 * min_span
    lo, hi = float(finite.min()), float(finite.max())
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
    return lo, hi


class _Scale(NamedTuple):
    """A discrete colour scale: ``cmap`` has one colour per band between ``levels``."""

    cmap: Colormap
    norm: Normalize
    levels: np.ndarray


def _colour_scale(comp: str, lo: float, hi: float, n: int = 20) -> _Scale:
    """Colour scale of a component over ``[lo, hi]`` in ``n`` bands.

    Strain components use ``RdBu_r`` with zero white (``J``: one white); the
    part of the map used is the part ``[lo, hi]`` covers when the map spans
    ``[-m, m]`` about the centre, ``m`` the larger distance of an end from
    it.  ``theta1_deg`` uses the cyclic ``twilight_shifted``.
    """
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise InputError(f"colour limits of {comp} must be finite with low < high, got {(lo, hi)}")
    levels = np.linspace(lo, hi, n + 1)
    mids = 0.5 * (levels[:-1] + levels[1:])
    step = (hi - lo) / n
    if comp == "theta1_deg":
        base = colormaps["twilight_shifted"]
        pos = (np.concatenate([[lo - step / 2], mids, [hi + step / 2]]) - lo) / (hi - lo)
    else:
        base = colormaps["RdBu_r"]
        centre = 1.0 if comp == "J" else 0.0
        m = max(abs(lo - centre), abs(hi - centre))
        pos = 0.5 + (np.concatenate([[lo - step / 2], mids, [hi + step / 2]]) - centre) / (2 * m)
    colours = base(np.clip(pos, 0.0, 1.0))
    cmap = ListedColormap(colours[1:-1], name=f"{comp}_scale")
    cmap = cmap.with_extremes(under=colours[0], over=colours[-1])
    return _Scale(cmap, Normalize(lo, hi), levels)


def _colorbar(fig: Figure, ax, scale: _Scale, label: str, *, alpha: float = 1.0, **kwargs):
    lo, hi = scale.levels[0], scale.levels[-1]
    ticks = MaxNLocator(6).tick_values(lo, hi)
    ticks = ticks[(ticks >= lo - 1e-12 * (hi - lo)) & (ticks <= hi + 1e-12 * (hi - lo))]
    sm = ScalarMappable(norm=scale.norm, cmap=scale.cmap)
    cbar = fig.colorbar(sm, ax=ax, ticks=ticks, extend="both", alpha=alpha, **kwargs)
    cbar.set_label(label)
    return cbar


# --------------------------------------------------------------------------- images and maps


def _show_image(ax, image: np.ndarray, *, vmin=None, vmax=None):
    artist = ax.imshow(
        image, cmap="gray", interpolation="nearest", origin="upper", vmin=vmin, vmax=vmax
    )
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    ax.set_xlim(-0.5, image.shape[1] - 0.5)
    ax.set_ylim(image.shape[0] - 0.5, -0.5)
    return artist


def _gray_range(image: np.ndarray) -> tuple[float, float]:
    if image.dtype == np.uint8:
        return 0.0, 255.0
    finite = _finite(image)
    if finite.size == 0 or finite.max() == finite.min():
        return 0.0, 1.0
    return float(finite.min()), float(finite.max())


def _check_image(image, name: str = "image") -> np.ndarray:
    a = np.asarray(image)
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)) or 0 in a.shape:
        raise InputError(f"{name} must be a (H, W) gray or (H, W, 3) colour image, got {a.shape}")
    return a


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
        _show_image(ax, image)
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
    if limits is None:
        limits = strain_limits(field, components)
    else:
        missing = [c for c in components if c not in limits]
        limits = {**strain_limits(field, missing), **limits} if missing else limits
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
) -> list[Path]:
    """Save the tracked grid and mesh over the reference and the last frame.

    Lost points on the last frame are drawn as red crosses.  Returns the
    written files (see :func:`save_figure` for ``path`` and ``formats``).
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

    Parameters
    ----------
    errors : (N, 2, 2) float
        Measured minus true nodal strain on ``frame``.

    Each panel uses symmetric colour limits and states the component's RMSE.
    Returns the written files (see :func:`save_figure`).
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


# --------------------------------------------------------------------------- principal crosses


def _nice_value(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above ``x`` (``x > 0``)."""
    e = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**e <= x * (1 + 1e-9):
            return float(f"{m * 10.0**e:.12g}")
    return float(f"{10.0**e:.12g}")


def _node_spacing(field: StrainField, frame: int) -> float:
    """Median over nodes of the shortest valid mesh edge at each node, on ``frame``."""
    tri = field.triangles[field.element_valid[frame]]
    if len(tri) == 0:
        return float("nan")
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    pos = field.points[frame]
    length = np.linalg.norm(pos[edges[:, 0]] - pos[edges[:, 1]], axis=1)
    shortest = np.full(field.n_points, np.inf)
    np.minimum.at(shortest, edges[:, 0], length)
    np.minimum.at(shortest, edges[:, 1], length)
    shortest = shortest[np.isfinite(shortest) & (shortest > 0)]
    return float(np.median(shortest)) if shortest.size else float("nan")


def plot_principal_crosses(
    image: np.ndarray,
    field: StrainField,
    frame: int,
    *,
    scale: float | None = None,
    at: Literal["nodes", "triangles"] = "nodes",
    key_value: float | None = None,
    title: str | None = None,
) -> Figure:
    """Principal strain directions as crosses over the image, on the deformed configuration.

    At each node (or triangle centroid) a cross of two bars centred on it:
    one along the first principal direction and one along the second, as
    directions in the current configuration (the material fibres along the
    reference principal directions after deformation, which stay
    orthogonal).  Each bar's length is ``scale * |E|`` of its principal
    strain, red for stretch (E > 0) and blue for shortening (E < 0).

    Parameters
    ----------
    image : (H, W) float or uint8
        The frame shown underneath.
    field : StrainField
        A 2D field.
    frame : int
    scale : float, keyword-only
        Bar length in pixels per unit strain.  Default: the longest bar is
        0.8 times the typical node spacing (the median over nodes of the
        shortest mesh edge), i.e. each arm from the centre is 0.4 of it.
    at : {"nodes", "triangles"}, keyword-only
        Nodal principal strains (:func:`surface_strain.nodal_scalars`,
        directions from :func:`surface_strain.nodal_principal_directions`)
        at the nodes, or the constant strain of each triangle at its centroid.
    key_value : float, keyword-only
        Strain of the key's bar (default: a round value, 1, 2 or 5 times a
        power of ten, not above the largest |E| drawn).
    title : str, keyword-only

    Returns
    -------
    matplotlib.figure.Figure
        The bars are two :class:`~matplotlib.collections.LineCollection`
        artists with ``gid`` ``"E1"`` and ``"E2"`` (one segment per drawn
        point, in the same order); points without finite values are skipped.
    """
    from matplotlib.patheffects import withStroke
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    image = _check_image(image)
    _check_2d(field)
    k = _frame_index(field, frame)
    if at not in ("nodes", "triangles"):
        raise InputError(f"at must be 'nodes' or 'triangles', got {at!r}")
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        raise InputError(f"scale must be a positive number of pixels per unit strain, got {scale}")
    if key_value is not None and not (np.isfinite(key_value) and key_value > 0):
        raise InputError(f"key_value must be a positive strain, got {key_value}")
    if at == "nodes":
        s = nodal_scalars(field)
        d = nodal_principal_directions(field)
        centres = field.points[k]
        ok = field.visible[k].copy()
    else:
        s = element_scalars(field)
        d = element_principal_directions(field)
        centres = field.points[k][field.triangles].mean(axis=1)
        ok = field.element_valid[k].copy()
    e1, e2 = s["E1"][k], s["E2"][k]
    u1, u2 = d.dir1_cur[k], d.dir2_cur[k]
    ok &= np.isfinite(e1) & np.isfinite(e2) & np.all(np.isfinite(centres), axis=1)
    ok &= np.all(np.isfinite(u1), axis=1) & np.all(np.isfinite(u2), axis=1)
    c, e1, e2, u1, u2 = centres[ok], e1[ok], e2[ok], u1[ok], u2[ok]
    largest = float(max(np.abs(e1).max(initial=0.0), np.abs(e2).max(initial=0.0)))
    if scale is None:
        spacing = _node_spacing(field, k)
        if not np.isfinite(spacing):
            spacing = 0.1 * min(image.shape[:2])
        scale = 0.8 * spacing / largest if largest > 0 else 0.0

    fig = Figure(figsize=_figsize_for_image(image, 1, 6.4), layout="constrained")
    ax = fig.add_subplot()
    _show_image(ax, image)
    outline = [withStroke(linewidth=3.2, foreground="white")]
    for gid, e, u in (("E1", e1, u1), ("E2", e2, u2)):
        half = (0.5 * scale * np.abs(e))[:, None] * u
        segments = np.stack([c - half, c + half], axis=1)
        colours = np.where(e >= 0, _STRETCH, _SHORTENING)
        lc = LineCollection(segments, colors=colours, linewidths=1.8, capstyle="round")
        lc.set_gid(gid)
        lc.set_path_effects(outline)
        ax.add_collection(lc, autolim=False)
    handles = [
        Line2D([], [], color=_STRETCH, lw=2, label="stretch (E > 0)"),
        Line2D([], [], color=_SHORTENING, lw=2, label="shortening (E < 0)"),
    ]
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.85)
    if scale > 0 and largest > 0:
        value = _nice_value(largest) if key_value is None else float(key_value)
        bar = AnchoredSizeBar(
            ax.transData,
            scale * value,
            f"|E| = {value:g}",
            loc="lower right",
            color="k",
            frameon=True,
            size_vertical=0,
            pad=0.4,
            sep=4,
            fontproperties={"size": 8},
        )
        bar.patch.set_alpha(0.85)
        ax.add_artist(bar)
    where = "nodes" if at == "nodes" else "triangles"
    ax.set_title(title or f"principal strains at the {where}, frame {k}")
    return fig


# --------------------------------------------------------------------------- curves


def mean_strain_curves(
    field: StrainField, components: Sequence[str] = ("Exx", "Eyy", "Exy")
) -> dict[str, dict[str, np.ndarray]]:
    """Mean and spatial SD of nodal strain components over the nodes, per frame.

    Returns
    -------
    dict
        ``{"mean": {comp: (T,)}, "sd": {comp: (T,)}, "n": {comp: (T,) int}}``:
        the mean over the nodes with a finite value, their standard deviation
        (``ddof=0``, the spread of this field, not an estimate for a
        population) and how many nodes entered; NaN on frames without any.
        The ``mean`` and ``sd`` entries are what :func:`plot_study_curves`
        takes per specimen.
    """
    scalars = _scalars(field, components)
    out: dict[str, dict[str, np.ndarray]] = {"mean": {}, "sd": {}, "n": {}}
    for comp in components:
        v = scalars[comp]
        ok = np.isfinite(v)
        n = ok.sum(axis=1)
        filled = np.where(ok, v, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = filled.sum(axis=1) / n
            sd = np.sqrt(np.where(ok, (filled - mean[:, None]) ** 2, 0.0).sum(axis=1) / n)
        out["mean"][comp] = np.where(n > 0, mean, np.nan)
        out["sd"][comp] = np.where(n > 0, sd, np.nan)
        out["n"][comp] = n
    return out


def _time_label(time_unit: str) -> str:
    if not isinstance(time_unit, str) or not time_unit:
        raise InputError(f"time_unit must be 'frame' or a unit such as 's', got {time_unit!r}")
    return "frame" if time_unit == "frame" else f"time ({time_unit})"


def _endpoint_text(x: float, time_unit: str) -> str:
    if time_unit == "frame":
        return f"endpoint (frame {x:g})"
    return f"endpoint ({x:.3g} {time_unit})"


def _draw_curves(ax, times, mean, sd, components, endpoint_x, time_unit, *, legend=True):
    for i, comp in enumerate(components):
        if comp not in mean:
            raise InputError(f"no mean curve for component {comp!r}; have {sorted(mean)}")
        m = np.asarray(mean[comp], dtype=float)
        if m.shape != times.shape:
            raise InputError(
                f"the mean curve of {comp} has shape {m.shape}, the times {times.shape}"
            )
        colour = _colour(comp, i)
        ax.plot(times, m, color=colour, lw=1.6, label=f"{_label(comp)} mean")
        if sd is not None and comp in sd:
            s = np.asarray(sd[comp], dtype=float)
            if s.shape != times.shape:
                raise InputError(
                    f"the SD curve of {comp} has shape {s.shape}, the times {times.shape}"
                )
            ax.fill_between(
                times, m - s, m + s, color=colour, alpha=0.2, lw=0, label=f"{_label(comp)} ± SD"
            )
    ax.axhline(0, color="k", lw=0.6)
    if endpoint_x is not None:
        ax.axvline(endpoint_x, color="0.3", ls="--", lw=1)
        ax.annotate(
            _endpoint_text(endpoint_x, time_unit),
            xy=(endpoint_x, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(-3, -3),
            textcoords="offset points",
            ha="right",
            va="top",
            fontsize=8,
            color="0.2",
        )
    ax.set_xlabel(_time_label(time_unit))
    ax.set_ylabel(_STRAIN_AXIS)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=8, loc="best", ncols=2)


def plot_strain_curves(
    field: StrainField,
    *,
    times: Sequence[float] | np.ndarray | None = None,
    time_unit: str = "frame",
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    endpoint: int | None = None,
    title: str = "",
) -> Figure:
    """Mean nodal strain over time with a band of +/- one spatial SD (the paper's Fig. 14).

    Parameters
    ----------
    field : StrainField
    times : (T,) float, keyword-only
        Time of each frame in ``time_unit`` (default: the frame indices).
    time_unit : str, keyword-only
        ``"frame"`` or a unit of ``times`` such as ``"s"``; labels the x axis.
    components : sequence of str, keyword-only
    endpoint : int, keyword-only
        Frame index of the contraction endpoint
        (:func:`strain2d.stats.contraction_endpoint`), marked by a dashed line.
    title : str, keyword-only

    Returns
    -------
    matplotlib.figure.Figure
    """
    stats = mean_strain_curves(field, components)
    T = field.n_frames
    t = np.arange(T, dtype=float) if times is None else np.asarray(times, dtype=float)
    if t.shape != (T,):
        raise InputError(f"times must have one value per frame, shape ({T},), got {t.shape}")
    x_end = None if endpoint is None else float(t[_frame_index(field, endpoint, "endpoint")])
    fig = Figure(figsize=(7.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    _draw_curves(ax, t, stats["mean"], stats["sd"], components, x_end, time_unit)
    if title:
        ax.set_title(title)
    return fig


def _group_order(items: Sequence[Mapping]) -> list[int]:
    """Indices of ``items`` with equal ``group`` adjacent, groups in order of appearance."""
    groups = list(dict.fromkeys(str(it.get("group") or "") for it in items))
    return sorted(range(len(items)), key=lambda i: groups.index(str(items[i].get("group") or "")))


def _name(item: Mapping, i: int) -> str:
    name = str(item.get("name", f"specimen {i + 1}"))
    group = item.get("group")
    return f"{name} ({group})" if group else name


def plot_study_curves(
    curves: Sequence[Mapping],
    *,
    time_unit: str = "frame",
    components: Sequence[str] = ("Exx", "Eyy"),
    ncols: int | None = None,
) -> Figure:
    """Mean +/- spatial SD over time for every specimen, one panel each (the paper's Fig. 14).

    Parameters
    ----------
    curves : sequence of dict
        One per specimen: ``"name"``, optional ``"group"``, ``"times"`` (T,),
        ``"mean"`` ``{comp: (T,)}``, optional ``"sd"`` ``{comp: (T,)}`` (e.g.
        from :func:`mean_strain_curves`), optional ``"endpoint"``: an int is a
        frame index into ``times``, a float a time.
    time_unit : str, keyword-only
        ``"frame"`` or the unit of ``times``.
    components : sequence of str, keyword-only
    ncols : int, keyword-only
        Panels per row (default: up to 4).

    Returns
    -------
    matplotlib.figure.Figure
        Panels share the strain axis; specimens of a group are adjacent.
    """
    if len(curves) == 0:
        raise InputError("curves is empty; give at least one specimen")
    n = len(curves)
    ncols = min(n, 4) if ncols is None else int(ncols)
    if ncols < 1:
        raise InputError(f"ncols must be at least 1, got {ncols}")
    nrows = math.ceil(n / ncols)
    fig = Figure(figsize=(3.4 * ncols + 0.6, 2.8 * nrows + 0.7), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharey=True, squeeze=False)).ravel()
    for ax, i in zip(axes, _group_order(curves), strict=False):
        c = curves[i]
        if "times" not in c or "mean" not in c:
            raise InputError(f"curves[{i}] needs 'times' and 'mean'")
        t = np.asarray(c["times"], dtype=float)
        if t.ndim != 1:
            raise InputError(f"curves[{i}]['times'] must be (T,), got shape {t.shape}")
        end = c.get("endpoint")
        if end is None:
            x_end = None
        elif isinstance(end, (int, np.integer)) and not isinstance(end, bool):
            if not -len(t) <= end < len(t):
                raise InputError(f"curves[{i}]['endpoint'] {end} is out of range of its times")
            x_end = float(t[end])
        else:
            x_end = float(end)
        _draw_curves(ax, t, c["mean"], c.get("sd"), components, x_end, time_unit, legend=False)
        ax.set_title(_name(c, i), fontsize=10)
        ax.tick_params(labelleft=True)
    for ax in axes[n:]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncols=2 * len(components), fontsize=8)
    return fig


# --------------------------------------------------------------------------- violins


def format_p(p: float | None) -> str:
    """A p-value as a figure or report shows it.

    Examples
    --------
    >>> format_p(2e-5), format_p(0.0042), format_p(0.0496), format_p(0.31)
    ('p < 0.001', 'p = 0.004', 'p = 0.050', 'p = 0.31')
    """
    if p is None or not np.isfinite(p):
        return "p = n/a"
    if p < 0.001:
        return "p < 0.001"
    if p < 0.1:
        return f"p = {p:.3f}"
    return f"p = {p:.2f}"


def _draw_violins(ax, positions, arrays, colours, *, width=0.7, rng=None, point_size=6.0):
    """Violins with the nodes as jittered points, a median bar and the quartiles."""
    rng = np.random.default_rng(0) if rng is None else rng
    for x, data, colour in zip(positions, arrays, colours, strict=True):
        if data.size == 0:
            continue
        if data.size >= 2 and np.ptp(data) > 1e-12 * max(1.0, float(np.abs(data).max())):
            parts = ax.violinplot(
                [data], positions=[x], widths=width, showextrema=False, showmedians=False
            )
            for body in parts["bodies"]:
                body.set_facecolor(colour)
                body.set_edgecolor(colour)
                body.set_alpha(0.35)
        jitter = rng.uniform(-0.18, 0.18, data.size) * width
        ax.scatter(
            x + jitter,
            data,
            s=point_size,
            color=colour,
            edgecolors="k",
            linewidths=0.3,
            alpha=0.8,
            zorder=3,
        )
        q1, med, q3 = np.percentile(data, [25, 50, 75])
        ax.vlines(x, q1, q3, color="k", lw=2.5, zorder=4)
        ax.hlines(med, x - 0.25 * width, x + 0.25 * width, color="k", lw=2, zorder=4)


def _bracket(ax, x0: float, x1: float, y: float, height: float, text: str, *, fontsize=8):
    ax.plot([x0, x0, x1, x1], [y, y + height, y + height, y], color="k", lw=0.9)
    ax.text(0.5 * (x0 + x1), y + 1.4 * height, text, ha="center", va="bottom", fontsize=fontsize)


def _test_lines(tests: Mapping, *, short: bool = False) -> str:
    label = tests.get("label", "paired t-test")
    n = tests.get("n")
    lines = []
    if "t_p" in tests:
        lines.append(f"{'t' if short else label}: {format_p(tests['t_p'])}")
    if "wilcoxon_p" in tests:
        lines.append(f"{'W' if short else 'Wilcoxon signed-rank'}: {format_p(tests['wilcoxon_p'])}")
    if n is not None and not short:
        lines.append(f"n = {n} nodes")
    return "\n".join(lines)


def _values(values: Mapping[str, np.ndarray], where: str) -> dict[str, np.ndarray]:
    if len(values) == 0:
        raise InputError(f"{where} is empty; give at least one component")
    return {str(k): _finite(v) for k, v in values.items()}


def plot_strain_violins(
    values: Mapping[str, np.ndarray],
    *,
    title: str = "",
    tests: Mapping | None = None,
) -> Figure:
    """Violins of nodal strain components at one frame (the paper's Fig. 15 for one specimen).

    Parameters
    ----------
    values : dict
        ``{component: (N,) nodal values}``, e.g. ``{"Exx": ..., "Eyy": ...}``
        at the contraction endpoint; NaN are left out.
    title : str, keyword-only
    tests : dict, keyword-only
        A paired comparison of the first two components, e.g. from
        :func:`strain2d.stats.paired_node_tests` with a ``"label"`` added:
        ``"t_p"``, ``"wilcoxon_p"``, ``"n"``, ``"label"`` (e.g.
        "node-level paired t-test"), each optional.  Drawn as a bracket
        annotated with the p-values.

    Returns
    -------
    matplotlib.figure.Figure
        Each component as a violin with every node as a (jittered) point,
        the median as a bar and the quartiles as a thick line.
    """
    data = _values(values, "values")
    comps = list(data)
    fig = Figure(figsize=(1.6 * len(comps) + 2.2, 4.4), layout="constrained")
    ax = fig.add_subplot()
    positions = np.arange(len(comps), dtype=float)
    _draw_violins(ax, positions, list(data.values()), [_colour(c, i) for i, c in enumerate(comps)])
    ax.set_xticks(positions, [_label(c) for c in comps])
    ax.set_xlim(-0.6, len(comps) - 0.4)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("component")
    ax.set_ylabel(_STRAIN_AXIS)
    ax.grid(alpha=0.3, axis="y")
    every = np.concatenate([*data.values(), [np.nan]])
    if tests and len(comps) >= 2 and np.isfinite(every).any():
        lo, hi = float(np.nanmin(every)), float(np.nanmax(every))
        span = max(hi - lo, 1e-3)
        _bracket(ax, 0, 1, hi + 0.06 * span, 0.03 * span, _test_lines(tests))
        ax.set_ylim(lo - 0.06 * span, hi + 0.4 * span)
    if title:
        ax.set_title(title)
    return fig


def _group_label(ax, group: str, x: float, offset_pt: float) -> None:
    """A group's name in bold under the x axis, centred at data ``x``."""
    ax.annotate(
        group,
        xy=(x, 0),
        xycoords=("data", "axes fraction"),
        xytext=(0, offset_pt),
        textcoords="offset points",
        ha="center",
        va="top",
        fontsize=10,
        fontweight="bold",
    )


def plot_study_violins(
    specimens: Sequence[Mapping],
    *,
    components: Sequence[str] = ("Exx", "Eyy"),
) -> Figure:
    """Violins of every specimen side by side (the paper's Fig. 15).

    Parameters
    ----------
    specimens : sequence of dict
        One per specimen: ``"name"``, optional ``"group"``, ``"values"``
        ``{component: (N,)}``, optional ``"tests"`` (as for
        :func:`plot_strain_violins`): the p-value of the node-level paired
        test between the first two components is written above each specimen.
    components : sequence of str, keyword-only

    Returns
    -------
    matplotlib.figure.Figure
        The components of a specimen are adjacent and coloured alike across
        specimens; specimens of a group are adjacent, the group named under
        its specimens.
    """
    if len(specimens) == 0:
        raise InputError("specimens is empty; give at least one")
    comps = list(components)
    order = _group_order(specimens)
    k = len(comps)
    step = 0.8
    positions, centres, group_spans = [], [], {}
    x = 0.0
    previous = None
    for i in order:
        group = str(specimens[i].get("group") or "")
        if previous is not None and group != previous:
            x += 0.8 * step  # a wider gap between groups
        previous = group
        xs = x + step * np.arange(k)
        positions.append(xs)
        centres.append(float(xs.mean()))
        lo_hi = group_spans.setdefault(group, [xs[0], xs[-1]])
        lo_hi[1] = xs[-1]
        x = xs[-1] + 1.6 * step
    fig = Figure(figsize=(max(4.5, 0.75 * k * len(order) + 2.0), 4.8), layout="constrained")
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)
    tops, bottoms = [], []
    per_specimen = []
    for xs, i in zip(positions, order, strict=True):
        spec = specimens[i]
        vals = spec.get("values")
        if not isinstance(vals, Mapping):
            raise InputError(f"specimens[{i}] needs 'values', a dict of component -> (N,)")
        missing = [c for c in comps if c not in vals]
        if missing:
            raise InputError(f"specimens[{i}] ({spec.get('name')}) has no values for {missing}")
        arrays = [_finite(vals[c]) for c in comps]
        _draw_violins(
            ax,
            xs,
            arrays,
            [_colour(c, j) for j, c in enumerate(comps)],
            width=0.7 * step,
            rng=rng,
            point_size=4.0,
        )
        present = [a for a in arrays if a.size]
        top = max((float(a.max()) for a in present), default=np.nan)
        tops.append(top)
        bottoms.append(min((float(a.min()) for a in present), default=np.nan))
        per_specimen.append((xs, top, spec.get("tests")))
    lo, hi = float(np.nanmin([*bottoms, np.inf])), float(np.nanmax([*tops, -np.inf]))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        lo, hi = -0.01, 0.01
    span = max(hi - lo, 1e-3)
    labels = set()
    for xs, top, tests in per_specimen:
        if tests and k >= 2 and "t_p" in tests and np.isfinite(top):
            _bracket(
                ax,
                xs[0],
                xs[1],
                top + 0.05 * span,
                0.025 * span,
                format_p(tests["t_p"]),
                fontsize=7,
            )
            labels.add(str(tests.get("label", "paired t-test")))
    ax.set_ylim(lo - 0.06 * span, hi + 0.3 * span)
    ax.set_xticks(centres, [str(specimens[i].get("name", f"specimen {i + 1}")) for i in order])
    ax.tick_params(axis="x", length=0)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_ylabel(_STRAIN_AXIS)
    ax.grid(alpha=0.3, axis="y")
    ax.set_xlim(positions[0][0] - step, positions[-1][-1] + step)
    if any(g for g in group_spans):
        for group, (g0, g1) in group_spans.items():
            _group_label(ax, group, 0.5 * (g0 + g1), -26)
        ax.set_xlabel("specimen (group)", labelpad=20)
    else:
        ax.set_xlabel("specimen")
    handles = [
        Line2D([], [], marker="s", ls="", ms=9, color=_colour(c, j), alpha=0.6, label=_label(c))
        for j, c in enumerate(comps)
    ]
    ax.legend(handles=handles, loc="lower left", fontsize=8, ncols=k)
    if labels:
        ax.set_title(
            f"p-values: {'; '.join(sorted(labels))} of {_label(comps[0])} vs {_label(comps[1])}",
            fontsize=9,
        )
    return fig


def plot_specimen_means(
    table: Sequence[Mapping],
    *,
    a: str = "Exx",
    b: str = "Eyy",
    tests: Mapping | None = None,
) -> Figure:
    """Each specimen's mean of two components joined by a line (specimen-level paired plot).

    The specimen, not the node, is the unit of this plot: it goes with the
    paired test on specimen means across specimens.

    Parameters
    ----------
    table : sequence of dict
        One row per specimen: ``"name"``, optional ``"group"``, and the two
        means either as ``row[a]``, ``row[b]`` or as ``row["mean"][a]``, ...
    a, b : str, keyword-only
        The two components (left and right in each group).
    tests : dict, keyword-only
        The specimen-level paired test, written under the title: one result
        (keys ``"t_p"``, ``"wilcoxon_p"``, ``"n"``, ``"label"``) or one per
        group ``{group: result}``.

    Returns
    -------
    matplotlib.figure.Figure
        Groups side by side; a thin line per specimen, the group mean as a
        thick line.
    """
    if len(table) == 0:
        raise InputError("table is empty; give at least one specimen")

    def mean_of(row, comp, i):
        source = row["mean"] if isinstance(row.get("mean"), Mapping) else row
        if comp not in source:
            raise InputError(f"table[{i}] ({row.get('name')}) has no mean for {comp!r}")
        return float(source[comp])

    groups: dict[str, list[int]] = {}
    for i, row in enumerate(table):
        groups.setdefault(str(row.get("group") or ""), []).append(i)
    fig = Figure(figsize=(max(3.6, 2.6 * len(groups) + 1.2), 4.4), layout="constrained")
    ax = fig.add_subplot()
    ca, cb = _colour(a, 0), _colour(b, 1)
    ticks, ticklabels = [], []
    for gi, (group, rows) in enumerate(groups.items()):
        x0, x1 = 3.0 * gi, 3.0 * gi + 1.0
        va = np.array([mean_of(table[i], a, i) for i in rows])
        vb = np.array([mean_of(table[i], b, i) for i in rows])
        for i, ya, yb in zip(rows, va, vb, strict=True):
            ax.plot([x0, x1], [ya, yb], color="0.55", lw=1, zorder=1)
            ax.annotate(
                str(table[i].get("name", i + 1)),
                xy=(x1, yb),
                xytext=(5, 0),
                textcoords="offset points",
                va="center",
                fontsize=7,
                color="0.3",
            )
        ax.scatter(
            np.full(va.size, x0), va, color=ca, s=28, edgecolors="k", linewidths=0.4, zorder=3
        )
        ax.scatter(
            np.full(vb.size, x1), vb, color=cb, s=28, edgecolors="k", linewidths=0.4, zorder=3
        )
        ok = np.isfinite(va) & np.isfinite(vb)
        ma, mb = (va[ok].mean(), vb[ok].mean()) if ok.any() else (np.nan, np.nan)
        ax.plot(
            [x0, x1], [ma, mb], color="k", lw=2.4, zorder=2, label="group mean" if gi == 0 else None
        )
        ticks += [x0, x1]
        ticklabels += [_label(a), _label(b)]
        if group:
            _group_label(ax, group, 0.5 * (x0 + x1), -22)
    ax.set_xticks(ticks, ticklabels)
    ax.set_xlim(-0.6, 3.0 * (len(groups) - 1) + 1.9)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_ylabel(f"specimen mean, {_STRAIN_AXIS}")
    ax.set_xlabel(
        "component (group)" if any(groups) else "component", labelpad=18 if any(groups) else 4
    )
    ax.grid(alpha=0.3, axis="y")
    ax.legend(loc="best", fontsize=8)
    n_total = len(table)
    title = f"specimen means of {_label(a)} and {_label(b)} (n = {n_total} specimens)"
    if tests:
        if "t_p" in tests or "wilcoxon_p" in tests:
            title += "\n" + _test_lines(tests, short=False).replace("\n", "; ").replace(
                " nodes", ""
            )
        else:
            parts = [
                f"{g}: {_test_lines(t, short=True).replace(chr(10), ', ')}"
                for g, t in tests.items()
            ]
            title += "\n" + "; ".join(parts)
    ax.set_title(title, fontsize=9)
    return fig


# --------------------------------------------------------------------------- animation


def write_strain_animation(
    path: str | os.PathLike,
    frames: Iterable[np.ndarray],
    field: StrainField,
    *,
    components: Sequence[str] = ("Exx", "Eyy"),
    limits: Mapping[str, tuple[float, float]] | None = None,
    fps: float = 10,
    time_labels: Sequence[str] | None = None,
    progress: Callable[[int, int | None], None] | None = None,
    alpha: float = 0.6,
    max_width: int = 960,
    dpi: int = 100,
) -> Path:
    """Write a video of the strain field over time, drawn on the frames (MP4 or GIF).

    Each output frame shows one panel per component: the video frame in gray,
    filled contours of the nodal strain on the deformed mesh, a colour bar
    fixed for the whole video and the frame number (or ``time_labels``).

    Parameters
    ----------
    path : path
        ``.mp4`` (H.264 through imageio-ffmpeg's ffmpeg, plays in web browsers)
        or ``.gif`` (imageio's pillow plugin).
    frames : iterable of (H, W) float or uint8
        The video, one image per frame of ``field``, read one at a time.
        uint8 images are shown on 0..255; float images on the range of the
        first image.
    field : StrainField
        A 2D field.
    components : sequence of str, keyword-only
    limits : dict, keyword-only
        Colour limits per component (default :func:`strain_limits` over every
        frame, the same as :func:`plot_strain_maps_at` uses).
    fps : float, keyword-only
        Frames per second of the output.
    time_labels : sequence of str, keyword-only
        One label per frame (e.g. ``"t = 1.5 s"``); default ``"frame k / T-1"``.
    progress : callable(done, total), keyword-only
        Called after each frame.
    alpha : float, keyword-only
        Opacity of the contours.
    max_width : int, keyword-only
        Largest width (and height, for tall frames) of the output in pixels;
        both are even.
    dpi : int, keyword-only
        Resolution of the rendering (sets text size relative to the frame).

    Returns
    -------
    Path
        ``path``.  The video is written under a temporary name and renamed
        when complete; an error or Ctrl-C leaves nothing at ``path``.

    Raises
    ------
    ValueError
        When ``frames`` yields more or fewer images than ``field`` has frames,
        or an option is invalid (:class:`strain2d.InputError`).

    Notes
    -----
    MP4 frames are streamed to the file as they are rendered.  Pillow writes
    a GIF only when it is closed, so a GIF holds every rendered frame in
    memory until the end: use MP4 for long videos.  Output dimensions are
    even (required by most MP4 players).
    """
    path = Path(path)
    kind = path.suffix.lower()
    if kind not in (".mp4", ".gif"):
        raise InputError(f"the animation must be .mp4 or .gif, got {path.name!r}")
    _check_2d(field)
    scalars = _scalars(field, components)
    if not (np.isfinite(fps) and fps > 0):
        raise InputError(f"fps must be a positive number, got {fps}")
    T = field.n_frames
    if time_labels is not None and len(time_labels) != T:
        raise InputError(f"time_labels has {len(time_labels)} entries for {T} frames")
    if max_width < 64:
        raise InputError(f"max_width must be at least 64 px, got {max_width}")
    if limits is None:
        limits = strain_limits(field, components)
    else:
        missing = [c for c in components if c not in limits]
        limits = {**strain_limits(field, missing), **limits} if missing else limits
    scales = {c: _colour_scale(c, *map(float, limits[c])) for c in components}
    tmp = path.with_name(f".{path.stem}.partial{kind}")
    writer = None
    state: dict = {}
    count = 0
    try:
        for count, image in enumerate(frames, start=1):
            k = count - 1
            if k >= T:
                raise InputError(f"frames yields more images than the field's {T} frames")
            image = _check_image(image, f"frame {k}")
            if not state:
                state = _animation_figure(image, field, components, scales, alpha, max_width, dpi)
            rgb = _animation_frame(
                state,
                image,
                field,
                k,
                scalars,
                components,
                scales,
                alpha,
                time_labels[k] if time_labels is not None else f"frame {k} / {T - 1}",
            )
            if writer is None:
                writer = _open_writer(tmp, kind, fps, rgb.shape)
            if kind == ".mp4":
                writer.send(np.ascontiguousarray(rgb))
            else:
                writer.write(rgb, duration=1000.0 / fps, loop=0)
            if progress:
                progress(count, T)
        if count != T:
            raise InputError(f"frames yields {count} images for a field of {T} frames")
        _close_writer(writer, kind)
        writer = None
        os.replace(tmp, path)
    finally:
        if writer is not None:
            try:
                _close_writer(writer, kind)
            except Exception:  # already failing; the temporary file is removed below
                pass
        tmp.unlink(missing_ok=True)
    return path


def _open_writer(tmp: Path, kind: str, fps: float, shape: tuple[int, ...]):
    h, w = shape[:2]
    if kind == ".mp4":
        # H.264 in yuv420p: what web browsers (the HTML report) and every player decode
        import imageio_ffmpeg

        writer = imageio_ffmpeg.write_frames(
            str(tmp),
            (w, h),
            fps=float(fps),
            codec="libx264",
            pix_fmt_in="rgb24",
            pix_fmt_out="yuv420p",
            quality=7,
            macro_block_size=2,  # the frames are already even on both sides
            ffmpeg_log_level="error",
            output_params=["-movflags", "+faststart"],
        )
        writer.send(None)  # start ffmpeg
        return writer
    import imageio.v3 as iio

    return iio.imopen(tmp, "w", plugin="pillow", extension=".gif")


def _close_writer(writer, kind: str) -> None:
    if kind == ".mp4":
        writer.close()
    else:
        writer.close()


def _animation_figure(image, field, components, scales, alpha, max_width, dpi) -> dict:
    """The reused figure of an animation: image, mesh and label artists, fixed colour bars."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    n = len(components)
    h, w = image.shape[:2]

    def height_for(width_px: int) -> int:  # panel: image + colour bar and labels beside it
        panel_in = width_px / dpi / n
        return max(64, 2 * (round(((panel_in - 1.25) * h / w + 0.95) * dpi) // 2))

    width_px = 2 * (min(int(max_width), 480 * n) // 2)
    height_px = height_for(width_px)
    if height_px > max_width:  # tall frames: the height is kept under max_width too
        image_in = (max_width / dpi - 0.95) * w / h
        width_px = max(64, 2 * (int((image_in + 1.25) * n * dpi) // 2))
        height_px = min(height_for(width_px), 2 * (int(max_width) // 2))
    fig = Figure(figsize=(width_px / dpi, height_px / dpi), dpi=dpi, layout="constrained")
    canvas = FigureCanvasAgg(fig)
    axes = np.atleast_1d(fig.subplots(1, n))
    vmin, vmax = _gray_range(image)
    state = {
        "fig": fig,
        "canvas": canvas,
        "axes": axes,
        "images": [],
        "meshes": [],
        "contours": [None] * n,
        "size": (width_px, height_px),
    }
    for ax, comp in zip(axes, components, strict=True):
        state["images"].append(_show_image(ax, image, vmin=vmin, vmax=vmax))
        mesh = LineCollection([], colors="k", linewidths=0.3, alpha=0.45)
        ax.add_collection(mesh, autolim=False)
        state["meshes"].append(mesh)
        cbar = _colorbar(fig, ax, scales[comp], _unit_label(comp), alpha=alpha, shrink=0.9)
        cbar.ax.tick_params(labelsize=7)
        cbar.ax.yaxis.label.set_fontsize(8)
        ax.set_title(_label(comp), fontsize=10)
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_fontsize(8)
        ax.yaxis.label.set_fontsize(8)
    state["label"] = fig.suptitle(" ", fontsize=10)
    return state


def _animation_frame(state, image, field, k, scalars, components, scales, alpha, label):
    """Render frame ``k`` into the reused figure; returns (H, W, 3) uint8 with even H, W."""
    fig = state["fig"]
    for j, comp in enumerate(components):
        ax = state["axes"][j]
        state["images"][j].set_data(image)
        if state["contours"][j] is not None:
            state["contours"][j].remove()
            state["contours"][j] = None
        values = scalars[comp][k]
        tri = _triangulation(field, k, values)
        if tri is not None:
            state["contours"][j] = _draw_contours(ax, tri, values, scales[comp], alpha)
            edges = tri.edges
            state["meshes"][j].set_segments(
                np.stack(
                    [np.column_stack([tri.x[edges[:, i]], tri.y[edges[:, i]]]) for i in (0, 1)],
                    axis=1,
                )
            )
        else:
            state["meshes"][j].set_segments([])
    state["label"].set_text(label)
    state["canvas"].draw()
    if not state.get("frozen"):
        fig.set_layout_engine("none")  # keep the first frame's layout: no jitter between frames
        state["frozen"] = True
    rgb = np.asarray(state["canvas"].buffer_rgba())[..., :3]
    w, h = state["size"]
    out = np.full((h, w, 3), 255, np.uint8)
    hh, ww = min(h, rgb.shape[0]), min(w, rgb.shape[1])
    out[:hh, :ww] = rgb[:hh, :ww]
    return out
