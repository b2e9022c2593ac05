"""Batches: many runs of a command line, in this process or on a Dask cluster.

A batch is a list of :class:`Job` s, each one run of a toolkit command
(``strain2d analyze``, ``mpm3d analyze``, ``stereo reconstruct``) into its own
result folder.  :func:`run_batch` runs them

* in this process, one after the other (``workers=1``),
* on a local Dask cluster of ``workers`` processes started for the batch, or
* on an existing Dask cluster (``scheduler="tcp://host:8786"``; its workers
  must see the input and output paths, as on a cluster's shared file system).

Each job runs the command's own ``main(argv)``, so a run in a batch is the run
the command line makes: checked the same way, written atomically (a crash or a
killed worker never leaves half a run), and carrying its parameters.  Faults
stay local to one run:

* an input the command refuses (a corrupt video, a bad option in the
  manifest) fails that run with the command's one-line reason, and the others
  go on;
* a worker that dies (killed, out of memory) has its run started again on
  another worker by the scheduler; a run whose workers died three times is
  reported as failed;
* a rerun skips every run that is complete with the same parameters: its
  folder carries the result marker, holds exactly what was written, was made
  by the same command line, and its inputs are unchanged since (size, and
  SHA-256 when the modification time is newer than the run).  Everything else
  is run again.

Progress goes to the terminal and, with timestamps, to the batch's log
(``batch.log``); ``batch.json`` records every run's outcome and is rewritten
atomically after each.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import difflib
import io
import json
import os
import signal
import socket
import sys
import threading
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

from tissue_core.csvtext import restore_cell
from tissue_core.errors import InputError
from tissue_core.filenames import readable
from tissue_core.interrupt import (
    SIGNALS,
    deferred_interrupt,
    exit_status,
    interrupt_signal,
    raise_if_interrupted,
    signal_name,
    was_interrupted,
)
from tissue_core.jsonio import write_json
from tissue_core.outputs import (
    LEDGER,
    check_name_lengths,
    foreign_content,
    name_too_long,
    read_marker,
    recorded_command,
    remove_stale_scratch,
    replaced_on_success,
    sha256_of,
    written,
    written_here,
)

__all__ = [
    "BATCH_FILE",
    "LOG_FILE",
    "Job",
    "RunOptions",
    "add_batch_arguments",
    "batch_folder",
    "check_workers",
    "differences",
    "job_state",
    "manifest_jobs",
    "manifest_rows",
    "raise_if_failed",
    "run_batch",
    "run_job",
    "update_batch_file",
]

#: the least memory a local worker process takes, bytes: Python, NumPy and Dask loaded
WORKER_BYTES = 100 * 2**20
#: the batch's record of every run, in the batch folder
BATCH_FILE = "batch.json"
#: the batch's log, appended to by every batch run in the folder
LOG_FILE = "batch.log"
_KIND = "tissue-strain batch"
#: command-line flags that do not change a run's result
_NEUTRAL_FLAGS = frozenset({"--overwrite", "-q", "--quiet", "-v", "--verbose"})


@dataclass(frozen=True)
class Job:
    """One run of a batch: a command line of the toolkit writing one result folder.

    Attributes
    ----------
    name : str
        The run's name (a specimen, a stack), unique in the batch.
    module : str
        The command line's module, whose ``main(argv)`` runs it (``"strain2d.cli"``).
    argv : tuple of str
        The command's arguments, ``--out`` included, without ``--overwrite``.
    out : str
        The result folder.
    inputs : tuple of str
        The files the run reads, checked for changes on a rerun.
    summary : str
        The JSON file in ``out`` that records the inputs' checksums (``input_files``).
    neutral : tuple of str
        The command's options that change how a run is made (how much memory it
        may use), never its result: a run made with other values of them counts
        as made with the same parameters.  A flag that takes a value ends with
        ``=`` (``"--memory-limit="``), a switch does not (``"--lazy"``).
    """

    name: str
    module: str
    argv: tuple[str, ...]
    out: str
    inputs: tuple[str, ...] = ()
    summary: str = "summary.json"
    neutral: tuple[str, ...] = ()

    def with_options(self, *options: str) -> Job:
        """The same job with ``options`` added to its command line."""
        return replace(self, argv=(*self.argv, *options))

    @property
    def command(self) -> list[str]:
        """The command line as a user would type it (the program's name first)."""
        return [self.module.split(".")[0], *self.argv]


@dataclass
class Outcome:
    """What became of one job: ``done``, ``skipped`` (complete already) or ``failed``."""

    name: str
    status: str
    out: str
    reason: str = ""
    seconds: float = 0.0
    worker: str = ""
    worker_deaths: int = 0
    messages: list[str] = field(default_factory=list)


def _parameters(argv: Iterable[str], neutral: Iterable[str] = ()) -> list[str]:
    """The arguments that make a run's result: without ``--overwrite``, the verbosity and
    the ``neutral`` options (see :class:`Job`)."""
    switches = {n for n in neutral if not n.endswith("=")}
    valued = {n[:-1] for n in neutral if n.endswith("=")}
    out, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a in _NEUTRAL_FLAGS or a in switches or (a.split("=", 1)[0] in valued and "=" in a):
            continue
        elif a in valued:
            skip = True  # and its value
        else:
            out.append(a)
    return out


def _inputs_unchanged(job: Job, out: Path, created: float) -> bool:
    """Whether every input recorded in the run's summary is the file it was."""
    try:
        summary = json.loads((out / job.summary).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    listed = summary.get("input_files") or summary.get("inputs") or []
    records = {str(r.get("path")): r for r in listed if isinstance(r, dict)}
    for path in job.inputs:
        # (names as the summary shows them: valid UTF-8, see tissue_core.filenames)
        record = records.get(readable(path), {})  # not recorded: unchanged if not touched since
        p = Path(path)
        try:
            if p.is_dir():
                files = sorted(x for x in p.iterdir() if x.is_file() and not x.name.startswith("."))
            else:
                files = [p]
            size = sum(f.stat().st_size for f in files)
            if record and size != record.get("bytes"):
                return False
            if max((f.stat().st_mtime for f in files), default=0.0) < created:
                continue  # not touched since the run: no need to read it again
            if not record or sha256_of(files)[0] != record.get("sha256"):
                return False
        except OSError:
            return False
    return True


def job_state(job: Job) -> str:
    """``"missing"``, ``"complete"`` (same parameters, intact, inputs unchanged), or why not.

    Anything else than ``"missing"`` and ``"complete"`` is a sentence saying
    why the folder must be made again (``--overwrite`` replaces it).
    """
    out = Path(job.out)
    if not out.exists():
        return "missing"
    if out.is_dir() and not any(out.iterdir()):
        return "missing"
    marker = read_marker(out)
    if marker is None:
        return f"{out} exists and is not a result of the toolkit"
    if foreign_content(out) is not None:
        return f"{out} was changed since it was written"
    recorded = (marker.get("command") or [])[1:]
    argv = [readable(a) for a in job.argv]  # as the marker records it
    if _parameters(recorded, job.neutral) != _parameters(argv, job.neutral):
        return f"{out} was made with other parameters"
    try:
        created = datetime.fromisoformat(marker["created"]).timestamp()
    except (KeyError, TypeError, ValueError):
        created = float("inf")  # unknown: read every input again
    if not _inputs_unchanged(job, out, created):
        return f"{out} was made from inputs that have changed since"
    return "complete"


def _error_line(text: str) -> str:
    """The command's one-line error, without its ``PROG COMMAND: error:`` prefix."""
    lines = [line for line in text.splitlines() if line.strip()]
    for line in reversed(lines):
        if ": error: " in line:
            return line.split(": error: ", 1)[1]
    return lines[-1] if lines else ""


class _ThreadStreams(io.TextIOBase):
    """``sys.stderr`` or ``sys.stdout`` while runs are made: each thread that set a stream of
    its own writes there, every other thread to the stream it replaced.  A worker with
    several threads makes several runs at once, and each run's messages are its own."""

    def __init__(self, fallback) -> None:
        self.fallback = fallback
        self.local = threading.local()
        self.users = 0

    def _target(self):
        return getattr(self.local, "stream", None) or self.fallback

    def write(self, text: str) -> int:
        return self._target().write(text)

    def flush(self) -> None:
        self._target().flush()

    def isatty(self) -> bool:
        return self._target().isatty()

    def __getattr__(self, name: str):  # encoding, fileno, ...: the stream's own
        return getattr(self._target(), name)


_STREAMS_LOCK = threading.Lock()


@contextlib.contextmanager
def _captured(name: str) -> Iterator[io.StringIO]:
    """This thread's writes to ``sys.<name>`` go to the buffer yielded; other threads' do not."""
    with _STREAMS_LOCK:
        streams = getattr(sys, name)
        if not isinstance(streams, _ThreadStreams):
            streams = _ThreadStreams(streams)
            setattr(sys, name, streams)
        streams.users += 1
    buffer = io.StringIO()
    streams.local.stream = buffer
    try:
        yield buffer
    finally:
        streams.local.stream = None
        with _STREAMS_LOCK:
            streams.users -= 1
            if streams.users == 0 and getattr(sys, name) is streams:
                setattr(sys, name, streams.fallback)


#: the threads a run may use on a worker of a local cluster (its share of the cores)
_THREADS_ENV = "TISSUE_STRAIN_RUN_THREADS"


def _share_the_cores() -> None:
    """On a local cluster's worker: OpenCV's thread pool to the worker's share of the cores
    (NumPy's BLAS is at one thread on Dask's workers, numba at NUMBA_NUM_THREADS)."""
    threads = os.environ.get(_THREADS_ENV)
    if threads:
        import cv2

        cv2.setNumThreads(int(threads))


def run_job(job: Job, overwrite: bool = False, *, remake: bool = False) -> Outcome:
    """Run one job here (in a worker, or in the batch's own process) and say how it went.

    The command's messages (warnings, its error line) are captured, not printed;
    an error the command does not expect (a defect) fails the job with its
    traceback in the messages rather than ending the batch.  A job found
    complete is not run again (``remake`` runs it all the same, with
    ``overwrite``): the scheduler starts a job again when the worker that
    made it died before handing its outcome back.
    """
    import importlib

    _share_the_cores()
    start = time.perf_counter()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    # made by an earlier attempt whose worker died after it (unless it is to be made again)
    if not remake and job_state(job) == "complete":
        return Outcome(job.name, "done", job.out, "", 0.0, worker, messages=["complete already"])
    argv = [*job.argv, "-q", *(["--overwrite"] if overwrite else [])]
    try:
        with _captured("stderr") as stderr, _captured("stdout"):
            try:
                status = importlib.import_module(job.module).main(argv)
            except SystemExit as exc:  # a usage error: argparse exits
                status = exc.code if isinstance(exc.code, int) else 2
    except Exception as exc:  # a defect: the batch goes on, the log keeps the traceback
        messages = [*stderr.getvalue().splitlines(), *traceback.format_exc().splitlines()]
        return Outcome(
            job.name,
            "failed",
            job.out,
            f"unexpected {type(exc).__name__}: {exc}",
            time.perf_counter() - start,
            worker,
            messages=messages,
        )
    text = stderr.getvalue()
    seconds = time.perf_counter() - start
    if status == 0:
        return Outcome(job.name, "done", job.out, "", seconds, worker, messages=text.splitlines())
    if status in {exit_status(signum) for signum in SIGNALS}:
        reason = "interrupted"
    else:
        reason = _error_line(text) or f"exit status {status}"
    return Outcome(job.name, "failed", job.out, reason, seconds, worker, messages=text.splitlines())


_TRUE = frozenset({"1", "yes", "true", "y", "x", "on"})
_FALSE = frozenset({"", "0", "no", "false", "n", "off"})


def _absolute(value):
    """A value given to the batch that names a file or folder here, as an absolute path (the
    runs may run elsewhere, and are compared by their command lines)."""
    if isinstance(value, list):
        return [_absolute(v) for v in value]
    if isinstance(value, str) and not value.startswith("-") and Path(value).exists():
        return str(Path(value).resolve())
    return value


def _as_typed(convert):
    """An argparse type that checks a value with ``convert`` and keeps the text as typed, so
    that ``--fps 30`` given to a batch passes on ``30`` as a manifest cell would."""

    def check(text: str) -> str:
        convert(text)
        return text

    check.__name__ = getattr(convert, "__name__", "value")
    return check


class RunOptions:
    """The options of a command that a batch passes on to each of its runs.

    Built on the batch command's parser like the command's own options (the
    same builder functions), through this object, which remembers each one.
    Their defaults are the command's; a value given to the batch applies to
    every run, a manifest column of the same name (``grid``, ``min_triangle_quality``)
    to its row only, and wins.

    Examples
    --------
    >>> parser = argparse.ArgumentParser()
    >>> options = RunOptions(parser, "options of each run")
    >>> _ = options.add_argument("--grid", default="7x7")
    >>> _ = options.add_argument("--fast", action="store_true")
    >>> args = parser.parse_args(["--fast"])
    >>> options.argv(args, {"grid": "9x9"}, where="line 2")
    ['--grid', '9x9', '--fast']
    >>> options.argv(args, {}, where="line 3")
    ['--fast']
    """

    def __init__(self, parser, title: str | None = None, *, _shared=None, _exclusive=None) -> None:
        self._target = parser.add_argument_group(title) if title else parser
        self._parser = parser
        self._actions: list[argparse.Action] = [] if _shared is None else _shared
        self._exclusive = _exclusive  # the actions of a mutually exclusive group, or None
        self._groups: list[list[argparse.Action]] = []  # shared with its groups once made

    def add_argument(self, *names, **kwargs) -> argparse.Action:
        convert = kwargs.get("type")
        if callable(convert):  # checked as the command checks it, passed on as typed
            kwargs["type"] = _as_typed(convert)
        action = self._target.add_argument(*names, **kwargs)
        action.default = argparse.SUPPRESS  # only what is given is passed on
        self._actions.append(action)
        if self._exclusive is not None:
            self._exclusive.append(action)
        return action

    def add_argument_group(self, title: str | None = None, **kwargs) -> RunOptions:
        group = RunOptions(self._parser, None, _shared=self._actions, _exclusive=self._exclusive)
        group._target = self._parser.add_argument_group(title, **kwargs)
        group._groups = self._groups
        return group

    def add_mutually_exclusive_group(self, **kwargs) -> RunOptions:
        members: list[argparse.Action] = []
        self._groups.append(members)
        group = RunOptions(self._parser, None, _shared=self._actions, _exclusive=members)
        group._target = self._target.add_mutually_exclusive_group(**kwargs)
        group._groups = self._groups
        return group

    def _by_column(self) -> dict[str, argparse.Action]:
        out = {}
        for action in self._actions:
            for flag in action.option_strings:
                if flag.startswith("--"):
                    out[flag[2:].replace("-", "_")] = action
        return out

    def columns(self, row: dict[str, str]) -> list[str]:
        """The manifest columns of ``row`` that are options of the runs."""
        known = self._by_column()
        return [c for c in row if c.replace("-", "_") in known]

    def argv(
        self,
        args: argparse.Namespace,
        row: dict[str, str],
        *,
        where: str,
        base: Path | None = None,
    ) -> list[str]:
        """The options of one run: the batch's, with the row's non-empty columns instead.

        A column naming a file or folder (``points``, ``tracks_file``) is taken
        relative to ``base`` (the manifest's folder) when it is there.
        """
        known = self._by_column()
        given: dict[argparse.Action, object] = {
            a: _absolute(getattr(args, a.dest)) for a in self._actions if hasattr(args, a.dest)
        }
        for column, text in row.items():
            action = known.get(column.replace("-", "_"))
            if action is None or text == "":
                continue
            for group in self._groups:  # the row's --scale-ruler replaces the batch's --scale
                if action in group:
                    for other in group:
                        given.pop(other, None)
            value = self._value(action, column, text, where)
            if base is not None and isinstance(value, str) and not Path(value).is_absolute():
                if (base / value).exists():
                    value = str((base / value).resolve())
            given[action] = value
        argv: list[str] = []
        for action in self._actions:  # in the parser's order, so the recorded command is stable
            if action not in given:
                continue
            flag = max(action.option_strings, key=len)
            value = given[action]
            if action.nargs == 0:
                if value is not None:
                    argv.append(flag)
            elif isinstance(value, list):  # nargs="+": the batch's list
                argv += [flag, *map(str, value)]
            else:
                argv += [flag, str(value)]
        return argv

    @staticmethod
    def _value(action: argparse.Action, column: str, text: str, where: str):
        if action.nargs == 0:  # a switch: yes or no
            if text.lower() in _TRUE:
                return True
            if text.lower() in _FALSE:
                return None
            raise InputError(f"{where}: column {column} is a switch: yes or no, got {text!r}")
        if action.choices is not None and text not in action.choices:
            choices = ", ".join(map(str, action.choices))
            raise InputError(f"{where}: column {column} must be one of {choices}, got {text!r}")
        if callable(action.type):
            try:
                action.type(text)
            except argparse.ArgumentTypeError as exc:  # the option's own checker says why
                raise InputError(f"{where}: column {column}: {exc}") from None
            except (TypeError, ValueError):
                name = getattr(action.type, "__name__", "value")
                article = "an" if name[:1] in "aeiou" else "a"
                raise InputError(
                    f"{where}: column {column} takes {article} {name}, got {text!r}"
                ) from None
        return text


def check_workers(workers: int | None, scheduler: str | None, n_jobs: int) -> int:
    """The number of local workers to start (0 with a scheduler), checked."""
    if scheduler is not None:
        if workers is not None:
            raise InputError("give --workers (a local cluster) or --scheduler, not both")
        if not scheduler.strip():
            raise InputError("--scheduler needs an address, e.g. tcp://10.0.0.5:8786")
        return 0
    if workers is None:
        workers = min(os.cpu_count() or 1, max(n_jobs, 1))
    if workers < 1:
        raise InputError(f"--workers must be 1 or more, got {workers}")
    if workers > 1:  # each a process of its own
        from tissue_core.resources import check_fits

        check_fits(
            f"--workers {workers} (worker processes)",
            memory=workers * WORKER_BYTES,
            remedy="use fewer --workers",
        )
    return workers


def add_batch_arguments(
    p: argparse.ArgumentParser, *, what: str, tables: Sequence[str] = ()
) -> None:
    """``--workers``, ``--scheduler`` and ``--overwrite`` of a batch command.

    ``tables``: the files of the batch folder that list its runs
    (:func:`update_batch_file`), which ``--overwrite`` replaces once edited.
    """
    g = p.add_argument_group("where the runs go")
    g.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help=f"run the {what} on a local Dask cluster of N worker processes (default: one per "
        "core, at most one per run); 1 runs them one after the other in this process",
    )
    g.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help=f"send the {what} to a running Dask scheduler, e.g. tcp://10.0.0.5:8786 "
        "(started with 'dask scheduler' and 'dask worker', or dask-jobqueue); its workers "
        "must see the same paths",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace runs made with other parameters or from changed inputs"
        + (f", and {' and '.join(tables)} when edited since the batch wrote it" if tables else "")
        + " (runs complete with the same parameters are always kept)",
    )


def manifest_rows(path: str | os.PathLike, *, required: Sequence[str]) -> list[dict[str, str]]:
    """A manifest CSV's rows: header names lower-cased and stripped, values stripped.

    Each row gets ``_line`` (its line number in the file) for messages.  A cell
    the toolkit wrote inert for spreadsheets (a manifest of ``sample_data_synth
    study``) is read as it was given (:func:`tissue_core.csvtext.restore_cell`).
    """
    from tissue_core.tables import cell_count_error

    path = Path(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.DictReader(f)
            rows = [(reader.line_num, row) for row in reader]
    except FileNotFoundError:
        raise InputError(f"manifest {path} does not exist") from None
    except IsADirectoryError:
        raise InputError(f"manifest {path} is a folder; give the CSV file") from None
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"manifest {path} cannot be read: {exc}") from None
    out = []
    for i, row in rows:
        cells = [v for k, v in row.items() if k is not None and v is not None]
        cells += row.get(None, [])
        if not any(v.strip() for v in cells):
            continue  # an empty row (a spreadsheet's trailing commas)
        if len(cells) != len(reader.fieldnames):  # more or fewer cells than the header
            raise cell_count_error(
                f"manifest {path}", i, len(cells), len(reader.fieldnames), ",".join(cells)
            )
        clean = {(k or "").strip().lower(): restore_cell((v or "").strip()) for k, v in row.items()}
        clean["_line"] = str(i)
        out.append(clean)
    if not out:
        raise InputError(f"manifest {path} has no rows; one row per run is needed")
    missing = [c for c in required if c not in out[0]]
    if missing:
        raise InputError(
            f"manifest {path} needs a column {missing[0]!r} (columns: {', '.join(required)}, "
            "one row per run)"
        )
    for row in out:
        for c in required:
            if not row[c]:
                raise InputError(f"manifest {path}, line {row['_line']}: the {c} column is empty")
    return out


def manifest_jobs(
    manifest: str | os.PathLike | list[dict[str, str]],
    out: Path,
    options: RunOptions,
    args: argparse.Namespace,
    *,
    module: str,
    command: str,
    sources: Sequence[tuple[str, str | None]],
    aliases: dict[str, str] | None = None,
    name_column: str = "specimen",
    own_columns: Sequence[str] = (),
    summary: str = "summary.json",
    neutral: Sequence[str] = (),
) -> tuple[list[Job], list[dict[str, str]], list[str]]:
    """The jobs of a manifest, one per row, each writing ``out/runs/NAME``.

    Parameters
    ----------
    manifest : path, or list of dict
        The manifest CSV, or rows already made (each with ``_line``, how
        messages name it; their paths relative to the current folder).
    sources : sequence of (column, flag)
        The input columns (relative to the manifest's folder or absolute) and
        the command's flag for each (``None``: a positional argument).
    aliases : dict, optional
        Other names of columns (``{"source": "video"}``).
    name_column : str
        The run's name (default: the first input's name without suffix).
    own_columns : sequence of str
        Columns the batch command itself uses (``group``).

    Returns
    -------
    jobs, rows, unused
        The rows (with the run's name in ``name_column``) and the columns
        neither the batch nor the command uses.
    """
    rows = manifest if isinstance(manifest, list) else manifest_rows(manifest, required=())
    aliases = aliases or {}
    for row in rows:
        for alias, column in aliases.items():
            if alias in row and column not in row:
                row[column] = row.pop(alias)
    first = rows[0]
    for column, _ in sources:
        if column not in first:
            raise InputError(f"manifest {manifest} needs a column {column!r}, one row per run")
    base = Path.cwd() if isinstance(manifest, list) else Path(manifest).resolve().parent
    run_columns = set(options.columns(first)) - {c for c, _ in sources}
    mine = {c for c, _ in sources} | {name_column, "_line", *own_columns}
    unused = [c for c in first if c not in mine and c not in run_columns]
    for column in unused:  # a misspelt option would be left out in silence
        near = _misspelt(column, list(options._by_column()))
        if near:
            warnings.warn(
                f"manifest column {column!r} is not used: no option of {command} has that "
                f"name (did you mean {near!r}?)",
                UserWarning,
                stacklevel=2,
            )
    jobs = []
    for row in rows:
        where = (
            row["_line"]
            if isinstance(manifest, list)
            else f"manifest {manifest}, line {row['_line']}"
        )
        argv: list[str] = [command]
        inputs = []
        for column, flag in sources:
            text = row.get(column, "")
            if not text:
                raise InputError(f"{where}: the {column} column is empty")
            path = Path(text) if Path(text).is_absolute() else base / text
            inputs.append(str(path))
            argv += [str(path)] if flag is None else [flag, str(path)]
        name = row.get(name_column) or Path(inputs[0]).stem
        problem = _bad_name(name)
        if problem:
            raise InputError(f"{where}: {name_column} {name!r} {problem}")
        problem = name_too_long(name, out)  # a run's folder is made under a temporary name
        if problem:
            raise InputError(f"{where}: {name_column} {problem}; give a shorter one")
        run = out / "runs" / name
        run_argv = options.argv(args, {c: row[c] for c in run_columns}, where=where, base=base)
        # files named by options (points, calibrations) are inputs too
        inputs += [a for a in run_argv if not a.startswith("-") and Path(a).is_file()]
        argv += [*run_argv, "--out", str(run)]
        jobs.append(
            Job(name, module, tuple(argv), str(run), tuple(inputs), summary, tuple(neutral))
        )
        row[name_column] = name
    _check_unique(jobs)
    return jobs, rows, unused


def _misspelt(column: str, names: Sequence[str]) -> str | None:
    """The option ``column`` looks like a misspelling of (letters swapped, one or two typed
    wrong or missing), or None: ``gird`` -> ``grid``, not ``true_endpoint`` -> ``endpoint``."""
    for name in names:
        if abs(len(name) - len(column)) > 2:
            continue
        swapped = sorted(name) == sorted(column)
        if swapped or difflib.SequenceMatcher(None, column, name).ratio() >= 0.8:
            return name
    return None


#: characters no run name may hold: path separators, shell patterns, and what Windows refuses
_BAD_CHARACTERS = frozenset('/\\*?[]<>:"|')


def _bad_name(name: str) -> str:
    """Why ``name`` cannot name a run's folder, or ``""``."""
    if not name.strip():
        return "is empty"
    if name.startswith("."):
        return "starts with '.' (hidden; the toolkit's scratch folders start so)"
    bad = sorted(set(name) & _BAD_CHARACTERS)
    if bad:
        return f"cannot name a folder (it holds {' '.join(bad)})"
    if any(ord(c) < 32 for c in name):
        return "holds a control character"
    return ""


def _check_unique(jobs: Sequence[Job]) -> None:
    names = [j.name.lower() for j in jobs]  # folders of names differing in case collide on
    dup = sorted({j.name for j in jobs if names.count(j.name.lower()) > 1})  # macOS, Windows
    if dup:
        raise InputError(
            f"run names must be unique in a batch; repeated: {', '.join(dup)} (a manifest "
            "names its runs in a 'specimen' column; by default a run takes its input's name)"
        )


def batch_folder(path: str | os.PathLike) -> Path:
    """The batch's output folder, made if needed; one that is not a batch's is refused."""
    path = Path(path)
    check_name_lengths(path, scratch=False)  # made as it is, not under a temporary name
    if path.exists() and not path.is_dir():
        raise InputError(f"--out {path} is a file; give a folder for the batch")
    if path.is_dir() and any(path.iterdir()):
        record = path / BATCH_FILE
        try:
            kind = json.loads(record.read_text(encoding="utf-8")).get("kind")
        except (OSError, ValueError, AttributeError):
            kind = None
        if kind != _KIND and not (path / LOCK_FILE).exists():
            raise InputError(
                f"--out {path} exists and is not a batch folder (no {BATCH_FILE}); give a new "
                "or empty folder"
            )
    path.mkdir(parents=True, exist_ok=True)
    return path


class _Log:
    """The batch's log file: timestamped lines, appended and flushed one at a time."""

    def __init__(self, path: Path, say: Callable[[str], None]) -> None:
        self.path = path
        self.say = say

    def __call__(self, message: str, *, show: bool = True, details: Sequence[str] = ()) -> None:
        stamp = datetime.now(UTC).isoformat(timespec="seconds")
        with open(self.path, "a", encoding="utf-8") as f:  # names as text: tissue_core.filenames
            f.write(f"{stamp} {readable(message)}\n")
            for line in details:
                f.write(f"{stamp}   | {readable(line)}\n")
        if show:
            self.say(message)


def update_batch_file(path: str | os.PathLike, text: str, *, overwrite: bool) -> str:
    """Write a file of the batch folder that lists its runs (a study manifest, a table of
    metrics) when it is the batch's to write; say what became of it.

    The file is the batch's while it holds exactly what a batch wrote there
    (the folder's ledger records it: :func:`tissue_core.outputs.written_here`):
    it is then written again whenever ``text`` differs.  A file the user
    edited, or one no batch wrote, is the user's, and is left as it is unless
    ``overwrite``.

    Returns
    -------
    str
        ``"written"``, ``"unchanged"`` (it holds ``text`` already), or
        ``"kept"`` (the user's, left as it is: the caller says so).
    """
    path = Path(path)
    try:
        current = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        current = None
    except (OSError, ValueError):  # a folder, or not text: not the batch's
        current = ""
    if current == text:
        return "unchanged"
    if current is not None and not overwrite and not written_here(path):
        return "kept"
    with replaced_on_success(path, record=True) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return "written"


def raise_if_failed(outcomes: Sequence[Outcome], folder: str | os.PathLike) -> None:
    """End the batch command with one line when runs failed: how many, the first and why."""
    failed = [o for o in outcomes if o.status == "failed"]
    if failed:
        more = f"; {len(failed) - 1} more" if len(failed) > 1 else ""
        raise InputError(
            f"{len(failed)} of {len(outcomes)} runs failed, the others are in {folder}: "
            f"{failed[0].name}: {failed[0].reason}{more} (see {Path(folder) / LOG_FILE})"
        )


def _write_record(folder: Path, command: list[str] | None, where: str, outcomes: list[Outcome]):
    from tissue_core import __version__

    record = {
        "kind": _KIND,
        "software": {"name": "tissue-strain", "version": __version__},
        "command": command,
        "updated": datetime.now(UTC).isoformat(timespec="seconds"),
        "where": where,
        "runs": [
            {k: v for k, v in asdict(o).items() if k != "messages"}
            for o in sorted(outcomes, key=lambda o: o.name)
        ],
    }
    with replaced_on_success(folder / BATCH_FILE) as tmp:
        write_json(tmp, record)


#: what differs between two runs of the same command on the same inputs: when, how long, and
#: how much memory they were allowed (mpm3d's parameters.memory: the results do not depend on it)
_PROVENANCE_KEYS = frozenset({"created", "updated", "command", "runtime_s", "out", "memory"})


def _without_provenance(value):
    if isinstance(value, dict):
        return {k: _without_provenance(v) for k, v in value.items() if k not in _PROVENANCE_KEYS}
    if isinstance(value, list):
        return [_without_provenance(v) for v in value]
    return value


#: files of a folder that record how results were made, not results
_NOT_RESULTS = frozenset(
    {
        ".tissue-strain-result.json",
        LEDGER,
        "report.html",
        BATCH_FILE,
        LOG_FILE,
        ".batch.lock",
        "run.log",  # a run's own log: when and how fast it was made
    }
)


def differences(a: str | os.PathLike, b: str | os.PathLike) -> list[str]:
    """The files that differ between two result folders, beyond their provenance.

    Every file is compared byte for byte, except: the result marker and the
    ledger of files, the batch's record and log and a run's log (how, when and
    where the runs were made); JSON files, compared without their time stamps, command lines and
    run times; and ``report.html``, which shows those.  Where a file names its own
    folder (a study lists its runs), the two folders' paths count as equal.
    An empty list means the two folders hold the same results.
    """
    a, b = Path(a).resolve(), Path(b).resolve()

    def files(root: Path) -> set[str]:
        return {
            p.relative_to(root).as_posix()
            for p in root.rglob("*")
            if p.is_file() and p.name not in _NOT_RESULTS
        }

    fa, fb = files(a), files(b)
    out = [f"{name}: only in {a}" for name in sorted(fa - fb)]
    out += [f"{name}: only in {b}" for name in sorted(fb - fa)]
    for name in sorted(fa & fb):
        x = (a / name).read_bytes().replace(readable(a).encode(), b"<folder>")
        y = (b / name).read_bytes().replace(readable(b).encode(), b"<folder>")
        if x == y:
            continue
        if name.endswith(".json"):
            try:
                if _without_provenance(json.loads(x)) == _without_provenance(json.loads(y)):
                    continue
            except ValueError:
                pass
        out.append(f"{name}: differs")
    return out


def _worker_deaths(dask_scheduler, key: str) -> int:  # runs on the scheduler
    ts = dask_scheduler.tasks.get(key)
    return 0 if ts is None else int(ts.suspicious)


def run_batch(
    jobs: Sequence[Job],
    folder: str | os.PathLike,
    *,
    workers: int = 1,
    scheduler: str | None = None,
    overwrite: bool = False,
    say: Callable[[str], None] = lambda message: None,
    notes: Sequence[str] = (),
    then: Callable[[list[Outcome], Callable[..., Outcome]], None] | None = None,
) -> list[Outcome]:
    """Run every job that is not complete already; return every job's outcome, in order.

    Parameters
    ----------
    jobs : sequence of Job
        Names must be unique.
    folder : path
        The batch folder, made if needed (see :func:`batch_folder`): ``batch.log``
        and ``batch.json``.
    workers : int
        Local worker processes (1: in this process, one run after the other).
    scheduler : str, optional
        The address of a running Dask scheduler; ``workers`` is then ignored.
    overwrite : bool
        Replace runs made with other parameters or from changed inputs; without
        it the batch is refused before any run starts.
    say : callable
        Progress lines (the command line's :class:`~tissue_core.progress.Progress`).
    notes : sequence of str
        Lines for the log and ``say`` after the batch's first (the manifest's
        columns not used, say).
    then : callable, optional
        ``then(outcomes, run)``, called once every job has an outcome (``outcomes``
        in the order of ``jobs``) and before the workers are let go:
        ``run(job, overwrite=False, remake=False)`` makes one more job where the runs
        were made and returns its :class:`Outcome`.  ``strain2d batch`` builds its
        study so, on a worker whose libraries are loaded already.
    """
    _check_unique(jobs)
    folder = batch_folder(folder)
    with _lock(folder):
        return _run_batch(jobs, folder, workers, scheduler, overwrite, say, notes, then)


#: the file that marks a batch folder as in use by a running batch
LOCK_FILE = ".batch.lock"


@contextlib.contextmanager
def _lock(folder: Path) -> Iterator[None]:
    """One batch at a time in a folder: two would make the same runs and rewrite each other's
    record."""
    path = folder / LOCK_FILE
    me = {"host": socket.gethostname(), "pid": os.getpid(), "started": _now()}
    for _ in range(2):
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            try:
                other = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                other = {}
            if other.get("host") == me["host"] and not _alive(other.get("pid")):
                path.unlink(missing_ok=True)  # left by a batch that was killed
                continue
            raise InputError(
                f"another batch (process {other.get('pid')} on {other.get('host')}, started "
                f"{other.get('started')}) is using {folder}; wait for it, or remove "
                f"{path} if it is gone"
            ) from None
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            json.dump(me, f)
        break
    try:
        yield
    finally:
        path.unlink(missing_ok=True)


def _alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (TypeError, ValueError, ProcessLookupError):
        return False
    except PermissionError:  # another user's process
        return True
    return True


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds")


def _run_batch(
    jobs, folder: Path, workers, scheduler, overwrite, say, notes=(), then=None
) -> list[Outcome]:
    log = _Log(folder / LOG_FILE, say)
    began = time.time()
    command = recorded_command.get()
    outcomes: dict[str, Outcome] = {}
    todo: list[tuple[Job, bool]] = []
    stale = []
    for job in jobs:
        remove_stale_scratch(job.out)  # left by a killed run: its earlier result put back
        state = job_state(job)
        if state == "complete":
            outcomes[job.name] = Outcome(job.name, "skipped", job.out, "complete already")
        elif state == "missing":
            todo.append((job, False))
        else:
            stale.append((job, state))
    if stale and not overwrite:
        job, state = stale[0]
        more = f" (and {len(stale) - 1} more)" if len(stale) > 1 else ""
        raise InputError(f"run {job.name}: {state}{more}; --overwrite makes them again")
    todo += [(job, True) for job, _ in stale]
    where = (
        f"the Dask scheduler at {scheduler}"
        if scheduler
        else ("this process" if workers == 1 else f"a local Dask cluster of {workers} workers")
    )
    log(
        f"batch of {len(jobs)} runs: {len(outcomes)} complete already, "
        + (f"{len(todo)} to run on {where}" if todo else "nothing to run")
    )
    if command:
        log("command: " + " ".join(command), show=False)
    for note in notes:
        log(note)
    for job, _ in todo:
        Path(job.out).parent.mkdir(parents=True, exist_ok=True)

    def finished(outcome: Outcome) -> None:
        outcomes[outcome.name] = outcome
        remove_stale_scratch(outcome.out)  # left by an attempt whose worker was killed
        done = sum(o.status != "skipped" for o in outcomes.values())
        count = f"[{done}/{len(todo)}]"
        deaths = outcome.worker_deaths
        retried = f" (started again: its worker died {deaths}x)" if deaths else ""
        if outcome.status == "done":
            written.append(outcome.out)
            what = (
                f"done: {outcome.reason}"
                if outcome.reason
                else f"done in {outcome.seconds:.1f} s on {outcome.worker}"
            )
        else:
            what = f"failed: {outcome.reason}"
        log(f"{count} {outcome.name}: {what}{retried}", details=outcome.messages)
        _write_record(folder, command, where, list(outcomes.values()))

    _write_record(folder, command, where, list(outcomes.values()))

    def after(run) -> None:  # ``then``, given every outcome; the log says what it made

        def logged(job: Job, overwrite: bool = False, remake: bool = False) -> Outcome:
            log(f"{job.name}: started", show=False)
            outcome = run(job, overwrite, remake)
            what = (
                f"done in {outcome.seconds:.1f} s on {outcome.worker}"
                if outcome.status == "done"
                else f"failed: {outcome.reason}"
            )
            log(f"{job.name}: {what}", show=False, details=outcome.messages)
            return outcome

        then([outcomes[j.name] for j in jobs], logged)

    def here(job: Job, overwrite: bool = False, remake: bool = False) -> Outcome:
        made = list(written)  # the job's own command clears the list
        outcome = run_job(job, overwrite, remake=remake)
        written[:] = made
        if outcome.reason == "interrupted" or was_interrupted():
            raise_if_interrupted()  # Ctrl-C (SIGTERM, SIGHUP) ended the job: it ends the batch
            raise KeyboardInterrupt
        return outcome

    extra: list[Job] = []  # run by ``then`` on the cluster
    try:
        if todo and workers == 1 and scheduler is None:
            for job, replace in todo:
                log(f"{job.name}: started", show=False)
                finished(here(job, replace))
            if then:
                after(here)
        elif todo:
            try:
                _run_on_dask(
                    todo, workers, scheduler, log, finished, after if then else None, extra
                )
            finally:
                if scheduler is None:  # the local workers are gone, and with them their runs
                    for job in [*(job for job, _ in todo), *extra]:
                        remove_stale_scratch(job.out)
        elif then:  # nothing to run: no workers to start for it
            after(here)
    except KeyboardInterrupt as exc:
        # a run a worker finished as the cluster closed is whole: it counts as made
        for job, _ in todo:
            if job.name not in outcomes and job_state(job) == "complete":
                finished(
                    Outcome(
                        job.name, "done", job.out, "its worker finished it as the batch stopped"
                    )
                )
        for job in extra:  # the study, say: made by this batch if its marker is newer
            if job_state(job) == "complete" and _made_since(job, began):
                written.append(job.out)
                log(f"{job.name}: its worker finished it as the batch stopped", show=False)
        made = sum(o.status == "done" for o in outcomes.values())
        still = " (runs in progress on the cluster may still be made)" if scheduler else ""
        signum = interrupt_signal(exc)
        how = "interrupted" if signum == signal.SIGINT else f"terminated ({signal_name(signum)})"
        log(f"{how}: {made} of {len(todo)} runs made{still}; a rerun makes the others", show=False)
        raise
    return [outcomes[j.name] for j in jobs]


def _made_since(job: Job, when: float) -> bool:
    """Whether the result in ``job.out`` was renamed into place at ``when`` or later."""
    try:
        return os.stat(job.out).st_mtime >= when - 1.0  # a coarse file system's rounding
    except OSError:
        return False


def _has_dashboard(client) -> bool:
    try:
        return "dashboard" in client.scheduler_info().get("services", {})
    except Exception:  # an old scheduler: no matter
        return False


#: seconds between the lines that say what a batch on Dask is doing while no run ends
HEARTBEAT_S = 60.0


def _threads(client) -> int:
    """How many runs the cluster can make at once now: its workers' threads (0: none)."""
    try:
        workers = client.scheduler_info(n_workers=-1).get("workers", {})
    except Exception:  # the scheduler does not answer now: one at a time until it does
        return 1
    return sum(int(w.get("nthreads", 1)) for w in workers.values())


#: seconds a batch waits for a cluster without workers before it gives up
NO_WORKERS_S = 600.0


def _in_turn(client, todo, submit, log, interval: float | None = None):
    """Submit the runs as the cluster has room (one per worker thread), and yield each
    ``(future, job)`` as it finishes; while none does, a line every ``interval`` seconds
    naming the runs in progress.

    Held back here rather than queued on the scheduler, so that a worker that dies
    takes no waiting run with it, and the runs in progress are known.
    """
    from distributed import wait

    interval = HEARTBEAT_S if interval is None else interval
    waiting = list(todo)
    running: dict = {}
    alone_since = None  # when the cluster was last seen without workers
    while waiting or running:
        threads = _threads(client)
        if threads:
            alone_since = None
        else:
            alone_since = alone_since or time.monotonic()
            if time.monotonic() - alone_since > NO_WORKERS_S:
                raise InputError(
                    f"the cluster has had no workers for {NO_WORKERS_S / 60:.0f} minutes: "
                    f"{len(running) + len(waiting)} runs not made (a rerun makes them)"
                )
        room = max(threads, 1) - len(running)  # one run asks an adaptive cluster for a worker
        while waiting and room > 0:
            job, replace = waiting.pop(0)
            running[submit(job, replace)] = job
            room -= 1
        try:
            done, _ = wait(list(running), timeout=interval, return_when="FIRST_COMPLETED")
        except TimeoutError:  # no run ended in the interval
            done = set()
        if not done and not threads:
            log(f"no workers: {len(running) + len(waiting)} runs wait for the cluster")
        elif not done:
            names = ", ".join(sorted(job.name for job in running.values()))
            log(f"{len(running)} running ({names}), {len(waiting)} waiting")
        for future in done:
            yield future, running.pop(future)


def _trimming(client) -> bool:
    """Whether any worker of the cluster started with MALLOC_TRIM_THRESHOLD_ set."""
    try:
        found = client.run(os.environ.get, _TRIM)
    except Exception:  # a worker that cannot answer: nothing to advise
        return False
    return any(value is not None for value in found.values())


_TRIM = "MALLOC_TRIM_THRESHOLD_"
#: the Dask setting that gives a nanny's workers the malloc variable
_TRIM_SETTING = f"distributed.nanny.pre-spawn-environ.{_TRIM}"


@contextlib.contextmanager
def _without_malloc_trimming() -> Iterator[None]:
    """Workers started in here (a local cluster's, restarted ones too) run without
    MALLOC_TRIM_THRESHOLD_.

    Dask's nannies set it in their workers, which turns glibc's adaptive mmap
    threshold off: every array over 128 KiB is then mapped afresh and its pages
    faulted in.  The same runs in two plain processes took 8.7-9.6 s with it and
    6.8-7.4 s without (2 cores).  A nanny also leaves it in its own process's
    environment, which later workers would inherit: it is taken out of this one.
    """
    import dask

    inherited = os.environ.pop(_TRIM, None)
    try:
        with dask.config.set({_TRIM_SETTING: None}):
            yield
    finally:
        if inherited is not None:
            os.environ[_TRIM] = inherited


def _run_on_dask(todo, workers, scheduler, log, finished, then=None, extra=None) -> None:
    """The runs on a local cluster or a scheduler's; then ``then(run)`` while the workers
    are still there (``extra`` lists the jobs it ran)."""
    import logging

    from dask.base import tokenize
    from distributed import Client, LocalCluster

    with contextlib.ExitStack() as stack:
        quiet = logging.getLogger().getEffectiveLevel() > logging.INFO
        for name in ("distributed", "dask", "bokeh", "tornado") if quiet else ():
            logger = logging.getLogger(name)
            stack.callback(logger.setLevel, logger.level)
            # the cluster's own chatter, its errors too (a worker busy with a run while the
            # cluster closes logs a failed heartbeat with a traceback): the batch reports
            # what happened to each run itself; -v shows them
            logger.setLevel(logging.CRITICAL)
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler, timeout="20s"))
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError(f"no Dask scheduler answers at {scheduler}: {exc}") from None
        else:
            # a signal while the cluster starts waits until it is up and in the stack, which
            # then closes it: one that lands half-way leaves worker processes, a scheduler
            # that goes on logging, and semaphores the resource tracker complains of
            with deferred_interrupt():
                try:
                    stack.enter_context(_without_malloc_trimming())
                    cluster = LocalCluster(
                        n_workers=workers,
                        threads_per_worker=1,  # a run is one task; its libraries' threads: its own
                        processes=True,
                        dashboard_address=":0",  # a free port: batches may run side by side
                        silence_logs=logging.CRITICAL,  # the workers' too
                        preload=["tissue_core._batch_worker"],  # Ctrl-C is the batch's alone
                        # the cores shared out: a run's compiled kernels use its worker's share
                        env={
                            "NUMBA_NUM_THREADS": str(max(1, (os.cpu_count() or 1) // workers)),
                            _THREADS_ENV: str(max(1, (os.cpu_count() or 1) // workers)),
                        },
                    )
                    stack.enter_context(cluster)
                except (RuntimeError, OSError, TimeoutError) as exc:
                    raise InputError(
                        f"a local Dask cluster of {workers} workers could not start: {exc} "
                        "(--workers 1 runs the batch without one)"
                    ) from None
                client = stack.enter_context(Client(cluster))
        n = len(client.scheduler_info(n_workers=-1).get("workers", {}))
        link = client.dashboard_link if _has_dashboard(client) else "none (install bokeh)"
        log(f"{n} workers; Dask dashboard: {link}", show=bool(scheduler) or n > 1)
        if scheduler and _trimming(client):
            log(
                "note: these workers run with MALLOC_TRIM_THRESHOLD_ set (Dask's nanny sets it), "
                "which made runs about a quarter slower in our measurements; the batches "
                "guide (docs/batches.md) says how to unset it"
            )

        def submit(job: Job, replace: bool):
            key = f"run-{job.name}-{tokenize(job, replace, time.time())}"
            return client.submit(run_job, job, replace, key=key, pure=False)

        for future, job in _in_turn(client, todo, submit, log):
            outcome = _outcome_of(future, job, client)
            finished(outcome)
        if then is not None:

            def run(job: Job, overwrite: bool = False, remake: bool = False) -> Outcome:
                extra.append(job)

                def submit_it(job: Job, overwrite: bool):
                    key = f"then-{job.name}-{tokenize(job, overwrite, remake, time.time())}"
                    return client.submit(
                        run_job, job, overwrite, remake=remake, key=key, pure=False
                    )

                # as the runs were: heartbeat lines, and an end when the cluster has no workers
                ((future, _),) = _in_turn(client, [(job, overwrite)], submit_it, log)
                return _outcome_of(future, job, client)

            then(run)


def _outcome_of(future, job: Job, client) -> Outcome:
    """The outcome of a job's future (waited for), with its workers' deaths counted."""
    try:
        outcome = future.result()
    except Exception as exc:  # KilledWorker: its workers died again and again
        reason = f"{type(exc).__name__}: {exc}"
        if type(exc).__name__ == "KilledWorker":
            reason = (
                "every worker that ran it died (out of memory? a crash?); the Dask "
                "setting distributed.scheduler.allowed-failures says how many may"
            )
        outcome = Outcome(job.name, "failed", job.out, reason)
    try:
        outcome.worker_deaths = client.run_on_scheduler(_worker_deaths, key=future.key)
    except Exception:  # the scheduler is gone: the count is not essential
        pass
    return outcome
