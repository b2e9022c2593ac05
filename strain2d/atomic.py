"""Atomic outputs: write to a temporary sibling, rename when complete.

An interrupted run (error, Ctrl-C) leaves no half-written result; existing
results are replaced only with ``overwrite=True``; an output never replaces
one of the run's inputs or the working directory.  Finished outputs get the
permissions the user's umask gives new files and folders.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Literal

from strain2d.errors import InputError

__all__ = ["atomic_dir", "atomic_file", "check_writable"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def _no_interrupt() -> Iterator[None]:
    """Hold back Ctrl-C (SIGINT) for the duration of the block, where the OS allows."""
    import signal
    import threading

    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not (
        threading.main_thread()
    ):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def check_writable(
    path: str | os.PathLike,
    *,
    overwrite: bool,
    kind: Literal["file", "dir"] = "dir",
    inputs: Sequence[str | os.PathLike] = (),
) -> Path:
    """Fail early if ``path`` may not be written.

    Refused: an existing ``path`` without ``overwrite``; an existing path of
    the other kind (a folder where a file goes, or the reverse); a missing
    parent folder; the working directory or one of its parents; a path that
    is, or holds, one of ``inputs``, or lies inside an input folder.
    """
    path = Path(path)
    target = path.resolve()
    if path.exists() or path.is_symlink():
        if not overwrite:
            raise InputError(f"{path} exists; pass --overwrite to replace it")
        if kind == "file" and path.is_dir():
            raise InputError(f"{path} is a folder; give a file name for the output")
        if kind == "dir" and not path.is_dir():
            raise InputError(f"{path} is a file; give a folder name for the output")
    cwd = Path.cwd().resolve()
    if target == cwd or target in cwd.parents:
        raise InputError(f"{path} is the working directory or holds it; choose another output")
    for source in inputs:
        s = Path(source).resolve()
        if s == target or target in s.parents:
            raise InputError(f"the output {path} would replace the input {source}")
        if s in target.parents and s.is_dir():
            raise InputError(f"the output {path} lies inside the input folder {source}")
    parent = target.parent
    if not parent.is_dir():
        raise InputError(f"output folder {parent} does not exist")
    return path


@contextlib.contextmanager
def atomic_dir(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
) -> Iterator[Path]:
    """Yield a temporary folder that becomes ``path`` when the block succeeds."""
    path = check_writable(path, overwrite=overwrite, kind="dir", inputs=inputs)
    parent = path.resolve().parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=parent))
            with _no_interrupt():  # never leave the old result moved and the new one not
                os.replace(path, old / path.name)
                os.replace(tmp, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
) -> Iterator[Path]:
    """Yield a temporary file name that replaces ``path`` when the block succeeds."""
    path = check_writable(path, overwrite=overwrite, kind="file", inputs=inputs)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.resolve().parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
