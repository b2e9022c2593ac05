"""The ground-truth reader on arbitrary files: a GroundTruth, or one line (InputError)."""

from __future__ import annotations

import json

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sample_data_synth import load_ground_truth, make_case
from tests.properties import property_settings
from tissue_core.errors import InputError, SourceError

values = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=6),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3)
    ),
    max_leaves=10,
)
TRUTH = make_case("rotation", size=64, n_frames=2).truth.to_dict()


@property_settings(60)
@given(
    key=st.sampled_from(sorted(TRUTH)),
    value=values,
    drop=st.booleans(),
    raw=st.one_of(st.none(), st.binary(max_size=60)),
)
def test_ground_truth(tmp_path, key, value, drop, raw):
    path = tmp_path / "truth.json"
    if raw is not None:
        path.write_bytes(raw)
    else:
        d = dict(TRUTH)
        if drop:
            del d[key]
        else:
            d[key] = value
        path.write_text(json.dumps(d))
    try:
        truth = load_ground_truth(path)
    except (InputError, SourceError):
        return
    assert truth.n_frames >= 2 and len(truth.roi) == 4


def test_a_folder_given_as_the_ground_truth_is_called_a_folder(tmp_path):
    with pytest.raises(SourceError, match=r"is a folder, not a ground-truth file$"):
        load_ground_truth(tmp_path)
