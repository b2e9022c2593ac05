"""Output folders that appear whole or not at all.

Results are written into a hidden temporary folder beside the target and
renamed into place at the end; an existing result is replaced only with
``overwrite``, and never when it is, or holds, an input or the working
directory.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

from mpm3d.errors import InputError

__all__ = ["output_folder"]


def _refuse(out: Path, overwrite: bool, inputs: Sequence[str | os.PathLike]) -> None:
    resolved = out.resolve()
    if out.exists() and not overwrite:
        raise InputError(f"{out} exists; pass --overwrite to replace it")
    if out.exists() and not out.is_dir():
        raise InputError(f"{out} is a file; give a folder name for --out")
    if not resolved.parent.is_dir():
        raise InputError(f"output folder {resolved.parent} does not exist")
    here = Path.cwd().resolve()
    if resolved == here or resolved in here.parents:
        raise InputError(f"{out} is the working directory or holds it; choose another --out")
    for item in inputs:
        src = Path(item).resolve()
        if src == resolved or resolved in src.parents:
            raise InputError(f"--out {out} would replace the input {item}")


@contextlib.contextmanager
def output_folder(
    out: str | os.PathLike, *, overwrite: bool = False, inputs: Sequence[str | os.PathLike] = ()
) -> Iterator[Path]:
    """Yield a scratch folder that becomes ``out`` if the block succeeds."""
    out = Path(out)
    _refuse(out, overwrite, inputs)
    scratch = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.resolve().parent))
    try:
        yield scratch
        mask = os.umask(0o022)
        os.umask(mask)
        scratch.chmod(0o777 & ~mask)
        if out.exists():
            trash = scratch.with_name(scratch.name.replace(".partial-", ".replaced-"))
            out.rename(trash)
            scratch.rename(out)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            scratch.rename(out)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
