"""Whether what an option asks for fits the memory and the disk, checked before it is made.

An option that sizes an array or a file (a grid of points, a frame size, a
number of frames or slices) can ask for more than the machine has: NumPy
then fails with a traceback after the work began, or the system swaps for
hours.  The commands estimate what they will need from their options and
inputs, before allocating or writing anything, and :func:`check_fits`
refuses the run in one line naming the option, what it asks for and what is
there.  Estimates count only the largest arrays and files, so they are
lower bounds: a run that is refused could not have finished.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
from pathlib import Path

from tissue_core.errors import InputError

__all__ = ["available_memory", "check_fits", "format_size", "free_disk"]


def available_memory() -> int:
    """Memory available to a new process now, bytes (psutil, else /proc/meminfo, else sysconf)."""
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except ImportError:
        pass
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def free_disk(path: str | os.PathLike) -> int | None:
    """Bytes free for a new file at ``path`` (on the disk of its nearest existing folder).

    None when no folder of ``path`` can be asked (the output's checks say why).
    """
    folder = Path(os.path.abspath(path))
    while not folder.is_dir():
        if folder.parent == folder:
            return None
        folder = folder.parent
    try:
        return int(shutil.disk_usage(folder).free)
    except OSError:
        return None


def format_size(n: float) -> str:
    """``n`` bytes in words, as NumPy names an allocation: ``"74.5 GiB"``, ``"512 KiB"``.

    Examples
    --------
    >>> format_size(80_000_000_000), format_size(3 * 2**20), format_size(12)
    ('74.5 GiB', '3 MiB', '12 bytes')
    """
    if n < 1024:
        return f"{int(n)} bytes"
    for unit in ("KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        n /= 1024
        if n < 1024 or unit == "EiB":
            break
    return f"{n:.3g} {unit}" if n < 1000 else f"{math.ceil(n)} {unit}"


def check_fits(
    what: str,
    *,
    memory: float = 0,
    disk: float = 0,
    out: str | os.PathLike | None = None,
    remedy: str = "ask for less",
) -> None:
    """Refuse, in one line, a run whose arrays or files cannot fit.

    Parameters
    ----------
    what : str
        The option and what it asks for, the start of the message, e.g.
        ``"--grid 3000x3000 (9000000 points tracked over 500 frames)"``.
    memory : float, keyword-only
        Bytes of memory the run needs at least (its largest arrays).
    disk : float, keyword-only
        Bytes the run writes at least into ``out``.
    out : path-like, keyword-only
        The output (file or folder, existing or not) whose disk is asked.
    remedy : str, keyword-only
        What to do instead, the end of the message.

    Raises
    ------
    InputError
        ``"WHAT needs 74.5 GiB of memory; 15.2 GiB is available: REMEDY"``
        (or the same for the disk, naming the folder).

    Examples
    --------
    >>> check_fits("--size 64", memory=4096)
    >>> check_fits("-n 2**30", memory=2.0**60)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    tissue_core.errors.InputError: -n 2**30 needs 1 EiB of memory; ... is available: ask for less
    """
    if not (math.isfinite(memory) and math.isfinite(disk)):
        raise InputError(f"{what} asks for more than any machine holds")
    if memory > 0:
        have = available_memory()
        if memory > have:
            raise InputError(
                f"{what} needs {format_size(memory)} of memory; {format_size(have)} is "
                f"available: {remedy}"
            )
    if disk > 0 and out is not None:
        free = free_disk(out)
        if free is not None and disk > free:
            folder = Path(os.path.abspath(out)).parent
            raise InputError(
                f"{what} writes {format_size(disk)}; the disk of {folder} has "
                f"{format_size(free)} free: {remedy}"
            )
