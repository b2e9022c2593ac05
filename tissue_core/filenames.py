"""File and folder names that are not UTF-8: read and written, and shown readably.

On Linux and macOS a name is a string of bytes.  Names made on Windows or on
a shared drive in another encoding (``vid\\xe9o.avi`` in Latin-1) are not
UTF-8; Python gives them as text with lone surrogates (``"vid\\udce9o.avi"``,
PEP 383) that it maps back to the same bytes, so Python's own file functions
open them.  Two things still fail on them:

* libraries that take a name and convert it to UTF-8 in compiled code
  (OpenCV's ``VideoCapture``, ``VideoWriter`` and ``FileStorage``, VTK's
  readers and writers): they raise ``UnicodeEncodeError``, or crash the
  process.  :func:`utf8_alias` gives them a UTF-8 name for the same file or
  folder to read: a symbolic link in a private temporary folder;
  :func:`utf8_output` a UTF-8 name to write a file under, moved to the real
  name when done;
* text that shows a name (JSON, HTML, CSV, figure titles, messages on a
  terminal) cannot hold a lone surrogate: UTF-8 has no code for it.
  :func:`readable` shows each byte that is not UTF-8 as ``\\xNN``, so the
  name stays recognisable and the text stays valid UTF-8.

Names that are UTF-8 pass through both unchanged, and so do all names on
Windows, whose file system stores text.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from tissue_core.errors import SourceError

__all__ = ["exact_name", "is_utf8", "readable", "utf8_alias", "utf8_output"]

#: a lone surrogate: an undecodable byte of a name (U+DC80..U+DCFF), or any other
_SURROGATE = re.compile("[\ud800-\udfff]")


def _escape(match: re.Match) -> str:
    code = ord(match.group())
    if 0xDC80 <= code <= 0xDCFF:  # the byte os.fsdecode could not decode
        return f"\\x{code - 0xDC00:02x}"
    return f"\\u{code:04x}"


def readable(text: str | os.PathLike) -> str:
    """``text`` (a name, or text holding names) as valid UTF-8 text.

    Each byte of a name that is not UTF-8 is shown as ``\\xNN``; other text
    is returned unchanged.

    Examples
    --------
    >>> import os
    >>> readable(os.fsdecode(b"/data/vid\\xe9o.avi"))
    '/data/vid\\\\xe9o.avi'
    >>> readable("vidéo.avi")
    'vidéo.avi'
    """
    text = os.fspath(text)
    if isinstance(text, bytes):
        text = os.fsdecode(text)
    return _SURROGATE.sub(_escape, text)


def is_utf8(path: str | os.PathLike) -> bool:
    """Whether ``path`` is UTF-8 text that libraries can take as it is."""
    return _SURROGATE.search(os.fspath(path)) is None


def exact_name(name: str | os.PathLike) -> str | None:
    """The bytes of a name that is not UTF-8, in hexadecimal; None for a UTF-8 name.

    Records that show a name with :func:`readable` keep this beside it, so that
    the name read back from them is the exact one (two names may read alike).

    Examples
    --------
    >>> import os
    >>> exact_name(os.fsdecode(b"r\\xe9sultat")), exact_name("run")
    ('72e973756c746174', None)
    """
    name = os.fspath(name)
    return None if is_utf8(name) else os.fsencode(name).hex()


def _private_folder(path: Path) -> str:
    """A new private temporary folder with a UTF-8 name, for a name stand-in for ``path``."""
    try:
        folder = tempfile.mkdtemp(prefix="tissue-strain-name-")
    except OSError as exc:
        raise SourceError(
            f"{readable(path)}: its name is not UTF-8, and no temporary folder for a UTF-8 "
            f"name could be made ({exc.strerror or exc})"
        ) from None
    if not is_utf8(folder):
        os.rmdir(folder)
        raise SourceError(
            f"{readable(path)}: its name is not UTF-8, and neither is the temporary folder "
            f"{readable(folder)} (set TMPDIR to a folder with a UTF-8 name)"
        )
    return folder


@contextlib.contextmanager
def utf8_alias(path: str | os.PathLike) -> Iterator[Path]:
    """A UTF-8 name for the existing file or folder ``path``, for libraries that read it.

    When ``path`` is UTF-8 it is yielded as it is.  Otherwise the name is a
    symbolic link to it in a private temporary folder, removed when the block
    ends (a library that opened the file keeps it open).  The link keeps the
    file's suffix: libraries choose formats by it.  Libraries that write use
    :func:`utf8_output`.

    Raises
    ------
    SourceError
        When no link can be made (no temporary folder, a file system without
        links): names the file.
    """
    path = Path(path)
    if is_utf8(path):
        yield path
        return
    suffix = path.suffix if is_utf8(path.suffix) else ""
    folder = _private_folder(path)
    try:
        link = Path(folder) / f"alias{suffix}"
        try:
            os.symlink(os.path.abspath(path), link, target_is_directory=path.is_dir())
        except OSError as exc:
            raise SourceError(
                f"{readable(path)}: its name is not UTF-8, and no link with a UTF-8 name "
                f"could be made to it ({exc.strerror or exc}); rename it"
            ) from None
        yield link
    finally:
        shutil.rmtree(folder, ignore_errors=True)


@contextlib.contextmanager
def utf8_output(path: str | os.PathLike) -> Iterator[Path]:
    """A UTF-8 name under which a library writes the file ``path`` (in an existing folder).

    When ``path`` is UTF-8 it is yielded as it is.  Otherwise the library
    writes a file in a private temporary folder (a link would not do: PyVista
    resolves links to the name they stand for), which is moved to ``path``
    when the block succeeds, through a temporary sibling and a rename so
    that ``path`` appears whole; nothing is left when the block fails.

    Raises
    ------
    SourceError
        When no temporary folder can be made.
    """
    path = Path(path)
    if is_utf8(path):
        yield path
        return
    suffix = path.suffix if is_utf8(path.suffix) else ""
    folder = _private_folder(path)
    try:
        scratch = Path(folder) / f"output{suffix}"
        yield scratch
        try:
            os.replace(scratch, path)
        except OSError as exc:
            if exc.errno != errno.EXDEV:
                raise
            # another file system: copy, then rename into place
            partial = path.with_name(f".{path.name}.tmp-{os.urandom(4).hex()}")
            try:
                shutil.copyfile(scratch, partial)
                os.replace(partial, path)
            finally:
                partial.unlink(missing_ok=True)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
