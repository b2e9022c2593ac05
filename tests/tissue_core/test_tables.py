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
        ("frame,point,x,y\n0,0,1,2\n0,1,1\n", "line 3: 3 cells where the header has 4: 0,1,1"),
        # a decimal comma: one cell too many, on the reference frame as anywhere
        ("frame,point,x,y\n0,0,1,5,2\n0,1,1,2\n", "line 2: 5 cells where the header has 4 (a"),
        ("frame,point,x,y\n0,0,1,2\n0,1,1,2,\n", "line 3: 5 cells where the header has 4"),
        ('frame,point,x,y\n0,0,1,2\n0,1,"1,5",2,3\n', "line 3: 5 cells"),
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


def test_a_decimal_comma_is_refused_not_read_into_the_next_column(tmp_path):
    """``1,5`` for 1.5 shifts every later cell of its row: the row is refused, naming it."""
    path = tmp_path / "points3d.csv"
    path.write_text(
        "frame,point,X,Y,Z,visible\n0,0,1.0,2.0,300.0,1\n0,1,11,5,2.0,300.0,1\n"
        "1,0,1.0,2.0,300.0,1\n1,1,11.0,2.0,300.0,1\n"
    )
    with pytest.raises(InputError) as error:
        read_long_table(path, required=("X", "Y", "Z"), optional=("visible",))
    assert str(error.value) == (
        f"{path}, line 3: 7 cells where the header has 6 (a decimal comma?): 0,1,11,5,2.0,300.0,1"
    )


def test_a_quoted_cell_holding_a_comma_is_one_cell(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text('frame,point,x,note\n0,0,1.5,"left, upper"\n0,1,2.5,\n')
    table = read_long_table(path, required=("x",))
    np.testing.assert_array_equal(table["x"], [[1.5, 2.5]])


@pytest.mark.parametrize("value", ["7", "0.5", "-1", "inf", "2"])
def test_a_flag_column_takes_0_or_1_only_and_names_the_line(tmp_path, value):
    path = tmp_path / "t.csv"
    path.write_text(f"frame,point,x,visible\n0,0,1,1\n0,1,2,0\n1,0,1,\n1,1,2,{value}\n")
    with pytest.raises(InputError) as error:
        read_long_table(path, required=("x",), optional=("visible",), flags=("visible",))
    assert str(error.value) == f"{path}, line 5: visible must be 0 or 1, got {float(value):g}"


def test_a_flag_column_keeps_0_1_and_empty(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("frame,point,x,visible\n0,0,1,1\n0,1,2,0\n1,0,1,\n1,1,2,1.0\n")
    table = read_long_table(path, required=("x",), optional=("visible",), flags=("visible",))
    np.testing.assert_array_equal(table["visible"], [[1, 0], [np.nan, 1]])
