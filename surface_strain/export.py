"""Result files for strain on surfaces: node and element tables, ParaView time series.

One table schema for 3D and 2D fields; 2D is its planar case.  For 3D fields
``strain_nodes.csv`` has the columns::

    frame,point,X,Y,Z,U,V,W,visible,Exx,Eyy,Exy,E1,E2,max_shear,J

and for 2D fields (:mod:`strain2d`'s contract) the planar ones, in lower
case, with the principal angle in the plane::

    frame,point,x,y,u,v,visible,Exx,Eyy,Exy,E1,E2,max_shear,theta1_deg,J[,uncertainty_px]

With a physical length (``length_unit``, e.g. a 2D run's ``--scale``) the
node table also has the positions and displacements in that unit, named with
it (``x_mm,y_mm,u_mm,v_mm`` after ``u,v``; ``uncertainty_mm`` after
``uncertainty_px``); the columns without a suffix keep the points' own unit.

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
ParaView opens the ``.pvd`` as a time series.  Each ``.vtp`` carries field
data naming the units: ``length_unit`` (of the points and ``displacement``),
``time_unit`` (of the ``.pvd``'s time steps) and ``array_units``, one
``"name: unit"`` string per array (strains ``1``, i.e. dimensionless).
With ``length_scale`` the points and displacements are in ``length_unit``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from surface_strain.field import StrainField, element_scalars, nodal_scalars
from surface_strain.streamed import iter_blocks
from tissue_core.vtkio import write_triangles

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


def _check_length(length_scale: float | None, length_unit: str | None) -> None:
    if length_scale is not None and not (np.isfinite(length_scale) and length_scale > 0):
        raise ValueError(f"length_scale must be a positive number, got {length_scale}")
    if length_scale is not None and not length_unit:
        raise ValueError("length_scale needs its length_unit")


def write_nodes_csv(
    path: str | os.PathLike,
    field: StrainField,
    uncertainty: np.ndarray | None = None,
    *,
    length_scale: float | None = None,
    length_unit: str | None = None,
) -> None:
    """Per-node positions, displacements and strain for every frame (see the module docstring).

    ``uncertainty`` ``(T, N)`` in px adds the ``uncertainty_px`` column.
    ``length_scale`` (``length_unit`` per point unit, e.g. 0.012 mm per px)
    adds the positions and displacements in ``length_unit``.
    """
    from tissue_core.tables import PerFrame, write_long_table

    _check_length(length_scale, length_unit)
    d = field.points.shape[-1]
    names = node_columns(d)[2:]
    points, reference = field.points, field.reference
    shape = points.shape[:2]

    # derived columns are computed a block of frames at a time, as the table is written
    def position(k: int, factor: float = 1.0) -> PerFrame:
        return PerFrame(shape, lambda a, b: points[a:b, :, k] * factor)

    def displacement(k: int, factor: float = 1.0) -> PerFrame:
        return PerFrame(shape, lambda a, b: (points[a:b, :, k] - reference[:, k]) * factor)

    scalars = nodal_scalars(field)
    columns = {names[k]: (points[..., k], "%.6f") for k in range(d)}
    columns |= {names[d + k]: (displacement(k), "%.6f") for k in range(d)}
    if length_scale is not None:
        columns |= {
            f"{names[k]}_{length_unit}": (position(k, length_scale), "%.8g") for k in range(d)
        }
        columns |= {
            f"{names[d + k]}_{length_unit}": (displacement(k, length_scale), "%.8g")
            for k in range(d)
        }
    columns["visible"] = (field.visible, "%d")
    columns |= {k: (scalars[k], "%.8g") for k in _scalars(d)}
    if uncertainty is not None:
        sigma = np.asarray(uncertainty, float)
        columns["uncertainty_px"] = (sigma, "%.4g")
        if length_scale is not None:
            columns[f"uncertainty_{length_unit}"] = (
                PerFrame(sigma.shape, lambda a, b: sigma[a:b] * length_scale),
                "%.4g",
            )
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


_DIMENSIONLESS = {*SCALARS, *_PLANAR_SCALARS} - {"theta1_deg"}


def _array_units(point_data: dict, cell_data: dict, length_unit: str) -> list[str]:
    """``"point NAME: UNIT"`` for every point and cell array, in order."""
    units = []
    for kind, data in (("point", point_data), ("cell", cell_data)):
        for key in data:
            if key == "displacement":
                unit = length_unit
            elif key in _DIMENSIONLESS:
                unit = "1 (dimensionless)"
            elif key == "theta1_deg":
                unit = "degree"
            elif key.startswith("principal_direction"):
                unit = "1 (unit vector)"
            else:  # visible, valid
                unit = "1 (flag)"
            units.append(f"{kind} {key}: {unit}")
    return units


def write_pvd(
    folder: str | os.PathLike,
    field: StrainField,
    *,
    name: str = "strain",
    times: np.ndarray | None = None,
    time_unit: str = "frame",
    length_scale: float | None = None,
    length_unit: str | None = None,
) -> Path:
    """Write a ParaView time series: ``folder/name.pvd`` and ``folder/name/name_####.vtp``.

    ``times`` are in ``time_unit``.  ``length_scale`` converts the points'
    unit to ``length_unit`` (e.g. 0.012 mm per px); without it the files stay
    in the points' unit, named by ``length_unit`` when given (default
    ``"px"`` for 2D fields, ``"input units"`` for 3D ones).

    Returns
    -------
    Path of the ``.pvd`` file.
    """
    _check_length(length_scale, length_unit)
    folder = Path(folder)
    sub = folder / name
    sub.mkdir(parents=True, exist_ok=True)
    T = field.n_frames
    times = np.arange(T, dtype=float) if times is None else np.asarray(times, dtype=float)
    factor = 1.0 if length_scale is None else float(length_scale)
    unit = length_unit or ("px" if field.points.shape[-1] == 2 else "input units")
    ref = _xyz(field.reference) * factor
    entries = []
    # a block of frames at a time (a streamed field's own blocks; an in-memory one whole)
    for start, block in iter_blocks(field):
        node = nodal_scalars(block)
        elem = element_scalars(block)
        dirs = _directions(block)
        for i in range(block.n_frames):
            t = start + i
            cur = _xyz(block.points[i]) * factor
            point_data = {"displacement": np.nan_to_num(cur - ref)}  # lost: 0, see "visible"
            point_data |= {key: values[i] for key, values in node.items()}
            point_data["visible"] = block.visible[i].astype(np.uint8)
            cell_data = {key: values[i] for key, values in elem.items()}
            cell_data["valid"] = block.element_valid[i].astype(np.uint8)
            for data, pd in ((point_data, dirs["node"]), (cell_data, dirs["element"])):
                # zero vectors where a direction is undefined: NaN vectors give VTK's XML
                # readers unreadable ranges
                data["principal_direction_1"] = np.nan_to_num(_xyz(pd.dir1_ref[i]))
                data["principal_direction_2"] = np.nan_to_num(_xyz(pd.dir2_ref[i]))
                data["principal_direction_1_current"] = np.nan_to_num(_xyz(pd.dir1_cur[i]))
                data["principal_direction_2_current"] = np.nan_to_num(_xyz(pd.dir2_cur[i]))
            units = {
                "length_unit": [unit],
                "time_unit": [time_unit],
                "array_units": _array_units(point_data, cell_data, unit),
            }
            fname = f"{name}_{t:04d}.vtp"
            write_triangles(
                sub / fname,
                np.where(np.isfinite(cur), cur, ref),
                field.triangles,
                point_data,
                cell_data,
                units,
            )
            entries.append(
                f'    <DataSet timestep="{times[t]:.10g}" part="0" file="{name}/{fname}"/>'
            )
    pvd = folder / f"{name}.pvd"
    pvd.write_text(
        '<?xml version="1.0"?>\n'
        '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
        "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n</VTKFile>\n"
    )
    return pvd
