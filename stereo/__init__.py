"""Two calibrated cameras: grid points tracked in both views and triangulated in 3D.

:mod:`stereo.calibration` calibrates a camera pair from checkerboard or
ChArUco images (or reads OpenCV calibration files); :mod:`stereo.match`
finds points of the left view in the right one; :mod:`stereo.reconstruct`
tracks them through both videos and triangulates them
(:mod:`stereo.camera`) into 3D tracks ``(T, N, 3)`` for
:mod:`surface_strain`.  From the shell: ``python -m stereo calibrate``,
``match``, ``reconstruct``.
"""

__all__ = ["__version__"]


def __getattr__(name: str):
    if name == "__version__":  # read from the package metadata only when asked
        from tissue_core.version import __version__

        return __version__
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
