"""Result files of a 2D run: nodal and element strain tables, ParaView time series.

The tables are :mod:`surface_strain.export`'s for a planar field.

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

from surface_strain import (
    StrainField,
    element_columns,
    node_columns,
    write_elements_csv,
    write_nodes_csv,
)

__all__ = [
    "ELEMENT_COLUMNS",
    "NODE_COLUMNS",
    "write_pvd",
    "write_strain_elements_csv",
    "write_strain_nodes_csv",
]

NODE_COLUMNS = node_columns(2)
ELEMENT_COLUMNS = element_columns(2)
#: ``write_strain_nodes_csv(path, field, uncertainty=None)``: surface_strain's, for a 2D field
write_strain_nodes_csv = write_nodes_csv
#: ``write_strain_elements_csv(path, field)``: surface_strain's, for a 2D field
write_strain_elements_csv = write_elements_csv


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
