"""Strain fields from videos of deforming tissue, without speckles.

Video -> virtual grid points tracked through every frame -> triangle mesh on
the reference grid -> deformation gradient and Green-Lagrange strain per
triangle and node, per frame -> figures, tables and ParaView exports, run
reports, and studies that combine many runs with the specimen as the unit.

Pixel convention: x = column, y = row, the centre of the top-left pixel is
(0, 0).
"""

from importlib import metadata as _metadata

from strain2d.errors import InputError, SourceError
from strain2d.frames import FrameSource, open_frames
from strain2d.grid import make_grid, read_points_csv
from strain2d.pipeline import Analysis, analyze, strain_from_tracks, track
from strain2d.report import run_outputs, write_run_report, write_study
from strain2d.run import Run, load_run
from strain2d.study import load_specimens, read_manifest, study_statistics
from strain2d.trackers import available_trackers, register_tracker
from strain2d.tracks import Tracks, read_tracks, write_tracks_csv

try:
    __version__ = _metadata.version("tissue-strain")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "Analysis",
    "FrameSource",
    "InputError",
    "Run",
    "SourceError",
    "Tracks",
    "__version__",
    "analyze",
    "available_trackers",
    "load_run",
    "load_specimens",
    "make_grid",
    "open_frames",
    "read_manifest",
    "read_points_csv",
    "read_tracks",
    "register_tracker",
    "run_outputs",
    "strain_from_tracks",
    "study_statistics",
    "track",
    "write_run_report",
    "write_study",
    "write_tracks_csv",
]
