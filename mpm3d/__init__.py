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
from tissue_core.lazy import lazy_exports

__getattr__, __dir__, _lazy = lazy_exports(
    __name__,
    {
        "tissue_core.version": ["__version__"],
        "mpm3d.io": ["Stack", "read_stack"],
        "mpm3d.analyze": ["analyze_stack", "write_analysis"],
        "mpm3d.mosaic": ["open_mosaic", "write_stitched"],
        "mpm3d.tiled": ["parse_memory"],
    },
)

__all__ = ["InputError", "MissingSpacingWarning", "SourceError", *_lazy]
