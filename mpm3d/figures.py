"""Figures of a lumen surface: height map, profiles, spectrum, 3D rendering.

Functions return :class:`matplotlib.figure.Figure` objects (no pyplot
state) or write a PNG (the 3D rendering); axes carry micrometres, colour
bars their units.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "plot_comparison",
    "plot_height_map",
    "plot_profiles",
    "plot_spectrum",
    "render_surface",
]


def _figure(width: float, height: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=110, layout="constrained")


def _extent(shape, spacing) -> tuple[float, float, float, float]:
    dy, dx = tuple(spacing)[-2:]
    ny, nx = shape
    return (-dx / 2, (nx - 0.5) * dx, (ny - 0.5) * dy, -dy / 2)


def _display(image: np.ndarray, size: int = 700) -> np.ndarray:
    """Block-average a large map to about the figure's resolution (faster, no aliasing)."""
    f = max(1, int(max(image.shape) // size))
    if f == 1:
        return image
    ny, nx = image.shape[0] // f, image.shape[1] // f
    return image[: ny * f, : nx * f].reshape(ny, f, nx, f).mean(axis=(1, 3))


def _height_panel(ax, height, spacing, *, vmin=None, vmax=None, title=""):
    im = ax.imshow(
        _display(height),
        extent=_extent(height.shape, spacing),
        cmap="viridis",
        vmin=vmin,
        vmax=vmax,
        interpolation="nearest",
    )
    ax.set_xlabel("x (µm)")
    ax.set_ylabel("y (µm)")
    ax.set_title(title)
    return im


def plot_height_map(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    valid: np.ndarray | None = None,
    folds=None,
    title: str = "lumen surface height",
):
    """Height map (um) with a colour bar; drop-outs hatched, fold crests marked.

    Parameters
    ----------
    height : (Y, X) um
    spacing : (dz, dy, dx) or (dy, dx) um
    valid : (Y, X) bool, optional
        Measured columns; the others (filled in) are shaded.
    folds : mpm3d.metrics.FoldTable, optional
        Crest positions are drawn as dots, one colour per fold.
    """
    fig = _figure(6.4, 5.2)
    ax = fig.add_subplot()
    im = _height_panel(ax, height, spacing, title=title)
    fig.colorbar(im, ax=ax, label="height (µm)", shrink=0.85)
    if valid is not None and not np.all(valid):
        shade = _display(np.where(np.asarray(valid, bool), np.nan, 1.0))
        ax.imshow(
            shade, extent=_extent(height.shape, spacing), cmap="Greys", alpha=0.5, vmin=0, vmax=1
        )
    if folds is not None and folds.crests["x_um"].size:
        ax.scatter(folds.crests["x_um"], folds.crests["y_um"], s=4, c="white", lw=0)
        for i, (x, y) in enumerate(zip(folds.folds["x_um"], folds.folds["y_um"], strict=True)):
            ax.annotate(f"fold {i}", (x, y), color="white", fontsize=8, ha="center")
    return fig


def plot_profiles(folds, *, max_profiles: int = 3):
    """Height along profiles across the folds, with crests and the fold heights.

    Parameters
    ----------
    folds : mpm3d.metrics.FoldTable
    max_profiles : int
        How many profiles to draw (spread over the map).
    """
    fig = _figure(7.0, 4.0)
    ax = fig.add_subplot()
    profiles = folds.profiles
    if profiles:
        lengths = np.array([len(p["s_um"]) for p in profiles])
        picks = np.argsort(lengths)[::-1][:max_profiles]
        for k in sorted(picks):
            p = profiles[k]
            ax.plot(p["s_um"], p["height_um"], lw=1.2, label=f"profile {k}")
            on = folds.crests["profile"] == k
            ax.plot(
                folds.crests["offset_um"][on],
                np.interp(folds.crests["offset_um"][on], p["s_um"], p["height_um"]),
                "v",
                color="k",
                ms=5,
            )
        ax.legend(fontsize=8)
    ax.set_xlabel("distance across the folds (µm)")
    ax.set_ylabel("height, form removed (µm)")
    ax.set_title("profiles across the fold crests (▼ crest)")
    ax.grid(alpha=0.3)
    return fig


def plot_spectrum(spectrum, *, wavelength_um: float | None = None):
    """Power spectrum of the height map around its dominant fold frequency.

    Frequencies in cycles per millimetre; the refined peak is circled.
    """
    fig = _figure(5.6, 4.8)
    ax = fig.add_subplot()
    fx, fy = spectrum.freq_x * 1e3, spectrum.freq_y * 1e3
    k = np.hypot(*spectrum.wavevector) * 1e3
    lim = max(3 * k, 4 * abs(fx[1] - fx[0]))
    sx, sy = np.abs(fx) <= lim, np.abs(fy) <= lim
    power = spectrum.power[np.ix_(sy, sx)]
    im = ax.imshow(
        np.log10(power / power.max() + 1e-12),
        extent=(fx[sx][0], fx[sx][-1], fy[sy][-1], fy[sy][0]),
        cmap="magma",
        vmin=-6,
        vmax=0,
    )
    kx, ky = spectrum.wavevector * 1e3
    ax.plot([kx, -kx], [ky, -ky], "o", mfc="none", mec="cyan", ms=12)
    wl = spectrum.wavelength_um if wavelength_um is None else wavelength_um
    ax.set_title(f"height spectrum: fold wavelength {wl:.0f} µm")
    ax.set_xlabel("kx (cycles/mm)")
    ax.set_ylabel("ky (cycles/mm)")
    fig.colorbar(im, ax=ax, label="log10 relative power", shrink=0.85)
    return fig


def plot_comparison(
    before: np.ndarray,
    after: np.ndarray,
    *,
    spacing_before: Sequence[float],
    spacing_after: Sequence[float],
    titles: tuple[str, str] = ("before", "after"),
):
    """Two height maps side by side on one colour scale (um, form removed)."""
    fig = _figure(11.0, 4.8)
    axes = fig.subplots(1, 2)
    lo = min(np.percentile(before, 0.5), np.percentile(after, 0.5))
    hi = max(np.percentile(before, 99.5), np.percentile(after, 99.5))
    im = None
    for ax, h, sp, t in zip(
        axes, (before, after), (spacing_before, spacing_after), titles, strict=True
    ):
        im = _height_panel(ax, h, sp, vmin=lo, vmax=hi, title=t)
    fig.colorbar(im, ax=list(axes), label="height, form removed (µm)", shrink=0.85)
    return fig


def render_surface(
    mesh,
    path,
    *,
    window_size: tuple[int, int] = (1000, 760),
    title: str = "",
    max_triangles: int = 300_000,
):
    """Write an off-screen 3D rendering of a surface mesh (PNG).

    The mesh (points ``(x, y, depth)`` in um) is coloured by height above
    its deepest point and seen obliquely from the lumen side, with a colour
    bar in micrometres.  Meshes over ``max_triangles`` are drawn from a
    copy simplified by quadric vertex clustering (Lindstrom 2000,
    doi:10.1145/344779.344912), which looks the same at figure size and
    renders several times faster without a GPU.
    """
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger

    # without a display VTK falls back to off-screen rendering after a warning
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    simplified = mesh.n_cells > max_triangles
    if simplified:
        from vtkmodules.vtkFiltersCore import vtkQuadricClustering

        cells = int(np.sqrt(max_triangles / 2))
        clustering = vtkQuadricClustering()
        clustering.SetInputData(mesh)
        clustering.SetNumberOfDivisions(cells, cells, cells)
        clustering.AutoAdjustNumberOfDivisionsOn()
        clustering.Update()
        mesh = pv.wrap(clustering.GetOutput())
    shown = mesh.copy(deep=False)
    z = np.asarray(mesh.points[:, 2])
    shown.point_data["height (µm)"] = z.max() - z
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    try:
        plotter.set_background("white")
        plotter.add_mesh(
            shown,
            scalars="height (µm)",
            cmap="viridis",
            smooth_shading=not simplified,  # clustering leaves a few non-manifold edges
            scalar_bar_args={"title": "height (µm)", "color": "black", "vertical": True},
        )
        plotter.add_axes(color="black", xlabel="x", ylabel="y", zlabel="depth")
        if title:
            plotter.add_text(title, font_size=10, color="black")
        # look from the objective side (depth grows away from the viewer), obliquely
        bounds = shown.bounds
        cx, cy = (bounds[0] + bounds[1]) / 2, (bounds[2] + bounds[3]) / 2
        cz = (bounds[4] + bounds[5]) / 2
        size = max(bounds[1] - bounds[0], bounds[3] - bounds[2])
        plotter.camera_position = [
            (cx - 0.3 * size, cy + 1.1 * size, cz - 1.2 * size),
            (cx, cy, cz),
            (0.0, 0.0, -1.0),
        ]
        plotter.reset_camera()
        plotter.camera.zoom(1.15)
        plotter.screenshot(str(path))
    finally:
        plotter.close()
