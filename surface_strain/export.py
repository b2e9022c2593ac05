"""Result files for strain on surfaces: node and element tables, ParaView time series.

One table schema for 3D and 2D fields; 2D is its planar case.  For 3D fields
``strain_nodes.csv`` has the columns::

    frame,point,X,Y,Z,U,V,W,visible,Exx,Eyy,Exy,E1,E2,max_shear,J

and for 2D fields (:mod:`strain2d`'s contract) the planar ones, in lower
case, with the principal angle in the plane::

    frame,point,x,y,u,v,visible,Exx,Eyy,Exy,E1,E2,max_shear,theta1_deg,J[,uncertainty_px]

``strain_elements.csv`` has ``frame,triangle,p0,p1,p2,valid`` and the same
strains.  Positions ``X, Y, Z`` and displacements ``U, V, W`` are in the
points' unit (pixels in 2D); strains are Green-Lagrange, dimensionless,
``Exx, Eyy, Exy`` in the directional frame the field was computed with;
``theta1_deg`` is the angle of the first principal direction from the x
axis; ``J`` is the area ratio; ``uncertainty_px`` the tracker's standard
deviation of each coordinate.  Lost values, and ``theta1_deg`` where
``E1 = E2``, are ``nan``.

:func:`write_pvd` writes ``name.pvd`` and one ``.vtp`` per frame: the mesh at
the frame's positions, point data ``displacement`` (vector), the nodal
scalars, the principal directions as unit vectors (``principal_direction_1``
and ``_2``: material directions in the reference configuration;
``..._current``: the same fibres in the current one; NaN where the strain
is isotropic) and ``visible``; cell data with the element scalars, their
principal directions and ``valid``.  Vectors are zero where undefined (a
lost point's displacement, an isotropic strain's directions): VTK's XML
readers cannot take NaN vectors; ``visible`` and the NaN scalars say where.
ParaView opens the ``.pvd`` as a time series.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from surface_strain.field import StrainField, element_scalars, nodal_scalars

__all__ = [
    "ELEMENT_COLUMNS",
    "NODE_COLUMNS",
    "element_columns",
    "node_columns",
    "write_elements_csv",
    "write_nodes_csv",
    "write_pvd",
]

SCALARS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J")
_PLANAR_SCALARS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "theta1_deg", "J")


def _scalars(d: int) -> tuple[str, ...]:
    return _PLANAR_SCALARS if d == 2 else SCALARS


def node_columns(d: int = 3) -> tuple[str, ...]:
    """Columns of ``strain_nodes.csv`` for a field in ``d`` = 2 or 3 dimensions."""
    axes = ("x", "y", "u", "v") if d == 2 else ("X", "Y", "Z", "U", "V", "W")
    return ("frame", "point", *axes, "visible", *_scalars(d))


def element_columns(d: int = 3) -> tuple[str, ...]:
    """Columns of ``strain_elements.csv`` for a field in ``d`` = 2 or 3 dimensions."""
    return ("frame", "triangle", "p0", "p1", "p2", "valid", *_scalars(d))


NODE_COLUMNS = node_columns(3)
ELEMENT_COLUMNS = element_columns(3)


def _xyz(a: np.ndarray) -> np.ndarray:
    """(..., 2 or 3) -> (..., 3), z = 0 for 2D."""
    if a.shape[-1] == 3:
        return a
    return np.concatenate([a, np.zeros((*a.shape[:-1], 1))], axis=-1)


def write_nodes_csv(
    path: str | os.PathLike, field: StrainField, uncertainty: np.ndarray | None = None
) -> None:
    """Per-node positions, displacements and strain for every frame (see the module docstring).

    ``uncertainty`` ``(T, N)`` in px adds the ``uncertainty_px`` column.
    """
    from tissue_core.tables import write_long_table

    d = field.points.shape[-1]
    names = node_columns(d)[2:]
    disp = field.points - field.reference[None]
    scalars = nodal_scalars(field)
    columns = {names[k]: (field.points[..., k], "%.6f") for k in range(d)}
    columns |= {names[d + k]: (disp[..., k], "%.6f") for k in range(d)}
    columns["visible"] = (field.visible, "%d")
    columns |= {k: (scalars[k], "%.8g") for k in _scalars(d)}
    if uncertainty is not None:
        columns["uncertainty_px"] = (np.asarray(uncertainty, float), "%.4g")
    write_long_table(path, columns)


def write_elements_csv(path: str | os.PathLike, field: StrainField) -> None:
    """Per-triangle strain for every frame (see the module docstring)."""
    from tissue_core.tables import write_long_table

    d = field.points.shape[-1]
    corners = np.broadcast_to(field.triangles, (field.n_frames, *field.triangles.shape))
    scalars = element_scalars(field)
    columns = {f"p{k}": (corners[..., k], "%d") for k in range(3)}
    columns["valid"] = (field.element_valid, "%d")
    columns |= {k: (scalars[k], "%.8g") for k in _scalars(d)}
    write_long_table(path, columns, index="triangle")


def _directions(field: StrainField) -> dict:
    """Principal directions per triangle and node: {"element"|"node": PrincipalDirections}."""
    from surface_strain.field import element_principal_directions, nodal_principal_directions

    return {
        "element": element_principal_directions(field, isotropic="nan"),
        "node": nodal_principal_directions(field, isotropic="nan"),
    }


def write_pvd(
    folder: str | os.PathLike,
    field: StrainField,
    *,
    name: str = "strain",
    times: np.ndarray | None = None,
) -> Path:
    """Write a ParaView time series: ``folder/name.pvd`` and ``folder/name/name_####.vtp``.

    Returns
    -------
    Path of the ``.pvd`` file.
    """
    import pyvista as pv

    folder = Path(folder)
    sub = folder / name
    sub.mkdir(parents=True, exist_ok=True)
    T = field.n_frames
    times = np.arange(T, dtype=float) if times is None else np.asarray(times, dtype=float)
    node = nodal_scalars(field)
    elem = element_scalars(field)
    dirs = _directions(field)
    faces = np.column_stack([np.full(field.n_triangles, 3), field.triangles]).ravel()
    ref = _xyz(field.reference)
    entries = []
    for t in range(T):
        cur = _xyz(field.points[t])
        mesh = pv.PolyData(np.where(np.isfinite(cur), cur, ref), faces=faces)
        mesh.point_data["displacement"] = np.nan_to_num(cur - ref)  # lost: 0, see "visible"
        for key, values in node.items():
            mesh.point_data[key] = values[t]
        mesh.point_data["visible"] = field.visible[t].astype(np.uint8)
        for key, values in elem.items():
            mesh.cell_data[key] = values[t]
        mesh.cell_data["valid"] = field.element_valid[t].astype(np.uint8)
        for data, pd in ((mesh.point_data, dirs["node"]), (mesh.cell_data, dirs["element"])):
            # zero vectors where a direction is undefined: NaN vectors give VTK's XML
            # readers unreadable ranges
            data["principal_direction_1"] = np.nan_to_num(_xyz(pd.dir1_ref[t]))
            data["principal_direction_2"] = np.nan_to_num(_xyz(pd.dir2_ref[t]))
            data["principal_direction_1_current"] = np.nan_to_num(_xyz(pd.dir1_cur[t]))
            data["principal_direction_2_current"] = np.nan_to_num(_xyz(pd.dir2_cur[t]))
        fname = f"{name}_{t:04d}.vtp"
        mesh.save(sub / fname, binary=True)
        entries.append(f'    <DataSet timestep="{times[t]:.10g}" part="0" file="{name}/{fname}"/>')
    pvd = folder / f"{name}.pvd"
    pvd.write_text(
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n"
    )
    return pvd
