"""surface_strain's readers on arbitrary files: a result, or one line (PointsError)."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from surface_strain.io import PointsError, read_points3d, read_triangles
from tests.properties import property_settings

SETTINGS = property_settings(40)
cell = st.one_of(
    st.integers(-2, 6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "nan", "inf", "x", " 1 ", "1e400", "null"]),
)
header = st.one_of(
    st.just(["frame", "point", "X", "Y", "Z", "visible"]),
    st.lists(
        st.sampled_from(["frame", "point", "X", "y", "Z", "visible", "p0", "extra"]), max_size=7
    ),
)


def csv_text(draw_header, rows, bom):
    text = "\n".join(",".join(r) for r in [draw_header, *rows]) + "\n"
    return ("\ufeff" if bom else "") + text


@SETTINGS
@given(head=header, rows=st.lists(st.lists(cell, max_size=7), max_size=12), bom=st.booleans())
def test_points3d(tmp_path, head, rows, bom):
    path = tmp_path / "p.csv"
    path.write_text(csv_text(head, rows, bom), encoding="utf-8")
    try:
        tracks = read_points3d(path)
        points, visible = tracks.positions, tracks.visible
    except PointsError:
        return
    assert points.ndim == 3 and points.shape[2] == 3 and visible.shape == points.shape[:2]
    assert np.isfinite(points[visible]).all() and visible[0].any()


@SETTINGS
@given(data=st.binary(max_size=300))
def test_points3d_bytes(tmp_path, data):
    (tmp_path / "p.csv").write_bytes(data)
    try:
        read_points3d(tmp_path / "p.csv")
    except PointsError:
        pass


@SETTINGS
@given(
    rows=st.lists(st.lists(cell, max_size=4), max_size=8),
    n=st.integers(0, 6),
    raw=st.one_of(st.none(), st.binary(max_size=100)),
)
def test_triangles(tmp_path, rows, n, raw):
    path = tmp_path / "t.csv"
    if raw is None:
        path.write_text("p0,p1,p2\n" + "\n".join(",".join(r) for r in rows) + "\n")
    else:
        path.write_bytes(raw)
    try:
        tri = read_triangles(path, n)
    except PointsError:
        return
    assert tri.ndim == 2 and tri.shape[1] == 3 and (0 <= tri).all() and (tri < n).all()
