"""Outputs that appear whole or not at all, and never replace a user's data.

Every result is written into a hidden temporary sibling of its target and
renamed into place when complete, so an error or Ctrl-C leaves no
half-written result.  A result folder carries a marker,
``.tissue-strain-result.json``, that lists what the toolkit wrote into it.
An existing folder is replaced (with ``overwrite=True``) only when it is such
a result and holds nothing the toolkit did not write: a folder without the
marker, or with a file of the user's in it, is refused with one line, and
nothing is removed.  Result folders nested in a result (``strain2d analyze
--out`` inside a ``sample_data_synth study`` folder) count as the toolkit's.
An empty folder may be used without ``overwrite``.

An existing output *file* is replaced only with ``overwrite=True`` and when
``is_result`` recognises it as one the toolkit writes (its CSV header, its
JSON keys).  No output may replace an input, hold one, lie inside an input
folder, or be the working directory or one of its parents.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

from tissue_core.errors import InputError
from tissue_core.interrupt import raise_if_interrupted

__all__ = [
    "MARKER",
    "atomic_dir",
    "atomic_file",
    "check_writable",
    "csv_header_is",
    "first_unknown_entry",
    "json_from_toolkit",
    "read_marker",
    "recorded_command",
]

#: name of the file that marks a folder as a result of the toolkit
MARKER = ".tissue-strain-result.json"
_MARKER_KIND = "tissue-strain result"
#: files that file browsers drop into any folder they show
_BROWSER_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini"})

#: the results renamed into place since the command began (cleared by tissue_core.cli), so
#: that Ctrl-C after them is not reported as "no output written"
written: list[str] = []

#: the command line being run, recorded in each marker (set by tissue_core.cli)
recorded_command: contextvars.ContextVar[list[str] | None] = contextvars.ContextVar(
    "recorded_command", default=None
)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def read_marker(folder: str | os.PathLike) -> dict | None:
    """The marker of a result folder, or None when ``folder`` is not one."""
    path = Path(folder) / MARKER
    if path.is_symlink() or not path.is_file():
        return None
    try:
        marker = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(marker, dict) or marker.get("kind") != _MARKER_KIND:
        return None
    files = marker.get("files")
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        return None
    return marker


def first_unknown_entry(folder: str | os.PathLike) -> str | None:
    """The first entry of a result folder that no toolkit result wrote, or None.

    ``folder`` must hold a marker (:func:`read_marker`); entries listed in it,
    files that file browsers add, and nested result folders that are clean
    themselves are the toolkit's.  Returns the entry's path relative to
    ``folder`` (``"."`` when ``folder`` has no valid marker).
    """
    root = Path(folder)
    marker = read_marker(root)
    if marker is None:
        return "."
    listed = set(marker["files"])
    for dirpath, dirnames, filenames in os.walk(root):
        rel = Path(dirpath).relative_to(root)
        for name in list(dirnames):
            entry = (rel / name).as_posix()
            dirnames.remove(name)
            full = Path(dirpath) / name
            if entry in listed and not full.is_symlink():
                dirnames.append(name)  # descend: its content must be listed too
            elif read_marker(full) is not None and not full.is_symlink():
                inner = first_unknown_entry(full)
                if inner is not None:
                    return (rel / name / inner).as_posix()
            else:
                return entry
        for name in filenames:
            entry = (rel / name).as_posix()
            if entry == MARKER or entry in listed or name in _BROWSER_FILES:
                continue
            return entry
    return None


def csv_header_is(*columns: str) -> Callable[[Path], bool]:
    """A recogniser for :func:`atomic_file`: the file's first line starts with these columns."""
    expected = ",".join(columns)

    def recognise(path: Path) -> bool:
        try:
            with open(path, encoding="utf-8-sig") as f:
                first = f.readline(4096).strip()
        except (OSError, UnicodeDecodeError):
            return False
        return first.replace(" ", "").lower().startswith(expected.lower())

    recognise.__doc__ = f"a CSV file whose header starts with {expected}"
    return recognise


def json_from_toolkit(*keys: str) -> Callable[[Path], bool]:
    """A recogniser for :func:`atomic_file`: a JSON object holding all of ``keys``."""

    def recognise(path: Path) -> bool:
        try:
            with open(path, encoding="utf-8") as f:
                data = json.loads(f.read(64 << 20))
        except (OSError, ValueError):
            return False
        return isinstance(data, dict) and all(k in data for k in keys)

    recognise.__doc__ = f"a JSON file with the keys {', '.join(keys)}"
    return recognise


def check_writable(
    path: str | os.PathLike,
    *,
    overwrite: bool,
    kind: Literal["file", "dir"] = "dir",
    inputs: Sequence[str | os.PathLike] = (),
    is_result: Callable[[Path], bool] | None = None,
    option: str = "--out",
) -> Path:
    """Fail early, with one line, if ``path`` may not be written.

    Parameters
    ----------
    path : path-like
        The output folder (``kind="dir"``) or file (``kind="file"``).
    overwrite : bool
        Whether an existing result may be replaced.
    inputs : sequence of path-like
        Every file and folder the command reads: the output may not replace
        one, hold one, or lie inside an input folder.
    is_result : callable, optional
        For files: tells whether an existing file is one the toolkit writes
        (see :func:`csv_header_is`); without it no existing file is replaced.
    option : str
        The option that names ``path``, for the messages.

    Raises
    ------
    InputError
        Naming ``path`` and the reason.
    """
    path = Path(path)
    if path.is_symlink():
        raise InputError(f"{option} {path} is a symbolic link; give the real {kind} instead")
    target = path.resolve()
    cwd = Path.cwd().resolve()
    if target == cwd or target in cwd.parents:
        raise InputError(
            f"{option} {path} is the working directory or holds it; choose a new folder"
        )
    for source in inputs:
        s = Path(source).resolve()
        if s == target or target in s.parents:
            raise InputError(f"{option} {path} would replace the input {source}")
        if s in target.parents and s.is_dir():
            raise InputError(f"{option} {path} lies inside the input folder {source}")
    if path.exists():
        if kind == "file":
            _check_file(path, overwrite, is_result, option)
        else:
            _check_dir(path, overwrite, option)
    parent = target.parent
    if not parent.is_dir():
        raise InputError(f"the folder {parent} for {option} {path.name} does not exist")
    _probe(parent, path, option)
    return path


def _probe(parent: Path, path: Path, option: str) -> None:
    """Fail now, not after the work, if nothing can be written beside ``path``."""
    try:
        os.rmdir(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=parent))
    except OSError as exc:
        raise InputError(
            f"{option} {path} cannot be written: {exc.strerror or exc} in {parent}"
        ) from None


def _check_file(path: Path, overwrite: bool, is_result, option: str) -> None:
    if path.is_dir():
        raise InputError(f"{option} {path} is a folder; give a file name for the output")
    if not overwrite:
        raise InputError(f"{option} {path} exists; pass --overwrite to replace it")
    if is_result is None or not is_result(path):
        what = f" ({is_result.__doc__})" if is_result is not None and is_result.__doc__ else ""
        raise InputError(
            f"{option} {path} exists and is not a file this toolkit writes{what}; "
            "it was left as it is: choose another name"
        )


def _check_dir(path: Path, overwrite: bool, option: str) -> None:
    if not path.is_dir():
        raise InputError(f"{option} {path} is a file; give a folder name for the output")
    if not any(path.iterdir()):
        return  # an empty folder holds nothing to lose
    if read_marker(path) is None:
        raise InputError(
            f"{option} {path} exists and is not a result of this toolkit (it has no {MARKER}); "
            "it was left as it is: choose a new folder"
        )
    if not overwrite:
        raise InputError(
            f"{option} {path} exists (an earlier result); pass --overwrite to replace it"
        )
    unknown = first_unknown_entry(path)
    if unknown is not None:
        raise InputError(
            f"{option} {path} holds {unknown}, which the earlier result did not write; "
            "nothing was replaced: move it out or choose a new folder"
        )


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


def _hide_scratch(exc: BaseException, scratch: Path, final: Path) -> None:
    """Name the final output, not the temporary folder, in an error message."""
    old, new = str(scratch), str(final)
    if isinstance(exc, OSError) and (exc.filename or exc.filename2):
        for attr in ("filename", "filename2"):
            value = getattr(exc, attr)
            if isinstance(value, str) and old in value:
                setattr(exc, attr, value.replace(old, new))
    if exc.args and isinstance(exc.args[0], str) and old in exc.args[0]:
        exc.args = (exc.args[0].replace(old, new), *exc.args[1:])


def _write_marker(folder: Path) -> None:
    from tissue_core import __version__

    entries = sorted(
        p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.name != MARKER
    )
    marker = {
        "kind": _MARKER_KIND,
        "note": "written by the tissue-strain toolkit; --overwrite may replace this folder "
        "as long as it holds only the files listed here",
        "software": {"name": "tissue-strain", "version": __version__},
        "command": recorded_command.get(),
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "files": entries,
    }
    (folder / MARKER).write_text(json.dumps(marker, indent=1) + "\n", encoding="utf-8")


@contextlib.contextmanager
def atomic_dir(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
    option: str = "--out",
) -> Iterator[Path]:
    """Yield a temporary folder that becomes the result folder ``path`` when the block succeeds.

    The folder gets the marker of a result (:data:`MARKER`) listing every
    file written into it.  See :func:`check_writable` for what may be replaced.
    """
    path = check_writable(path, overwrite=overwrite, kind="dir", inputs=inputs, option=option)
    parent = path.resolve().parent
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=parent))
    try:
        try:
            yield tmp
        except BaseException as exc:
            _hide_scratch(exc, tmp, path)
            raise
        _write_marker(tmp)
        os.chmod(tmp, 0o777 & ~_umask())
        # the folder may have changed while the command ran: check it again
        check_writable(path, overwrite=overwrite, kind="dir", inputs=inputs, option=option)
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=parent))
            raise_if_interrupted()
            with _no_interrupt():  # never leave the old result moved and the new one not
                os.replace(path, old / path.name)
                os.replace(tmp, path)
                written.append(str(path))
                shutil.rmtree(old, ignore_errors=True)
        else:
            raise_if_interrupted()
            with _no_interrupt():
                os.replace(tmp, path)
                written.append(str(path))
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def atomic_file(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
    is_result: Callable[[Path], bool] | None = None,
    option: str = "--out",
) -> Iterator[Path]:
    """Yield a temporary file name that becomes ``path`` when the block succeeds.

    See :func:`check_writable` for what may be replaced.
    """
    kwargs = {"overwrite": overwrite, "inputs": inputs, "is_result": is_result, "option": option}
    path = check_writable(path, kind="file", **kwargs)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.tmp-", dir=path.resolve().parent)
    os.close(fd)
    tmp = Path(name)
    try:
        try:
            yield tmp
        except BaseException as exc:
            _hide_scratch(exc, tmp, path)
            raise
        os.chmod(tmp, 0o666 & ~_umask())
        check_writable(path, kind="file", **kwargs)
        raise_if_interrupted()
        with _no_interrupt():
            os.replace(tmp, path)
            written.append(str(path))
    finally:
        if tmp.exists():
            tmp.unlink()
