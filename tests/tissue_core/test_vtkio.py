"""tissue_core.vtkio: one VTK XML writer for every package."""

from __future__ import annotations

import os

import numpy as np
import pytest

from tissue_core.vtkio import write_polydata


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
