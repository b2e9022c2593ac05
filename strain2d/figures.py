"""Figures of 2D runs: the tracked grid, strain contour maps and their shared colour scales.

Per run: the tracked grid (:func:`plot_tracked_grid`), contour maps of
strain components on the deformed configuration (:func:`plot_strain_maps`,
:func:`plot_strain_maps_at`) and the nodal strain error
(:func:`plot_strain_errors`).

Conventions
-----------
* Built on :class:`matplotlib.figure.Figure` directly, never pyplot, so
  importing or calling this module does not change the global matplotlib
  state or backend.  Functions named ``plot_*`` save and return the written paths;
  :func:`strain_maps_figure` returns the ``Figure`` and
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
  different frames can be compared by eye.
"""

from __future__ import annotations

import operator
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib import colormaps, rc_context
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from matplotlib.tri import Triangulation

from strain2d.errors import InputError
from strain2d.tracks import Tracks
from surface_strain import (
    StrainField,
    nodal_scalars,
)

__all__ = [
    "plot_strain_errors",
    "plot_strain_maps",
    "plot_strain_maps_at",
    "plot_tracked_grid",
    "save_figure",
    "strain_limits",
    "strain_maps_figure",
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
        tmp = out.with_name(f".{out.name}.partial")
        metadata = {"svg": {"Date": None}, "pdf": {"CreationDate": None}}.get(fmt)
        try:
            # a fixed salt makes SVG element ids, hence the file, reproducible
            with rc_context({"svg.hashsalt": "strain2d"}):
                fig.savefig(
                    tmp,
                    format=fmt,
                    dpi=dpi,
                    bbox_inches="tight" if tight else None,
                    metadata=metadata,
                )
            os.replace(tmp, out)
        finally:
            tmp.unlink(missing_ok=True)
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
        every frame of the field, so that these maps share one scale.
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
