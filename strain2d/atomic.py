"""Atomic outputs: write to a temporary sibling, rename when complete.

An interrupted run (error, Ctrl-C) leaves no half-written result; existing
results are replaced only with ``overwrite=True``.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

from strain2d.errors import InputError

__all__ = ["atomic_dir", "atomic_file", "check_writable"]


def check_writable(path: str | os.PathLike, *, overwrite: bool) -> Path:
    """Fail early if ``path`` exists and may not be overwritten, or its parent is missing."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise InputError(f"{path} exists; pass --overwrite to replace it")
    parent = path.absolute().parent
    if not parent.is_dir():
        raise InputError(f"output folder {parent} does not exist")
    return path


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder that becomes ``path`` when the block succeeds."""
    path = check_writable(path, overwrite=overwrite)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=path.absolute().parent))
    try:
        yield tmp
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=tmp.parent))
            os.replace(path, old / path.name)
            os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, *, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary file name that replaces ``path`` when the block succeeds."""
    path = check_writable(path, overwrite=overwrite)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.absolute().parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
