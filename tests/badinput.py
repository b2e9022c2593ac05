"""The contract every command keeps on bad input, checked the same way for all of them.

Each package's ``test_bad_input.py`` runs its command lines on broken,
hostile and conflicting input through :func:`assert_refused`: exit status 2,
exactly one line on stderr (after any timestamped progress lines) that starts
with ``PROG COMMAND: error:`` and names the file or option and the problem,
no traceback, inputs byte-identical, no output and no temporary file left
behind, and nothing of the user's removed.  Text a spreadsheet would run
(the ``formula`` family: names starting with ``=``, ``+``, ``-``, ``@``) is
not an error: :func:`assert_inert` checks that such a command succeeds and
that every CSV it wrote holds the text inert.  :func:`interrupt` sends Ctrl-C
(or SIGTERM, SIGHUP) to a real process at a chosen moment: exit 130 (143,
129) and one line, or (when the command had already finished) exit 0 and a
complete result; never a traceback, never half a result, no process of its
left running.  :func:`killed` ends a real process with SIGKILL while it
writes, and :func:`stale_scratch` leaves what such a process leaves, for the
next run to remove.

``scripts/bad_input_counts.py`` counts these cases per command for the
reliability guide (docs/reliability.md); the tests are named
``test_bad_input[COMMAND-FAMILY-CASE]`` (or ``test_interrupt[COMMAND-...]``)
so that it can.
"""

from __future__ import annotations

import csv
import glob
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: families of bad input, as the reliability guide (docs/reliability.md) names them
FAMILIES = (
    "missing",  # files and folders that are not there
    "empty",  # empty files, folders without images
    "truncated",  # files cut short
    "wrong-type",  # a text file named .tif, a video that is an image, ...
    "stack",  # big-endian, float, NaN, odd dtypes (accepted: see the mpm3d tests)
    "csv",  # NaN, inf, strings, duplicates, BOM, missing columns
    "option",  # out-of-range, negative, non-finite option values
    "conflict",  # options that contradict each other
    "output",  # unwritable, foreign, or inside an input folder
    "interrupt",  # Ctrl-C at a random moment
    "terminate",  # SIGTERM or SIGHUP (kill, timeout, scancel, docker stop) at a random moment
    "stale",  # scratch folders and files left by an earlier run that was killed (SIGKILL)
    "formula",  # user text that a spreadsheet would run: =, +, -, @, tab, CR at a cell's start
    "filename",  # file and folder names that are not UTF-8 (Windows-origin and shared drives)
    "allocation",  # options that size an allocation beyond the inputs or the memory
    "nonfinite",  # infinite or NaN pixel values in frames
    "calibration",  # calibrations that cannot be physical: wrong board, zero baseline, ...
)


def parse_case_id(case: str) -> tuple[str, str, str]:
    """``"import-calib-csv-nan-focal"`` -> ``("import-calib", "csv", "nan-focal")``."""
    found = [(case.find(f"-{f}-"), f) for f in FAMILIES if case.find(f"-{f}-") > 0]
    if not found:
        raise ValueError(f"bad-input case {case!r} names no family of {FAMILIES}")
    at, family = min(found)
    return case[:at], family, case[at + len(family) + 2 :]


def unwritable_folder(tmp_path: Path) -> Path:
    """A folder nothing can be written into: a read-only one, or /sys where root runs the tests
    (root ignores permission bits)."""
    folder = Path(tmp_path) / "locked"
    folder.mkdir(exist_ok=True)
    folder.chmod(0o555)
    try:
        os.rmdir(tempfile.mkdtemp(dir=folder))
    except OSError:
        return folder
    folder.chmod(0o755)
    return Path("/sys")


_PROGRESS = re.compile(r"^\[ *\d+\.\d s\] ")


def message_lines(err: str) -> list[str]:
    """The lines of stderr that are not timestamped progress (``[  1.2 s] ...``)."""
    return [line for line in err.splitlines() if line.strip() and not _PROGRESS.match(line)]


def write(folder: Path, name: str, content: str | bytes) -> Path:
    """Write ``content`` (text as UTF-8, or bytes) to ``folder/name``, making its folder."""
    path = Path(folder) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8", errors="surrogatepass")
    return path


def snapshot(*paths: str | os.PathLike) -> dict[str, bytes | None]:
    """Bytes of every file under ``paths`` (None for folders), to compare before and after."""
    out: dict[str, bytes | None] = {}
    for path in map(Path, paths):  # os.path: False for a name too long, where pathlib raises
        if os.path.isdir(path):
            out[str(path)] = None
            for p in sorted(path.rglob("*")):
                out[str(p)] = p.read_bytes() if p.is_file() else None
        elif os.path.exists(path):
            out[str(path)] = path.read_bytes()
    return out


def scratch_left(folder: str | os.PathLike) -> list[str]:
    """Temporary files and folders the atomic writers left in ``folder``."""
    return [p.name for p in Path(folder).iterdir() if ".tmp-" in p.name or ".old-" in p.name]


def assert_refused(
    main: Callable[[list[str]], int],
    argv: Sequence[object],
    capsys,
    *,
    prog: str,
    fragments: Sequence[str] = (),
    inputs: Sequence[str | os.PathLike] = (),
    out: str | os.PathLike | None = None,
) -> str:
    """Run ``main(argv)`` in-process and check the bad-input contract; return the error line.

    ``fragments`` must all appear in the error line (name the file or option
    and the problem); ``inputs`` must be byte-identical afterwards; ``out``
    (the output the command was asked to write) must be as it was before:
    absent, or with the same content, and with no temporary sibling.
    """
    argv = [str(a) for a in argv]
    watched = [*inputs, *([out] if out is not None else [])]
    before = snapshot(*watched)
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's own usage errors
        status = exc.code
    captured = capsys.readouterr()
    err = captured.err
    assert "Traceback" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    errors = message_lines(err)
    assert status == 2, f"exit {status} for {argv}: {err}"
    assert len(errors) == 1, f"not one error line for {argv}:\n{err}"
    line = errors[0]
    assert lines[-1] == line, err
    assert line.startswith(f"{prog} ") and ": error: " in line, line
    for fragment in fragments:
        assert fragment in line, f"{fragment!r} not in: {line}"
    assert snapshot(*watched) == before, f"{argv} changed its inputs or output"
    if out is not None and Path(out).resolve().parent.is_dir():
        assert scratch_left(Path(out).resolve().parent) == []
    return line


def formula_cells(where: str | os.PathLike) -> list[str]:
    """``FILE: CELL`` for every cell of every CSV under ``where`` (a folder, or one CSV file)
    that a spreadsheet would run: one that starts with ``=``, ``+``, ``-``, ``@``, a tab or a
    carriage return and is not a plain number (``-0.5``, ``+3``, ``-inf``)."""
    from tissue_core.csvtext import FORMULA_STARTS

    def number(cell: str) -> bool:
        try:
            float(cell)
        except ValueError:
            return False
        return cell == cell.strip() and "_" not in cell

    found = []
    where = Path(where)
    for path in sorted(where.rglob("*.csv")) if where.is_dir() else [where]:
        with open(path, newline="", encoding="utf-8-sig") as f:
            for row in csv.reader(f):
                found += [
                    f"{path}: {cell!r}"
                    for cell in row
                    if cell.startswith(FORMULA_STARTS) and not number(cell)
                ]
    return found


def assert_inert(
    main: Callable[[list[str]], int],
    argv: Sequence[object],
    capsys,
    *,
    out: str | os.PathLike,
    inputs: Sequence[str | os.PathLike] = (),
) -> str:
    """Run ``main(argv)`` on names a spreadsheet would run as formulas; return its stderr.

    The command must succeed (exit 0, no traceback), leave ``inputs``
    byte-identical and no temporary file beside ``out``, and no CSV under
    ``out`` (a folder, or a CSV file) may hold a cell that starts a formula.
    """
    argv = [str(a) for a in argv]
    before = snapshot(*inputs)
    status = main(argv)
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    assert status == 0, f"exit {status} for {argv}: {err}"
    assert snapshot(*inputs) == before, f"{argv} changed its inputs"
    out = Path(out)
    assert out.exists(), f"{argv} wrote no {out}"
    assert scratch_left(out.resolve().parent) == []
    assert formula_cells(out) == []
    return err


def _start(argv: Sequence[object], cwd, stderr=subprocess.PIPE) -> subprocess.Popen:
    """``python ARGV...`` with this checkout first on the path, in a session of its own (so
    that the processes it starts can be found: :func:`session_processes`)."""
    return subprocess.Popen(
        [sys.executable, *map(str, argv)],
        cwd=cwd or REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        stdout=subprocess.DEVNULL,
        stderr=stderr,
        text=True,
        start_new_session=True,
    )


def session_processes(sid: int) -> list[str]:
    """The processes of session ``sid`` still running (not zombies): ``"PID NAME"`` each."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text(errors="replace")
        except OSError:  # ended meanwhile
            continue
        name = text[text.index("(") + 1 : text.rindex(")")]
        fields = text[text.rindex(")") + 2 :].split()
        if int(fields[3]) == sid and fields[0] not in ("Z", "X"):  # fields 3 and 6 of proc(5)
            found.append(f"{stat.parent.name} {name}")
    return found


def _state(pid: int) -> str:
    """The state of process ``pid`` (``R``, ``S``, ``T``: stopped, ...; ``X`` when it is gone)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text(errors="replace")
    except OSError:
        return "X"
    return text[text.rindex(")") + 2 :].split()[0]


def assert_no_process_left(sid: int, timeout: float = 30.0) -> None:
    """No process that the command started outlives it (an encoder, a cluster's workers).

    Waits up to ``timeout`` seconds for processes that are ending (multiprocessing's
    resource tracker, once it sees its parent's pipe close), then fails naming those
    still running.
    """
    if not Path("/proc/self/stat").exists():
        return
    deadline = time.monotonic() + timeout
    while session_processes(sid) and time.monotonic() < deadline:
        time.sleep(0.05)
    left = session_processes(sid)
    assert left == [], f"processes left running by the command: {left}"


#: ``when=WRITING``: the moment the command's own temporary result holds something
WRITING = "<writing>"


def writing(out: str | os.PathLike, pid: int | None = None) -> bool:
    """Whether a temporary sibling of ``out`` (of process ``pid``, if given) holds something:
    a folder with an entry, or a file."""
    out = Path(out)
    prefixes = tuple(
        f".{out.name}.{kind}-{'' if pid is None else f'{pid}-'}" for kind in ("tmp", "old")
    )
    for p in out.parent.glob(f".{glob.escape(out.name)}.*"):
        if p.name.startswith(prefixes):
            try:
                if not p.is_dir() or any(p.iterdir()):
                    return True
            except OSError:  # removed meanwhile
                pass
    return False


def _cpu_seconds(pid: int) -> float:
    """CPU time (user and system, seconds) process ``pid`` has run; 0 once it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text(errors="replace")
    except OSError:
        return 0.0
    fields = text[text.rindex(")") + 2 :].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime


def interrupt(
    argv: Sequence[object],
    *,
    after: float,
    out: str | os.PathLike,
    inputs: Sequence[str | os.PathLike] = (),
    when: str | None = None,
    may_finish: bool = False,
    cwd: str | os.PathLike | None = None,
    timeout: float = 240,
    signum: int = signal.SIGINT,
) -> tuple[int, str]:
    """Start ``python ARGV...`` and send it ``signum``; check the contract; return (status,
    stderr).

    The signal (SIGINT: Ctrl-C; SIGTERM: ``kill PID``; SIGHUP) goes to the
    process alone once it has run ``after`` seconds of its own CPU time (on
    an idle machine, ``after`` seconds after it starts; on a busy one later,
    so that it still lands past Python's own start-up, in the imports), or, with ``when``,
    ``after`` seconds after a line of stderr holding ``when`` appeared (a
    progress step; :data:`WRITING`: once its temporary result holds
    something), so that it lands in a known stage whatever the machine's
    speed.  The process must then exit 130 (143, 129) with one line
    ``...: interrupted; no output written`` (``...: terminated (SIGTERM); no
    output written``) and leave no output, or, if the result was already in
    place, say so, and leave no process it started running.  Exit 0 (it
    finished first) fails unless ``may_finish``.  Inputs are byte-identical
    either way.
    """
    import threading

    before = snapshot(*inputs)
    proc = _start(argv, cwd)
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    start = time.monotonic()
    anchor = None if when is not None else start
    while proc.poll() is None and time.monotonic() - start < timeout:
        if anchor is None and (
            writing(out, proc.pid) if when == WRITING else any(when in ln for ln in list(lines))
        ):
            anchor = time.monotonic()
        if when is None:
            due = _cpu_seconds(proc.pid) >= after
        else:
            due = anchor is not None and time.monotonic() >= anchor + after
        if due:
            proc.send_signal(signum)
            break
        time.sleep(0.005)
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    reader.join(timeout=10)
    proc.stderr.close()
    err = "".join(lines)
    out = Path(out)
    status = 128 + signum
    said = (
        "interrupted" if signum == signal.SIGINT else f"terminated ({signal.Signals(signum).name})"
    )
    assert "Traceback" not in err, err
    assert proc.returncode in (0, status), f"exit {proc.returncode}: {err}"
    if proc.returncode == status:
        messages = message_lines(err)
        assert messages, f"exit {status} without a message line:\n{err}"
        if out.exists():  # the signal came after the result was complete, and says so
            assert messages[-1].endswith(f": {said} after the results were written to {out}"), err
        else:
            assert messages[-1].endswith(f": {said}; no output written"), err
    else:
        assert may_finish, f"the command finished before the signal reached it:\n{err}"
        assert out.exists()
    assert_no_process_left(proc.pid)
    assert scratch_left(out.resolve().parent) == []
    assert snapshot(*inputs) == before
    return proc.returncode, err


def killed(
    argv: Sequence[object],
    *,
    out: str | os.PathLike,
    cwd: str | os.PathLike | None = None,
    timeout: float = 240,
) -> list[str]:
    """Start ``python ARGV...`` and SIGKILL it while it writes ``out``; return the scratch left.

    "While it writes": as soon as a temporary sibling of ``out`` holds
    something (a folder with an entry, or a file), which is what a run killed
    outright (SIGKILL, out of memory, a power cut) leaves behind.  The process
    is stopped (SIGSTOP) and seen to be writing still before it is killed, so
    that a result renamed into place just then does not count.
    """
    out = Path(out)
    proc = _start(argv, cwd, stderr=subprocess.DEVNULL)
    start = time.monotonic()
    while proc.poll() is None and time.monotonic() - start < timeout:
        if writing(out):
            proc.send_signal(signal.SIGSTOP)
            while proc.poll() is None and _state(proc.pid) not in ("T", "t", "Z", "X"):
                time.sleep(0.001)  # a rename in progress ends before it stops
            if writing(out):
                break
            proc.send_signal(signal.SIGCONT)  # its result was renamed into place just then
        time.sleep(0.002)
    proc.kill()
    proc.wait(timeout=60)
    assert proc.returncode == -signal.SIGKILL, f"exit {proc.returncode}: it ended before writing"
    for pid in session_processes(proc.pid):  # what it started dies with it here
        os.kill(int(pid.split()[0]), signal.SIGKILL)
    return scratch_left(out.parent)


#: a run that writes its result as the toolkit does and is killed (SIGKILL) half-way
_KILLED_WRITER = """
import os, signal, sys
from tissue_core import outputs

writer = {"dir": outputs.atomic_dir, "file": outputs.atomic_file}.get(sys.argv[1])
with (writer or outputs.replaced_on_success)(sys.argv[2]) as tmp:
    if sys.argv[1] == "dir":
        tmp = tmp / "half.csv"
    tmp.write_text("half a result")
    os.kill(os.getpid(), signal.SIGKILL)
"""


def stale_scratch(out: str | os.PathLike, kind: str = "dir") -> list[str]:
    """Leave beside ``out`` the scratch of a run killed (SIGKILL) while writing it: a folder
    (``kind="dir"``), a file (``"file"``), or a file that replaces one the toolkit keeps up to
    date (``"replaced"``: a batch's record); return the scratch's names."""
    done = subprocess.run(
        [sys.executable, "-c", _KILLED_WRITER, kind, str(out)],
        env={**os.environ, "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == -signal.SIGKILL, done.stderr
    left = scratch_left(Path(out).parent)
    assert left, "no scratch was left"
    return left
