"""Camera and microscope together: membrane strain along the folding surface.

The camera's strain (:mod:`strain2d`) is the projection of a wall that
folds; the multiphoton microscope's height maps (:mod:`mpm3d`) show the
folds.  This package lifts the camera's mesh onto the height maps and
measures each triangle along the surface, separating true stretch from
length hidden in folds (:mod:`multimodal.geometry`); the two are
registered from landmark pairs or automatically from the images
(:mod:`multimodal.registration`).  A stereo run's surface and the
microscope's are registered in 3D (:mod:`multimodal.surface3d`: landmarks,
refined by ICP where the surfaces' shapes allow).
"""

from tissue_core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "tissue_core.version": ["__version__"],
        "multimodal.geometry": [
            "EDGES",
            "Similarity",
            "SurfaceMap",
            "SurfaceMosaic",
            "Tortuosity",
            "directional_tortuosity",
            "fold_aware_strain",
            "surface_lengths",
            "surface_metric",
            "tortuosity_correction",
        ],
        "multimodal.io": [
            "read_landmarks",
            "read_landmarks3d",
            "read_microscope_image",
            "read_surface_map",
            "read_transform",
        ],
        "multimodal.registration": ["Registration", "register_images"],
        "multimodal.surface3d": [
            "IcpResult",
            "Similarity3D",
            "closest_points_on_mesh",
            "heightmap_points",
            "mesh_index",
            "refine_icp",
        ],
        "multimodal.run": ["FoldStrain", "fold_strain_run", "write_fold_run"],
    },
)
