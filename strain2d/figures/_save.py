"""Writing a figure in one or more formats, atomically and reproducibly."""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

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
            if fmt == "png" and not tight and _plain_savefig():
                _draw_png(fig, tmp, dpi, options["pil_kwargs"])
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


def _draw_png(fig: Figure, path, dpi: float, pil_kwargs: dict) -> None:
    """The PNG ``savefig`` writes, drawn once: ``savefig`` draws a figure with a layout
    engine twice (once to lay it out, once to render it at the layout found)."""
    import matplotlib.image
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    kept = fig.dpi
    fig.set_dpi(dpi)
    try:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()
        matplotlib.image.imsave(
            path, canvas.buffer_rgba(), format="png", dpi=dpi, pil_kwargs=pil_kwargs
        )
    finally:
        fig.set_dpi(kept)
