"""Exceptions and warnings for problems a user can cause.

The errors are the toolkit's (:mod:`tissue_core.errors`); they and the
warnings subclass the built-in ``ValueError`` / ``OSError`` / ``UserWarning`` so
callers can catch them generically; ``python -m mpm3d`` turns the errors into
one line on stderr and exit status 2, and the warnings into one line each.
"""

from __future__ import annotations

from tissue_core.errors import InputError, SourceError

__all__ = [
    "InputError",
    "MissingSpacingWarning",
    "MosaicGapWarning",
    "NoDataWarning",
    "SourceError",
    "SurfaceOutsideWarning",
    "WorkFolderWarning",
    "warn_no_data",
]


class MissingSpacingWarning(UserWarning):
    """The stack carries no voxel spacing and none was given; 1 um voxels are assumed."""


class SurfaceOutsideWarning(UserWarning):
    """Part of the surface lies above the first slice: the stack does not contain it."""


class MosaicGapWarning(UserWarning):
    """Part of a mosaic's extent lies in no tile."""


class WorkFolderWarning(UserWarning):
    """The temporary folder of the work maps is not where ``TMPDIR`` says, or is in memory."""


class NoDataWarning(UserWarning):
    """Some voxels are NaN (no data): they count as lumen."""


def warn_no_data(missing: float, *, stacklevel: int = 3) -> None:
    """Say, when ``missing`` (the share of NaN voxels in a subsample) is above 0, how NaN is
    taken: as lumen, so that NaN within the tissue leaves its surface unmeasured there and
    walls the mesh at its edge."""
    import warnings

    if missing <= 0:
        return
    share = f"{100 * missing:.2g} %" if missing >= 1e-4 else "under 0.01 %"
    warnings.warn(
        NoDataWarning(
            f"about {share} of the voxels are NaN (no data; estimated on a subsample): they "
            "count as lumen, so where they lie within the tissue its surface is not measured "
            "and the mesh has a wall at their edge"
        ),
        stacklevel=stacklevel,
    )
