"""A video of the strain field drawn on the frames: MP4 through ffmpeg, or GIF.

One figure is laid out and drawn once on an Agg canvas (no pyplot); each
frame then draws only what changes (the image, the contours, the mesh and the
time) over the kept background; MP4 frames stream to imageio-ffmpeg's ffmpeg as H.264, GIF frames
go to imageio's pillow plugin.  Both are imported when a video is written.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from strain2d.errors import InputError
from strain2d.figures._checks import _check_2d, _check_image, _finite, _scalars
from strain2d.figures._maps import _draw_contours, _show_image, _triangulation
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
            if not state:
                state = _animation_figure(
                    image, field, components, scales, alpha, max_width, dpi, length
                )
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


def _animation_figure(image, field, components, scales, alpha, max_width, dpi, length) -> dict:
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
        state["images"].append(_show_image(ax, image, vmin=vmin, vmax=vmax, length=length))
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
    canvas = state["canvas"]
    if "background" not in state:
        # the first frame lays the figure out; then everything that does not change (axes,
        # colour bars, titles) is drawn once, kept, and only the frame's own artists are
        # drawn over it from then on (about 4 times faster than redrawing the figure)
        canvas.draw()
        fig.set_layout_engine("none")  # keep the first frame's layout: no jitter
        for artist in _changing(state):
            artist.set_animated(True)
        canvas.draw()
        state["background"] = canvas.copy_from_bbox(fig.bbox)
    canvas.restore_region(state["background"])
    for artist in _changing(state):
        artist.set_animated(True)  # new contour sets too
        fig.draw_artist(artist)
    for ax in state["axes"]:  # the frame lines over the image, as a full drawing has them
        for spine in ax.spines.values():
            fig.draw_artist(spine)
    rgb = np.asarray(canvas.buffer_rgba())[..., :3]
    w, h = state["size"]
    out = np.full((h, w, 3), 255, np.uint8)
    hh, ww = min(h, rgb.shape[0]), min(w, rgb.shape[1])
    out[:hh, :ww] = rgb[:hh, :ww]
    return out


def _changing(state) -> list:
    """The artists that change from frame to frame, in drawing order."""
    out = []
    for j in range(len(state["axes"])):
        out.append(state["images"][j])
        if state["contours"][j] is not None:
            out.append(state["contours"][j])
        out.append(state["meshes"][j])
    return [*out, state["label"]]


def _gray_range(image: np.ndarray) -> tuple[float, float]:
    if image.dtype == np.uint8:
        return 0.0, 255.0
    finite = _finite(image)
    if finite.size == 0 or finite.max() == finite.min():
        return 0.0, 1.0
    return float(finite.min()), float(finite.max())
