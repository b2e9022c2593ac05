"""Reading single images whole, or not at all.

OpenCV decodes a JPEG that was cut short (a copy interrupted, a full disk)
without an error: it fills the missing rows with gray and prints a warning
on the process's stderr.  :func:`read_gray` refuses such files instead, from
their structure: a PNG must reach its ``IEND`` chunk, a JPEG must end its
image data with an ``EOI`` marker, a TIFF's pages and pixel data must lie
within the file (:func:`tissue_core.tiff_files.check_complete`).  What
OpenCV and the libraries under it (libtiff, FFmpeg) print on the process's
stderr while they decode goes to the log (:func:`caught_stderr`), so that
the command's own line is the only one on the terminal.
"""

from __future__ import annotations

import logging
import os
import sys
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from tissue_core.errors import SourceError

__all__ = ["caught_stderr", "cut_short", "read_gray", "read_image"]

log = logging.getLogger(__name__)

#: one thread at a time points the process's stderr elsewhere
_STDERR_LOCK = threading.Lock()


@contextmanager
def caught_stderr() -> Iterator[list[str]]:
    """Keep what compiled code prints on the process's stderr in this block off the terminal.

    OpenCV logs a TIFF it cannot decode (``[ WARN:0@0.03] ... TIFFReadDirectory``),
    its AVI reader prints what it finds wrong in a damaged header, and its
    FFmpeg backend logs a codec it cannot open, all straight to file
    descriptor 2.  Yields a list that holds that text (stripped, possibly
    empty) once the block has ended; the caller logs it.
    """
    said: list[str] = []
    with _STDERR_LOCK, tempfile.TemporaryFile() as caught:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):  # no stderr to keep quiet
            yield said
            said.append("")
            return
        try:
            os.dup2(caught.fileno(), 2)
            yield said
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            said.append(caught.read().decode("utf-8", "replace").strip())


_PNG = b"\x89PNG\r\n\x1a\n"


def _png_cut_short(data: bytes) -> bool:
    pos = len(_PNG)
    while pos + 8 <= len(data):
        length = int.from_bytes(data[pos : pos + 4], "big")
        kind = data[pos + 4 : pos + 8]
        pos += 12 + length  # length, type, data, CRC
        if kind == b"IEND":
            return pos > len(data)
    return True


def _jpeg_cut_short(data: bytes) -> bool:
    pos = 2  # after SOI
    while pos + 4 <= len(data):
        if data[pos] != 0xFF:
            return False  # not the structure this walk knows: let the decoder judge
        marker = data[pos + 1]
        if marker == 0xFF:  # fill byte
            pos += 1
            continue
        if marker == 0xDA:  # start of scan: the image data runs to the EOI marker
            return data.find(b"\xff\xd9", pos) < 0
        if 0xD0 <= marker <= 0xD9 or marker == 0x01:  # markers without a length
            pos += 2
            continue
        pos += 2 + int.from_bytes(data[pos + 2 : pos + 4], "big")
    return True


def cut_short(data: bytes) -> bool:
    """Whether PNG or JPEG ``data`` ends before the image does (other formats: False).

    Examples
    --------
    >>> import cv2
    >>> png = cv2.imencode(".png", np.zeros((8, 8), np.uint8))[1].tobytes()
    >>> cut_short(png), cut_short(png[:-20])
    (False, True)
    """
    if data.startswith(_PNG):
        return _png_cut_short(data)
    if data.startswith(b"\xff\xd8"):
        return _jpeg_cut_short(data)
    return False


def read_gray(path: str | os.PathLike) -> np.ndarray:
    """An image file as a gray (H, W) uint8 array.

    Raises
    ------
    SourceError
        One line naming the file: missing, a folder, empty, cut short, or
        not an image OpenCV can decode.
    """
    import cv2

    return read_image(path, flags=cv2.IMREAD_GRAYSCALE)


def read_image(path: str | os.PathLike, *, flags: int | None = None) -> np.ndarray:
    """An image file as OpenCV decodes it with ``flags`` (default: any depth, any colour).

    Raises
    ------
    SourceError
        As :func:`read_gray`.
    """
    import cv2

    if flags is None:
        flags = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR
    path = Path(path)
    if path.is_dir():
        raise SourceError(f"{path} is a folder, not an image")
    if not path.exists():
        raise SourceError(f"no such file: {path}")
    data = path.read_bytes()
    if not data:
        raise SourceError(f"{path} is empty (0 bytes), not an image")
    if cut_short(data):
        raise SourceError(f"{path} is truncated: the file ends before the image does")
    if data[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+"):
        _check_tiff(data, path)
    with caught_stderr() as said:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if said[0]:
        log.info("OpenCV on decoding %s: %s", path, said[0])
    if image is None:
        raise SourceError(f"{path} is not an image OpenCV can read")
    return image


def _check_tiff(data: bytes, path: Path) -> None:
    """Refuse a TIFF cut short, naming what is missing (OpenCV says only that it failed)."""
    import io

    import tifffile

    from tissue_core.tiff_files import check_complete, tifffile_messages

    try:
        with tifffile_messages() as messages, tifffile.TiffFile(io.BytesIO(data)) as tif:
            check_complete(tif, tif.series[0], str(path), messages)
    except SourceError:
        raise
    except Exception as exc:  # tifffile raises many types on damaged files
        log.info("tifffile on %s: %s", path, exc)  # OpenCV may still decode it
