"""Stereo reconstruction of tracked grid points (not implemented yet).

This package will hold camera calibration (checkerboard and ChArUco targets),
cross-view matching of grid points, and triangulation of the points tracked in
both views into 3D tracks ``(T, N, 3)`` for :mod:`surface_strain`.  Nothing in
it works yet; ``python -m stereo`` says so and exits with status 2.
"""
