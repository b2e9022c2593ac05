"""Figures of strain on surfaces: a component on the deformed mesh, curves over time, violins.

:func:`render_strain` writes an off-screen PyVista rendering (PNG);
:func:`plot_strain_curves`, :func:`plot_strain_violins` and
:func:`plot_tracking_quality` return :class:`matplotlib.figure.Figure`
objects (no pyplot state).  Time axes are in seconds when a frame rate is
known (``fps``), in frames otherwise.
"""

from __future__ import annotations

import numpy as np

from surface_strain.field import StrainField, nodal_scalars

__all__ = [
    "colour_range",
    "plot_strain_curves",
    "plot_strain_violins",
    "plot_tracking_quality",
    "render_strain",
]

_COMPONENTS = ("Exx", "Eyy", "Exy", "E1", "E2")
#: line styles that keep coinciding curves apart (E1 on Exx under a uniaxial stretch)
_STYLES = ("-", "--", "-.", ":", (0, (6, 2, 1, 2, 1, 2)))


def _frame_label(t: int, fps: float | None) -> str:
    """``"frame 3"``, or ``"t = 0.3 s (frame 3)"`` with a frame rate."""
    return f"t = {t / fps:.4g} s (frame {t})" if fps else f"frame {t}"


def _time_axis(n_frames: int, times, fps: float | None, time_unit: str | None):
    """The x values and axis label of a curve over time: seconds when known, else frames."""
    if time_unit not in (None, "s", "frame"):
        raise ValueError(f"time_unit must be 's' or 'frame', got {time_unit!r}")
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps}")
    if times is None:
        x = np.arange(n_frames) / fps if fps else np.arange(n_frames, dtype=float)
    else:
        x = np.asarray(times, dtype=float)
        if x.shape != (n_frames,):
            raise ValueError(f"times must have one value per frame ({n_frames}), got {x.shape}")
    unit = time_unit or ("s" if fps else "frame")
    return x, "time (s)" if unit == "s" else "frame"


def colour_range(values: np.ndarray, *, min_span: float = 0.01) -> tuple[float, float]:
    """Colour limits that fit strain values: symmetric about 0 where they change sign.

    Values of one sign get their own range, widened about its middle to at
    least ``min_span`` so that tracking noise on a uniform field does not fill
    the whole scale.  NaN values are left out.

    Examples
    --------
    >>> colour_range(np.array([0.074, 0.08, 0.087]))
    (0.074, 0.087)
    >>> colour_range(np.array([0.0800, 0.0803]))  # noise on a uniform field
    (0.07515, 0.08515)
    >>> colour_range(np.array([-0.02, 0.05, np.nan]))
    (-0.05, 0.05)
    """
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return (0.0, 1.0)
    lo, hi = float(v.min()), float(v.max())
    if lo < 0 < hi:
        m = max(-lo, hi)
        return (-m, m)
    if hi - lo < min_span:
        middle = (hi + lo) / 2
        lo, hi = middle - min_span / 2, middle + min_span / 2
    return (round(lo, 12), round(hi, 12))


def render_strain(
    field: StrainField,
    path,
    *,
    key: str = "E1",
    frame: int = -1,
    unit: str = "mm",
    window_size: tuple[int, int] = (900, 700),
    clim: tuple[float, float] | None = None,
    fps: float | None = None,
) -> None:
    """Render a nodal strain component on the deformed surface at ``frame`` (PNG).

    The title names the frame, and its time in seconds when ``fps`` is given.

    The colour range fits the values (:func:`colour_range`) unless ``clim``
    is given: symmetric about zero on a diverging map where they change sign,
    their own range on a sequential one otherwise, so that E1 between 0.074
    and 0.087 is not drawn as one colour on a scale from 0.  Pass ``clim`` for
    the same range in every frame.
    """
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger

    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    t = field.n_frames - 1 if frame < 0 else frame
    pts = field.points[t]
    if pts.shape[1] == 2:
        pts = np.column_stack([pts, np.zeros(len(pts))])
    ref = field.reference if field.reference.shape[1] == 3 else np.column_stack(
        [field.reference, np.zeros(len(field.reference))]
    )  # fmt: skip
    pts = np.where(np.isfinite(pts), pts, ref)
    values = nodal_scalars(field)[key][t]
    faces = np.column_stack([np.full(field.n_triangles, 3), field.triangles]).ravel()
    mesh = pv.PolyData(pts, faces=faces)
    mesh.point_data[key] = values
    if clim is None:
        clim = colour_range(values)
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    try:
        plotter.set_background("white")
        plotter.add_mesh(
            mesh,
            scalars=key,
            cmap="RdBu_r" if clim[0] < 0 else "viridis",
            clim=clim,
            nan_color="lightgray",
            show_edges=True,
            edge_color="gray",
            ambient=0.6,  # colours close to the colour bar, shading still shows the shape
            diffuse=0.4,
            scalar_bar_args={"title": f"{key} (-), Green-Lagrange", "color": "black"},
        )
        plotter.add_axes(color="black", xlabel=f"X ({unit})", ylabel=f"Y ({unit})",
                         zlabel=f"Z ({unit})")  # fmt: skip
        plotter.add_text(f"{key}, {_frame_label(t, fps)}", font_size=10, color="black")
        plotter.view_vector((0.3, -0.6, -1.0), viewup=(0.0, -1.0, 0.0))
        plotter.reset_camera()
        plotter.screenshot(str(path))
    finally:
        plotter.close()


def plot_strain_curves(
    field: StrainField,
    *,
    times=None,
    fps: float | None = None,
    time_unit: str | None = None,
):
    """Mean nodal strain over time with a band of +/- one spatial SD, per component.

    Parameters
    ----------
    field : StrainField
    times : (T,) float, optional, keyword-only
        The x values; default ``frame / fps``, or the frame index without ``fps``.
    fps : float, optional, keyword-only
        Frame rate: the axis is ``time (s)``.
    time_unit : {"s", "frame"}, optional, keyword-only
        The unit of ``times`` when no ``fps`` says it (default: seconds with
        ``fps``, else frames).
    """
    from matplotlib.figure import Figure

    node = nodal_scalars(field)
    x, xlabel = _time_axis(field.n_frames, times, fps, time_unit)
    fig = Figure(figsize=(7.5, 4.2), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    for key, style in zip(_COMPONENTS, _STYLES, strict=True):
        values = node[key]
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(values).any(axis=1)
            mean = np.where(ok, np.nanmean(np.where(ok[:, None], values, 0.0), axis=1), np.nan)
            sd = np.where(ok, np.nanstd(np.where(ok[:, None], values, 0.0), axis=1), np.nan)
        (line,) = ax.plot(x, mean, label=key, linestyle=style, lw=1.6)
        ax.fill_between(x, mean - sd, mean + sd, color=line.get_color(), alpha=0.15, lw=0)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("Green-Lagrange strain (-), mean ± spatial SD")
    ax.legend(ncols=5, fontsize=8, loc="upper left")
    ax.grid(alpha=0.3)
    return fig


def plot_strain_violins(field: StrainField, *, frame: int = -1, fps: float | None = None):
    """Distribution over the nodes of each component at ``frame`` (its time with ``fps``)."""
    from matplotlib.figure import Figure

    t = field.n_frames - 1 if frame < 0 else frame
    node = nodal_scalars(field)
    data = [node[k][t][np.isfinite(node[k][t])] for k in _COMPONENTS]
    fig = Figure(figsize=(6.5, 4.0), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    keep = [i for i, d in enumerate(data) if d.size > 1]
    if keep:
        ax.violinplot([data[i] for i in keep], positions=keep, showmedians=True)
    ax.set_xticks(range(len(_COMPONENTS)), _COMPONENTS)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_ylabel("Green-Lagrange strain (-), over the nodes")
    ax.set_title(_frame_label(t, fps))
    ax.grid(alpha=0.3, axis="y")
    return fig


def plot_tracking_quality(
    visible_fraction: np.ndarray,
    coverage: np.ndarray,
    *,
    times=None,
    fps: float | None = None,
    time_unit: str | None = None,
):
    """Points still tracked and surface area with valid strain, in percent, over time.

    Parameters
    ----------
    visible_fraction : (T,) float
        Fraction of the points visible on each frame.
    coverage : (T,) float
        Fraction of the reference surface area whose triangles have valid
        strain on each frame.
    times, fps, time_unit
        As for :func:`plot_strain_curves`.
    """
    from matplotlib.figure import Figure

    visible = 100 * np.asarray(visible_fraction, dtype=float)
    cover = 100 * np.asarray(coverage, dtype=float)
    x, xlabel = _time_axis(len(visible), times, fps, time_unit)
    fig = Figure(figsize=(7.5, 3.0), dpi=100, layout="constrained")
    ax = fig.add_subplot()
    dots = len(x) <= 30  # markers on short runs only: they would hide the lines of long ones
    ax.plot(x, visible, "-o" if dots else "-", ms=3, lw=1.6, label="points visible")
    ax.plot(x, cover, "--s" if dots else "--", ms=3, lw=1.4,
            label="surface area with valid strain")  # fmt: skip
    low = min(np.nanmin(visible, initial=100), np.nanmin(cover, initial=100))
    ax.set_ylim(max(0.0, min(low - 5, 90.0)), 101)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("% of the reference")
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3)
    return fig
