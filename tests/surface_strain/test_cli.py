"""``python -m surface_strain compute`` on analytic 3D tracks, the files read back with VTK's own
XML readers, and the errors a user can cause (exit 2, one line)."""

import csv
import json
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

from surface_strain.cli import main
from tests.badinput import message_lines
from tests.tolerances import EXACT


def cli(*argv) -> int:
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def _write(path, points, visible=None):
    T, N = points.shape[:2]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["frame", "point", "X", "Y", "Z", "reproj_error", "visible"])
        for t in range(T):
            for i in range(N):
                vis = 1 if visible is None else int(visible[t, i])
                w.writerow([t, i, *points[t, i], 0.01, vis])


def _tilted_sheet_tracks(n=5, frames=4):
    """A grid on a tilted plane stretched homogeneously in its own axes: exact for triangles."""
    u, v = np.meshgrid(np.linspace(-10, 10, n), np.linspace(-8, 8, n))
    a, b = math.radians(20), math.radians(-15)
    e1 = np.array([math.cos(a), 0, math.sin(a)])
    e2 = np.cross(np.array([-math.sin(a), 0, math.cos(a)]), e1)
    e2 = math.cos(b) * e2 + math.sin(b) * np.cross(e1, e2)
    e2 -= e1 * (e1 @ e2)
    e2 /= np.linalg.norm(e2)
    centre = np.array([5.0, -3.0, 450.0])
    pts = []
    lam = np.linspace(1, 1.2, frames), np.linspace(1, 0.9, frames)
    for t in range(frames):
        p = centre + (lam[0][t] * u.ravel())[:, None] * e1 + (lam[1][t] * v.ravel())[:, None] * e2
        pts.append(p)
    return np.stack(pts), e1, e2, lam


def test_exact_strain_on_a_stretched_tilted_sheet_and_the_paraview_files(tmp_path):
    points, e1, e2, lam = _tilted_sheet_tracks()
    src = tmp_path / "points3d.csv"
    _write(src, points)
    out = tmp_path / "out"
    d = ",".join(f"{x:.15g}" for x in e1), ",".join(f"{x:.15g}" for x in e2)
    code = cli("compute", src, "--grid", "5x5", "--directions", f"vectors:{d[0]}:{d[1]}",
               "--out", out, "-q")  # fmt: skip
    assert code == 0
    rows = list(csv.DictReader((out / "strain_nodes.csv").read_text().splitlines()))
    assert list(rows[0])[:5] == ["frame", "point", "X", "Y", "Z"]
    T = points.shape[0]
    for key, truth in (("Exx", (lam[0] ** 2 - 1) / 2), ("Eyy", (lam[1] ** 2 - 1) / 2)):
        got = np.array([float(r[key]) for r in rows]).reshape(T, -1)
        np.testing.assert_allclose(got, truth[:, None] * np.ones_like(got), atol=1e-9)
    exy = np.array([float(r["Exy"]) for r in rows])
    assert np.abs(exy).max() < 1e-9
    # every .vtp of the series, read back with VTK's XML reader
    pvd = ET.parse(out / "strain.pvd").getroot()
    files = [ds.get("file") for ds in pvd.iter("DataSet")]
    assert len(files) == T
    errors = []
    for t, name in enumerate(files):
        reader = vtkXMLPolyDataReader()
        reader.AddObserver("ErrorEvent", lambda obj, event: errors.append(event))
        reader.GetExecutive().AddObserver("ErrorEvent", lambda obj, event: errors.append(event))
        reader.SetFileName(str(out / name))
        reader.Update()
        mesh = reader.GetOutput()
        assert mesh.GetNumberOfPoints() == 25 and mesh.GetNumberOfCells() == 32
        np.testing.assert_allclose(vtk_to_numpy(mesh.GetPoints().GetData()), points[t], atol=1e-9)
        pd, cd = mesh.GetPointData(), mesh.GetCellData()
        disp = vtk_to_numpy(pd.GetArray("displacement"))
        np.testing.assert_allclose(disp, points[t] - points[0], atol=1e-9)
        np.testing.assert_allclose(vtk_to_numpy(pd.GetArray("Exx")), (lam[0][t] ** 2 - 1) / 2,
                                   atol=1e-9)  # fmt: skip
        for array in ("Eyy", "Exy", "E1", "E2", "J", "max_shear", "visible"):
            assert pd.GetArray(array) is not None, array
        for array in ("Exx", "E1", "valid", "principal_direction_1"):
            assert cd.GetArray(array) is not None, array
        if t > 0:  # the first principal direction is the sheet's first axis, up to sign
            dirs = vtk_to_numpy(pd.GetArray("principal_direction_1"))
            np.testing.assert_allclose(np.abs(dirs @ e1), 1.0, atol=1e-9)
    assert errors == []  # VTK's reader took every file without complaint
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mesh"]["n_triangles"] == 32 and summary["frames"] == T
    assert summary["command"][:2] == ["surface_strain", "compute"] and summary["schema"] == 1
    for name in ("E1_frame0003.png", "strain_over_time.png", "violins_frame0003.png"):
        assert (out / "figures" / name).stat().st_size > 10_000


def test_rigid_motion_of_a_curved_sheet_gives_zero_strain_and_stereo_layout_works(tmp_path):
    u, v = np.meshgrid(np.linspace(-1, 1, 6), np.linspace(-1, 1, 6))
    ref = np.column_stack([u.ravel(), v.ravel(), 0.3 * u.ravel() ** 2]) * 10
    c, s = math.cos(0.3), math.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, c, s], [0, -s, c]])
    points = np.stack([ref, ref @ R.T + [3.0, -2.0, 5.0]])
    visible = np.ones(points.shape[:2], bool)
    visible[1, 7] = False  # a lost point
    src = tmp_path / "rec" / "points3d.csv"
    src.parent.mkdir()
    _write(src, points, visible)
    # the grid comes from a stereo summary beside the points
    (src.parent / "summary.json").write_text(json.dumps({"unit": "mm", "points": {"grid": [6, 6]}}))
    out = tmp_path / "out"
    assert cli("compute", src, "--out", out, "--no-figures", "-q") == 0
    rows = list(csv.DictReader((out / "strain_nodes.csv").read_text().splitlines()))
    E = np.array([[float(r[k]) for k in ("Exx", "Eyy", "Exy")] for r in rows]).reshape(2, 36, 3)
    assert np.isnan(E[1, 7]).all()
    ok = np.isfinite(E[1]).all(axis=1)
    # only nodes whose every triangle touches the lost one lose their value
    from surface_strain.mesh import grid_triangles

    tri = grid_triangles(6, 6)
    orphaned = [i for i in range(36) if all(7 in t for t in tri if i in t)]
    assert set(np.flatnonzero(~ok)) == {7, *orphaned}
    assert np.abs(E[1][ok]).max() < EXACT
    assert json.loads((out / "summary.json").read_text())["mesh"]["method"].startswith("grid 6x6")


def one_line(capsys) -> str:
    """The one error line, after any timestamped progress lines."""
    err = message_lines(capsys.readouterr().err)
    assert len(err) == 1 and "error" in err[0], err
    return err[0]


def test_errors_exit_2_with_one_line(tmp_path, capsys):
    points, *_ = _tilted_sheet_tracks(frames=2)
    src = tmp_path / "p.csv"
    _write(src, points)
    out = tmp_path / "o"
    assert cli("compute", tmp_path / "missing.csv", "--out", out) == 2
    assert "not found" in one_line(capsys)
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,point,X,Y\n0,0,1,2\n")
    assert cli("compute", bad, "--out", out) == 2
    assert "lacks the column" in one_line(capsys)
    assert cli("compute", src, "--grid", "4x4", "--out", out) == 2
    assert "4x4 grid has 16 points" in one_line(capsys)
    assert cli("compute", src, "--directions", "cone:1,2", "--out", out) == 2
    assert "--directions must be" in one_line(capsys)
    assert cli("compute", src, "--directions", "vectors:0,0,1:0,0,2", "--grid", "5x5",
               "--out", out) == 2  # fmt: skip
    one_line(capsys)
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert cli("compute", src, "--out", out, "--overwrite") == 2
    assert "not a result of this toolkit" in one_line(capsys)
    assert [p.name for p in out.iterdir()] == ["notes.txt"]


@pytest.mark.parametrize("fps", ["0", "nan"])
def test_bad_frame_rate(tmp_path, capsys, fps):
    points, *_ = _tilted_sheet_tracks(frames=2)
    src = tmp_path / "p.csv"
    _write(src, points)
    assert cli("compute", src, "--fps", fps, "--out", tmp_path / "o") == 2
    assert "--fps" in one_line(capsys)


def test_scattered_points_on_a_cap_meshed_on_their_sphere(tmp_path):
    rng = np.random.default_rng(0)
    n = 200
    theta = np.arccos(rng.uniform(math.cos(1.3), 1, n))
    phi = rng.uniform(0, 2 * np.pi, n)
    ref = (
        np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
        * 10
    )
    src = tmp_path / "cap.csv"
    _write(src, np.stack([ref, 1.1 * ref]))  # uniform inflation: E = (1.1^2 - 1) / 2
    out = tmp_path / "out"
    assert cli("compute", src, "--projection", "sphere", "--no-figures", "--out", out, "-q") == 0
    rows = list(csv.DictReader((out / "strain_nodes.csv").read_text().splitlines()))
    last = [r for r in rows if r["frame"] == "1"]
    for key in ("E1", "E2"):
        got = np.array([float(r[key]) for r in last])
        assert np.nanmax(np.abs(got - 0.105)) < 1e-9
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mesh"]["method"] == "Delaunay on the best-fit sphere"


def test_a_point_lost_on_the_reference_frame_is_left_out(tmp_path):
    points, *_ = _tilted_sheet_tracks(frames=3)
    visible = np.ones(points.shape[:2], bool)
    visible[:, 12] = False  # the centre point, lost from the start
    src = tmp_path / "p.csv"
    _write(src, points, visible)
    out = tmp_path / "o"
    assert cli("compute", src, "--grid", "5x5", "--no-figures", "--out", out, "-q") == 0
    rows = list(csv.DictReader((out / "strain_nodes.csv").read_text().splitlines()))
    E1 = np.array([float(r["E1"]) for r in rows]).reshape(3, 25)
    assert np.isnan(E1[:, 12]).all()
    assert np.isfinite(np.delete(E1, 12, axis=1)).all()


def test_more_bad_inputs(tmp_path, capsys):
    points, *_ = _tilted_sheet_tracks(frames=2)
    src = tmp_path / "p.csv"
    _write(src, points)
    out = tmp_path / "o"
    assert cli("compute", src, "--grid", "25x1", "--out", out) == 2
    assert "at least 2 x 2" in one_line(capsys)
    tri = tmp_path / "tri.csv"
    tri.write_text("p0,p1,p2\n0,1\n")
    assert cli("compute", src, "--triangles", tri, "--out", out) == 2
    assert "line 2: 2 cells where the header has 3" in one_line(capsys)
    (tmp_path / "summary.json").write_text(json.dumps({"points": 25}))  # not a stereo summary
    assert cli("compute", src, "--no-figures", "--out", out, "-q") == 0
