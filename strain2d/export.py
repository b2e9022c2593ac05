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

from surface_strain import (
    element_columns,
    node_columns,
    write_elements_csv,
    write_nodes_csv,
    write_pvd,
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
