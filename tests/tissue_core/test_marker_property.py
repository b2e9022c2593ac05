"""The marker reader on arbitrary files: a folder counts as a result only with a valid marker."""

from __future__ import annotations

import json

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tissue_core.outputs import MARKER, first_unknown_entry, read_marker

values = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=6),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=10,
)


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    content=st.one_of(
        values.map(json.dumps),
        st.builds(
            lambda files: json.dumps({"kind": "tissue-strain result", "files": files}),
            st.one_of(values, st.lists(st.text(max_size=6), max_size=3)),
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
    if marker is None:
        assert first_unknown_entry(folder) == "."
    else:
        assert isinstance(marker["files"], list)
        unknown = first_unknown_entry(folder)
        assert (unknown is None) == ("a.csv" in marker["files"])
