"""Strain fields from videos of deforming tissue, without speckles.

Video -> virtual grid points tracked through every frame -> triangle mesh on
the reference grid -> deformation gradient and Green-Lagrange strain per
triangle and node, per frame -> figures, tables and ParaView exports, run
reports, and studies that combine many runs with the specimen as the unit.

Pixel convention: x = column, y = row, the centre of the top-left pixel is
(0, 0).
"""

from tissue_core.lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "tissue_core.version": ["__version__"],
        "strain2d.errors": ["InputError", "SourceError"],
        "strain2d.frames": ["FrameSource", "open_frames"],
        "strain2d.grid": [
            "default_roi",
            "make_grid",
            "mask_triangles",
            "masked_grid",
            "points_on_tissue",
            "parse_grid",
            "parse_roi",
            "read_points_csv",
            "validate_points",
        ],
        "strain2d.pipeline": [
            "Analysis",
            "analysis_of",
            "analyze",
            "check_tracks_fit",
            "strain_from_tracks",
            "track",
        ],
        "strain2d.report": ["run_outputs", "write_run_report", "write_study"],
        "strain2d.run": ["Run", "load_run", "write_run"],
        "strain2d.study": ["load_specimens", "read_manifest", "study_statistics"],
        "strain2d.trackers": [
            "TrackerOption",
            "add_tracker_arguments",
            "available_trackers",
            "get_tracker",
            "register_tracker",
            "tracker_inputs",
            "tracker_options",
        ],
        "strain2d.tracks": ["Tracks", "read_tracks", "write_tracks_csv"],
    },
)
