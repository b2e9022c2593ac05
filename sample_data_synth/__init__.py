"""Synthetic inputs with exact ground truth.

Speckle patterns and a tissue photograph deformed by analytic maps, rendered
with sensor noise and written as real video and TIFF files, and multiphoton
z-stacks of a folded lumen whose surface is known exactly
(:mod:`sample_data_synth.stacks`), and stereo pairs (calibration boards and
deforming membranes seen through OpenCV's camera model,
:mod:`sample_data_synth.stereo`), each with a ground-truth file beside it.
Depends on no other package of the toolkit but its ground floor, :mod:`tissue_core`.
"""

from tissue_core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "tissue_core.version": ["__version__"],
        "sample_data_synth.cases": [
            "CASES",
            "GroundTruth",
            "SyntheticVideo",
            "load_ground_truth",
            "make_case",
            "write_video",
        ],
        "sample_data_synth.deformations": [
            "Field",
            "Homogeneous",
            "equibiaxial",
            "rotation",
            "simple_shear",
        ],
        "sample_data_synth.render": ["add_sensor_noise", "render_image", "render_speckle"],
        "sample_data_synth.speckle": ["SpecklePattern", "speckle_pattern"],
        "sample_data_synth.tissue": ["TISSUE_CASES", "Light", "make_tissue_case", "tissue_texture"],
        "sample_data_synth.variants": ["Variant", "make_variant", "tissue_variants"],
        "sample_data_synth.pieces": ["PIECES_GRID", "make_rotation_pieces", "texture_depth"],
        "sample_data_synth.still": ["NOISE_LEVELS", "make_still_video"],
        "sample_data_synth.sheet": ["make_muscle_sheet", "muscle_texture"],
        "sample_data_synth.stacks": [
            "STACK_CASES",
            "SyntheticStack",
            "fold_height_field",
            "make_stack_case",
            "render_stack",
            "save_stack_truth",
            "write_stack",
        ],
        "sample_data_synth.patch": ["MicroscopePatch", "microscope_patch", "write_patch"],
        "sample_data_synth.stereo": [
            "STEREO_CASES",
            "CalibrationViews",
            "CharucoBoard",
            "Checkerboard",
            "CircleGrid",
            "StereoRig",
            "StereoScene",
            "default_rig",
            "load_stereo_scene",
            "parse_board",
            "render_calibration_views",
            "render_surface_scene",
            "save_calibration_views",
            "save_stereo_scene",
            "undistort_points",
        ],
    },
)
