"""Long tables: one reader and writer for every frame,point,... file."""

import numpy as np
import pytest

from tissue_core.errors import InputError
from tissue_core.tables import read_long_table, write_long_table


def test_write_then_read_gives_the_same_arrays(tmp_path):
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=(3, 4)), rng.normal(size=(3, 4))
    y[1, 2] = np.nan
    write_long_table(tmp_path / "t.csv", {"X": (x, "%.17g"), "Y": (y, "%.17g")})
    table = read_long_table(tmp_path / "t.csv", required=("x", "Y"))
    assert table.n_frames == 3 and table.n_points == 4
    np.testing.assert_array_equal(table["x"], x)
    np.testing.assert_array_equal(table["y"], y)  # NaN stays NaN


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("", "is empty"),
        ("frame,point,x,Y\n", "has no rows"),
        ("frame,point,x\n0,0,1\n", "lacks the column Y (needs frame,point,x,Y)"),
        ("frame,point,x,y\n0,0,1,2\n0,1,a,2\n", "line 3: not a number: 0,1,a,2"),
        ("frame,point,x,y\n0,0,1,2\n0,1,1\n", "line 3: too few values"),
        ("frame,point,x,y\n0,0.5,1,2\n", "line 2: frame and point must be whole numbers"),
        ("frame,point,x,y\n0,0,1,2\n-1,0,1,2\n", "line 3: negative frame or point index"),
        ("frame,point,x,y\n0,0,1,2\n0,0,1,2\n", "repeats or skips rows"),
        ("frame,point,x,y\n0,0,1,2\n1,1,1,2\n", "incomplete"),
        # indices far beyond the rows: refused before any (T, N) array is made
        ("frame,point,x,y\n100000000000,0,1,2\n", "frame indices up to 1e+11"),
        ("frame,point,x,y\n1e300,0,1,2\n", "frame indices up to 1e+300"),
        ("frame,point,x,y\n0,1e19,1,2\n", "point indices up to 1e+19"),
    ],
)
def test_what_is_not_a_long_table_is_one_clear_error(tmp_path, body, message):
    path = tmp_path / "t.csv"
    path.write_text(body)
    with pytest.raises(InputError, match=r"t\.csv") as error:
        read_long_table(path, required=("x", "Y"))
    assert message in str(error.value)


def test_cells_a_clean_reader_cannot_take_are_read_row_by_row(tmp_path):
    """Empty cells, quotes, a BOM and blank lines: the row-by-row reader takes over."""
    path = tmp_path / "t.csv"
    path.write_text('\ufeffFrame,Point,X,Y\n0,0,"1.5",\n\n0,1,null,2\n,,,\n', encoding="utf-8")
    table = read_long_table(path, required=("x", "y"))
    np.testing.assert_array_equal(table["x"], [[1.5, np.nan]])
    np.testing.assert_array_equal(table["y"], [[np.nan, 2.0]])
