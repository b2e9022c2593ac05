"""Membrane strain on triangulated surfaces in 2D and 3D.

The kinematics engine of the toolkit: deformation map ``F``, Green-Lagrange
strain ``E``, area ratio, principal strains, directional components and nodal
averages for triangles in the plane or on curved surfaces in space.  The 2D
strain pipeline (:mod:`strain2d`) is its planar special case.
"""

from importlib import metadata as _metadata

from surface_strain.field import (
    StrainField,
    compute_strain,
    element_scalars,
    nodal_scalars,
    scalar_fields,
)
from surface_strain.kinematics import (
    area_ratio,
    deformation_gradient,
    directional_components,
    euler_almansi,
    green_lagrange,
    logarithmic_strain,
    principal_strains,
    reference_frames,
    right_cauchy_green,
    triangle_areas,
)
from surface_strain.mesh import best_fit_plane, delaunay_triangles, grid_triangles, triangle_quality
from surface_strain.nodal import nodal_average

try:
    __version__ = _metadata.version("tissue-strain")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "StrainField",
    "area_ratio",
    "best_fit_plane",
    "compute_strain",
    "deformation_gradient",
    "delaunay_triangles",
    "directional_components",
    "element_scalars",
    "euler_almansi",
    "green_lagrange",
    "grid_triangles",
    "logarithmic_strain",
    "nodal_average",
    "nodal_scalars",
    "principal_strains",
    "reference_frames",
    "right_cauchy_green",
    "scalar_fields",
    "triangle_areas",
    "triangle_quality",
]
