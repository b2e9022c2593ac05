"""Writing a figure in one or more formats, atomically and reproducibly."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib import rc_context
from matplotlib.figure import Figure

from strain2d.errors import InputError
from tissue_core.outputs import replaced_on_success

__all__ = ["save_figure"]

#: zlib level of PNG files (1, the fastest, to 9; Pillow's default is 6)
PNG_COMPRESSION = 1


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
        # PNG: zlib's fastest level, a quarter of the default's time for files a few % larger
        options = {"pil_kwargs": {"compress_level": PNG_COMPRESSION}} if fmt == "png" else {}
        # a fixed salt makes SVG element ids, hence the file, reproducible
        with replaced_on_success(out) as tmp, rc_context({"svg.hashsalt": "strain2d"}):
            if fmt == "png" and _plain_savefig():
                _draw_png(fig, tmp, dpi, options["pil_kwargs"], tight=tight)
            else:
                fig.savefig(
                    tmp,
                    format=fmt,
                    dpi=dpi,
                    bbox_inches="tight" if tight else None,
                    metadata=metadata,
                    **options,
                )
        written.append(out)
    return written


def _plain_savefig() -> bool:
    """Whether ``savefig`` would draw the figure as it is (no savefig style of a user's)."""
    from matplotlib import rcParams

    return (
        rcParams["savefig.bbox"] is None
        and not rcParams["savefig.transparent"]
        and all(str(rcParams[f"savefig.{c}"]) == "auto" for c in ("facecolor", "edgecolor"))
    )


def _draw_png(fig: Figure, path, dpi: float, pil_kwargs: dict, *, tight: bool = False) -> None:
    """The PNG ``savefig`` writes, drawn once: ``savefig`` draws a figure with a layout
    engine twice (once to lay it out, once to render it at the layout found), and three
    times with ``bbox_inches="tight"``; here ``tight`` crops the drawn pixels instead (see
    :func:`_crop`)."""
    import matplotlib.image
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    kept = fig.dpi
    fig.set_dpi(dpi)
    try:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        pixels = np.asarray(canvas.buffer_rgba())
        if tight:
            pixels = _crop(pixels, fig, dpi)
        matplotlib.image.imsave(path, pixels, format="png", dpi=dpi, pil_kwargs=pil_kwargs)
    finally:
        fig.set_dpi(kept)


def _crop(pixels: np.ndarray, fig: Figure, dpi: float) -> np.ndarray:
    """The drawn figure cropped to what is drawn on its background, with a margin of
    ``savefig.pad_inches``, as ``bbox_inches="tight"`` crops it; a figure with nothing
    drawn is kept whole."""
    from matplotlib import rcParams
    from matplotlib.colors import to_rgba

    background = np.round(np.asarray(to_rgba(fig.get_facecolor())) * 255).astype(np.uint8)
    if background[3] == 0:  # a transparent figure: whatever has some opacity is drawn
        drawn = pixels[..., 3] != 0
    else:
        drawn = (pixels != background).any(axis=-1)
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    if rows.size == 0:
        return pixels
    pad = round(float(rcParams["savefig.pad_inches"]) * dpi)
    top, bottom = rows[0] - pad, rows[-1] + 1 + pad
    left, right = cols[0] - pad, cols[-1] + 1 + pad
    h, w = drawn.shape
    cropped = pixels[max(top, 0) : min(bottom, h), max(left, 0) : min(right, w)]
    widen = ((max(-top, 0), max(bottom - h, 0)), (max(-left, 0), max(right - w, 0)))
    if any(any(side) for side in widen):  # the margin reaches past the figure: its colour
        cropped = np.concatenate(
            [np.pad(cropped[..., c], widen, constant_values=background[c])[..., None]
             for c in range(4)],
            axis=-1,
        )  # fmt: skip
    return cropped
