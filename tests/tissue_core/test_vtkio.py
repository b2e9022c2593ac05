"""tissue_core.vtkio: one VTK XML writer for every package."""

from __future__ import annotations

import os

import numpy as np
import pytest

from tissue_core.vtkio import write_polydata, write_triangles


def _triangle():
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData

    points = vtkPoints()
    points.SetData(numpy_to_vtk(np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0]], float), deep=True))
    cells = vtkCellArray()
    cells.InsertNextCell(3, [0, 1, 2])
    mesh = vtkPolyData()
    mesh.SetPoints(points)
    mesh.SetPolys(cells)
    strain = numpy_to_vtk(np.array([0.1, -0.2, 0.3]), deep=True)
    strain.SetName("E")
    mesh.GetPointData().AddArray(strain)
    return mesh


def _read(path):
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    out = reader.GetOutput()
    return (
        vtk_to_numpy(out.GetPoints().GetData()),
        vtk_to_numpy(out.GetPointData().GetArray("E")),
        out.GetNumberOfCells(),
    )


@pytest.mark.parametrize(("compressor", "appended"), [("zlib", False), ("lz4", True)])
def test_a_mesh_written_reads_back_the_same(tmp_path, compressor, appended):
    path = tmp_path / "mesh.vtp"
    write_polydata(_triangle(), path, compressor=compressor, appended=appended)
    points, strain, cells = _read(path)
    np.testing.assert_array_equal(points, [[0, 0, 0], [1, 0, 0], [0, 2, 0]])
    np.testing.assert_array_equal(strain, [0.1, -0.2, 0.3])
    assert cells == 1
    head = path.read_bytes()[:400]
    assert (b"LZ4DataCompressor" if compressor == "lz4" else b"ZLibDataCompressor") in head
    assert (b'format="appended"' in path.read_bytes()) is appended


def test_a_name_that_is_not_utf8_is_written_under_that_name(tmp_path):
    name = os.fsencode(tmp_path) + b"/caf\xe9.vtp"
    write_polydata(_triangle(), os.fsdecode(name))
    assert os.path.exists(name)
    os.rename(name, tmp_path / "plain.vtp")  # VTK's reader takes UTF-8 names only
    assert _read(tmp_path / "plain.vtp")[2] == 1


def test_an_unknown_compressor_and_a_failed_write_are_errors(tmp_path):
    with pytest.raises(ValueError, match="compressor"):
        write_polydata(_triangle(), tmp_path / "m.vtp", compressor="lzma")
    with pytest.raises(OSError, match="could not write"):
        write_polydata(_triangle(), tmp_path / "no such folder" / "m.vtp")


def _read_all(path):
    """Points, triangles, and every point, cell and field array of a VTP, read by VTK."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    out = reader.GetOutput()
    arrays = {}
    for kind, data in (("point", out.GetPointData()), ("cell", out.GetCellData())):
        for i in range(data.GetNumberOfArrays()):
            arrays[kind, data.GetArrayName(i)] = vtk_to_numpy(data.GetArray(i))
        arrays[kind, "active"] = data.GetScalars().GetName() if data.GetScalars() else None
    fields = out.GetFieldData()
    for i in range(fields.GetNumberOfArrays()):
        a = fields.GetAbstractArray(i)
        arrays["field", a.GetName()] = [a.GetValue(k) for k in range(a.GetNumberOfValues())]
    cells = vtk_to_numpy(out.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    return vtk_to_numpy(out.GetPoints().GetData()), cells, arrays


@pytest.mark.parametrize("n", [3, 5000])
def test_triangles_written_without_vtk_read_back_by_vtk(tmp_path, n):
    """The NumPy writer's file, read by VTK's own reader: every value, type and string back
    (5,000 points: arrays of several zlib blocks)."""
    rng = np.random.default_rng(n)
    points = rng.random((n, 3))
    triangles = rng.integers(0, n, (2 * n, 3))
    point_data = {
        "displacement": rng.random((n, 3)),
        "visible": rng.random(n) < 0.5,
        "count": rng.integers(-9, 9, n).astype(np.int32),
    }
    cell_data = {"Exx": rng.random(2 * n).astype(np.float32), "valid": np.ones(2 * n, np.uint8)}
    field_data = {"length_unit": ["\u00b5m"], "array_units": ["point a: 1", 'x <&"> y', ""]}
    path = tmp_path / "mesh.vtp"
    write_triangles(path, points, triangles, point_data, cell_data, field_data)
    got_points, got_triangles, arrays = _read_all(path)
    np.testing.assert_array_equal(got_points, points)
    np.testing.assert_array_equal(got_triangles, triangles)
    for kind, data in (("point", point_data), ("cell", cell_data)):
        assert arrays[kind, "active"] == next(iter(data))
        for name, values in data.items():
            got = arrays[kind, name]
            assert got.dtype == (np.uint8 if values.dtype == bool else values.dtype)
            np.testing.assert_array_equal(got, values)
    for name, texts in field_data.items():
        assert arrays["field", name] == texts


def test_triangles_take_any_name_and_refuse_what_vtk_cannot_hold(tmp_path):
    name = os.fsencode(tmp_path) + b"/caf\xe9.vtp"
    write_triangles(os.fsdecode(name), np.eye(3), [[0, 1, 2]], {"E": np.zeros(3)})
    os.rename(name, tmp_path / "plain.vtp")
    assert _read_all(tmp_path / "plain.vtp")[1].tolist() == [[0, 1, 2]]
    with pytest.raises(ValueError, match="has 2 values for 3"):
        write_triangles(tmp_path / "m.vtp", np.eye(3), [[0, 1, 2]], {"E": np.zeros(2)})
    with pytest.raises(ValueError, match="complex"):
        write_triangles(tmp_path / "m.vtp", np.eye(3), [[0, 1, 2]], {"E": np.zeros(3, complex)})
    with pytest.raises(OSError):
        write_triangles(tmp_path / "no such folder" / "m.vtp", np.eye(3), [[0, 1, 2]])


@pytest.mark.parametrize("chunk", [1, 7, 5000])
def test_triangles_streamed_a_chunk_at_a_time_read_back_by_vtk(tmp_path, chunk):
    """A mesh given a chunk at a time (chunks smaller and larger than a zlib block),
    with point arrays, numeric and text field data: VTK reads it back whole; nothing
    but the file is left in the folder, and a file of the toolkit's old work name there
    is the user's and stays."""
    import pyvista as pv

    from tissue_core.vtkio import write_triangles_streamed

    rng = np.random.default_rng(chunk)
    points = rng.random((3000, 3)).astype(np.float32)
    tris = rng.integers(0, 3000, (5000, 3))
    normals = rng.random((3000, 3)).astype(np.float32)
    height = rng.random(3000)

    def chunks(a):
        return lambda: (a[i : i + chunk] for i in range(0, len(a), chunk))

    mine = tmp_path / "mesh.vtp.body"
    mine.write_text("a user's file")
    path = tmp_path / "mesh.vtp"
    write_triangles_streamed(
        path, 3000, 5000, chunks(points), chunks(tris),
        {"Normals": ("float32", 3, chunks(normals)), "height": ("float64", 1, chunks(height))},
        {"level": np.array([0.5, 2.0]), "unit": ["µm"]}, normals="Normals",
    )  # fmt: skip
    back = pv.read(path)
    assert np.array_equal(back.points, points) and np.array_equal(back.regular_faces, tris)
    assert np.array_equal(back.point_data["Normals"], normals) and back.active_normals is not None
    assert np.array_equal(back.point_data["height"], height)
    assert back.field_data["level"].tolist() == [0.5, 2.0]
    assert str(back.field_data["unit"][0]) == "µm"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.vtp", "mesh.vtp.body"]
    assert mine.read_text() == "a user's file"
    with pytest.raises(ValueError, match="values for"):
        write_triangles_streamed(tmp_path / "short.vtp", 3001, 5000, chunks(points), chunks(tris))
