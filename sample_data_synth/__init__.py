"""Synthetic inputs with exact ground truth.

Speckle patterns and a tissue photograph deformed by analytic maps, rendered
with sensor noise and written as real video and TIFF files, and multiphoton
z-stacks of a folded lumen whose surface is known exactly
(:mod:`sample_data_synth.stacks`), and stereo pairs (calibration boards and
deforming membranes seen through OpenCV's camera model,
:mod:`sample_data_synth.stereo`), each with a ground-truth file beside it.
Depends on no other package of the toolkit.
"""

from importlib import metadata as _metadata

from sample_data_synth.cases import (
    CASES,
    GroundTruth,
    SyntheticVideo,
    load_ground_truth,
    make_case,
    write_video,
)
from sample_data_synth.deformations import Field, Homogeneous, equibiaxial, rotation, simple_shear
from sample_data_synth.render import add_sensor_noise, render_image, render_speckle
from sample_data_synth.speckle import SpecklePattern, speckle_pattern
from sample_data_synth.stacks import (
    STACK_CASES,
    SyntheticStack,
    fold_height_field,
    make_stack_case,
    render_stack,
    save_stack_truth,
    write_stack,
)
from sample_data_synth.stereo import (
    STEREO_CASES,
    CalibrationViews,
    CharucoBoard,
    Checkerboard,
    StereoRig,
    StereoScene,
    default_rig,
    load_stereo_scene,
    parse_board,
    render_calibration_views,
    render_surface_scene,
    save_calibration_views,
    save_stereo_scene,
    undistort_points,
)

try:
    __version__ = _metadata.version("tissue-strain")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "CASES",
    "STACK_CASES",
    "STEREO_CASES",
    "CalibrationViews",
    "CharucoBoard",
    "Checkerboard",
    "Field",
    "GroundTruth",
    "Homogeneous",
    "SpecklePattern",
    "StereoRig",
    "StereoScene",
    "SyntheticStack",
    "SyntheticVideo",
    "add_sensor_noise",
    "default_rig",
    "equibiaxial",
    "fold_height_field",
    "load_ground_truth",
    "load_stereo_scene",
    "make_case",
    "make_stack_case",
    "parse_board",
    "render_calibration_views",
    "render_image",
    "render_speckle",
    "render_stack",
    "render_surface_scene",
    "rotation",
    "save_calibration_views",
    "save_stack_truth",
    "save_stereo_scene",
    "simple_shear",
    "speckle_pattern",
    "undistort_points",
    "write_stack",
    "write_video",
]
