"""``StrainField``: the arrays of one strain computation, travelling together."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from surface_strain._typing import BoolArray, FloatArray, IntArray
from surface_strain.kinematics import (
    area_ratio,
    deformation_gradient,
    directional_components,
    green_lagrange,
    principal_strains,
    reference_frames,
    triangle_areas,
)
from surface_strain.nodal import nodal_average

__all__ = [
    "StrainField",
    "compute_strain",
    "element_scalars",
    "nodal_scalars",
    "scalar_fields",
]


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
    directions : (2, d) float
        Material directions that define the x, y frame of ``E``.
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
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        T, N, d = self.points.shape
        M = len(self.triangles)
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
            "directions": (2, d),
        }
        for name, shape in expected.items():
            got = np.shape(getattr(self, name))
            if got != shape:
                raise ValueError(f"StrainField.{name} must have shape {shape}, got {got}")

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


def scalar_fields(E: FloatArray) -> dict[str, FloatArray]:
    """Named scalar fields of a strain tensor array.

    Parameters
    ----------
    E : (..., 2, 2) float

    Returns
    -------
    dict
        ``Exx, Eyy, Exy, E1, E2`` (principal, ``E1 >= E2``), ``max_shear``
        (``(E1 - E2) / 2``) and ``theta1_deg`` (angle of the ``E1`` direction from
        the frame's x axis, in (-90, 90]; NaN where ``E1 - E2 < 1e-9``, i.e.
        where the strain is isotropic and no direction is principal), each of
        shape ``(...)``.
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


def compute_strain(
    reference: FloatArray,
    points: FloatArray,
    triangles: IntArray,
    *,
    visible: BoolArray | None = None,
    directions: Sequence[Sequence[float]] | FloatArray | None = None,
) -> StrainField:
    """Deformation and Green-Lagrange strain of a triangle mesh over time.

    Parameters
    ----------
    reference : (N, d) float
        Reference positions (d = 2 or 3), e.g. the tracked grid on frame 0.
    points : (T, N, d) float
        Positions per frame.
    triangles : (M, 3) int
        Mesh on the reference points, e.g. from
        :func:`surface_strain.mesh.delaunay_triangles`.
    visible : (T, N) bool, optional, keyword-only
        False marks a lost point; its triangles get NaN for that frame and are
        left out of the nodal averages.
    directions : (2, d) float, optional, keyword-only
        Material directions of the x, y frame (default global X and Y).

    Returns
    -------
    StrainField

    Examples
    --------
    >>> import numpy as np
    >>> from surface_strain.mesh import delaunay_triangles
    >>> X = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=float)
    >>> field = compute_strain(X, np.stack([X, 1.5 * X]), delaunay_triangles(X))
    >>> float(field.nodal_E[1, 0, 0, 0])
    0.625
    """
    reference = np.asarray(reference, dtype=float)
    points = np.asarray(points, dtype=float)
    if points.ndim != 3 or points.shape[1:] != reference.shape:
        raise ValueError(
            f"points must have shape (T, {reference.shape[0]}, {reference.shape[-1]}), "
            f"got {points.shape}"
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
    safe = np.where(visible[..., None], points, reference)  # finite stand-ins, masked below
    F = deformation_gradient(reference, safe, triangles)
    element_valid = np.all(visible[:, triangles], axis=-1)
    F[~element_valid] = np.nan
    E_local = green_lagrange(F)
    d = reference.shape[1]
    dirs = np.eye(d)[:2] if directions is None else np.asarray(directions, dtype=float)
    E = directional_components(E_local, basis, dirs)
    areas = triangle_areas(reference, triangles)
    nodal_E = nodal_average(E, triangles, N, weights=areas, axis=1)
    return StrainField(
        reference=reference,
        points=points,
        triangles=triangles,
        basis=basis,
        F=F,
        E=E,
        visible=visible,
        element_valid=element_valid,
        nodal_E=nodal_E,
        reference_areas=areas,
        directions=dirs,
    )


def element_scalars(field: StrainField) -> dict[str, FloatArray]:
    """Per-triangle scalar fields, each ``(T, M)``: those of :func:`scalar_fields`
    plus the area ratio ``J``."""
    out = scalar_fields(field.E)
    out["J"] = area_ratio(field.F)
    return out


def nodal_scalars(field: StrainField) -> dict[str, FloatArray]:
    """Per-node scalar fields, each ``(T, N)``.

    Tensor components and principal values come from the nodal (averaged)
    tensor ``nodal_E``; ``J`` is the area-weighted average of the element
    area ratios.
    """
    out = scalar_fields(field.nodal_E)
    out["J"] = nodal_average(
        area_ratio(field.F), field.triangles, field.n_points, weights=field.reference_areas, axis=1
    )
    return out
