"""JSON results: one policy for every file the toolkit writes.

Non-finite numbers (NaN, infinity) are written as ``null``, so that every
result is valid JSON that any reader accepts (Python's ``json`` would write
the invalid tokens ``NaN`` and ``Infinity``); NumPy scalars and arrays become
plain numbers and lists, paths strings.  Text is valid UTF-8 everywhere: a
file name that is not UTF-8 is shown with its undecodable bytes as ``\\xNN``
(:func:`tissue_core.filenames.readable`), so strict JSON readers accept every
file.  Files are indented, UTF-8, and end with a newline.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import PurePath

from tissue_core.filenames import readable

__all__ = ["dumps", "jsonable", "write_json"]


def jsonable(value):
    """``value`` as plain JSON data: NaN and infinity as None, NumPy values as Python ones.

    Text and paths are valid UTF-8 (:func:`tissue_core.filenames.readable`).

    Examples
    --------
    >>> import numpy as np
    >>> jsonable({"a": np.array([1.0, np.nan]), "b": float("inf"), 3: np.int64(2)})
    {'a': [1.0, None], 'b': None, '3': 2}
    """
    if isinstance(value, dict):
        return {readable(str(k)): jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    if isinstance(value, str | PurePath):
        return readable(value)
    tolist = getattr(value, "tolist", None)  # NumPy arrays and scalars, without importing NumPy
    if tolist is not None and not isinstance(value, str | bytes):
        return jsonable(tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def dumps(data, *, indent: int | None = 2) -> str:
    """``data`` as JSON text under the toolkit's policy (see the module docstring)."""
    return json.dumps(jsonable(data), indent=indent, allow_nan=False)


def write_json(path: str | os.PathLike, data) -> None:
    """Write ``data`` to ``path`` as indented JSON (see the module docstring)."""
    with open(path, "w", encoding="utf-8") as f:
        f.write(dumps(data))
        f.write("\n")
