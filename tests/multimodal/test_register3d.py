"""The microscope's surface onto a stereo run's: 3D landmarks, ICP, and the command."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from multimodal.geometry import SurfaceMap
from multimodal.surface3d import (
    PARAMETERS,
    Similarity3D,
    _rotation,
    closest_points_on_mesh,
    refine_icp,
)
from sample_data_synth.patch import microscope_patch, write_patch
from surface_strain.mesh import grid_triangles
from tests.scenes import SphereCap
from tissue_core.errors import InputError


def _truth() -> Similarity3D:
    return Similarity3D(1e-3, _rotation(np.array([0.3, -0.2, 0.8])), np.array([3.0, -5.0, 450.0]))


def test_landmarks_give_the_similarity_exactly_and_their_residuals():
    rng = np.random.default_rng(0)
    truth = _truth()
    microscope = rng.uniform(0, 2000, (6, 3))
    camera = truth.apply(microscope)
    found, residual = Similarity3D.from_landmarks(microscope, camera)
    np.testing.assert_allclose(found.scale, truth.scale, rtol=1e-12)
    np.testing.assert_allclose(found.rotation, truth.rotation, atol=1e-12)
    np.testing.assert_allclose(found.shift, truth.shift, atol=1e-9)
    assert residual.max() < 1e-9
    np.testing.assert_allclose(found.inverse(camera), microscope, atol=1e-8)
    # a known scale is kept; one pair moved shows in its residual
    moved = camera.copy()
    moved[2] += [0.05, 0.0, 0.0]
    kept, residual = Similarity3D.from_landmarks(microscope, moved, scale=1e-3)
    assert kept.scale == 1e-3 and np.argmax(residual) == 2
    # mirrored: x flipped before the rotation
    mirrored = Similarity3D(1e-3, truth.rotation, truth.shift, mirrored=True)
    found, residual = Similarity3D.from_landmarks(
        microscope, mirrored.apply(microscope), mirrored=True
    )
    assert found.mirrored and residual.max() < 1e-9
    np.testing.assert_allclose(found.rotation, truth.rotation, atol=1e-12)
    again = Similarity3D.from_dict(json.loads(json.dumps(found.as_dict())))
    np.testing.assert_allclose(again.apply(microscope), found.apply(microscope), atol=1e-12)


@pytest.mark.parametrize(
    ("microscope", "message"),
    [
        (np.zeros((2, 3)), "3 landmark pairs or more"),
        (np.column_stack([np.arange(4.0), np.arange(4.0), np.zeros(4)]), "on one line"),
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 0]]), "finite"),
    ],
)
def test_landmarks_that_cannot_register_are_refused(microscope, message):
    camera = np.arange(microscope.size, dtype=float).reshape(-1, 3) ** 1.5
    with pytest.raises(InputError, match=message):
        Similarity3D.from_landmarks(microscope, camera)


def _grid_mesh(f, n=25, half=10.0):
    xs = np.linspace(-half, half, n)
    x, y = np.meshgrid(xs, xs)
    vertices = np.column_stack([x.ravel(), y.ravel(), f(x, y).ravel()])
    return vertices, grid_triangles(n, n)


def test_closest_points_on_a_mesh_match_every_triangle_tried():
    vertices, triangles = _grid_mesh(lambda x, y: 0.05 * (x**2 - y**2) + np.sin(x))
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-12, 12, (400, 2)), rng.uniform(-4, 4, 400)])
    closest, distance, _, outside = closest_points_on_mesh(points, vertices, triangles)
    _, exhaustive, _, _ = closest_points_on_mesh(
        points, vertices, triangles, candidates=len(triangles)
    )
    inner = np.all(np.abs(points[:, :2]) < 9, axis=1)
    np.testing.assert_allclose(distance[inner], exhaustive[inner], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(closest - points, axis=1), distance, atol=1e-12)
    # beyond the mesh's border: outside; well within it and near the surface: not
    beyond = np.all(np.abs(points[:, :2]) > 10.5, axis=1)
    assert outside[beyond].all()
    near = np.all(np.abs(points[:, :2]) < 8, axis=1) & (distance < 0.3)
    assert near.any() and not outside[near].any()


def _bumps(x, y):
    return 1.5 * np.exp(-((x - 2) ** 2 + (y + 1) ** 2) / 4) - np.exp(
        -((x + 3) ** 2 + (y - 2) ** 2) / 6
    )


def test_icp_recovers_every_parameter_where_the_shapes_fix_them():
    """A bumpy surface fixes all seven: a start 2 degrees, 0.3 mm and 3 % off comes back."""
    truth = Similarity3D(1.0, _rotation(np.array([0.1, 0.2, 0.5])), np.array([1.0, 2.0, 3.0]))
    vertices, triangles = _grid_mesh(_bumps, n=121)
    xs = np.linspace(-6, 6, 80)
    x, y = np.meshgrid(xs, xs)
    local = np.column_stack([x.ravel(), y.ravel(), _bumps(x, y).ravel()])
    microscope = (local - truth.shift) @ truth.rotation  # the microscope's frame
    start = Similarity3D(
        1.03,
        _rotation(np.radians([1.5, -1.0, 1.2])) @ truth.rotation,
        truth.shift + np.array([0.3, -0.2, 0.1]),
    )
    found = refine_icp(microscope, vertices, triangles, start)
    assert found.converged and found.fitness > 0.95
    assert all(found.fixed_by_surfaces[k] > 0.9 for k in PARAMETERS)
    error = np.linalg.norm(found.transform.apply(microscope) - local, axis=1)
    assert np.sqrt(np.mean(error**2)) < 2e-3  # the mesh's facets: 0.01 of a grid step
    assert found.rms_after < 0.02 * found.rms_before


def test_icp_on_a_plane_fixes_the_normal_and_tilts_and_keeps_the_landmarks_in_plane():
    """A folded patch of a flat wall: its distance and tilts come from the surfaces; where it
    lies in the plane, its turn and its scale stay the start's (the landmarks')."""
    vertices, triangles = _grid_mesh(lambda x, y: 0 * x, n=9)  # the plane z = 0, mm
    xs = np.linspace(-1500, 1500, 61)
    x, y = np.meshgrid(xs, xs)
    depth = 10 * np.cos(2 * np.pi * x / 170.0)  # folds 20 um high, symmetric about x = 0
    microscope = np.column_stack([x.ravel(), y.ravel(), depth.ravel()])
    # truth: the microscope's axes are the camera's, 1e-3 mm per um; the start is off
    start = Similarity3D(
        1.02e-3, _rotation(np.radians([1.0, -1.5, 3.0])), np.array([0.04, -0.03, 0.05])
    )
    found = refine_icp(microscope, vertices, triangles, start)
    fixed = found.fixed_by_surfaces
    for name in ("shift_normal", "tilt_about_u", "tilt_about_v"):
        assert fixed[name] > 0.99, name
    for name in ("shift_u", "shift_v", "turn_about_normal", "scale"):
        assert fixed[name] < 0.01, name
    t = found.transform
    moved = t.apply(microscope)
    # no tilt left, the folds' mean plane on the camera's plane
    assert abs(t.rotation[2, 2] - 1) < 1e-8
    assert abs(moved[:, 2].mean()) < 1e-8
    # in the plane: the start's scale and turn; its centre moved only by the tilt's removal
    assert t.scale == pytest.approx(start.scale, rel=1e-12)
    turn = math.degrees(math.atan2(t.rotation[1, 0], t.rotation[0, 0]))
    start_turn = math.degrees(math.atan2(start.rotation[1, 0], start.rotation[0, 0]))
    assert turn == pytest.approx(start_turn, abs=0.05)  # less the tilt's removal (2nd order)
    assert abs(turn) > 2.5  # the start's 3 degrees, not the truth's 0
    np.testing.assert_allclose(
        moved[:, :2].mean(axis=0), start.apply(microscope)[:, :2].mean(axis=0), atol=5e-3
    )
    assert np.abs(start.apply(microscope)[:, :2].mean(axis=0)).max() > 0.02  # the start's


def _stereo_run(folder, scene, n=41, half=12.0):
    from tissue_core.tables import write_long_table

    xs = np.linspace(-half, half, n)
    x, y = np.meshgrid(xs, xs)
    points = scene.positions(np.column_stack([x.ravel(), y.ravel()]), 0)[None]
    folder.mkdir()
    write_long_table(
        folder / "points3d.csv",
        {
            **{a: (points[..., k], "%.6f") for k, a in enumerate("XYZ")},
            "visible": (np.ones(points.shape[:2], int), "%d"),
        },
    )
    (folder / "summary.json").write_text(json.dumps({"unit": "mm"}), encoding="utf-8")


def _run(*argv):
    return subprocess.run(
        [sys.executable, "-m", "multimodal", *argv], capture_output=True, text=True, timeout=300
    )


@pytest.mark.xdist_group("register3d")
def test_register3d_puts_the_patch_on_the_stereo_surface(tmp_path):
    scene = SphereCap()
    _stereo_run(tmp_path / "run", scene)
    patch = microscope_patch(scene, center=(4.0, -3.0), landmark_mm=0.05, rng=3)
    files = write_patch(patch, tmp_path / "patch")
    out = tmp_path / "reg"
    done = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--landmarks",
                str(files["landmarks"]), "--out", str(out))  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "fixed by the surfaces: shift_normal" in done.stderr + done.stdout
    record = json.loads((out / "registration.json").read_text())
    found = Similarity3D.from_dict(record["transform"])
    start = Similarity3D.from_dict(record["start"])
    truth = Similarity3D(patch.scale, patch.rotation, patch.shift)
    xs = np.linspace(0, 2000, 21)
    x, y = np.meshgrid(xs, xs)
    grid = np.column_stack([x.ravel(), y.ravel(), np.full(x.size, -180.0)])
    normal = truth.rotation[:, 2]

    def off_normal(t):  # um along the surface's normal, RMS over the patch
        return 1e3 * np.sqrt(np.mean(((t.apply(grid) - truth.apply(grid)) @ normal) ** 2))

    assert off_normal(start) > 10  # 50 um of picking error per axis
    # left: the facets of a 0.6 mm grid below a 60 mm sphere (about 0.7 um), and the
    # landmarks' 6.5 % error of scale on the patch's 17 um of curvature (about 1.1 um)
    assert off_normal(found) < 2.5
    assert record["icp"]["rms_after_um"] < 6.0  # the folds: 15 um peak to peak, 5.3 RMS
    assert record["landmarks"]["pairs"] == 4
    assert "shift_u" in record["icp"]["parameters_not_fixed"]
    for name in ("microscope_surface.vtp", "camera_surface.vtp", "landmarks.csv",
                 "figures/registration3d.png"):  # fmt: skip
        assert (out / name).is_file(), name
    import pyvista as pv

    surface = pv.read(out / "microscope_surface.vtp")
    from multimodal.run import _surface_step  # the mesh multimodal strain draws too

    k = _surface_step(SurfaceMap(patch.height_um, (5.0, 5.0)))
    assert surface.n_points == patch.height_um[::k, ::k].size and surface.n_cells > 0
    above = surface.point_data["above_camera_surface"]
    assert np.nanmax(np.abs(above)) < 0.012  # mm: the folds, 7.5 um each way, and the rest
    assert np.nanmean(above) == pytest.approx(0.0, abs=0.002)
    # a second run does not replace the first without --overwrite; a start from the first's
    # registration.json gives the same transform
    again = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--landmarks",
                 str(files["landmarks"]), "--out", str(out))  # fmt: skip
    assert again.returncode == 2 and "--overwrite" in again.stderr
    inside = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--transform",
                  str(out / "registration.json"), "--out", str(out), "--overwrite")  # fmt: skip
    assert inside.returncode == 2 and "would replace the input" in inside.stderr
    redo = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--transform",
                str(out / "registration.json"), "--out", str(tmp_path / "redo"))  # fmt: skip
    assert redo.returncode == 0, redo.stderr
    second = json.loads((tmp_path / "redo" / "registration.json").read_text())
    np.testing.assert_allclose(
        Similarity3D.from_dict(second["transform"]).apply(grid), found.apply(grid), atol=1e-6
    )


@pytest.mark.xdist_group("register3d")
def test_register3d_bad_input_is_one_line(tmp_path):
    scene = SphereCap()
    _stereo_run(tmp_path / "run", scene)
    files = write_patch(microscope_patch(scene, rng=1), tmp_path / "patch")
    bad = tmp_path / "bad.csv"
    bad.write_text("camera_x,camera_y,microscope_x,microscope_y\n1,2,3,4\n", encoding="utf-8")
    far = tmp_path / "far.csv"
    rows = files["landmarks"].read_text().splitlines()
    far.write_text("\n".join([rows[0], *(r.replace(",4", ",90") for r in rows[1:])]) + "\n")
    cases = [
        ([str(tmp_path), str(files["heightmap"]), "--landmarks", str(files["landmarks"])],
         "no points3d.csv"),
        ([str(tmp_path / "run"), str(files["heightmap"]), "--landmarks", str(bad)], "camera_z"),
        ([str(tmp_path / "run"), str(tmp_path / "none.tif"), "--landmarks", str(bad)], "none.tif"),
        ([str(tmp_path / "run"), str(files["heightmap"]), "--transform", str(bad)], "JSON"),
        ([str(tmp_path / "run"), str(files["heightmap"]), "--landmarks", str(files["landmarks"]),
          "--frame", "3"], "--frame 3"),
        ([str(tmp_path / "run"), str(files["heightmap"]), "--landmarks", str(files["landmarks"]),
          "--scale", "-1"], "--scale"),
    ]  # fmt: skip
    for argv, message in cases:
        done = _run("register3d", *argv, "--out", str(tmp_path / "out"))
        assert done.returncode == 2, (argv, done.stderr)
        assert message in done.stderr, (argv, done.stderr)
        assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


@pytest.mark.xdist_group("register3d")
def test_register3d_flags_what_makes_a_registration_doubtful(tmp_path):
    """Registrations that run but are doubtful say why: a microscope upside down (x and y
    swapped), landmark pairs mismatched, a scale the run's unit does not give."""
    scene = SphereCap()
    _stereo_run(tmp_path / "run", scene)
    files = write_patch(microscope_patch(scene, rng=2), tmp_path / "patch")
    rows = files["landmarks"].read_text().splitlines()
    cells = [r.split(",") for r in rows[1:]]
    swapped = [",".join([*c[:3], c[4], c[3], c[5]]) for c in cells]
    mismatched = [rows[2], rows[1], *rows[3:]]  # the camera side of two pairs exchanged
    mismatched = [",".join(m.split(",")[:3] + c[3:]) for m, c in zip(mismatched, cells,
                                                                       strict=True)]  # fmt: skip
    good = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--landmarks",
                str(files["landmarks"]), "--out", str(tmp_path / "good"))  # fmt: skip
    assert good.returncode == 0 and "flagged: the surfaces' shapes do not fix" in good.stderr
    for name, lines, expected in (
        ("swapped", swapped, "depth points towards the cameras"),
        ("mismatched", mismatched, "the landmarks disagree"),
    ):
        path = tmp_path / f"{name}.csv"
        path.write_text("\n".join([rows[0], *lines]) + "\n", encoding="utf-8")
        done = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--landmarks",
                    str(path), "--out", str(tmp_path / name))  # fmt: skip
        assert done.returncode == 0, done.stderr
        assert expected in done.stderr, (name, done.stderr)
        assert expected not in good.stderr
        record = json.loads((tmp_path / name / "registration.json").read_text())
        assert any(expected in f for f in record["flags"])
    wrong = _run("register3d", str(tmp_path / "run"), str(files["heightmap"]), "--landmarks",
                 str(files["landmarks"]), "--scale", "1e-6", "--out",
                 str(tmp_path / "um"))  # fmt: skip
    assert wrong.returncode == 0 and "where the units make 0.001" in wrong.stderr


@pytest.mark.xdist_group("register3d")
def test_register3d_refuses_landmarks_off_the_map_and_outputs_inside_an_input(tmp_path):
    scene = SphereCap()
    _stereo_run(tmp_path / "run", scene)
    files = write_patch(microscope_patch(scene, rng=2), tmp_path / "patch")
    base = ["register3d", str(tmp_path / "run"), str(files["heightmap"])]
    cases = [
        (["--landmarks", str(files["landmarks"]), "--pixel-um", "2"], "is not on the height map"),
        (["--landmarks", str(files["landmarks"]), "--out", str(tmp_path / "run" / "reg")],
         "inside the input folder"),
        (["--transform", str(files["truth"]), "--scale", "0.001"], "--scale goes with"),
        (["--transform", str(files["truth"]), "--mirrored"], "--mirrored goes with"),
        (["--landmarks", ""], "no such landmarks file"),
    ]  # fmt: skip
    for extra, message in cases:
        out = [] if "--out" in extra else ["--out", str(tmp_path / "out")]
        done = _run(*base, *extra, *out)
        assert done.returncode == 2 and message in done.stderr, (extra, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists() and not (tmp_path / "run" / "reg").exists()
    # the truth's own placement is a start register3d takes
    done = _run(*base, "--transform", str(files["truth"]), "--out", str(tmp_path / "out"))
    assert done.returncode == 0, done.stderr


def test_a_transform_written_with_few_decimals_is_taken_and_bad_ones_are_refused():
    truth = _truth()
    d = truth.as_dict()
    d["rotation"] = np.round(truth.rotation, 5).tolist()
    near = Similarity3D.from_dict(d)
    np.testing.assert_allclose(near.rotation @ near.rotation.T, np.eye(3), atol=1e-12)
    assert np.abs(near.rotation - truth.rotation).max() < 1e-5
    for change, message in (
        ({"mirrored": "false"}, "true or false"),
        ({"scale_per_um": True}, "scale_per_um"),
        ({"scale_per_um": "0.001"}, "scale_per_um"),
        ({"scale_per_um": 1e300}, "not plausible"),
        ({"shift": [0.0, float("nan"), 1.0]}, "finite"),
        ({"rotation": [[1, 0, 0], [0, 1, 0]]}, "rotation"),
    ):
        with pytest.raises(InputError, match=message):
            Similarity3D.from_dict({**truth.as_dict(), **change})
    with pytest.raises(InputError, match="JSON object"):
        Similarity3D.from_dict(None)


def test_folds_the_camera_does_not_see_fix_no_scale():
    """A small field of view with deep folds (400 um, folds 30 um high) on a flat wall: the
    folds are the microscope's alone; fitting the scale to them would flatten them onto the
    camera's plane. The scale stays the start's and ICP converges."""
    vertices, triangles = _grid_mesh(lambda x, y: 0 * x, n=9)  # the plane z = 0, mm
    xs = np.linspace(-200, 200, 81)
    x, y = np.meshgrid(xs, xs)
    microscope = np.column_stack([x.ravel(), y.ravel(), 15 * np.cos(2 * np.pi * x / 90).ravel()])
    start = Similarity3D(
        1.03e-3, _rotation(np.radians([2.0, -1.0, 4.0])), np.array([0.01, 0.02, 0.03])
    )
    found = refine_icp(microscope, vertices, triangles, start)
    assert found.converged
    assert found.transform.scale == pytest.approx(start.scale, rel=1e-12)
    assert found.fixed_by_surfaces["scale"] < 0.01
    assert found.fixed_by_surfaces["shift_normal"] > 0.99
    # the folds' mean plane on the camera's: the folds' RMS is what is left (15 / sqrt 2 um)
    assert found.rms_after * 1e3 == pytest.approx(15 / np.sqrt(2), rel=0.05)
