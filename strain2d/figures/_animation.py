"""A video of the strain field drawn on the frames: MP4 through ffmpeg, or GIF.

The figure (axes, colour bars, titles, labels) is laid out and drawn once by
Matplotlib on an Agg canvas (no pyplot).  Each frame is then drawn without a
Matplotlib draw: the video frame sampled into each panel as
``imshow(interpolation="nearest")`` samples it, the filled contours of the
nodal strain rasterised on the deformed mesh (linear within each triangle,
banded at the colour scale's levels as ``tricontourf`` bands them), the
mesh's edges, all seen through what Matplotlib draws over the image (the
axes' frame); only the time label is drawn by Matplotlib.  These steps run
in NumPy, or compiled (:mod:`strain2d.figures._animation_kernels`, the same
pixels) where numba is loaded already or the video is long.  MP4 frames
stream to imageio-ffmpeg's ffmpeg as H.264, GIF frames go to imageio's
pillow plugin.  Both are imported when a video is written.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from strain2d.errors import InputError
from strain2d.figures._checks import _check_2d, _check_image, _finite, _scalars
from strain2d.figures._maps import _show_image
from strain2d.figures._style import (
    _colorbar,
    _colour_scale,
    _label,
    _unit_label,
    completed_limits,
)
from surface_strain import StrainField

__all__ = ["write_strain_animation"]


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
    length=None,
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
    length : PixelScale, keyword-only
        The pixel size: axes in its unit instead of pixels.

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
    limits = completed_limits(field, components, limits)
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
            label = time_labels[k] if time_labels is not None else f"frame {k} / {T - 1}"
            if not state:
                state = _animation_figure(
                    image, field, components, scales, alpha, max_width, dpi, length, label=label
                )
            rgb = _animation_frame(state, image, field, k, scalars, components, label)
            if writer is None:
                writer = _open_writer(tmp, kind, fps, rgb.shape)
            if kind == ".mp4":
                writer.send(rgb)
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
            # a faster search than x264's default: a third of its time, a file 6 % larger
            output_params=["-preset", "superfast", "-movflags", "+faststart"],
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


#: How much an edge of the mesh darkens a pixel it crosses fully: the strain maps' edges are
#: 0.3 pt wide (0.42 px at 100 dpi) at 45 % opacity
_EDGE_SHADE = 0.45 * 0.3 / 72 * 100


def _animation_figure(
    image, field, components, scales, alpha, max_width, dpi, length, *, label: str = " "
) -> dict:
    """Lay the animation's figure out, draw what does not change once, prepare every panel.

    The figure is laid out with ``label`` as its title, whose height is kept
    for every frame.  Returns what :func:`_animation_frame` draws frames
    with: the figure, its axes and title, the drawing without the frame
    (``under``, (H, W, 3) uint8) and, per panel, its pixels in the output,
    where they sample the frame and how much of them the axes' frame covers.
    """
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
    images = []
    for ax, comp in zip(axes, components, strict=True):
        images.append(_show_image(ax, image, vmin=vmin, vmax=vmax, length=length))
        cbar = _colorbar(fig, ax, scales[comp], _unit_label(comp), alpha=alpha, shrink=0.9)
        cbar.ax.tick_params(labelsize=7)
        cbar.ax.yaxis.label.set_fontsize(8)
        ax.set_title(_label(comp), fontsize=10)
        ax.tick_params(labelsize=7)
        ax.xaxis.label.set_fontsize(8)
        ax.yaxis.label.set_fontsize(8)
    # what does not change is drawn once, without the frame's image and the title: over
    # white axes (the drawing around the image and over it), then over black ones, which
    # leaves how much of the image shows through each pixel (all of it, but where the axes'
    # frame covers it)
    for artist in images:
        artist.set_visible(False)
    title = fig.suptitle(label, fontsize=10)
    canvas.draw()  # lays the figure out; the layout is kept for every frame (no jitter)
    fig.set_layout_engine("none")
    size = (width_px, height_px)
    title_rows = _title_rows(fig, canvas, title, size)
    _clear_rows(fig, canvas, title_rows)
    under = _rgb(canvas, size)
    faces = [ax.get_facecolor() for ax in axes]
    for ax in axes:
        ax.patch.set_facecolor("black")
        fig.draw_artist(ax.patch)
        for spine in ax.spines.values():
            fig.draw_artist(spine)
    dark = _rgb(canvas, size)
    for ax, face, artist in zip(axes, faces, images, strict=True):
        ax.patch.set_facecolor(face)
        artist.set_visible(True)
    return {
        "fig": fig,
        "canvas": canvas,
        "axes": axes,
        "label": title,
        "size": size,
        "under": under,
        "title_rows": title_rows,
        "panels": [_panel(ax, image.shape[:2], canvas, under, dark) for ax in axes],
        "gray": (vmin, vmax, _colour_table(images[0])),
        "bands": {c: _bands(scales[c], alpha) for c in components},
        "edges": _mesh_edges(field.triangles),
        "compiled": _compiled(field.n_frames),
    }


#: frames from which the animation draws its frames with the compiled kernels even where
#: no tracker loaded numba: loading it (0.2 s) and its compiler (0.15-0.35 s) costs what the
#: kernels save on some 40-60 frames of two panels at 960 px
_COMPILED_FROM = 100


def _compiled(n_frames: int) -> bool:
    """Whether to draw the frames with the compiled kernels
    (:mod:`strain2d.figures._animation_kernels`): numba already loaded here (by gdic or
    dic), or a video long enough to pay for loading it.  The pixels are the same."""
    import sys

    return "numba" in sys.modules or n_frames >= _COMPILED_FROM


def _rgb(canvas, size: tuple[int, int], rows: int | None = None) -> np.ndarray:
    """The canvas (its first ``rows``) as (H, W, 3) uint8 of ``size`` = (W, H), padded white."""
    w, h = size
    h = h if rows is None else rows
    rgb = np.asarray(canvas.buffer_rgba())[:h, :w, :3]
    out = np.full((h, w, 3), 255, np.uint8)
    out[: rgb.shape[0], : rgb.shape[1]] = rgb
    return out


def _title_rows(fig, canvas, title, size: tuple[int, int]) -> int:
    """How many rows at the top of the output hold the title alone: down to the first row
    below it that anything else is drawn in."""
    from matplotlib.colors import to_rgba

    height = canvas.get_width_height()[1]
    below = int(np.ceil(height - title.get_window_extent(canvas.get_renderer()).y0))
    rgba = np.asarray(canvas.buffer_rgba())[: size[1], : size[0]]
    background = np.round(np.array(to_rgba(fig.get_facecolor())) * 255).astype(np.uint8)
    drawn = np.flatnonzero((rgba[below:] != background).any(axis=(1, 2)))
    return int(min(below + (drawn[0] if drawn.size else rgba.shape[0]), size[1]))


def _clear_rows(fig, canvas, rows: int) -> None:
    """Paint the canvas's first ``rows`` rows in the figure's colour."""
    from matplotlib.colors import to_rgba

    buffer = np.asarray(canvas.buffer_rgba())
    buffer[:rows] = np.round(np.array(to_rgba(fig.get_facecolor())) * 255).astype(np.uint8)


def _panel(ax, shape: tuple[int, int], canvas, under: np.ndarray, dark: np.ndarray) -> dict:
    """Where a panel's image lies in the output, and how it samples a frame."""
    height = canvas.get_width_height()[1]
    rows_out, cols_out = under.shape[:2]
    box = ax.bbox  # display coordinates: x to the right, y up from the bottom of the canvas
    c0 = max(0, int(np.ceil(box.x0 - 0.5)))
    c1 = min(cols_out - 1, int(np.floor(box.x1 - 0.5)))
    r0 = max(0, int(np.ceil(height - box.y1 - 0.5)))
    r1 = min(rows_out - 1, int(np.floor(height - box.y0 - 0.5)))
    (sx, _, tx), (_, sy, ty), _ = ax.transData.get_matrix()
    # the centres of the panel's pixels in image (data) coordinates
    x_data = (np.arange(c0, c1 + 1) + 0.5 - tx) / sx
    y_data = (height - (np.arange(r0, r1 + 1) + 0.5) - ty) / sy
    window = (slice(r0, r1 + 1), slice(c0, c1 + 1))
    through = (under[window].astype(np.float32) - dark[window]) / 255.0
    return {
        "window": window,
        "x_data": x_data,
        "y_data": y_data,
        "extent": tuple(shape),
        "shape": tuple(shape),
        "sample": _sampling(x_data, y_data, shape, shape),
        # image coordinates -> the window's pixel coordinates (pixel centres at whole numbers)
        "to_window": (sx, tx - 0.5 - c0, -sy, height - ty - 0.5 - r0),
        "dark": dark[window].astype(np.float32),
        "through": through,
    }


def _sampling(x_data, y_data, extent: tuple[int, int], shape: tuple[int, int]):
    """The rows and columns of an image of ``shape`` that the panel's pixels show.

    The nearest pixel, as ``imshow(interpolation="nearest")`` samples; an
    image of another size than the first frame's ``extent`` (H, W) is
    stretched over it, as ``imshow`` shows it after ``set_data``.
    """
    (he, we), (h, w) = extent, shape
    cols = np.floor((x_data + 0.5) * (w / we)).astype(np.intp).clip(0, w - 1)
    rows = np.floor((y_data + 0.5) * (h / he)).astype(np.intp).clip(0, h - 1)
    return rows, cols


def _colour_table(artist) -> np.ndarray:
    """(257, 3) float32: the image's colour map (gray) as Matplotlib quantises it, and white."""
    table = artist.cmap(np.arange(256) / 255.0, bytes=True)[:, :3]
    return np.vstack([table, [255, 255, 255]]).astype(np.float32)


def _bands(scale, alpha: float) -> dict:
    """A colour scale's bands: (n + 3, 3) colours below, of each band, above, and of none.

    Band ``k`` holds ``levels[k - 1] < v <= levels[k]`` (0: below the scale,
    n + 1: above it), as ``tricontourf`` bands values; band n + 2 is no value
    (opacity 0).
    """
    from matplotlib.cm import ScalarMappable

    levels = scale.levels
    step = levels[1] - levels[0]
    middles = np.concatenate([[levels[0] - step], levels[:-1] + step / 2, [levels[-1] + step]])
    rgba = ScalarMappable(norm=scale.norm, cmap=scale.cmap).to_rgba(middles, bytes=True)
    colours = np.vstack([rgba[:, :3], [0, 0, 0]]).astype(np.float32)
    opacity = np.full(len(colours), alpha, np.float32)
    opacity[-1] = 0.0
    return {"low": float(levels[0]), "step": float(step), "n": len(levels) - 1,
            "colours": colours, "opacity": opacity}  # fmt: skip


def _mesh_edges(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's edges once each, (E, 2) nodes, and the edges of each triangle, (M, 3)."""
    pairs = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    edges, which = np.unique(pairs, axis=0, return_inverse=True)
    return edges, which.reshape(-1, 3)


def _animation_frame(state, image, field, k, scalars, components, label) -> np.ndarray:
    """Draw frame ``k``: (H, W, 3) uint8 with even H and W."""
    out = state["under"].copy()
    pos = field.points[k]
    valid = field.element_valid[k]
    triangles = field.triangles
    compiled = state["compiled"]
    for panel, comp in zip(state["panels"], components, strict=True):
        rgb = _gray(state, image, panel, compiled)
        values = scalars[comp][k]
        good = valid & np.all(np.isfinite(values[triangles]), axis=1)
        if good.any():
            sx, tx, sy, ty = panel["to_window"]
            xy = np.column_stack([pos[:, 0] * sx + tx, pos[:, 1] * sy + ty])
            _fill_bands(rgb, xy, values, triangles, good, state["bands"][comp], compiled)
            _shade_edges(rgb, xy, state["edges"], good, compiled)
        if compiled:
            from strain2d.figures._animation_kernels import compose

            compose(out[panel["window"]], panel["dark"], panel["through"], rgb)
        else:
            shown = panel["dark"] + panel["through"] * rgb
            out[panel["window"]] = shown.clip(0.0, 255.0).round().astype(np.uint8)
    rows = state["title_rows"]
    if rows:
        fig, canvas = state["fig"], state["canvas"]
        _clear_rows(fig, canvas, rows)
        state["label"].set_text(label)
        fig.draw_artist(state["label"])
        out[:rows] = _rgb(canvas, state["size"], rows)
    return out


def _gray(state: dict, image: np.ndarray, panel: dict, compiled: bool = False) -> np.ndarray:
    """The frame as the panel shows it: (h, w, 3) float32 at the panel's pixels
    (``compiled``: 8-bit gray frames through :func:`~strain2d.figures._animation_kernels.gray`,
    the same pixels)."""
    shape = image.shape[:2]
    if shape != panel["shape"]:
        panel["shape"] = shape
        panel["sample"] = _sampling(panel["x_data"], panel["y_data"], panel["extent"], shape)
    rows, cols = panel["sample"]
    vmin, vmax, table = state["gray"]
    if compiled and image.ndim == 2 and image.dtype == np.uint8 and (vmin, vmax) == (0.0, 255.0):
        from strain2d.figures._animation_kernels import gray

        return gray(image, rows, cols, table)
    seen = image.take(rows, axis=0).take(cols, axis=1)
    if seen.ndim == 2:  # the colour map over vmin..vmax, quantised as imshow quantises it
        if seen.dtype != np.uint8 or (vmin, vmax) != (0.0, 255.0):
            scaled = seen.astype(np.float32)
            scaled -= vmin
            scaled *= 256.0 / (vmax - vmin)
            np.clip(scaled, 0, 255, out=scaled)
            # not a number: the colour map's "bad" colour, transparent over the white axes
            seen = np.nan_to_num(scaled, copy=False, nan=256).astype(np.uint16)
        return table.take(seen, axis=0)
    if seen.dtype == np.uint8:  # colour frames as they are
        rgb, opacity = seen[..., :3].astype(np.float32), seen[..., 3:] / np.float32(255)
    else:
        seen = np.nan_to_num(seen.astype(np.float32), nan=0.0).clip(0.0, 1.0)
        rgb, opacity = seen[..., :3] * np.float32(255), seen[..., 3:]
    if opacity.shape[-1]:  # RGBA over the white axes
        rgb = rgb * opacity + 255.0 * (1.0 - opacity)
    return rgb


def _fill_bands(rgb, xy, values, triangles, good, bands, compiled: bool = False) -> None:
    """Blend the banded field on the triangles ``good`` over ``rgb`` (h, w, 3) float32, in place.

    ``xy`` (N, 2) are the nodes in the pixel coordinates of ``rgb`` (pixel
    centres at whole numbers).  The field is linear within each triangle
    (clipped to its nodes' range) and coloured by band at the bands'
    opacity.  As ``tricontourf`` without antialiasing fills each band up to
    the pixels its edge touches, a pixel beside a higher band is covered by
    both: the higher band's colour is blended over it again.  ``compiled``:
    the same pixels from :func:`strain2d.figures._animation_kernels.fill_bands`.
    """
    used = np.flatnonzero(good)
    corners = xy[triangles[used]]  # (m, 3, 2)
    # the pixels the triangles can touch
    (x0, y0), (x1, y1) = corners.min(axis=(0, 1)), corners.max(axis=(0, 1))
    c0, r0 = max(int(np.floor(x0)), 0), max(int(np.floor(y0)), 0)
    c1, r1 = min(int(np.ceil(x1)) + 1, rgb.shape[1]), min(int(np.ceil(y1)) + 1, rgb.shape[0])
    if c1 <= c0 or r1 <= r0:
        return
    rgb = rgb[r0:r1, c0:c1]
    corners = corners - np.array([c0, r0], np.float64)
    # each triangle's plane through its corners' values, v = gx x + gy y + g0, and their range
    v = values[triangles[used]]  # (m, 3)
    d1, d2 = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]
    dv1, dv2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    det[det == 0] = np.inf  # a triangle without area: its first corner's value
    plane = np.empty((len(used), 5), np.float32)
    plane[:, 0] = (dv1 * d2[:, 1] - dv2 * d1[:, 1]) / det
    plane[:, 1] = (dv2 * d1[:, 0] - dv1 * d2[:, 0]) / det
    plane[:, 2] = v[:, 0] - plane[:, 0] * corners[:, 0, 0] - plane[:, 1] * corners[:, 0, 1]
    plane[:, 3], plane[:, 4] = v.min(axis=1), v.max(axis=1)
    if compiled:
        from strain2d.figures._animation_kernels import fill_bands

        fill_bands(rgb, np.ascontiguousarray(corners), plane, bands["low"], bands["step"],
                   bands["n"], bands["colours"], bands["opacity"])  # fmt: skip
        return
    r, c, t = _raster_triangles(corners, rgb.shape[:2])
    gx, gy, g0, low, high = plane.take(t, axis=0).T
    field = (gx * c.astype(np.float32) + gy * r.astype(np.float32) + g0).clip(low, high)
    band = np.full(rgb.shape[:2], -1, np.int16)  # -1: none (the last colour, transparent)
    level = np.ceil((field - bands["low"]) / bands["step"]).clip(0, bands["n"] + 1)
    band.reshape(-1)[r * rgb.shape[1] + c] = level
    colours, opacity = bands["colours"], bands["opacity"]
    rgb += (colours.take(band, axis=0, mode="wrap") - rgb) * opacity.take(band, mode="wrap")[
        ..., None
    ]
    # the highest band beside each pixel
    beside = np.full_like(band, -1)
    np.maximum(beside[:, 1:], band[:, :-1], out=beside[:, 1:])
    np.maximum(beside[:, :-1], band[:, 1:], out=beside[:, :-1])
    np.maximum(beside[1:], band[:-1], out=beside[1:])
    np.maximum(beside[:-1], band[1:], out=beside[:-1])
    r, c = np.nonzero((beside > band) & (band >= 0))
    top = beside[r, c]
    rgb[r, c] += (colours[top] - rgb[r, c]) * opacity[top][:, None]


def _raster_triangles(corners: np.ndarray, shape: tuple[int, int]):
    """The pixels whose centres lie in each triangle: (rows, cols, triangle) int arrays.

    ``corners`` (M, 3, 2) in pixel coordinates (pixel centres at whole
    numbers); pixels outside ``shape`` (H, W) are left out.  A pixel on an
    edge between two triangles is listed for both.
    """
    h, w = shape
    x, y = corners[..., 0], corners[..., 1]
    top = np.ceil(y.min(axis=1)).clip(0, h).astype(np.intp)
    bottom = np.floor(y.max(axis=1)).clip(-1, h - 1).astype(np.intp)
    n_rows = np.maximum(bottom - top + 1, 0)
    tri = np.repeat(np.arange(len(corners)), n_rows)
    row = top[tri] + np.arange(tri.size) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows)
    # where each row's centre line crosses the triangle's edges
    left = np.full(row.size, np.inf)
    right = np.full(row.size, -np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        xa, ya, xb, yb = x[tri, i], y[tri, i], x[tri, j], y[tri, j]
        crosses = (np.minimum(ya, yb) <= row) & (row <= np.maximum(ya, yb)) & (ya != yb)
        at = xa + (row - ya) * (xb - xa) / np.where(crosses, yb - ya, 1.0)
        left = np.where(crosses, np.minimum(left, at), left)
        right = np.where(crosses, np.maximum(right, at), right)
    crossed = np.isfinite(left)
    first = np.where(crossed, np.ceil(left), 0).clip(0, w).astype(np.intp)
    last = np.where(crossed, np.floor(right), -1).clip(-1, w - 1).astype(np.intp)
    n_cols = np.maximum(last - first + 1, 0)
    span = np.repeat(np.arange(row.size), n_cols)
    col = first[span] + np.arange(span.size) - np.repeat(np.cumsum(n_cols) - n_cols, n_cols)
    return row[span], col, tri[span]


def _shade_edges(rgb, xy, edges, good, compiled: bool = False) -> None:
    """Darken ``rgb`` in place along the edges of the triangles ``good``, as thin lines.

    Each edge is drawn on its own, so where several meet at a node they
    darken it together, as the strain maps' edges do.  ``compiled``: the
    same pixels through :func:`~strain2d.figures._animation_kernels.shade_edges`.
    """
    import cv2

    pairs, of_triangle = edges
    drawn = np.zeros(len(pairs), bool)
    drawn[of_triangle[good].ravel()] = True
    ends = xy[pairs[drawn]]  # (e, 2, 2)
    cover = np.zeros(rgb.shape[:2], np.uint8)
    cv2.polylines(cover, list(np.round(ends * 16).astype(np.int32)), False, 255, 1, cv2.LINE_AA, 4)
    # the pixel of a node: each edge that ends there covers about half of it
    node = np.round(ends.reshape(-1, 2)).astype(np.intp)
    inside = (node[:, 0] >= 0) & (node[:, 0] < rgb.shape[1])
    inside &= (node[:, 1] >= 0) & (node[:, 1] < rgb.shape[0])
    per_level = np.float32(_EDGE_SHADE) / 255
    at, count = np.unique(node[inside, 1] * rgb.shape[1] + node[inside, 0], return_counts=True)
    darkest = (1.0 - _EDGE_SHADE / 2) ** count
    if compiled:
        from strain2d.figures._animation_kernels import shade_edges

        shade_edges(rgb, cover, per_level, at // rgb.shape[1], at % rgb.shape[1], darkest)
        return
    shade = 1.0 - per_level * cover
    flat = shade.reshape(-1)
    flat[at] = np.minimum(flat[at], darkest)
    rgb *= shade[..., None]


def _gray_range(image: np.ndarray) -> tuple[float, float]:
    if image.dtype == np.uint8:
        return 0.0, 255.0
    finite = _finite(image)
    if finite.size == 0 or finite.max() == finite.min():
        return 0.0, 1.0
    return float(finite.min()), float(finite.max())
