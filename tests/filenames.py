"""File and folder names that are not UTF-8, for the tests of every command.

Names made on Windows or on shared drives in Latin-1 (``vid\\xe9o.avi``) are
not UTF-8; Python gives them as text with lone surrogates (``os.fsdecode``).
:func:`latin1` makes such a name, :func:`run_process` passes it to a real
process as the bytes a shell would (a crash in compiled code kills the
process, so these cases need one of their own), and :func:`assert_readable`
checks that every text file a command wrote is valid UTF-8 that strict
readers accept.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from tests.badinput import REPO, message_lines

#: suffixes of the text files the toolkit writes
TEXT_SUFFIXES = frozenset({".json", ".csv", ".html", ".md", ".pvd", ".log", ".txt", ".xml", ".yml"})


def latin1(text: str) -> str:
    """``text`` as the name a Latin-1 system stores: ``"vidéo.avi"`` -> ``"vid\\udce9o.avi"``."""
    return os.fsdecode(text.encode("latin-1"))


def shown(text: str | os.PathLike) -> str:
    """How the toolkit shows a name in text: each byte that is not UTF-8 as ``\\xNN``."""
    return os.fsencode(text).decode("utf-8", "backslashreplace")


def strict_json(path: str | os.PathLike):
    """The JSON file ``path`` read as a strict reader would: UTF-8, no lone surrogates."""
    data = json.loads(Path(path).read_bytes().decode("utf-8"))
    json.dumps(data, ensure_ascii=False).encode("utf-8")  # raises on a lone surrogate
    return data


def assert_readable(folder: str | os.PathLike) -> list[Path]:
    """Every text file under ``folder`` is valid UTF-8 and its JSON parses strictly; returns
    the files checked."""
    checked = []
    for path in sorted(Path(folder).rglob("*")):
        if not path.is_file() or path.suffix.lower() not in TEXT_SUFFIXES:
            continue
        text = path.read_bytes().decode("utf-8")  # raises on bytes that are not UTF-8
        assert "\\udc" not in text, f"{path} shows a name as Python's repr does"
        if path.suffix == ".json":
            strict_json(path)
        checked.append(path)
    return checked


def run_process(
    argv: Sequence[str | os.PathLike],
    *,
    cwd: str | os.PathLike | None = None,
    timeout: float = 300,
) -> tuple[int, str]:
    """Run ``python ARGV...`` with the arguments as bytes; return (exit status, stderr).

    stderr must be valid UTF-8 without a traceback, whatever the status.
    """
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [os.fsencode(sys.executable), *(os.fsencode(a) for a in argv)],
        cwd=cwd or REPO,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        timeout=timeout,
    )
    err = proc.stderr.decode("utf-8")
    assert "Traceback" not in err, err
    return proc.returncode, err


def assert_ran(argv: Sequence[str | os.PathLike], out: str | os.PathLike, **kwargs) -> str:
    """``python ARGV...`` exits 0 with nothing but progress and warnings on stderr, and writes
    ``out`` with readable text files; returns stderr."""
    status, err = run_process(argv, **kwargs)
    assert status == 0, f"exit {status}:\n{err}"
    assert not [line for line in message_lines(err) if ": error: " in line], err
    assert "\\udc" not in err, err
    assert Path(out).exists(), err
    if Path(out).is_dir():
        assert_readable(out)
    return err


def assert_refused_process(
    argv: Sequence[str | os.PathLike], *, fragments: Sequence[str] = (), **kwargs
) -> str:
    """``python ARGV...`` exits 2 with one error line holding ``fragments`` (names as the
    toolkit shows them); returns the line."""
    status, err = run_process(argv, **kwargs)
    lines = message_lines(err)
    assert status == 2, f"exit {status}:\n{err}"
    assert len(lines) == 1 and ": error: " in lines[0], err
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in: {lines[0]}"
    return lines[0]
