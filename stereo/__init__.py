"""Two calibrated cameras: grid points tracked in both views and triangulated in 3D.

:mod:`stereo.calibration` calibrates a camera pair from checkerboard or
ChArUco images (or reads OpenCV calibration files); :mod:`stereo.match`
finds points of the left view in the right one; :mod:`stereo.reconstruct`
tracks them through both videos and triangulates them
(:mod:`stereo.camera`) into 3D tracks ``(T, N, 3)`` for
:mod:`surface_strain`.  From the shell: ``python -m stereo calibrate``,
``match``, ``reconstruct``.
"""

from tissue_core.lazy import lazy_exports

__all__ = ["__version__"]


__getattr__, __dir__ = lazy_exports(__name__, {"tissue_core.version": ["__version__"]})[:2]
