"""``StrainField``: the arrays of one strain computation, travelling together.

Also the per-triangle and per-node outputs derived from one: scalar fields
(components, principal values, maximum shear, area ratio) and principal
directions as vectors in space.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np

from surface_strain._typing import BoolArray, FloatArray, IntArray
from surface_strain.kinematics import (
    PrincipalDirections,
    area_ratio,
    cylindrical_directions,
    deformation_gradient,
    green_lagrange,
    material_frame,
    principal_directions,
    principal_strains,
    reference_frames,
    spherical_directions,
    triangle_areas,
)
from surface_strain.nodal import _aligned_axes, _corner_sum, _triangle_sum, nodal_average

__all__ = [
    "StrainField",
    "compute_strain",
    "element_principal_directions",
    "element_scalars",
    "nodal_principal_directions",
    "nodal_scalars",
    "scalar_fields",
]

#: Named direction fields accepted by :func:`compute_strain` (with ``axis=``).
DirectionKind = Literal["cylindrical", "spherical", "polar"]
_DIRECTION_KINDS = ("cylindrical", "spherical", "polar")


#: Principal directions are undefined where E1 - E2 is below this.
ISOTROPIC_TOLERANCE = 1e-9


@dataclass(frozen=True, repr=False)
class StrainField:
    """Per-triangle and per-node strain over time on one mesh.

    Attributes
    ----------
    reference : (N, d) float
        Reference node positions (d = 2 or 3).
    points : (T, N, d) float
        Node positions per frame.
    triangles : (M, 3) int
    basis : (M, d, 2) float
        Reference tangent basis of each triangle.
    F : (T, M, d, 2) float
        Deformation map; NaN where a triangle has a lost vertex.
    E : (T, M, 2, 2) float
        Green-Lagrange strain in the directional frame (``[[Exx, Exy], [Exy, Eyy]]``).
    visible : (T, N) bool
        False where a node is lost (given, or non-finite position).
    element_valid : (T, M) bool
        False where any vertex of the triangle is lost.
    nodal_E : (T, N, 2, 2) float
        Area-weighted nodal average of ``E`` over valid adjacent triangles.
    reference_areas : (M,) float
    directions : (2, d) or (M, 2, d) float
        Material directions that define the x, y frame of ``E``: one pair for
        the whole mesh or one per triangle (as given, before projection).
    frame : (M, d, 2) float
        The orthonormal frame ``(e1, e2)`` of ``E`` on each triangle, as vectors
        in space: ``directions`` projected onto the tangent plane and
        orthonormalized (:func:`surface_strain.material_frame`).  Default
        (``None`` at construction): the tangent basis ``basis``.
    meta : dict
        Free-form provenance (e.g. the named direction field and its axis).
    """

    reference: FloatArray
    points: FloatArray
    triangles: IntArray
    basis: FloatArray
    F: FloatArray
    E: FloatArray
    visible: BoolArray
    element_valid: BoolArray
    nodal_E: FloatArray
    reference_areas: FloatArray
    directions: FloatArray
    frame: FloatArray | None = None
    meta: dict = field(default_factory=dict)

    @cached_property
    def _nodal_scalars(self) -> dict[str, FloatArray]:
        out = scalar_fields(self.nodal_E)
        out["J"] = nodal_average(
            area_ratio(self.F), self.triangles, self.n_points, weights=self.reference_areas, axis=1
        )
        for v in out.values():
            v.setflags(write=False)
        return out

    def __post_init__(self) -> None:
        T, N, d = self.points.shape
        M = len(self.triangles)
        if self.frame is None:
            object.__setattr__(self, "frame", np.asarray(self.basis))
        expected = {
            "reference": (N, d),
            "triangles": (M, 3),
            "basis": (M, d, 2),
            "F": (T, M, d, 2),
            "E": (T, M, 2, 2),
            "visible": (T, N),
            "element_valid": (T, M),
            "nodal_E": (T, N, 2, 2),
            "reference_areas": (M,),
            "frame": (M, d, 2),
        }
        for name, shape in expected.items():
            got = np.shape(getattr(self, name))
            if got != shape:
                raise ValueError(f"StrainField.{name} must have shape {shape}, got {got}")
        if np.shape(self.directions) not in ((2, d), (M, 2, d)):
            raise ValueError(
                f"StrainField.directions must have shape (2, {d}) or ({M}, 2, {d}), "
                f"got {np.shape(self.directions)}"
            )

    @property
    def n_frames(self) -> int:
        return self.points.shape[0]

    @property
    def n_points(self) -> int:
        return self.points.shape[1]

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    def __repr__(self) -> str:
        lost = int((~self.element_valid).sum())
        return (
            f"StrainField({self.n_frames} frames, {self.n_points} nodes, "
            f"{self.n_triangles} triangles, {self.points.shape[2]}D, "
            f"{lost} lost triangle-frames)"
        )

    def frames(self, start: int, stop: int) -> StrainField:
        """Frames ``start`` to ``stop - 1`` as a field of their own (views where possible).

        Per-frame quantities (nodal scalars, principal directions) of the
        result are computed for those frames only.  ``start`` and ``stop``
        follow ``range``: ``0 <= start <= stop <= n_frames``.
        """
        start, stop = _frame_range(start, stop, self.n_frames)
        one = slice(start, stop)
        return StrainField(
            reference=self.reference,
            points=self.points[one],
            triangles=self.triangles,
            basis=self.basis,
            F=self.F[one],
            E=self.E[one],
            visible=self.visible[one],
            element_valid=self.element_valid[one],
            nodal_E=self.nodal_E[one],
            reference_areas=self.reference_areas,
            directions=self.directions,
            frame=self.frame,
            meta=self.meta,
        )

    @cached_property
    def _element_scalar_arrays(self) -> dict[str, FloatArray]:
        out = scalar_fields(self.E)
        out["J"] = area_ratio(self.F)
        for v in out.values():
            v.setflags(write=False)
        return out

    def _element_scalars(self) -> dict[str, FloatArray]:
        # computed once per field, as the nodal ones (a streamed field's tables read a
        # block's columns one at a time)
        return dict(self._element_scalar_arrays)


def _frame_range(start: int, stop: int, n_frames: int) -> tuple[int, int]:
    start, stop = int(start), int(stop)
    if not 0 <= start <= stop <= n_frames:
        raise ValueError(f"frames {start}:{stop} are not within the {n_frames} frames")
    return start, stop


def scalar_fields(E: FloatArray) -> dict[str, FloatArray]:
    """Named scalar fields of a strain tensor array.

    Parameters
    ----------
    E : (..., 2, 2) float
        Green-Lagrange strain (dimensionless) in some orthonormal frame.

    Returns
    -------
    dict
        Each of shape ``(...)``:

        * ``Exx, Eyy, Exy``: components in the frame (``Exy`` is the tensor
          shear ``E12``; the engineering shear is ``2 Exy``);
        * ``E1, E2``: principal strains, ``E1 >= E2``;
        * ``max_shear``: ``(E1 - E2) / 2``, the largest value of the tensor
          shear component ``E12`` over all in-plane rotations of the frame
          (the radius of Mohr's circle; reached at 45 degrees from the
          principal directions).  Frame-independent;
        * ``theta1_deg``: angle of the ``E1`` direction from the frame's x axis,
          in (-90, 90]; NaN where ``E1 - E2 < 1e-9``, i.e. where the strain is
          isotropic and no direction is principal.

    References
    ----------
    .. [1] Holzapfel, G. A. (2000). Nonlinear Solid Mechanics. Wiley. Sec. 2.5-2.6.
    """
    values, vectors = principal_strains(E)
    theta = np.degrees(np.arctan2(vectors[..., 1, 0], vectors[..., 0, 0]))  # in (-90, 90]
    theta = np.where(values[..., 0] - values[..., 1] < ISOTROPIC_TOLERANCE, np.nan, theta)
    return {
        "Exx": E[..., 0, 0],
        "Eyy": E[..., 1, 1],
        "Exy": E[..., 0, 1],
        "E1": values[..., 0],
        "E2": values[..., 1],
        "max_shear": 0.5 * (values[..., 0] - values[..., 1]),
        "theta1_deg": theta,
    }


def _resolve_directions(
    directions,
    reference: np.ndarray,
    triangles: np.ndarray,
    basis: np.ndarray,
    axis,
    directions_at: str,
) -> tuple[np.ndarray, dict]:
    """Directions as (2, d) or (M, 2, d), and provenance for ``meta``."""
    N, d = reference.shape
    M = len(triangles)
    if directions_at not in ("auto", "triangles", "nodes"):
        raise ValueError(
            f"directions_at must be 'auto', 'triangles' or 'nodes', got {directions_at!r}"
        )
    if directions is None:
        if axis is not None:
            raise ValueError("axis is only used with directions='cylindrical' or 'spherical'")
        return np.eye(d)[:2], {}
    if isinstance(directions, str):
        if directions not in _DIRECTION_KINDS:
            raise ValueError(
                f"directions must be one of {', '.join(map(repr, _DIRECTION_KINDS))} "
                f"or an array, got {directions!r}"
            )
        if axis is None:
            raise ValueError(f"directions={directions!r} needs axis=(point, direction)")
        centroids = reference[triangles].mean(axis=1)
        normals = np.cross(basis[:, :, 0], basis[:, :, 1]) if d == 3 else None
        if d == 2:
            if directions == "cylindrical":
                raise ValueError("directions='cylindrical' needs 3D points")
            point = np.asarray(axis[0] if np.ndim(axis[0]) else axis, dtype=float)
            if point.shape != (2,):
                raise ValueError(
                    f"for 2D points axis must be the centre (x, y) of the polar frame, got {axis!r}"
                )
            axis3 = (np.append(point, 0.0), [0.0, 0.0, 1.0])
            c3 = np.column_stack([centroids, np.zeros(M)])
            n3 = np.broadcast_to([0.0, 0.0, 1.0], (M, 3))
            dirs = spherical_directions(c3, n3, axis=axis3)[:, :, :2]
            meta_axis = point.tolist()
        else:
            if directions == "cylindrical":
                dirs = cylindrical_directions(centroids, axis=axis)
            else:
                dirs = spherical_directions(centroids, normals, axis=axis)
            meta_axis = [np.asarray(a, dtype=float).tolist() for a in axis]
        return dirs, {"directions": directions, "axis": meta_axis}
    if axis is not None:
        raise ValueError("axis is only used with directions='cylindrical' or 'spherical'")
    a = np.asarray(directions, dtype=float)
    if a.shape == (2, d):
        return a, {}
    if a.ndim != 3 or a.shape[1:] != (2, d) or a.shape[0] not in (M, N):
        raise ValueError(
            f"directions must have shape (2, {d}), ({M}, 2, {d}) per triangle or "
            f"({N}, 2, {d}) per node, got {a.shape}"
        )
    at = directions_at
    if at == "auto":
        if M == N:
            raise ValueError(
                f"directions of shape {a.shape} could be per node or per triangle "
                "(the mesh has as many of each); pass directions_at='nodes' or 'triangles'"
            )
        at = "triangles" if a.shape[0] == M else "nodes"
    if a.shape[0] != (M if at == "triangles" else N):
        raise ValueError(
            f"directions_at={at!r} needs directions of shape "
            f"({M if at == 'triangles' else N}, 2, {d}), got {a.shape}"
        )
    if at == "nodes":
        a = a[triangles].mean(axis=1)  # at the centroid: mean of the vertices' vectors
    return a, {}


def compute_strain(
    reference: FloatArray,
    points: FloatArray,
    triangles: IntArray,
    *,
    visible: BoolArray | None = None,
    directions: Sequence[Sequence[float]] | FloatArray | DirectionKind | None = None,
    axis: tuple[Sequence[float], Sequence[float]] | Sequence[float] | None = None,
    directions_at: Literal["auto", "triangles", "nodes"] = "auto",
) -> StrainField:
    """Deformation and Green-Lagrange strain of a triangle mesh over time.

    Parameters
    ----------
    reference : (N, d) float
        Reference positions (d = 2 or 3), e.g. the tracked grid on frame 0.
        Must be finite.
    points : (T, N, d) float
        Positions per frame.  NaN marks a lost point, like ``visible=False``.
    triangles : (M, 3) int
        Mesh on the reference points, e.g. from
        :func:`surface_strain.mesh.delaunay_triangles`.
    visible : (T, N) bool, optional, keyword-only
        False marks a lost point; its triangles get NaN for that frame and are
        left out of the nodal averages (the neighbours' values stay finite).
    directions : keyword-only
        Material directions of the x, y frame of ``E`` (``Exx, Eyy, Exy``).
        Each is projected onto a triangle's reference tangent plane and the
        pair orthonormalized (:func:`surface_strain.material_frame`).  One of

        * ``None`` (default): global X and Y;
        * ``(2, d)`` array: two constant vectors;
        * ``(M, 2, d)`` or ``(N, 2, d)`` array: a pair per triangle, or per node
          (the mean of a triangle's three vertex vectors is used; they should
          have consistent signs);
        * ``"cylindrical"`` with ``axis=(point, direction)``: x axial, y
          circumferential (:func:`surface_strain.cylindrical_directions`), e.g.
          longitudinal and circumferential on a tube;
        * ``"spherical"`` (alias ``"polar"``) with ``axis=(point, direction)``:
          x meridional, y circumferential about the axis
          (:func:`surface_strain.spherical_directions`), e.g. on a dome or an
          inflating membrane; on a flat disc normal to the axis the polar frame
          (radial, circumferential).  For 2D points ``axis`` is the centre
          ``(x, y)`` and this is the polar frame.

        Named fields are evaluated at the reference triangle centroids with
        the triangles' reference normals.
    axis : (point, direction) of 3-vectors, keyword-only
        The axis of a named direction field.
    directions_at : {"auto", "triangles", "nodes"}, keyword-only
        Where an ``(K, 2, d)`` direction array lives; "auto" decides by ``K``
        and refuses when the mesh has as many nodes as triangles.

    Returns
    -------
    StrainField

    Raises
    ------
    ValueError
        Bad shapes or options, a non-finite reference, a degenerate reference
        triangle, or a direction normal to a triangle (the message names it;
        there is no silent fallback).

    Examples
    --------
    >>> import numpy as np
    >>> from surface_strain.mesh import delaunay_triangles
    >>> X = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=float)
    >>> field = compute_strain(X, np.stack([X, 1.5 * X]), delaunay_triangles(X))
    >>> float(field.nodal_E[1, 0, 0, 0])
    0.625
    """
    setup = _strain_setup(reference, points, triangles, visible, directions, axis, directions_at)
    return _strain_field(setup, setup.points, setup.visible)


@dataclass(frozen=True)
class _StrainSetup:
    """What every frame's strain needs: the checked inputs and the reference geometry."""

    reference: FloatArray
    points: FloatArray
    visible: BoolArray
    triangles: IntArray
    basis: FloatArray
    directions: FloatArray
    meta: dict
    frame: FloatArray
    rotation: FloatArray  # (M, 2, 2): the frame's axes in tangent coordinates
    areas: FloatArray


def _strain_setup(reference, points, triangles, visible, directions, axis, directions_at):
    """:func:`compute_strain`'s checks and reference geometry (see there)."""
    reference = np.asarray(reference, dtype=float)
    points = np.asarray(points, dtype=float)
    if points.ndim != 3 or points.shape[1:] != reference.shape:
        raise ValueError(
            f"points must have shape (T, {reference.shape[0]}, {reference.shape[-1]}), "
            f"got {points.shape}"
        )
    bad_ref = ~np.all(np.isfinite(reference), axis=-1)
    if np.any(bad_ref):
        raise ValueError(
            f"reference holds {int(bad_ref.sum())} non-finite position(s), first is point "
            f"{int(np.flatnonzero(bad_ref)[0])}; drop lost reference points before meshing"
        )
    triangles = np.asarray(triangles)
    T, N, _ = points.shape
    if visible is None:
        visible = np.ones((T, N), dtype=bool)
    visible = np.asarray(visible, dtype=bool)
    if visible.shape != (T, N):
        raise ValueError(f"visible must have shape ({T}, {N}), got {visible.shape}")
    visible = visible & np.all(np.isfinite(points), axis=-1)

    basis, _ = reference_frames(reference, triangles)
    dirs, meta = _resolve_directions(directions, reference, triangles, basis, axis, directions_at)
    try:
        frame = material_frame(basis, dirs)
    except ValueError as exc:
        if directions is None:
            raise ValueError(
                f"{exc} (directions: the default global X and Y, which suit surfaces "
                "facing Z; pass directions=, e.g. 'cylindrical' or 'spherical' with axis=)"
            ) from None
        raise
    R = np.einsum("mdi,mdk->mik", basis, frame)  # frame axes in tangent coordinates
    areas = triangle_areas(reference, triangles)
    return _StrainSetup(reference, points, visible, triangles, basis, dirs, meta, frame, R, areas)


def _strain_field(setup: _StrainSetup, points: FloatArray, visible: BoolArray) -> StrainField:
    """The StrainField of some frames ``points (t, N, d)``, ``visible (t, N)`` of a setup."""
    F, E, element_valid, nodal_E = _strain_arrays(setup, points, visible)
    return StrainField(
        reference=setup.reference,
        points=points,
        triangles=setup.triangles,
        basis=setup.basis,
        F=F,
        E=E,
        visible=visible,
        element_valid=element_valid,
        nodal_E=nodal_E,
        reference_areas=setup.areas,
        directions=setup.directions,
        frame=setup.frame,
        meta=setup.meta,
    )


def _strain_arrays(setup: _StrainSetup, points: FloatArray, visible: BoolArray):
    """F, E, element_valid and nodal_E of some frames ``points (t, N, d)``, ``visible (t, N)``."""
    reference, triangles = setup.reference, setup.triangles
    safe = np.where(visible[..., None], points, reference)  # finite stand-ins, masked below
    F = deformation_gradient(reference, safe, triangles)
    element_valid = np.all(visible[:, triangles], axis=-1)
    F[~element_valid] = np.nan
    E_local = green_lagrange(F)
    R = setup.rotation
    E = np.einsum("mki,...mkl,mlj->...mij", R, E_local, R)
    nodal_E = nodal_average(E, triangles, len(reference), weights=setup.areas, axis=1)
    return F, E, element_valid, nodal_E


def element_scalars(field: StrainField) -> dict[str, FloatArray]:
    """Per-triangle scalar fields, each ``(T, M)``.

    Those of :func:`scalar_fields` (``Exx, Eyy, Exy, E1, E2, max_shear,
    theta1_deg``) of ``field.E`` plus the area ratio ``J`` (current / reference
    area, :func:`surface_strain.area_ratio`).  NaN on lost triangles.
    """
    return field._element_scalars()


def nodal_scalars(field: StrainField) -> dict[str, FloatArray]:
    """Per-node scalar fields, each ``(T, N)``, read-only.

    Tensor components, principal values, ``max_shear`` and ``theta1_deg`` come
    from the nodal (averaged) tensor ``nodal_E``; ``J`` is the area-weighted
    average of the element area ratios.  NaN at nodes whose adjacent triangles
    are all lost.  Computed once per field (the tables, the ParaView series,
    the figures and the statistics of a run all use them); copy an array to
    change it.
    """
    return dict(field._nodal_scalars)


def _check_isotropic(isotropic: str) -> None:
    if isotropic not in ("keep", "nan"):
        raise ValueError(f"isotropic must be 'keep' or 'nan', got {isotropic!r}")


def element_principal_directions(
    field: StrainField, *, isotropic: Literal["keep", "nan"] = "keep"
) -> PrincipalDirections:
    """Principal strain directions of each triangle as vectors in space.

    See :func:`surface_strain.principal_directions` for the definitions and
    sign conventions (``dir1`` at (-90, 90] degrees from the frame's x axis,
    ``(dir1, dir2, n)`` right-handed).

    Parameters
    ----------
    field : StrainField
    isotropic : {"keep", "nan"}, keyword-only
        Where ``E1 - E2 < 1e-9`` every direction is principal: "keep" returns
        an arbitrary orthonormal pair there (still unit vectors), "nan" returns
        NaN like ``theta1_deg``.

    Returns
    -------
    PrincipalDirections
        ``(dir1_ref, dir2_ref, dir1_cur, dir2_cur)``, each ``(T, M, d)`` unit
        vectors; NaN on lost triangles.

    Examples
    --------
    >>> import numpy as np
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    >>> x = X * [1.0, 1.2, 1.0]                   # stretch along y
    >>> f = compute_strain(X, x[None], np.array([[0, 1, 2]]))
    >>> element_principal_directions(f).dir1_ref.round(6)
    array([[[0., 1., 0.]]])
    """
    _check_isotropic(isotropic)
    out = principal_directions(field.E, field.F, field.basis, frame=field.frame)
    if isotropic == "nan":
        values, _ = principal_strains(field.E)
        iso = (values[..., 0] - values[..., 1] < ISOTROPIC_TOLERANCE)[..., None]
        out = PrincipalDirections(*(np.where(iso, np.nan, v) for v in out))
    return out


def _cross_or_rot90(n: np.ndarray | None, v: np.ndarray) -> np.ndarray:
    """``n x v`` in 3D; ``v`` turned by +90 degrees in 2D."""
    if n is None:
        return np.stack([-v[..., 1], v[..., 0]], axis=-1)
    return np.cross(n, v)


def _project_unit(v: np.ndarray, n: np.ndarray | None) -> np.ndarray:
    if n is not None:
        v = v - np.sum(v * n, axis=-1, keepdims=True) * n
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm > 0, v / norm, np.nan)


def nodal_principal_directions(
    field: StrainField, *, isotropic: Literal["keep", "nan"] = "keep"
) -> PrincipalDirections:
    """Principal strain directions at the nodes as vectors in space.

    For each frame and node, the ``dir1`` vectors of the adjacent valid
    triangles (:func:`element_principal_directions`) are averaged with the
    reference areas as weights after aligning their signs (a direction is an
    axis, ``v ~ -v``): each is flipped where it points away from the dominant
    axis of the adjacent triangles' orientation tensor ``sum_e A_e v_e v_e^T``
    (see :func:`surface_strain.nodal_axes`).  The average is projected onto the
    node's tangent plane, normalized, and flipped to point within 90 degrees
    of the node's frame axis ``e1`` (the area-weighted mean of the adjacent
    triangles' ``frame[:, :, 0]``); ``dir2 = n x dir1`` completes a right-handed
    orthonormal frame with the node normal ``n``.  The current directions
    average the adjacent ``dir1_cur`` with the same signs, projected onto the
    node's current tangent plane, and ``dir2_cur = n_cur x dir1_cur``.

    Node normals are the area-weighted, sign-aligned averages of the adjacent
    triangles' unit normals: reference normals for the reference directions,
    current normals (of the valid triangles) for the current ones.

    Parameters
    ----------
    field : StrainField
    isotropic : {"keep", "nan"}, keyword-only
        "keep" averages every valid triangle; "nan" leaves isotropic triangles
        (``E1 - E2 < 1e-9``) out of the average and returns NaN where the nodal
        tensor ``nodal_E`` is isotropic, like ``theta1_deg`` of
        :func:`nodal_scalars`.

    Returns
    -------
    PrincipalDirections
        ``(dir1_ref, dir2_ref, dir1_cur, dir2_cur)``, each ``(T, N, d)`` unit
        vectors; NaN at nodes whose adjacent triangles are all lost.

    Notes
    -----
    The nodal principal values ``E1, E2`` of :func:`nodal_scalars` are those of
    the averaged tensor ``nodal_E``, whereas these directions average the
    element directions; in a smooth field the two agree to the discretization
    error.  Where ``E1`` and ``E2`` are close the direction is ill-conditioned.

    Examples
    --------
    >>> import numpy as np
    >>> from surface_strain.mesh import grid_triangles
    >>> X = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2)
    >>> f = compute_strain(X, (X * [1.0, 1.3])[None], grid_triangles(3, 3))
    >>> nodal_principal_directions(f).dir1_cur[0, 4].round(6)
    array([0., 1.])
    """
    _check_isotropic(isotropic)
    elem = element_principal_directions(field, isotropic=isotropic)
    tri = field.triangles
    N = field.n_points
    d = field.points.shape[2]
    w = field.reference_areas
    e1 = _triangle_sum(w[:, None] * field.frame[:, :, 0], tri, N)
    if d == 3:
        n_tri = np.cross(field.basis[:, :, 0], field.basis[:, :, 1])
        total, n_signs = _aligned_axes(n_tri, tri, N, w)
        orient = _triangle_sum(w[:, None] * n_tri, tri, N)
        flip_n = np.where(np.sum(total * orient, axis=-1, keepdims=True) < 0, -1.0, 1.0)
        n_ref = _project_unit(total * flip_n, None)  # (N, 3)
        n_cur_tri = _project_unit(np.cross(field.F[..., 0], field.F[..., 1]), None)  # (T, M, 3)
        valid_cur = np.all(np.isfinite(n_cur_tri), axis=-1)
        wn = (w[:, None] * n_signs)[None, :, :, None]  # (1, M, 3, 1)
        n_cur = _corner_sum(
            wn * np.where(valid_cur[..., None], n_cur_tri, 0.0)[:, :, None, :], tri, N
        )
        n_cur = _project_unit(n_cur * flip_n, None)  # (T, N, 3)
    else:
        n_ref = n_cur = None
    total, signs = _aligned_axes(elem.dir1_ref, tri, N, w)  # (T, N, d), (T, M, 3)
    flip = np.where(np.sum(total * e1, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    dir1_ref = _project_unit(total * flip, n_ref)
    cur = np.where(np.isfinite(elem.dir1_cur), elem.dir1_cur, 0.0)
    total_cur = _corner_sum((w[:, None] * signs)[..., None] * cur[:, :, None, :], tri, N)
    dir1_cur = _project_unit(total_cur * flip, n_cur)
    dir1_cur = np.where(np.isfinite(dir1_ref), dir1_cur, np.nan)
    out = PrincipalDirections(
        dir1_ref,
        _cross_or_rot90(n_ref, dir1_ref),
        dir1_cur,
        _cross_or_rot90(n_cur, dir1_cur),
    )
    if isotropic == "nan":
        values, _ = principal_strains(field.nodal_E)
        iso = (values[..., 0] - values[..., 1] < ISOTROPIC_TOLERANCE)[..., None]
        out = PrincipalDirections(*(np.where(iso, np.nan, v) for v in out))
    return out
