"""Strain fields computed a block of frames at a time, for videos of any length.

:func:`compute_strain` holds the deformation map, the strain per triangle and
per node and every derived scalar for every frame at once: about 11 KiB a
frame on a 7 x 7 grid, 1.2 GiB for 3,000 frames of a 40 x 40 one.
:func:`streamed_strain` returns a :class:`StreamedStrainField` instead: the
same attributes, but ``F``, ``E``, ``element_valid``, ``nodal_E`` and the
arrays of :func:`~surface_strain.nodal_scalars` and
:func:`~surface_strain.element_scalars` are :class:`FrameArray` objects that
compute the frames they are indexed with (a block of ``block_frames`` frames
at a time, the last two blocks kept) from the positions.  Only the positions
and visibility, which the tracker gave, are held whole.

Indexing by frame (``field.nodal_E[k]``, ``field.E[a:b, m]``) costs a block;
:func:`iter_blocks` walks a field block by block for reductions over time
(curves, limits, tables).  Converting a whole :class:`FrameArray` to an
array (``np.asarray``, a NumPy function on it) computes every frame, as
:func:`compute_strain` would have: it works, and it is what the code that
streams avoids.  The values are those of :func:`compute_strain`, bit for bit:
every frame's strain depends on that frame's positions only.
"""

from __future__ import annotations

import operator
import time
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from surface_strain._typing import BoolArray, FloatArray
from surface_strain.field import (
    StrainField,
    _frame_range,
    _strain_field,
    _strain_setup,
    nodal_scalars,
)

__all__ = ["FrameArray", "StreamedStrainField", "iter_blocks", "streamed_strain"]

#: frames computed together by default: 64 frames of a 40 x 40 grid are about 25 MiB
BLOCK_FRAMES = 64


class _Blocks:
    """Computes blocks of frames of one field and keeps the last two."""

    def __init__(self, setup, n_frames: int, block_frames: int) -> None:
        self.setup = setup
        self.n_frames = n_frames
        self.size = block_frames
        self._cache: OrderedDict[int, StrainField] = OrderedDict()
        self.seconds = 0.0  # spent computing blocks

    def __getstate__(self) -> dict:
        # a copy sent to another process computes the blocks it reads there: none are sent
        return {**self.__dict__, "_cache": OrderedDict(), "seconds": 0.0}

    def block(self, b: int) -> StrainField:
        if b in self._cache:
            self._cache.move_to_end(b)
            return self._cache[b]
        s = self.setup
        start, stop = b * self.size, min((b + 1) * self.size, self.n_frames)
        began = time.perf_counter()
        one = _strain_field(s, s.points[start:stop], s.visible[start:stop])
        self.seconds += time.perf_counter() - began
        self._cache[b] = one
        while len(self._cache) > 2:
            self._cache.popitem(last=False)
        return one

    def frames(self, start: int, stop: int) -> list[tuple[int, StrainField]]:
        """(offset of ``start`` in the block, block) for the blocks that frames start:stop touch."""
        if start >= stop:
            return []
        first, last = start // self.size, (stop - 1) // self.size
        return [(b * self.size, self.block(b)) for b in range(first, last + 1)]


class FrameArray:
    """A ``(T, ...)`` array of a :class:`StreamedStrainField`, computed for the frames indexed.

    Supports ``len``, ``shape``, ``ndim``, ``dtype``, iteration over frames
    and indexing whose first index picks frames (an integer, a slice, an
    integer or boolean array); the rest of the index applies to the frames'
    arrays.  ``np.asarray(a)`` computes every frame.
    """

    def __init__(self, blocks: _Blocks, name: str, frame_shape: tuple, dtype) -> None:
        self._blocks = blocks
        self._name = name
        self.shape = (blocks.n_frames, *frame_shape)
        self.dtype = np.dtype(dtype)

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"FrameArray({self._name}, shape={self.shape}, dtype={self.dtype})"

    def _of(self, one: StrainField) -> np.ndarray:
        kind, _, key = self._name.partition(":")
        if kind == "node":
            return nodal_scalars(one)[key]
        if kind == "element":  # computed once per block (the block's own cache)
            return one._element_scalars()[key]
        return getattr(one, self._name)

    def _range(self, start: int, stop: int) -> np.ndarray:
        parts = []
        for offset, one in self._blocks.frames(start, stop):
            lo, hi = max(start - offset, 0), min(stop - offset, one.n_frames)
            parts.append(self._of(one)[lo:hi])
        if not parts:
            return np.empty((0, *self.shape[1:]), self.dtype)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        if not key or key[0] is Ellipsis:
            return np.asarray(self)[key]
        first, rest = key[0], key[1:]
        T = self.shape[0]
        if isinstance(first, slice):
            start, stop, step = first.indices(T)
            if step == 1:
                return self._range(start, max(start, stop))[(slice(None), *rest)]
            first = np.arange(start, stop, step)
        try:
            k = operator.index(first)
        except TypeError:
            pass
        else:
            if not -T <= k < T:
                raise IndexError(f"frame {k} is out of range for {T} frames")
            k %= T
            return self._range(k, k + 1)[(0, *rest)]
        idx = np.asarray(first)
        if idx.dtype == bool:
            if idx.shape != (T,):
                raise IndexError(f"a boolean frame index must have shape ({T},)")
            idx = np.flatnonzero(idx)
        idx = idx.astype(int, casting="same_kind")
        if idx.size and not (-T <= idx.min() and idx.max() < T):
            raise IndexError(f"frame index out of range for {T} frames")
        idx = idx % T if idx.size else idx
        flat = idx.ravel()
        out = np.empty((flat.size, *self.shape[1:]), self.dtype)
        # each block the frames lie in is computed once, and its frames copied out: a view
        # of a frame would keep its whole block alive
        size = self._blocks.size
        for b in np.unique(flat // size):
            at = np.flatnonzero(flat // size == b)
            out[at] = self._of(self._blocks.block(int(b)))[flat[at] - b * size]
        out = out.reshape(*idx.shape, *self.shape[1:])
        return out[(Ellipsis, *rest)] if rest else out

    def __iter__(self) -> Iterator[np.ndarray]:
        for k in range(self.shape[0]):
            yield self[k]

    def __array__(self, dtype=None, copy=None):
        whole = self._range(0, self.shape[0])
        return whole if dtype is None else whole.astype(dtype)


_NODAL = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "theta1_deg", "J")


@dataclass(frozen=True, repr=False)
class StreamedStrainField(StrainField):
    """A :class:`~surface_strain.StrainField` whose per-frame arrays are computed when read.

    Made by :func:`streamed_strain`; see the module's description.
    ``points`` and ``visible`` are arrays (the positions given); ``F``,
    ``E``, ``element_valid`` and ``nodal_E`` are :class:`FrameArray`.
    """

    blocks: _Blocks | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        # dataclasses.replace(field, points=...) would keep the blocks of the old positions
        if self.blocks is None or self.points is not self.blocks.setup.points:
            raise ValueError(
                "a StreamedStrainField is made by streamed_strain(); for some of its frames "
                "use field.frames(start, stop)"
            )
        super().__post_init__()

    @property
    def block_frames(self) -> int:
        return self.blocks.size

    @property
    def seconds_computing(self) -> float:
        """Seconds spent computing blocks so far (the strain's time, counted where it is read)."""
        return self.blocks.seconds

    @cached_property
    def _nodal_scalars(self) -> dict[str, FrameArray]:
        return {k: FrameArray(self.blocks, f"node:{k}", (self.n_points,), float) for k in _NODAL}

    def _element_scalars(self) -> dict[str, FrameArray]:
        M = self.n_triangles
        return {k: FrameArray(self.blocks, f"element:{k}", (M,), float) for k in _NODAL}

    def frames(self, start: int, stop: int) -> StrainField:
        start, stop = _frame_range(start, stop, self.n_frames)
        if start == stop:
            return super().frames(0, 0)
        parts = [
            one.frames(max(start - offset, 0), min(stop - offset, one.n_frames))
            for offset, one in self.blocks.frames(start, stop)
        ]
        if len(parts) == 1:
            return parts[0]
        join = {
            k: np.concatenate([getattr(p, k) for p in parts])
            for k in ("points", "F", "E", "visible", "element_valid", "nodal_E")
        }
        first = parts[0]
        return StrainField(
            reference=first.reference,
            triangles=first.triangles,
            basis=first.basis,
            reference_areas=first.reference_areas,
            directions=first.directions,
            frame=first.frame,
            meta=first.meta,
            **join,
        )

    def __repr__(self) -> str:
        return (
            f"StreamedStrainField({self.n_frames} frames, {self.n_points} nodes, "
            f"{self.n_triangles} triangles, {self.points.shape[2]}D, "
            f"computed {self.block_frames} frames at a time)"
        )


def streamed_strain(
    reference: FloatArray,
    points: FloatArray,
    triangles,
    *,
    visible: BoolArray | None = None,
    directions=None,
    axis=None,
    directions_at="auto",
    block_frames: int = BLOCK_FRAMES,
) -> StreamedStrainField:
    """:func:`~surface_strain.compute_strain`, computed a block of frames at a time when read.

    Parameters are those of :func:`~surface_strain.compute_strain`, checked
    the same way, plus ``block_frames`` (a whole number >= 1): how many
    frames are computed together.  Memory then holds the positions and the
    last two blocks, whatever the number of frames.

    Examples
    --------
    >>> import numpy as np
    >>> from surface_strain import compute_strain, grid_triangles
    >>> X = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2)
    >>> points = np.stack([X * (1 + 0.01 * t) for t in range(100)])
    >>> lazy = streamed_strain(X, points, grid_triangles(3, 3), block_frames=16)
    >>> float(lazy.nodal_E[99, 0, 0, 0]) == float(compute_strain(
    ...     X, points, grid_triangles(3, 3)).nodal_E[99, 0, 0, 0])
    True
    """
    if isinstance(block_frames, bool) or not isinstance(block_frames, int | np.integer):
        raise ValueError(f"block_frames must be a whole number >= 1, got {block_frames!r}")
    if block_frames < 1:
        raise ValueError(f"block_frames must be a whole number >= 1, got {block_frames}")
    setup = _strain_setup(reference, points, triangles, visible, directions, axis, directions_at)
    T, N, d = setup.points.shape
    M = len(setup.triangles)
    blocks = _Blocks(setup, T, int(block_frames))
    return StreamedStrainField(
        reference=setup.reference,
        points=setup.points,
        triangles=setup.triangles,
        basis=setup.basis,
        F=FrameArray(blocks, "F", (M, d, 2), float),
        E=FrameArray(blocks, "E", (M, 2, 2), float),
        visible=setup.visible,
        element_valid=FrameArray(blocks, "element_valid", (M,), bool),
        nodal_E=FrameArray(blocks, "nodal_E", (N, 2, 2), float),
        reference_areas=setup.areas,
        directions=setup.directions,
        frame=setup.frame,
        meta=setup.meta,
        blocks=blocks,
    )


def iter_blocks(
    field: StrainField, *, block_frames: int | None = None
) -> Iterator[tuple[int, StrainField]]:
    """Walk a field a block of frames at a time: ``(first frame, StrainField of the block)``.

    A :class:`StreamedStrainField` is walked in its own blocks (each computed
    once); an in-memory field in blocks of ``block_frames`` (default: the
    whole field at once, views, no copy).
    """
    T = field.n_frames
    if isinstance(field, StreamedStrainField):
        size = field.block_frames
        for start in range(0, T, size):
            yield start, field.blocks.block(start // size)
        return
    size = T if block_frames is None else int(block_frames)
    for start in range(0, T, max(size, 1)):
        yield start, field.frames(start, min(start + size, T))
