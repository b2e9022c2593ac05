"""Multiphoton z-stacks to lumen surface and fold metrics (not implemented yet).

This package will read microscopy stacks ``(Z, Y, X)`` or ``(Z, C, Y, X)`` with
their voxel spacing in micrometres, extract the lumen surface (height map and
isosurface mesh) and measure folds (height, wavelength, orientation,
roughness).  Nothing in it works yet; ``python -m mpm3d`` says so and exits
with status 2.
"""
