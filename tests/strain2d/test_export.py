import numpy as np
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from strain2d.export import write_pvd
from strain2d.pipeline import strain_from_tracks
from strain2d.tracks import Tracks
from surface_strain import element_scalars, nodal_scalars


def _field():
    ref = np.stack(np.meshgrid(np.linspace(0, 40, 4), np.linspace(0, 30, 3)), -1).reshape(-1, 2)
    A = np.array([[1.2, 0.1], [0.0, 0.9]])
    pos = np.stack([ref, ref @ A.T + 2, ref @ (A @ A).T])
    vis = np.ones((3, 12), bool)
    vis[2, 0] = False
    return strain_from_tracks(Tracks(pos, vis, np.ones((3, 12))))


def test_pvd_series_reads_back_with_vtk(tmp_path):
    field = _field()
    pvd = write_pvd(tmp_path, field, times=np.array([0.0, 0.5, 1.0]))
    import xml.etree.ElementTree as ET

    entries = ET.parse(pvd).getroot().find("Collection").findall("DataSet")
    assert [float(e.get("timestep")) for e in entries] == [0.0, 0.5, 1.0]
    node, elem = nodal_scalars(field), element_scalars(field)
    for t, entry in enumerate(entries):
        reader = vtkXMLPolyDataReader()
        reader.SetFileName(str(tmp_path / entry.get("file")))
        reader.Update()
        poly = reader.GetOutput()
        assert poly.GetNumberOfPoints() == 12 and poly.GetNumberOfCells() == field.n_triangles
        pts = vtk_to_numpy(poly.GetPoints().GetData())
        np.testing.assert_allclose(pts[field.visible[t], :2], field.points[t][field.visible[t]])
        pd, cd = poly.GetPointData(), poly.GetCellData()
        disp = vtk_to_numpy(pd.GetArray("displacement"))
        np.testing.assert_allclose(disp[:, :2], field.points[t] - field.reference)
        for key in ("Exx", "Eyy", "Exy", "E1", "E2", "J"):
            np.testing.assert_allclose(vtk_to_numpy(pd.GetArray(key)), node[key][t], equal_nan=True)
            np.testing.assert_allclose(vtk_to_numpy(cd.GetArray(key)), elem[key][t], equal_nan=True)
        np.testing.assert_array_equal(vtk_to_numpy(pd.GetArray("visible")), field.visible[t])
        np.testing.assert_array_equal(vtk_to_numpy(cd.GetArray("valid")), field.element_valid[t])


def test_pvd_series_is_written_with_vtk_alone(tmp_path):
    """The series needs VTK's XML writer, not pyvista (a second of imports per run)."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from strain2d.export import write_pvd\n"
        "from surface_strain import compute_strain, grid_triangles\n"
        "X = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2)\n"
        "field = compute_strain(X, np.stack([X, X * 1.1]), grid_triangles(3, 3))\n"
        f"write_pvd({str(tmp_path)!r}, field, length_scale=0.5, length_unit='mm')\n"
        "assert 'pyvista' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(tmp_path / "strain" / "strain_0001.vtp"))
    reader.Update()
    poly = reader.GetOutput()
    fields = poly.GetFieldData()
    unit = fields.GetAbstractArray("length_unit")
    assert unit.GetValue(0) == "mm"
    units = fields.GetAbstractArray("array_units")
    listed = [units.GetValue(i) for i in range(units.GetNumberOfValues())]
    assert "point displacement: mm" in listed and "cell valid: 1 (flag)" in listed
    assert poly.GetPointData().GetScalars().GetName() == "displacement"
    assert poly.GetCellData().GetScalars().GetName() == "Exx"
    np.testing.assert_allclose(vtk_to_numpy(poly.GetPoints().GetData())[4], [0.55, 0.55, 0])
