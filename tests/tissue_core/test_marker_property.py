"""The marker on arbitrary content: a folder is replaceable only with a marker that records it.

Whatever a marker holds (JSON of any shape, records of any kind, names such as
``..`` or absolute paths, binary noise), :func:`foreign_content` finds the
user's file in the folder unless the marker records exactly that file.
"""

from __future__ import annotations

import hashlib
import json

from hypothesis import given
from hypothesis import strategies as st

from tests.properties import property_settings
from tissue_core.outputs import MARKER, foreign_content, read_marker

values = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=6),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=10,
)
TRUE_RECORD = {"size": 1, "sha256": hashlib.sha256(b"x").hexdigest(), "mtime_ns": 0}
names = st.sampled_from(["a.csv", "b.csv", "..", "../a.csv", "/a.csv", "./a.csv", "A.CSV", ""])
records = st.one_of(st.just(TRUE_RECORD), values, st.just({"size": 1, "sha256": "0" * 64}))


@property_settings(80)
@given(
    content=st.one_of(
        values.map(json.dumps),
        st.builds(
            lambda files, folders: json.dumps(
                {"kind": "tissue-strain result", "files": files, "folders": folders}
            ),
            st.one_of(values, st.dictionaries(names, records, max_size=3)),
            st.one_of(values, st.lists(names, max_size=3)),
        ),
        st.binary(max_size=80).map(lambda b: b.decode("latin-1")),
    )
)
def test_any_marker_content(tmp_path, content):
    folder = tmp_path / "out"
    folder.mkdir(exist_ok=True)
    (folder / MARKER).write_text(content, encoding="utf-8")
    (folder / "a.csv").write_text("x")
    marker = read_marker(folder)
    foreign = foreign_content(folder)
    if marker is None:
        assert foreign == f"no {MARKER}"
    else:
        recorded = marker["files"].get("a.csv")
        assert (foreign is None) == (recorded == TRUE_RECORD or (
            isinstance(recorded, dict) and recorded.get("size") == 1
            and recorded.get("sha256") == TRUE_RECORD["sha256"]))  # fmt: skip
