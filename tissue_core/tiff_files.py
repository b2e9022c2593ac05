"""TIFF files read whole or refused: what tifffile says about a broken file, in one error.

tifffile reads what it can of a damaged file: a broken chain of pages (a
file cut short by a full disk or a killed copy) gives fewer pages and an
``ERROR`` log line instead of an exception, so a truncated movie reads as
"1 frame" and the line lands on the terminal before the command's own.
:func:`tifffile_messages` collects those lines while a file is read (they
go to the log at INFO, shown with ``-v``), and :func:`check_complete` turns
them, and data that runs past the end of the file, into one
:class:`~tissue_core.errors.SourceError` that says the file is truncated.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

from tissue_core.errors import SourceError

__all__ = ["check_complete", "tifffile_messages"]

log = logging.getLogger(__name__)

#: what tifffile logs when the chain of pages or a page's data is broken
_DAMAGE = re.compile(
    r"page|IFD|corrupted|ByteCounts|StripOffsets|data offset|ImageJ series metadata",
    re.IGNORECASE,
)


@contextmanager
def tifffile_messages() -> Iterator[list[str]]:
    """Collect what tifffile logs while this thread reads a file, instead of printing it.

    Yields the list of the messages that tell of a broken file (for
    :func:`check_complete`); every message is logged again at INFO, under
    this module's name.
    """
    messages: list[str] = []
    thread = threading.get_ident()

    def collect(record: logging.LogRecord) -> bool:
        if record.thread != thread:
            return True
        text = record.getMessage()
        log.info("tifffile: %s", text)
        if record.levelno >= logging.ERROR and _DAMAGE.search(text):
            messages.append(text)
        return False

    tiff_logger = logging.getLogger("tifffile")
    tiff_logger.addFilter(collect)
    try:
        yield messages
    finally:
        tiff_logger.removeFilter(collect)


def check_complete(tif, series, path: str, messages: list[str]) -> None:
    """Raise SourceError when the file is cut short or its pages are damaged.

    Parameters
    ----------
    tif : tifffile.TiffFile
        The open file.
    series : tifffile.TiffPageSeries
        The series that is read (usually ``tif.series[0]``).
    path : str
        The file's name, for the message.
    messages : list of str
        What :func:`tifffile_messages` collected while the file was opened.
    """
    size = tif.filehandle.size
    n_pages = len(tif.pages)  # indexes every page: a broken chain is logged here
    if n_pages == 0 or not series.shape:
        raise SourceError(f"{path} is a TIFF file that holds no images")
    md = tif.imagej_metadata if tif.is_imagej else None
    announced = md.get("images") if isinstance(md, Mapping) else None
    planes = math.prod(n for a, n in zip(series.axes, series.shape, strict=True) if a not in "YXS")
    if isinstance(announced, int) and announced > planes:
        raise SourceError(
            f"{path} is truncated or damaged: its ImageJ metadata announces {announced} "
            f"images but the file holds {n_pages} page{'s' if n_pages != 1 else ''} "
            f"({size} bytes)"
        )
    if messages:
        detail = re.sub(r"^<[^>]*>\s*", "", messages[0])
        raise SourceError(f"{path} is truncated or damaged: {detail} (the file has {size} bytes)")
    if series.dataoffset is not None:
        end = series.dataoffset + series.size * series.dtype.itemsize
    else:
        end = 0
        for page in series.pages:
            if page is None:
                raise SourceError(f"{path} is truncated or damaged: a page of the stack is missing")
            ends = [o + c for o, c in zip(page.dataoffsets, page.databytecounts, strict=False)]
            end = max([end, *ends])
    if end > size:
        raise SourceError(
            f"{path} is truncated: its pixel data runs to byte {end} but the file "
            f"ends at byte {size}"
        )
