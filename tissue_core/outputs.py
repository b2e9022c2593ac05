"""Outputs that appear whole or not at all, and never replace a user's data.

Every result is written into a hidden temporary sibling of its target and
renamed into place when complete, so an error or Ctrl-C (SIGTERM, SIGHUP)
leaves no half-written result.  The temporary names carry their owner,
``.NAME.tmp-PID-START@HOST@XXXXXXXX`` (``.NAME.old-...`` for an earlier result
being replaced; START is the process's start time, so that a pid used again
is not taken for the owner): a run killed outright (SIGKILL, a power cut)
cannot clean up, and the next command that writes NAME removes what such
runs left, or puts back the earlier result a replacement was holding.
Scratch whose owner is alive, on another host, or whose name is not of this
form is never touched.

A result folder carries a marker, ``.tissue-strain-result.json``, that lists
every file the toolkit wrote into it with its size, time and SHA-256.  An
existing folder is replaced (``overwrite=True``) only when it has that marker
and holds exactly what the toolkit wrote: a folder without the marker, one
with a file of the user's in it, or one where a file was edited since, is
refused with one line and nothing is removed.  Result folders nested in a
result (``strain2d analyze --out`` inside a ``sample_data_synth study``
folder) count as the toolkit's when they are intact themselves.  An empty
folder may be used without ``overwrite``.

An output *file* (``strain2d track --out TRACKS.csv``) is recorded in a ledger
beside it, ``.tissue-strain-files.json``; an existing file is replaced only
with ``overwrite=True`` and when the ledger says the toolkit wrote exactly
that content.  No output may replace an input, hold one, lie inside an input
folder, or be the working directory or one of its parents.  A name longer than
the file system allows (255 bytes on most; an output's own name needs room for
its temporary name, :data:`SCRATCH_BYTES` more) is refused before anything is
made (:func:`name_too_long`).

Both records are valid UTF-8 JSON.  A name that is not UTF-8 is listed as
:func:`~tissue_core.filenames.readable` shows it, and its exact bytes under
``exact_names``, so that ``--overwrite`` recognises exactly the files listed.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import glob
import hashlib
import json
import logging
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Literal

from tissue_core.errors import InputError
from tissue_core.filenames import exact_name, readable
from tissue_core.interrupt import deferred_interrupt, raise_if_interrupted

__all__ = [
    "LEDGER",
    "MARKER",
    "SCRATCH_BYTES",
    "atomic_dir",
    "atomic_file",
    "check_name_lengths",
    "check_writable",
    "foreign_content",
    "name_too_long",
    "read_marker",
    "recorded_command",
    "remove_stale_scratch",
    "replaced_on_success",
    "sha256_of",
    "written_here",
]

log = logging.getLogger(__name__)

#: name of the file that marks a folder as a result of the toolkit
MARKER = ".tissue-strain-result.json"
_MARKER_KIND = "tissue-strain result"
#: name of the file that records the output files the toolkit wrote into a folder
LEDGER = ".tissue-strain-files.json"
_LEDGER_KIND = "tissue-strain files"
#: files that file browsers drop into any folder they show
_BROWSER_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini"})
#: the bytes an output's temporary name adds to its own: ``.NAME.tmp-`` and 8 random characters
SCRATCH_BYTES = len("..tmp-") + 8
#: the longest name in bytes where the file system cannot be asked (most allow 255)
_NAME_MAX = 255

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


# --------------------------------------------------------------------------- scratch

#: what follows ``.NAME.tmp-`` (or ``.old-``) in a scratch name: its owner, then mkdtemp's part
_OWNER = re.compile(r"(?P<pid>\d+)-(?P<start>\d+)@(?P<host>[A-Za-z0-9._-]+)@")


def _host() -> str:
    """This host as scratch names record it: its name (letters, digits, ``.``, ``-``, ``_``),
    and its process-id namespace where there is one (containers that share a host name and a
    folder still tell their processes apart)."""
    name = re.sub(r"[^A-Za-z0-9.-]", "_", socket.gethostname())[:32] or "localhost"
    try:
        return f"{name}-pidns{os.stat('/proc/self/ns/pid').st_ino}"
    except OSError:
        return name


def _process(pid: int) -> tuple[str, int]:
    """``(state, start time)`` of a process from ``/proc/PID/stat`` (OSError where there is
    none)."""
    with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as f:
        text = f.read()
    fields = text[text.rindex(")") + 2 :].split()  # the name, in parentheses, may hold spaces
    return fields[0], int(fields[19])  # fields 3 and 22 of proc(5)


def _start_time(pid: int) -> int:
    """The start time of process ``pid`` (clock ticks after boot), 0 where it is not known."""
    try:
        return _process(pid)[1]
    except (OSError, ValueError, IndexError):
        return 0


def _owner() -> str:
    """This process as scratch names record it: ``PID-START@HOST``."""
    pid = os.getpid()
    return f"{pid}-{_start_time(pid)}@{_host()}"


def _scratch_prefix(base: str, kind: Literal["tmp", "old"]) -> str:
    """The start of a scratch name for ``base`` (``.NAME``), up to the random part."""
    return f"{base}.{kind}-{_owner()}@"


def _running(pid: int, start: int) -> bool:
    """Whether the process ``pid`` that started at ``start`` runs on this host (a zombie does
    not; a pid used again by a later process is not it).  True when it cannot be told."""
    try:
        state, started = _process(pid)
    except FileNotFoundError:
        if os.path.exists("/proc/self/stat"):
            return False
    except (OSError, ValueError, IndexError):
        pass
    else:
        return state not in ("Z", "X") and start in (0, started)
    try:  # no /proc: whether the pid exists at all
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # another user's process, or no way to ask
        return True
    return True


def remove_stale_scratch(path: str | os.PathLike) -> list[Path]:
    """Remove what runs killed while writing ``path`` left beside it; return what was removed.

    Scratch of ``path`` (``.NAME.tmp-*``, ``.NAME.old-*``) is removed when its
    owner ran on this host and is no longer running.  A ``.old-`` folder
    holds the earlier result while it is replaced: if ``path`` is missing
    (the run was killed between the two renames), the earlier result is put
    back instead.  Scratch of a live process, of another host, or with a
    name not of the toolkit's form is left alone; a failure to remove is
    logged, never raised.
    """
    path = Path(path)
    if path.name in ("", ".", ".."):
        return []
    return _clear_stale(path.parent, f".{path.name}", path)


def _clear_stale(parent: Path, base: str, path: Path) -> list[Path]:
    removed = []
    if not parent.is_dir():
        return removed
    host = _host()
    for kind in ("tmp", "old"):
        prefix = f"{base}.{kind}-"
        for scratch in sorted(parent.glob(glob.escape(prefix) + "*")):
            owner = _OWNER.match(scratch.name[len(prefix) :])
            if (
                owner is None
                or owner["host"] != host
                or scratch.is_symlink()  # never made by the toolkit
                or _running(int(owner["pid"]), int(owner["start"]))
            ):
                continue
            try:
                earlier = scratch / path.name
                if kind == "old" and earlier.exists() and not os.path.lexists(path):
                    os.replace(earlier, path)
                    log.info("%s: put back the earlier result a killed run was replacing", path)
                if scratch.is_dir():
                    shutil.rmtree(scratch)
                else:
                    scratch.unlink()
            except OSError as exc:
                log.warning("%s, left by a killed run, could not be removed: %s", scratch, exc)
                continue
            log.info("removed %s, left by process %s, which was killed", scratch, owner["pid"])
            removed.append(scratch)
    return removed


# --------------------------------------------------------------------------- records


def sha256_of(paths) -> tuple[str, int]:
    """SHA-256 of the files ``paths`` read in order as one stream, and its length in bytes."""
    digest = hashlib.sha256()
    total = 0
    for path in paths:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
                total += len(block)
    return digest.hexdigest(), total


def _sha256(path: Path) -> str:
    return sha256_of([path])[0]


def _record(path: Path) -> dict:
    stat = path.stat()
    return {"size": stat.st_size, "mtime_ns": stat.st_mtime_ns, "sha256": _sha256(path)}


def _unchanged(path: Path, record) -> bool:
    """Whether ``path`` still holds what ``record`` describes (the hash only when needed)."""
    if not isinstance(record, dict) or path.is_symlink() or not path.is_file():
        return False
    stat = path.stat()
    if stat.st_size != record.get("size"):
        return False
    if stat.st_mtime_ns == record.get("mtime_ns"):
        return True
    return _sha256(path) == record.get("sha256")  # copied, or touched: compare the content


def _read_json(path: Path, kind: str) -> dict | None:
    if path.is_symlink() or not path.is_file():
        return None
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("kind") != kind:
        return None
    files = data.get("files")
    if not isinstance(files, dict) or not all(
        isinstance(k, str) and isinstance(v, dict) for k, v in files.items()
    ):
        return None
    exact = data.setdefault("exact_names", {})
    if not isinstance(exact, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in exact.items()
    ):
        return None
    return data


def _listed(record: dict, entry: str) -> str | None:
    """The key under which a marker or ledger lists ``entry`` (a relative name), or None.

    A name that is not UTF-8 is listed as it reads, with its exact bytes in
    ``exact_names``: a name that only reads alike is not the one listed.
    """
    key = readable(entry)
    return key if record["exact_names"].get(key) == exact_name(entry) else None


def read_marker(folder: str | os.PathLike) -> dict | None:
    """The marker of a result folder, or None when ``folder`` is not one."""
    marker = _read_json(Path(folder) / MARKER, _MARKER_KIND)
    if marker is not None:
        folders = marker.get("folders", [])
        if not isinstance(folders, list) or not all(isinstance(f, str) for f in folders):
            return None
    return marker


def foreign_content(folder: str | os.PathLike) -> str | None:
    """What in a result folder the toolkit did not write, in words; None when there is nothing.

    Entries listed in the marker with unchanged content, files that file
    browsers add, and nested result folders that pass this check themselves
    are the toolkit's.  A subfolder that cannot be listed is not.
    """
    root = Path(folder)
    marker = read_marker(root)
    if marker is None:
        return f"no {MARKER}"
    files, folders = marker["files"], set(marker.get("folders", []))

    def listed(entry: str, among) -> str | None:
        key = _listed(marker, entry)
        return key if key in among else None

    def cannot_list(error: OSError) -> None:
        raise error

    try:
        for dirpath, dirnames, filenames in os.walk(root, onerror=cannot_list):
            rel = Path(dirpath).relative_to(root)
            for name in list(dirnames):
                entry = (rel / name).as_posix()
                full = Path(dirpath) / name
                dirnames.remove(name)
                if full.is_symlink():
                    return f"{entry}, a link the earlier result did not make"
                if listed(entry, folders) is not None:
                    dirnames.append(name)  # descend: its content must be listed too
                elif read_marker(full) is not None:
                    inner = foreign_content(full)
                    if inner is not None:
                        return f"{entry}/{inner}"
                else:
                    return f"{entry}, which the earlier result did not write"
            for name in filenames:
                entry = (rel / name).as_posix()
                if entry == MARKER or name in _BROWSER_FILES:
                    continue
                key = listed(entry, files)
                if key is None:
                    return f"{entry}, which the earlier result did not write"
                if not _unchanged(Path(dirpath) / name, files[key]):
                    return f"{entry}, which was changed after the toolkit wrote it"
    except OSError as exc:
        return f"{exc.filename or 'a subfolder'}, which cannot be read ({exc.strerror or exc})"
    return None


def _file_written_here(path: Path) -> bool:
    ledger = _read_json(path.parent / LEDGER, _LEDGER_KIND)
    if ledger is None:
        return False
    key = _listed(ledger, path.name)
    return key is not None and _unchanged(path, ledger["files"].get(key))


def written_here(path: str | os.PathLike) -> bool:
    """Whether the file ``path`` holds exactly what the toolkit wrote there.

    True when its folder's ledger (:data:`LEDGER`) records it and its content
    is unchanged since; False for a file the user edited, one the toolkit did
    not write, or one that is not there.
    """
    try:
        return _file_written_here(Path(path))
    except OSError:  # there, but it cannot be read: not known to be the toolkit's
        return False


# --------------------------------------------------------------------------- checks


def _name_max(folder: Path) -> int:
    """The longest name, in bytes, the file system of ``folder`` (or of its nearest existing
    parent) allows."""
    for candidate in (folder, *folder.parents):
        try:
            return int(os.pathconf(candidate, "PC_NAME_MAX"))
        except (OSError, ValueError, AttributeError):  # not there (yet), or no pathconf
            continue
    return _NAME_MAX


def name_too_long(name: str, folder: str | os.PathLike, *, scratch: bool = True) -> str:
    """Why ``name`` is too long for a file or folder in ``folder``, in words; ``""`` if it is not.

    ``scratch``: the name is written under a temporary name first (every
    output of :func:`atomic_dir` and :func:`atomic_file`, every run of a
    batch), which needs :data:`SCRATCH_BYTES` more.

    Examples
    --------
    >>> name_too_long("S01", "/tmp")
    ''
    >>> name_too_long("x" * 300, "/tmp", scratch=False)
    "'xxxxxxxxxxxxxxxxxxxx...xxxxxxxxxx' is 300 bytes long; names here may have at most 255"
    """
    size = len(os.fsencode(name))
    limit = _name_max(Path(os.path.abspath(folder)))
    if scratch:
        limit -= SCRATCH_BYTES
    if size <= limit:
        return ""
    shown = name if len(name) <= 40 else f"{name[:20]}...{name[-10:]}"
    why = f" (the toolkit writes it under a temporary name {SCRATCH_BYTES} bytes longer first)"
    return f"{shown!r} is {size} bytes long; names here may have at most {limit}" + (
        why if scratch else ""
    )


def check_name_lengths(
    path: str | os.PathLike, *, option: str = "--out", scratch: bool = True
) -> None:
    """Refuse ``path`` in one line when one of its names is longer than the file system allows.

    Its own (last) name needs room for its temporary name when ``scratch``
    (see :func:`name_too_long`).  Checked before anything looks at ``path``:
    the system refuses a name too long with an error of its own.

    Raises
    ------
    InputError
        Naming ``option``, the name and the limit.
    """
    path = Path(path)
    parts = path.parts
    for k, part in enumerate(parts):
        if part in (path.anchor, "", ".", ".."):
            continue
        last = k == len(parts) - 1
        problem = name_too_long(part, Path(*parts[:k]) if k else ".", scratch=scratch and last)
        if problem:
            raise InputError(f"{option}: the name {problem}; choose a shorter one")


def _same(a: Path, b: Path) -> bool:
    """Whether two paths are one file or folder (also on case-insensitive file systems)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``folder`` is ``path`` or one of its (existing) ancestors."""
    return any(_same(p, folder) for p in (path, *path.parents) if p.exists())


def check_writable(
    path: str | os.PathLike,
    *,
    overwrite: bool,
    kind: Literal["file", "dir"] = "dir",
    inputs: Sequence[str | os.PathLike] = (),
    option: str = "--out",
) -> Path:
    """Fail early, with one line, if ``path`` may not be written.

    The scratch that killed runs left beside ``path`` is removed first
    (:func:`remove_stale_scratch`).

    Parameters
    ----------
    path : path-like
        The output folder (``kind="dir"``) or file (``kind="file"``).
    overwrite : bool
        Whether an earlier result of the toolkit may be replaced.
    inputs : sequence of path-like
        Every file and folder the command reads: the output may not replace
        one, hold one, or lie inside an input folder.
    option : str
        The option that names ``path``, for the messages.

    Raises
    ------
    InputError
        Naming ``path`` and the reason.
    """
    path = Path(path)
    check_name_lengths(path, option=option)
    if path.is_symlink():
        raise InputError(f"{option} {path} is a symbolic link; give the real {kind} instead")
    target = path.resolve()
    if _inside(Path.cwd().resolve(), target):
        raise InputError(
            f"{option} {path} is the working directory or holds it; choose a new folder"
        )
    if path.name in ("", ".", ".."):
        raise InputError(f"{option} {path} does not name a {kind}; give a new name")
    for source in map(Path, inputs):
        if source.exists() and _inside(source.resolve(), target):
            raise InputError(f"{option} {path} would replace the input {source}")
        if source.is_dir() and _inside(target, source.resolve()):
            raise InputError(f"{option} {path} lies inside the input folder {source}")
    remove_stale_scratch(path)  # first: it may put an earlier result back
    if path.exists():
        if kind == "file":
            _check_file(path, overwrite, option)
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
        with deferred_interrupt():  # a Ctrl-C between the two calls would leave the probe
            os.rmdir(tempfile.mkdtemp(prefix=_scratch_prefix(f".{path.name}", "tmp"), dir=parent))
    except OSError as exc:
        raise InputError(
            f"{option} {path} cannot be written: {exc.strerror or exc} in {parent}"
        ) from None


def _check_file(path: Path, overwrite: bool, option: str) -> None:
    if path.is_dir():
        raise InputError(f"{option} {path} is a folder; give a file name for the output")
    if not _file_written_here(path):
        raise InputError(
            f"{option} {path} exists and is not a file this toolkit wrote (or it was changed "
            f"since; see {LEDGER}); it was left as it is: choose another name"
        )
    if not overwrite:
        raise InputError(
            f"{option} {path} exists (an earlier result); pass --overwrite to replace it"
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
    foreign = foreign_content(path)
    if foreign is not None:
        raise InputError(
            f"{option} {path} holds {foreign}; nothing was replaced: move it out or "
            "choose a new folder"
        )


# --------------------------------------------------------------------------- writing


#: errors of a write the disk refused (full, over the quota, a file too large)
_DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def _hide_scratch(exc: BaseException, scratch: Path, final: Path) -> None:
    """Name the final output, not the temporary folder, in an error message.

    A write the disk refused names no file when it comes from ``write`` or
    ``close`` (``[Errno 28] No space left on device``): the output being
    written is named then.
    """
    if isinstance(exc, OSError) and exc.errno in _DISK_FULL and not exc.filename:
        exc.filename = str(scratch)
    old, new = str(scratch), str(final)
    if isinstance(exc, OSError):
        for attr in ("filename", "filename2"):
            value = getattr(exc, attr)
            if isinstance(value, str) and old in value:
                setattr(exc, attr, value.replace(old, new))
    if exc.args and isinstance(exc.args[0], str) and old in exc.args[0]:
        exc.args = (exc.args[0].replace(old, new), *exc.args[1:])


def _provenance() -> dict:
    from tissue_core import __version__

    return {
        "software": {"name": "tissue-strain", "version": __version__},
        "command": [readable(a) for a in recorded_command.get() or []] or None,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
    }


def _write_marker(folder: Path) -> None:
    files, folders, exact = {}, [], {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        if rel == MARKER:
            continue
        if exact_name(rel) is not None:
            exact[readable(rel)] = exact_name(rel)
        if p.is_dir() and not p.is_symlink():
            folders.append(readable(rel))
        else:
            files[readable(rel)] = _record(p)
    marker = {
        "kind": _MARKER_KIND,
        "note": "written by the tissue-strain toolkit; --overwrite may replace this folder "
        "as long as it holds exactly the files listed here",
        **_provenance(),
        "folders": folders,
        "files": files,
        "exact_names": exact,
    }
    (folder / MARKER).write_text(json.dumps(marker, indent=1) + "\n", encoding="utf-8")


def _record_in_ledger(path: Path) -> None:
    """Add ``path`` to its folder's ledger (written atomically; a failure only loses the record)."""
    ledger_path = path.parent / LEDGER
    ledger = _read_json(ledger_path, _LEDGER_KIND) or {
        "kind": _LEDGER_KIND,
        "note": "files the tissue-strain toolkit wrote here; --overwrite replaces only these, "
        "and only while their content is unchanged",
        "files": {},
        "exact_names": {},
    }
    key = readable(path.name)
    ledger["files"][key] = {**_record(path), **_provenance()}
    ledger["exact_names"].pop(key, None)
    if exact_name(path.name) is not None:
        ledger["exact_names"][key] = exact_name(path.name)
    try:
        _clear_stale(path.parent, LEDGER, path.parent / LEDGER)
        fd, name = tempfile.mkstemp(prefix=_scratch_prefix(LEDGER, "tmp"), dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(ledger, f, indent=1)
            f.write("\n")
        os.replace(name, ledger_path)
    except OSError as exc:
        log.warning("%s: could not record %s in %s (%s)", path.parent, path.name, LEDGER, exc)
        with contextlib.suppress(OSError, UnboundLocalError):
            os.unlink(name)


@contextlib.contextmanager
def replaced_on_success(path: str | os.PathLike, *, record: bool = False) -> Iterator[Path]:
    """A temporary file beside ``path`` (same suffix) that becomes ``path`` if the block succeeds.

    No policy: for library writers that were given ``path`` (a file inside a
    result being written, or a file the caller named); the command lines'
    outputs use :func:`atomic_file`, which also checks what may be replaced.
    With ``record``, ``path`` is also recorded in its folder's ledger
    (:data:`LEDGER`), so that :func:`written_here` can tell later whether it
    still holds what was written (a batch's table in the batch folder).
    """
    path = Path(path)
    remove_stale_scratch(path)
    prefix = _scratch_prefix(f".{path.name}", "tmp")
    fd, name = tempfile.mkstemp(prefix=prefix, suffix=path.suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        try:
            yield tmp
        except BaseException as exc:
            _hide_scratch(exc, tmp, path)
            raise
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp made it private
        if record:
            with deferred_interrupt():  # Ctrl-C waits until the file and its record are in place
                os.replace(tmp, path)
                _record_in_ledger(path)
        else:
            os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_dir(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
    option: str = "--out",
) -> Iterator[Path]:
    """Yield a temporary folder that becomes the result folder ``path`` when the block succeeds.

    The folder gets the marker of a result (:data:`MARKER`) recording every
    file written into it.  See :func:`check_writable` for what may be replaced.
    """
    path = check_writable(path, overwrite=overwrite, kind="dir", inputs=inputs, option=option)
    parent = path.resolve().parent
    tmp = Path(tempfile.mkdtemp(prefix=_scratch_prefix(f".{path.name}", "tmp"), dir=parent))
    old = None
    try:
        try:
            yield tmp
            _write_marker(tmp)
            os.chmod(tmp, 0o777 & ~_umask())
        except BaseException as exc:
            _hide_scratch(exc, tmp, path)
            raise
        # the folder may have changed while the command ran: check it again
        check_writable(path, overwrite=overwrite, kind="dir", inputs=inputs, option=option)
        raise_if_interrupted()
        with deferred_interrupt():  # Ctrl-C waits until the result is in place, whole
            if path.exists():
                old = Path(
                    tempfile.mkdtemp(prefix=_scratch_prefix(f".{path.name}", "old"), dir=parent)
                )
                os.replace(path, old / path.name)
                try:
                    os.replace(tmp, path)
                except BaseException:
                    os.replace(old / path.name, path)  # put the earlier result back
                    old.rmdir()
                    raise
            else:
                os.replace(tmp, path)
            written.append(str(path))
            if old is not None:
                _remove(old, path)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _remove(old: Path, path: Path) -> None:
    """Remove the earlier result once the new one is in place; say so if it cannot be."""
    errors = []
    shutil.rmtree(old, onerror=lambda *error: errors.append(error))
    if errors or old.exists():
        log.warning("the earlier result of %s could not be removed: it is in %s", path, old)


@contextlib.contextmanager
def atomic_file(
    path: str | os.PathLike,
    *,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
    option: str = "--out",
) -> Iterator[Path]:
    """Yield a temporary file name that becomes ``path`` when the block succeeds.

    The file is recorded in its folder's ledger (:data:`LEDGER`).  See
    :func:`check_writable` for what may be replaced.
    """
    kwargs = {"overwrite": overwrite, "inputs": inputs, "option": option}
    path = check_writable(path, kind="file", **kwargs)
    prefix = _scratch_prefix(f".{path.name}", "tmp")
    fd, name = tempfile.mkstemp(prefix=prefix, dir=path.resolve().parent)
    os.close(fd)
    tmp = Path(name)
    try:
        try:
            yield tmp
            os.chmod(tmp, 0o666 & ~_umask())
        except BaseException as exc:
            _hide_scratch(exc, tmp, path)
            raise
        check_writable(path, kind="file", **kwargs)
        raise_if_interrupted()
        with deferred_interrupt():
            os.replace(tmp, path)
            written.append(str(path))
            _record_in_ledger(path)
    finally:
        if tmp.exists():
            tmp.unlink()
