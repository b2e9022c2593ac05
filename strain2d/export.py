"""Result files: nodal and element strain tables, ParaView time series, summary.

``strain_nodes.csv`` columns::

    frame,point,x,y,u,v,visible,Exx,Eyy,Exy,E1,E2,max_shear,theta1_deg,J[,uncertainty_px]

``uncertainty_px`` (trackers that measure it) is the standard deviation of
each coordinate of the tracked position, in pixels.

``strain_elements.csv`` columns::

    frame,triangle,p0,p1,p2,valid,Exx,Eyy,Exy,E1,E2,max_shear,theta1_deg,J

Positions and displacements are in pixels (x = column, y = row, centre of the
top-left pixel at (0, 0)); strains are Green-Lagrange, dimensionless;
``theta1_deg`` is the angle of the first principal direction from the x axis;
``J`` is the area ratio.  Lost values, and ``theta1_deg`` where ``E1 = E2``, are
``nan``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from surface_strain import StrainField, element_scalars, nodal_scalars

__all__ = [
    "ELEMENT_COLUMNS",
    "NODE_COLUMNS",
    "write_pvd",
    "write_strain_elements_csv",
    "write_strain_nodes_csv",
]

_SCALARS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "theta1_deg", "J")
NODE_COLUMNS = ("frame", "point", "x", "y", "u", "v", "visible", *_SCALARS)
ELEMENT_COLUMNS = ("frame", "triangle", "p0", "p1", "p2", "valid", *_SCALARS)


def write_strain_nodes_csv(
    path: str | os.PathLike, field: StrainField, uncertainty: np.ndarray | None = None
) -> None:
    """Write per-node strain for every frame (see the module docstring); ``uncertainty``
    ``(T, N)`` in px adds the ``uncertainty_px`` column."""
    T, N = field.n_frames, field.n_points
    frame, point = np.meshgrid(np.arange(T), np.arange(N), indexing="ij")
    pos = field.points
    disp = pos - field.reference
    scalars = nodal_scalars(field)
    table = np.column_stack(
        [
            frame.ravel(),
            point.ravel(),
            pos[..., 0].ravel(),
            pos[..., 1].ravel(),
            disp[..., 0].ravel(),
            disp[..., 1].ravel(),
            field.visible.ravel(),
            *(scalars[k].ravel() for k in _SCALARS),
        ]
    )
    fmt = ["%d", "%d", "%.6f", "%.6f", "%.6f", "%.6f", "%d"] + ["%.8g"] * len(_SCALARS)
    header = list(NODE_COLUMNS)
    if uncertainty is not None:
        table = np.column_stack([table, np.asarray(uncertainty, float).reshape(T * N)])
        fmt.append("%.4g")
        header.append("uncertainty_px")
    with open(path, "w") as f:
        f.write(",".join(header) + "\n")
        np.savetxt(f, table, fmt=fmt, delimiter=",")


def write_strain_elements_csv(path: str | os.PathLike, field: StrainField) -> None:
    """Write per-triangle strain for every frame (see the module docstring)."""
    T, M = field.n_frames, field.n_triangles
    frame, tri = np.meshgrid(np.arange(T), np.arange(M), indexing="ij")
    scalars = element_scalars(field)
    verts = field.triangles[tri.ravel()]
    table = np.column_stack(
        [
            frame.ravel(),
            tri.ravel(),
            verts,
            field.element_valid.ravel(),
            *(scalars[k].ravel() for k in _SCALARS),
        ]
    )
    fmt = ["%d"] * 6 + ["%.8g"] * len(_SCALARS)
    with open(path, "w") as f:
        f.write(",".join(ELEMENT_COLUMNS) + "\n")
        np.savetxt(f, table, fmt=fmt, delimiter=",")


def write_pvd(
    folder: str | os.PathLike,
    field: StrainField,
    *,
    name: str = "strain",
    times: np.ndarray | None = None,
) -> Path:
    """Write a ParaView time series: ``folder/name.pvd`` and ``folder/name/name_####.vtp``.

    The same files as :func:`surface_strain.export.write_pvd` (2D points at
    z = 0): point data ``displacement``, the nodal scalars, the principal
    directions and ``visible``; cell data with the element scalars and
    ``valid``.

    Returns
    -------
    Path of the ``.pvd`` file.
    """
    from surface_strain import write_pvd as write_series

    return write_series(folder, field, name=name, times=times)
