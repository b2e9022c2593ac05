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
    element_principal_directions,
    element_scalars,
    nodal_principal_directions,
    nodal_scalars,
    scalar_fields,
)
from surface_strain.kinematics import (
    PrincipalDirections,
    area_ratio,
    cylindrical_directions,
    deformation_gradient,
    directional_components,
    euler_almansi,
    green_lagrange,
    logarithmic_strain,
    material_frame,
    principal_directions,
    principal_strains,
    reference_frames,
    right_cauchy_green,
    spherical_directions,
    triangle_areas,
    triangle_normals,
)
from surface_strain.mesh import (
    best_fit_cylinder,
    best_fit_plane,
    best_fit_sphere,
    delaunay_triangles,
    edge_lengths,
    folded_triangles,
    grid_triangles,
    point_normals,
    triangle_quality,
)
from surface_strain.nodal import nodal_average, nodal_axes

try:
    __version__ = _metadata.version("tissue-strain")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "PrincipalDirections",
    "StrainField",
    "area_ratio",
    "best_fit_cylinder",
    "best_fit_plane",
    "best_fit_sphere",
    "compute_strain",
    "cylindrical_directions",
    "deformation_gradient",
    "delaunay_triangles",
    "directional_components",
    "edge_lengths",
    "element_principal_directions",
    "element_scalars",
    "euler_almansi",
    "folded_triangles",
    "green_lagrange",
    "grid_triangles",
    "logarithmic_strain",
    "material_frame",
    "nodal_average",
    "nodal_axes",
    "nodal_principal_directions",
    "nodal_scalars",
    "point_normals",
    "principal_directions",
    "principal_strains",
    "reference_frames",
    "right_cauchy_green",
    "scalar_fields",
    "spherical_directions",
    "triangle_areas",
    "triangle_normals",
    "triangle_quality",
]
