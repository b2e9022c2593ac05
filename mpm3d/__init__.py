"""Multiphoton z-stacks to the lumen surface and its folds.

Read a stack ``(Z, Y, X)`` or ``(Z, C, Y, X)`` with its voxel spacing in
micrometres (:mod:`mpm3d.io`), find the lumen surface as a sub-voxel height
map (:mod:`mpm3d.heightmap`) and as a mesh (:mod:`mpm3d.surface`), measure
its folds and roughness (:mod:`mpm3d.metrics`), compare two stacks
(:mod:`mpm3d.compare`).  From the shell: ``python -m mpm3d analyze
STACK.tif --out DIR`` and ``python -m mpm3d compare BEFORE.tif AFTER.tif
--out DIR``.
"""

from mpm3d.errors import InputError, MissingSpacingWarning, SourceError


def __getattr__(name: str):
    if name == "__version__":  # read from the package metadata only when asked
        from tissue_core.version import __version__

        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["InputError", "MissingSpacingWarning", "SourceError", "__version__"]
