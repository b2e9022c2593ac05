"""Every strain2d reader, on arbitrary bytes: a result, or one of the toolkit's errors.

Property-based (hypothesis): whatever a file holds (text, numbers, NaN,
duplicates, a byte-order mark, binary noise, a cut-off zip), the reader
returns a valid value or raises InputError/SourceError, which the command
line turns into one line and exit status 2; never another exception.
"""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from strain2d.errors import InputError, SourceError
from strain2d.grid import read_points_csv
from strain2d.run import load_run
from strain2d.study import read_manifest
from strain2d.tracks import read_tracks
from tests.badinput import write
from tests.properties import property_settings

SETTINGS = property_settings(40)
ERRORS = (InputError, SourceError)

cell = st.one_of(
    st.integers(-3, 50).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(["", "nan", "inf", "-inf", "x", "1e400", " 3 ", "0x10", "None", "1,5"]),
    st.text(max_size=5),
)


def table(columns):
    """CSV text: a header (the given columns, sometimes shuffled or cut) and rows of cells."""
    header = st.lists(st.sampled_from([*columns, "extra", "X", " y"]), min_size=0, max_size=7)
    return st.tuples(
        st.one_of(st.just(list(columns)), header),
        st.lists(st.lists(cell, min_size=0, max_size=8), max_size=12),
        st.booleans(),  # byte-order mark
        st.sampled_from(["\n", "\r\n"]),
    ).map(
        lambda t: ("\ufeff" if t[2] else "") + t[3].join(",".join(r) for r in [t[0], *t[1]]) + t[3]
    )


@SETTINGS
@given(text=table(["x", "y"]))
def test_points_csv(tmp_path, text):
    try:
        points = read_points_csv(write(tmp_path, "p.csv", text))
    except ERRORS:
        return
    assert points.ndim == 2 and points.shape[1] == 2 and points.dtype == float


@SETTINGS
@given(data=st.binary(max_size=300))
def test_points_csv_bytes(tmp_path, data):
    try:
        read_points_csv(write(tmp_path, "p.csv", data))
    except ERRORS:
        pass


@SETTINGS
@given(text=table(["frame", "point", "x", "y", "visible", "quality"]))
def test_tracks_csv(tmp_path, text):
    try:
        tracks = read_tracks(write(tmp_path, "t.csv", text))
    except ERRORS:
        return
    T, N = tracks.visible.shape
    assert tracks.positions.shape == (T, N, 2) and tracks.quality.shape == (T, N)
    assert np.isfinite(tracks.positions[tracks.visible]).all()


arrays = st.one_of(
    st.builds(np.zeros, st.tuples(st.integers(0, 3), st.integers(0, 4), st.integers(1, 3))),
    st.builds(np.full, st.tuples(st.integers(1, 3), st.integers(1, 3)), st.just(np.nan)),
    st.just(np.array(["a", "b"])),
    st.just(np.array([[1 + 2j]])),
    st.just(np.array(3.0)),
)


@SETTINGS
@given(
    names=st.lists(
        st.sampled_from(["positions", "tracks", "visible", "quality", "other"]),
        min_size=0,
        max_size=4,
        unique=True,
    ),
    values=st.lists(arrays, min_size=4, max_size=4),
    cut=st.one_of(st.none(), st.integers(0, 400)),
)
def test_tracks_npz(tmp_path, names, values, cut):
    buffer = io.BytesIO()
    np.savez(buffer, **dict(zip(names, values, strict=False)))
    data = buffer.getvalue()
    path = write(tmp_path, "t.npz", data if cut is None else data[:cut])
    try:
        tracks = read_tracks(path)
    except ERRORS:
        return
    assert tracks.positions.ndim == 3 and tracks.positions.shape[2] == 2


@SETTINGS
@given(data=st.binary(max_size=400), suffix=st.sampled_from([".npy", ".npz", ".csv"]))
def test_tracks_bytes(tmp_path, data, suffix):
    try:
        read_tracks(write(tmp_path, "t" + suffix, data))
    except ERRORS:
        pass


@SETTINGS
@given(text=table(["run", "specimen", "group", "endpoint"]))
def test_manifest(tmp_path, text):
    try:
        entries = read_manifest(write(tmp_path, "m.csv", text))
    except ERRORS:
        return
    for e in entries:
        assert str(e["run"]) and (e["endpoint"] is None or e["endpoint"] >= 0)


json_values = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


@SETTINGS
@given(
    summary=st.one_of(
        json_values.map(lambda v: json.dumps(v, allow_nan=True)),
        st.binary(max_size=50).map(lambda b: b.decode("latin-1")),
    ),
    nodes=table(
        [
            "frame",
            "point",
            "x",
            "y",
            "u",
            "v",
            "visible",
            "Exx",
            "Eyy",
            "Exy",
            "E1",
            "E2",
            "max_shear",
            "theta1_deg",
            "J",
        ]
    ),
)
def test_run_folder(tmp_path, summary, nodes):
    run = tmp_path / "run"
    run.mkdir(exist_ok=True)
    write(run, "summary.json", summary)
    write(run, "strain_nodes.csv", nodes)
    try:
        load_run(run)
    except ERRORS:
        pass


def test_a_cut_zip_is_one_line(tmp_path):
    """The case that reached users as a BadZipFile traceback."""
    np.savez(tmp_path / "t.npz", positions=np.zeros((2, 3, 2)))
    data = (tmp_path / "t.npz").read_bytes()
    for cut in (10, 100, len(data) - 30):
        (tmp_path / "cut.npz").write_bytes(data[:cut])
        try:
            read_tracks(tmp_path / "cut.npz")
        except InputError as exc:
            assert "cut.npz" in str(exc)
        else:  # pragma: no cover - a cut zip is never readable
            raise AssertionError("a cut zip was read")
    assert not isinstance(zipfile.BadZipFile(), ERRORS)  # so the reader must translate it


@SETTINGS
@given(
    data=st.binary(max_size=600),
    suffix=st.sampled_from([".tif", ".avi", ".mp4", ".png", ".jpg"]),
    keep=st.integers(0, 4000),
)
def test_frame_sources(tmp_path, small_case, data, suffix, keep):
    """Arbitrary bytes, or a real video/TIFF cut anywhere, under a frame source's name."""
    from strain2d.frames import open_frames

    folder, _ = small_case
    real = {".tif": "eq.tif", ".avi": "eq.avi"}.get(suffix)
    content = (folder / real).read_bytes()[:keep] if real and keep % 2 else data
    path = write(tmp_path, "frames" + suffix, content)
    try:
        source = open_frames(path)
        frames = list(source)
    except ERRORS:
        return
    assert len(frames) == len(source) >= 2
    assert all(f.shape == source.shape for f in frames)
