"""A streamed strain field (computed a block of frames at a time) equals the in-memory one.

Issue 17: ``strain2d analyze`` keeps memory flat on long videos by computing
the strain when it is read.  Every array, every way of indexing it, the
derived scalars and the blocks must give exactly what
:func:`surface_strain.compute_strain` gives.
"""

import numpy as np
import pytest

from surface_strain import (
    FrameArray,
    StreamedStrainField,
    compute_strain,
    delaunay_triangles,
    element_scalars,
    iter_blocks,
    nodal_scalars,
    streamed_strain,
)

ARRAYS = ("F", "E", "nodal_E", "element_valid")


def _case(d: int, T: int = 50, seed: int = 0):
    """A jittered 5 x 4 grid stretching over T frames, with points lost at random."""
    rng = np.random.default_rng(seed)
    X = np.stack(np.meshgrid(np.arange(5.0), np.arange(4.0)), -1).reshape(-1, 2)
    tri = delaunay_triangles(X)
    if d == 3:
        X = np.column_stack([X, 0.1 * X[:, 0] ** 2])  # a curved sheet
    stretch = 1 + 0.01 * np.arange(T)
    P = X[None] * stretch[:, None, None] + rng.normal(0, 0.01, (T, *X.shape))
    visible = rng.random((T, len(X))) > 0.05
    visible[0] = True
    return X, P, tri, visible


def _same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("block", [1, 7, 50, 64])
def test_every_array_and_index_equals_the_in_memory_field(d, block):
    X, P, tri, visible = _case(d)
    whole = compute_strain(X, P, tri, visible=visible)
    lazy = streamed_strain(X, P, tri, visible=visible, block_frames=block)
    assert isinstance(lazy, StreamedStrainField)
    for name in ARRAYS:
        a, b = getattr(whole, name), getattr(lazy, name)
        assert isinstance(b, FrameArray) and b.shape == a.shape and b.dtype == a.dtype
        assert len(b) == len(a) and b.ndim == a.ndim
        for key in [
            0,
            49,
            -1,
            -50,
            slice(5, 20),
            slice(None),
            slice(3, None, 4),
            slice(40, 10),
            (slice(None), 2),
            (-1, 2),
            [3, 49, 0, 3],
            np.arange(50) % 2 == 0,
            np.array([[1, 2], [3, 4]]),
        ]:
            assert _same(a[key], b[key]), (name, key)
        assert _same(a, np.asarray(b))
        assert all(_same(x, y) for x, y in zip(a, b, strict=True))
        with pytest.raises(IndexError):
            b[50]
    for scalars in (nodal_scalars, element_scalars):
        sa, sb = scalars(whole), scalars(lazy)
        assert sa.keys() == sb.keys()
        for key in sa:
            assert _same(sa[key], np.asarray(sb[key])), key
            assert _same(sa[key][17], sb[key][17]), key
    assert _same(whole.points, lazy.points) and _same(whole.visible, lazy.visible)


def _count_triangle_scalars(monkeypatch) -> list:
    """Count the computations of a field's per-triangle scalars (cached per field)."""
    from functools import cached_property

    from surface_strain.field import StrainField

    calls = []
    original = StrainField.__dict__["_element_scalar_arrays"].func
    counted = cached_property(lambda self: calls.append(1) or original(self))
    counted.__set_name__(StrainField, "_element_scalar_arrays")
    monkeypatch.setattr(StrainField, "_element_scalar_arrays", counted)
    return calls


def test_a_kept_block_computes_its_triangle_scalars_once(monkeypatch):
    """The tables read a streamed field's per-triangle scalars a column at a time: each
    kept block computes them once, and again only after it was dropped."""
    X, P, tri, visible = _case(2, T=31)
    lazy = streamed_strain(X, P, tri, visible=visible, block_frames=8)
    expected = element_scalars(compute_strain(X, P, tri, visible=visible))
    calls = _count_triangle_scalars(monkeypatch)
    columns = element_scalars(lazy)
    for key in columns:  # every column of frames 0..15: blocks 0 and 1, kept
        assert _same(columns[key][:16], expected[key][:16]), key
    assert len(calls) == 2
    for key in columns:  # frames 16..31: blocks 2 and 3; 0 and 1 are dropped
        columns[key][16:]
    assert len(calls) == 4
    columns["Exx"][0]  # block 0 again: computed again
    assert len(calls) == 5
    with pytest.raises(ValueError, match="read-only"):
        expected["Exx"][0, 0] = 1.0  # shared by every reader: copy to change


def test_a_whole_triangle_column_computes_each_block_once(monkeypatch):
    """Reading a whole per-triangle column (all 4 blocks) computes each block's strain and
    scalars once, though only two blocks are kept."""
    import surface_strain.streamed as streamed

    X, P, tri, visible = _case(2, T=31)
    lazy = streamed_strain(X, P, tri, visible=visible, block_frames=8)
    expected = element_scalars(compute_strain(X, P, tri, visible=visible))
    fields = []
    original_field = streamed._strain_field
    monkeypatch.setattr(
        streamed, "_strain_field", lambda *a: fields.append(1) or original_field(*a)
    )
    scalars = _count_triangle_scalars(monkeypatch)
    whole = element_scalars(lazy)["Exx"][:]
    assert _same(whole, expected["Exx"])
    assert len(fields) == 4 and len(scalars) == 4
    assert _same(np.asarray(element_scalars(lazy)["Eyy"]), expected["Eyy"])
    assert len(fields) == 8 and len(scalars) == 8  # the blocks kept are the last two: 4 again


@pytest.mark.parametrize("block", [1, 6, 64])
def test_blocks_cover_every_frame_once_and_frames_cross_blocks(block):
    X, P, tri, visible = _case(2, T=31)
    whole = compute_strain(X, P, tri, visible=visible)
    lazy = streamed_strain(X, P, tri, visible=visible, block_frames=block)
    for field, size in ((lazy, block), (whole, None)):
        starts, seen = [], []
        for start, sub in iter_blocks(field, block_frames=size):
            starts.append(start)
            seen.extend(range(start, start + sub.n_frames))
            assert _same(sub.nodal_E, whole.nodal_E[start : start + sub.n_frames])
        assert seen == list(range(31))
    for start, stop in [(0, 31), (5, 20), (30, 31), (7, 7)]:
        a, b = whole.frames(start, stop), lazy.frames(start, stop)
        assert b.n_frames == stop - start
        for name in (*ARRAYS, "points", "visible"):
            assert _same(getattr(a, name), getattr(b, name)), (name, start, stop)
    with pytest.raises(ValueError, match="not within"):
        lazy.frames(3, 40)


def test_the_field_computes_only_the_frames_read(computed_blocks):
    """Reading one frame of a long field computes its block, not the video."""
    X, P, tri, visible = _case(2, T=400)
    lazy = streamed_strain(X, P, tri, visible=visible, block_frames=16)
    computed = computed_blocks
    lazy.nodal_E[390]
    lazy.E[391, 0]
    nodal_scalars(lazy)["E1"][395]
    assert computed == [16]  # one block, kept for the next reads
    lazy.nodal_E[:40]
    assert computed == [16, 16, 16, 16]  # frames 0-47: three more blocks
    computed.clear()  # frames spread over the video: each block they lie in once, copied out
    picked = nodal_scalars(lazy)["Exx"][[200, 5, 210, 7, 390, 201]]  # blocks 12, 0, 13, 24
    assert computed == [16, 16, 16, 16]
    assert picked.shape == (6, 20) and (picked.base is None or picked.base.size == picked.size)


@pytest.mark.parametrize("bad", [0, -3, 2.5, True, "64"])
def test_a_bad_block_size_is_refused(bad):
    X, P, tri, visible = _case(2, T=5)
    with pytest.raises(ValueError, match="block_frames"):
        streamed_strain(X, P, tri, visible=visible, block_frames=bad)


def test_checks_are_those_of_compute_strain():
    X, P, tri, _ = _case(2, T=5)
    with pytest.raises(ValueError, match="points must have shape"):
        streamed_strain(X, P[:, :3], tri)
    bad = X.copy()
    bad[0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        streamed_strain(bad, P, tri)


def test_replacing_arrays_of_a_streamed_field_is_refused():
    """Its blocks are computed from its own positions: new ones would not match them."""
    import dataclasses

    X, P, tri, visible = _case(2, T=5)
    lazy = streamed_strain(X, P, tri, visible=visible)
    with pytest.raises(ValueError, match="frames"):
        dataclasses.replace(lazy, points=P[:1], visible=visible[:1])


def test_a_copy_sent_to_another_process_computes_its_own_blocks():
    """Pickled (for a worker process) without the blocks computed here: a long video's copy
    is its positions, and it gives the same values."""
    import pickle

    X, P, tri, visible = _case(2, T=60)
    lazy = streamed_strain(X, P, tri, visible=visible, block_frames=10)
    empty = len(pickle.dumps(lazy))
    for _, _block in iter_blocks(lazy):  # every block computed here (the last two kept)
        pass
    assert lazy.seconds_computing > 0
    sent = pickle.dumps(lazy)
    assert len(sent) <= empty + 1000  # no computed block travels
    copy = pickle.loads(sent)
    assert copy.seconds_computing == 0
    assert _same(copy.nodal_E[55], lazy.nodal_E[55])
    assert _same(nodal_scalars(copy)["E1"][3:17], nodal_scalars(lazy)["E1"][3:17])
    assert copy.seconds_computing > 0  # it computed them there
