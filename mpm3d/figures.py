"""Figures of a lumen surface: height map, profiles, spectrum, 3D rendering.

Functions return :class:`matplotlib.figure.Figure` objects (no pyplot
state) or write a PNG (the 3D rendering); axes carry micrometres, colour
bars their units.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = [
    "HEIGHT_LABEL",
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


def _display(image: np.ndarray, size: int = 700, *, where=None) -> np.ndarray:
    """Block-average a large map to about the figure's resolution (faster, no aliasing),
    a band of block rows at a time (no copy of a large map).  With ``where`` (a function
    of a band of rows), the map's band is ``where(band)`` first."""
    f = max(1, int(max(image.shape) // size))
    if f == 1:
        return image if where is None else where(np.asarray(image))
    ny, nx = image.shape[0] // f, image.shape[1] // f
    out = np.empty((ny, nx))
    step = max(1, 256 // f)
    for a in range(0, ny, step):
        b = min(ny, a + step)
        band = np.asarray(image[a * f : b * f, : nx * f])
        if where is not None:
            band = where(band)
        out[a:b] = band.reshape(b - a, f, nx, f).mean(axis=(1, 3))
    return out


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


#: profiles whose crests the height map figure marks, at most (every k-th profile's)
MAX_CREST_PROFILES = 60

#: colour-bar label of the heights (see :data:`mpm3d.heightmap.HEIGHT_DATUM`)
HEIGHT_LABEL = "height above the deepest slice (µm)"


def _outlined(color: str = "black", width: float = 2.5):
    """A stroke round text or markers, so they read on any colour of the map."""
    from matplotlib import patheffects

    return [patheffects.withStroke(linewidth=width, foreground=color)]


def plot_height_map(
    height: np.ndarray,
    *,
    spacing: Sequence[float],
    valid: np.ndarray | None = None,
    folds=None,
    title: str = "lumen surface height",
    clim: tuple[float, float] | None = None,
    label: str = HEIGHT_LABEL,
):
    """Height map (um) with a colour bar; drop-outs shaded, fold crests marked.

    Parameters
    ----------
    height : (Y, X) um
        Height above the datum (:data:`mpm3d.heightmap.HEIGHT_DATUM`).
    spacing : (dz, dy, dx) or (dy, dx) um
    valid : (Y, X) bool, optional
        Measured columns; the others (filled in) are shaded.
    folds : mpm3d.metrics.FoldTable, optional
        Crests found along each profile are drawn as white dots with a
        black rim, each fold labelled at its crest line's upper end.
    clim : (low, high) um, optional
        Colour limits (by default the map's range); pass the same limits
        to :func:`render_surface` so one colour is one height in both.
    label : str
        The colour bar's label.
    """
    fig = _figure(6.4, 5.2)
    ax = fig.add_subplot()
    lo, hi = clim if clim is not None else (float(np.nanmin(height)), float(np.nanmax(height)))
    im = _height_panel(ax, height, spacing, vmin=lo, vmax=hi, title=title)
    fig.colorbar(im, ax=ax, label=label, shrink=0.85)
    if valid is not None and not np.all(valid):
        shade = _display(valid, where=lambda band: np.where(band.astype(bool), np.nan, 1.0))
        ax.imshow(
            shade, extent=_extent(height.shape, spacing), cmap="Greys", alpha=0.5, vmin=0, vmax=1
        )
    if folds is not None and folds.crests["x_um"].size:
        # on a wide field the profiles (a sixteenth of a wavelength apart) would cover the
        # map with dots: those of every k-th profile are drawn, at most MAX_CREST_PROFILES
        ids = np.unique(folds.crests["profile"])
        every = max(1, math.ceil(len(ids) / MAX_CREST_PROFILES))
        shown = np.isin(folds.crests["profile"], ids[::every])
        n_shown = int(shown.sum())
        ax.scatter(
            folds.crests["x_um"][shown],
            folds.crests["y_um"][shown],
            s=max(3.0, 14.0 * min(1.0, math.sqrt(400 / max(n_shown, 1)))),  # smaller if many
            facecolor="white",
            edgecolor="black",
            linewidths=0.6,
            label="crest (one per profile)"
            if every == 1
            else f"crest (one per profile, on one profile in {every})",
            zorder=3,
        )
        ax.legend(loc="lower right", fontsize=8, framealpha=0.85)
        ny = height.shape[0]
        dy = tuple(spacing)[-2]
        for i, (x, y) in enumerate(zip(folds.folds["x_um"], folds.folds["y_um"], strict=True)):
            ax.annotate(
                f"fold {i}",
                (x, y),
                xytext=(0, 0),
                textcoords="offset points",
                color="white",
                fontsize=10,
                fontweight="bold",
                ha="center",
                va="center",
                path_effects=_outlined(),
                bbox={"boxstyle": "round,pad=0.25", "fc": "black", "ec": "none", "alpha": 0.55},
                zorder=4,
                annotation_clip=True,
            )
        ax.set_ylim((ny - 0.5) * dy, -dy / 2)
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
            index = p.get("profile", k)
            ax.plot(p["s_um"], p["height_um"], lw=1.2, label=f"profile {index}")
            on = folds.crests["profile"] == index
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


def _nice_ticks(low: float, high: float, n: int = 5, *, slack: float = 0.01) -> np.ndarray:
    """Round tick values in [low, high], or up to ``slack`` of the range outside it."""
    from matplotlib.ticker import MaxNLocator

    ticks = MaxNLocator(n).tick_values(low, high)
    tol = slack * abs(high - low)  # 0 on an axis from 1.25 um, say
    return ticks[(ticks >= low - tol) & (ticks <= high + tol)]


def _nice_length(length: float) -> float:
    """The largest of 1, 2, 5 x 10^k not above ``length``."""
    k = 10 ** math.floor(math.log10(length))
    return max(m * k for m in (1, 2, 5) if m * k <= length)


def render_surface(
    mesh,
    path,
    *,
    datum_depth_um: float,
    clim: tuple[float, float] | None = None,
    window_size: tuple[int, int] = (1000, 800),
    title: str = "",
    label: str = HEIGHT_LABEL,
    max_triangles: int = 300_000,
) -> dict:
    """Write an off-screen 3D rendering of a surface mesh (PNG), with axes and a scale bar.

    The mesh (points ``(x, y, depth)`` in um) is coloured by its height
    above the datum plane ``datum_depth_um`` below slice 0 (the package's
    datum: :data:`mpm3d.heightmap.HEIGHT_DATUM`) and seen obliquely from
    the lumen side, x to the right and y towards the viewer as in the height
    map figure.  Axes in micrometres run along the datum plane's left and
    front edges (x, y) and up its back-left corner (height above the
    datum); a scale bar lies on the datum plane in front; the colour bar is
    below.  Meshes over ``max_triangles`` are drawn from a copy simplified
    by uniform vertex clustering (Rossignac & Borrel 1993,
    doi:10.1007/978-3-642-78114-8_29), a chunk of triangles at a time (a mesh on
    disk too, :class:`mpm3d.meshstream.DiskMesh`), which looks the same at figure
    size and renders several times faster without a GPU.

    Returns
    -------
    dict
        ``clim`` (the colour limits, um), ``scale_bar_um``, ``simplified``
        (whether a simplified copy was drawn) and ``triangles_drawn``.
    """
    import pyvista as pv
    from vtkmodules.vtkCommonCore import vtkLogger

    # without a display VTK falls back to off-screen rendering after a warning
    vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    from mpm3d.meshstream import DiskMesh, bounds_of

    simplified = mesh.n_cells > max_triangles
    if isinstance(mesh, DiskMesh) and not simplified:
        mesh = mesh.polydata()
    if simplified:
        # a chunk of triangles at a time, for a mesh on disk and in memory alike (the
        # same figure from either path)
        cells = np.sqrt(max_triangles / 2)  # bins along the longest side, for a flat sheet
        bounds = bounds_of(mesh)
        simple = _cluster_chunks(mesh, int(cells), bounds)
        if simple.n_cells > max_triangles:  # folds' flanks fill more bins: fewer, larger
            cells *= 0.95 * np.sqrt(max_triangles / simple.n_cells)
            simple = _cluster_chunks(mesh, int(cells), bounds)
        mesh = simple
    shown = pv.PolyData(mesh.points, mesh.faces) if mesh.n_cells else mesh.copy()
    datum = float(datum_depth_um)
    height = datum - np.asarray(shown.points[:, 2], np.float64)
    shown.point_data["height"] = height
    if clim is None:
        clim = (float(height.min()), float(height.max()))
    clim = (float(clim[0]), float(clim[1]))
    x0, x1, y0, y1, zmin, _ = shown.bounds
    size = max(x1 - x0, y1 - y0)
    top = datum - zmin  # the highest point's height
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    try:
        plotter.set_background("white")
        plotter.add_mesh(
            shown,
            scalars="height",
            cmap="viridis",
            clim=clim,
            smooth_shading=not simplified,  # clustering leaves a few non-manifold edges
            show_scalar_bar=False,
        )
        bar_actor = plotter.add_scalar_bar(
            title=label,
            color="black",
            vertical=False,
            position_x=0.22,
            position_y=0.03,
            width=0.56,
            height=0.09,
            title_font_size=18,
            label_font_size=15,
            n_labels=5,
            fmt="%.0f",
        )
        from vtkmodules.vtkCommonCore import vtkDoubleArray

        values = vtkDoubleArray()
        for v in _nice_ticks(*clim, slack=0.0):
            values.InsertNextValue(float(v))
        bar_actor.SetUseCustomLabels(True)
        bar_actor.SetCustomLabels(values)
        # the datum plane's outline and the axes, in the stack frame (depth down)
        floor = np.array([[x0, y0, datum], [x1, y0, datum], [x1, y1, datum], [x0, y1, datum]])
        plotter.add_mesh(
            pv.lines_from_points(np.vstack([floor, floor[:1]])), color="grey", line_width=1
        )
        plotter.add_mesh(pv.Line((x0, y0, datum), (x0, y0, zmin)), color="black", line_width=2)
        off = 0.05 * size
        tick_points, tick_labels, ticks = [], [], []
        for v in _nice_ticks(x0, x1):
            ticks.append(((v, y1, datum), (v, y1 + off / 3, datum)))
            tick_points.append((v, y1 + off, datum))
            tick_labels.append(f"{v:.0f}")
        for v in _nice_ticks(y0, y1):
            if v - y0 < 0.5 * off:  # the corner where the height axis starts at 0
                continue
            ticks.append(((x0, v, datum), (x0 - off / 3, v, datum)))
            tick_points.append((x0 - off, v, datum))
            tick_labels.append(f"{v:.0f}")
        # as many height ticks for the axis's length as the x and y axes have for theirs
        for v in _nice_ticks(0.0, top, max(2, min(5, round(6 * top / size)))):
            ticks.append(((x0, y0, datum - v), (x0 - off / 3, y0, datum - v)))
            tick_points.append((x0 - off, y0, datum - v))
            tick_labels.append(f"{v:.0f}")
        for a, b in ticks:
            plotter.add_mesh(pv.Line(a, b), color="black", line_width=2)
        plotter.add_mesh(pv.Line((x0, y1, datum), (x1, y1, datum)), color="black", line_width=2)
        plotter.add_mesh(pv.Line((x0, y0, datum), (x0, y1, datum)), color="black", line_width=2)
        label_style = {
            "text_color": "black",
            "shape": None,
            "show_points": False,
            "always_visible": True,
            "bold": False,
            "justification_horizontal": "center",
            "justification_vertical": "center",
        }
        plotter.add_point_labels(
            np.array(tick_points, float), tick_labels, font_size=14, **label_style
        )
        titles = [
            ((x0 + x1) / 2, y1 + 2.6 * off, datum),
            (x0 - 3.2 * off, (y0 + y1) / 2, datum),
            (x0, y0, datum - top - 1.2 * off),
        ]
        plotter.add_point_labels(
            np.array(titles, float),
            ["x (µm)", "y (µm)", "height (µm)"],
            font_size=16,
            **label_style,
        )
        bar = _nice_length(0.25 * (x1 - x0))
        bar_y = y1 + 4.2 * off
        plotter.add_mesh(
            pv.Line((x1 - bar, bar_y, datum), (x1, bar_y, datum)), color="black", line_width=6
        )
        plotter.add_point_labels(
            np.array([[x1 - bar / 2, bar_y + off, datum]]),
            [f"{bar:.0f} µm"],
            font_size=16,
            **label_style,
        )
        if title:
            plotter.add_text(title, font_size=10, color="black")
        # look from the objective side (depth grows away from the viewer), obliquely
        cx, cy, cz = (x0 + x1) / 2, (y0 + y1) / 2, (zmin + datum) / 2
        plotter.camera_position = [
            (cx - 0.3 * size, cy + 1.1 * size, cz - 1.2 * size),
            (cx, cy, cz),
            (0.0, 0.0, -1.0),
        ]
        plotter.reset_camera()
        camera = plotter.camera
        camera.zoom(1.05)
        # lift the scene a little on the screen: the colour bar lies below it
        up = np.asarray(camera.up, float)
        lift = -0.06 * size * up / np.linalg.norm(up)
        camera.position = tuple(np.asarray(camera.position) + lift)
        camera.focal_point = tuple(np.asarray(camera.focal_point) + lift)
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return {
        "clim": clim,
        "scale_bar_um": float(bar),
        "simplified": bool(simplified),
        "triangles_drawn": int(shown.n_cells),
    }


def _cluster_chunks(mesh, cells: int, bounds: tuple[np.ndarray, np.ndarray]):
    """A mesh (in memory or a :class:`mpm3d.meshstream.DiskMesh`) simplified a chunk at a
    time by uniform vertex clustering (Rossignac & Borrel 1993): ``cells`` bins along the
    longest side of its ``bounds`` (lowest, highest point), each bin's vertex the mean of
    the points in it (over the whole mesh, so chunks meet without cracks), the triangles
    whose corners fall in three bins."""
    import pyvista as pv

    from mpm3d.meshstream import chunks_of, point_chunks_of

    lo, hi = (np.asarray(b, np.float64) for b in bounds)
    size = max(float((hi - lo).max()) / cells, 1e-6)
    n = np.floor((hi - lo) / size).astype(np.int64) + 1

    def bins(p: np.ndarray) -> np.ndarray:
        i = np.clip(np.floor((np.asarray(p, np.float64) - lo) / size).astype(np.int64), 0, n - 1)
        return i[:, 0] + n[0] * (i[:, 1] + n[1] * i[:, 2])

    keys = np.zeros(0, np.int64)
    sums = np.zeros((0, 4))
    for p in point_chunks_of(mesh):
        b = bins(p)
        keys, at = np.unique(np.concatenate([keys, b]), return_inverse=True)
        new = np.column_stack([np.asarray(p, np.float64), np.ones(len(p))])
        both = np.concatenate([sums, new])
        sums = np.stack([np.bincount(at, weights=both[:, k], minlength=len(keys))
                         for k in range(4)], axis=1)  # fmt: skip
    tris = []
    for p, t, _ in chunks_of(mesh)():  # the triangles as the mesh has them (outward)
        c = np.searchsorted(keys, bins(p))[t]
        c = c[(c[:, 0] != c[:, 1]) & (c[:, 1] != c[:, 2]) & (c[:, 0] != c[:, 2])]
        first = np.argmin(c, axis=1)  # each from its least corner, winding kept
        tris.append(np.take_along_axis(c, (first[:, None] + np.arange(3)) % 3, axis=1))
    tris = np.unique(np.concatenate(tris), axis=0)
    points = sums[:, :3] / sums[:, 3:]
    return pv.PolyData(points, np.column_stack([np.full(len(tris), 3), tris]).ravel())
