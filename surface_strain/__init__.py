"""Membrane strain on triangulated surfaces in 2D and 3D.

The kinematics engine of the toolkit: deformation map ``F``, Green-Lagrange
strain ``E``, area ratio, principal strains, directional components and nodal
averages for triangles in the plane or on curved surfaces in space.  The 2D
strain pipeline (:mod:`strain2d`) is its planar special case.
"""

from tissue_core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "tissue_core.version": ["__version__"],
        "surface_strain.cycles": [
            "CYCLE_COMPONENTS",
            "Cycle",
            "activity",
            "cycle_statistics",
            "detect_cycles",
            "find_run_cycles",
            "mean_strain_noise",
            "stimulus_pulses",
            "write_cycles_csv",
        ],
        "surface_strain.export": [
            "element_columns",
            "node_columns",
            "write_elements_csv",
            "write_nodes_csv",
            "write_pvd",
        ],
        "surface_strain.field": [
            "StrainField",
            "compute_strain",
            "element_principal_directions",
            "element_scalars",
            "nodal_principal_directions",
            "nodal_scalars",
            "scalar_fields",
        ],
        "surface_strain.kinematics": [
            "PrincipalDirections",
            "area_ratio",
            "cylindrical_directions",
            "deformation_gradient",
            "directional_components",
            "euler_almansi",
            "green_lagrange",
            "logarithmic_strain",
            "material_frame",
            "principal_directions",
            "principal_strains",
            "reference_frames",
            "right_cauchy_green",
            "spherical_directions",
            "triangle_areas",
            "triangle_normals",
        ],
        "surface_strain.mesh": [
            "best_fit_cylinder",
            "best_fit_plane",
            "best_fit_sphere",
            "delaunay_triangles",
            "edge_lengths",
            "folded_triangles",
            "grid_triangles",
            "point_normals",
            "triangle_quality",
        ],
        "surface_strain.nodal": ["nodal_average", "nodal_axes"],
        "surface_strain.streamed": [
            "FrameArray",
            "StreamedStrainField",
            "iter_blocks",
            "streamed_strain",
        ],
        "surface_strain.report": ["measurement_quality", "write_run_report"],
        "surface_strain.tracks": ["Tracks"],
        "surface_strain.io": ["PointsError", "read_points3d", "read_triangles"],
        "surface_strain.run": [
            "RUN_SCHEMA",
            "Mesh",
            "choose_mesh",
            "parse_directions",
            "write_run",
        ],
    },
)
