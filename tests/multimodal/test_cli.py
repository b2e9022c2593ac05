"""``python -m multimodal strain`` on a rendered folding wall, and on bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest

from sample_data_synth.folds import make_folding_wall, write_folding_wall


def _run(*argv, check=True) -> subprocess.CompletedProcess:
    done = subprocess.run(
        [sys.executable, "-m", *argv], capture_output=True, text=True, timeout=300
    )
    if check:
        assert done.returncode == 0, done.stderr
    return done


@pytest.fixture(scope="module", params=["folding", "mixed"])
def wall(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp(request.param)
    case = make_folding_wall(request.param, n_frames=4)
    files = write_folding_wall(case, folder)
    _run(
        "strain2d", "analyze", str(files["video"]), "--grid", "5x5", "--roi",
        "160,160,320,320", "--tracker", "dic", "--animation", "none", "--out",
        str(folder / "run"),
    )  # fmt: skip
    return case, files, folder


@pytest.mark.xdist_group("multimodal_wall")  # each wall rendered and run once, on one worker
def test_the_surface_strain_is_the_true_stretch_where_the_camera_sees_folds(wall):
    case, files, folder = wall
    out = folder / "fold_landmarks"
    _run(
        "multimodal", "strain", str(folder / "run"), "--before", str(files["before"]),
        "--after", str(files["after"]), "--landmarks", str(files["landmarks"]),
        "--out", str(out),
    )  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    true = case.wall.true_strain()
    means = summary["mean_strain"]
    assert summary["coverage"]["on_maps"] == summary["coverage"]["triangles"] == 32
    assert means["projected"]["Exx"] < true[0, 0] - 0.1  # the folds look like contraction
    assert means["fold_aware"]["Exx"] == pytest.approx(true[0, 0], abs=0.01)
    assert means["fold_aware"]["Eyy"] == pytest.approx(true[1, 1], abs=0.01)
    assert means["corrected"]["Exx"] == pytest.approx(true[0, 0], abs=0.02)
    # the registration from hand-picked landmarks, with its residual
    transform = summary["transform"]
    assert transform["from"] == "landmarks" and 0 < transform["residual_um_rms"] < 3
    assert transform["scale_um_per_px"] == pytest.approx(case.camera_um, rel=0.02)
    rows = (out / "fold_strain.csv").read_text().splitlines()
    assert rows[0].startswith("triangle,p0,p1,p2,on_maps,Exx_projected")
    assert len(rows) == 33
    assert (out / "figures" / "fold_strain.png").stat().st_size > 10_000
    assert summary["software"]["name"] == "multimodal"
    # a run like the others: studies load it (frame 1 is the deformed state)
    from strain2d import load_run

    run = load_run(out)
    assert run.n_frames == 2 and run.endpoint == 1
    assert np.nanmean(run.nodal["Exx"][1]) == pytest.approx(true[0, 0], abs=0.01)
    assert np.isfinite(run.nodal["Exx"][1]).all() and (run.nodal["Exx"][0] == 0).all()
    report = (out / "report.html").read_text(encoding="utf-8")
    assert "Fold-aware membrane strain" in report and "data:image/png;base64" in report
    assert [r["path"] for r in summary["inputs"]][2:4] == [str(files["before"]),
                                                          str(files["after"])]  # fmt: skip


@pytest.mark.xdist_group("multimodal_wall")  # each wall rendered and run once, on one worker
def test_a_given_transform_and_a_flat_surface_give_the_camera_strain(wall, tmp_path):
    import tifffile

    _, files, folder = wall
    flat = tmp_path / "flat.tif"
    tifffile.imwrite(flat, np.zeros((480, 480), np.float32), imagej=True,
                     resolution=(1 / 3.0, 1 / 3.0), metadata={"unit": "um"})  # fmt: skip
    out = tmp_path / "flat_run"
    _run(
        "multimodal", "strain", str(folder / "run"), "--before", str(flat), "--after",
        str(flat), "--transform", str(files["transform"]), "--out", str(out),
    )  # fmt: skip
    summary = json.loads((out / "summary.json").read_text())
    means = summary["mean_strain"]
    for c in ("Exx", "Eyy", "Exy"):
        assert means["fold_aware"][c] == pytest.approx(means["projected"][c], abs=1e-9)
        assert means["corrected"][c] == pytest.approx(means["projected"][c], abs=1e-9)


BAD = [
    (["--before", "missing.tif"], "does not exist"),
    (["--transform", "1,2,3"], "SCALE,ANGLE,SHIFT_X,SHIFT_Y"),
    (["--transform", "0,0,0,0"], "scale must be positive"),
    (["--frame", "0"], "outside the run's frames"),
    (["--frame", "99"], "outside the run's frames"),
    (["--landmarks", "bad_landmarks.csv"], "needs a header with columns camera_x"),
    (["--before", "nopixel.tif"], "pixel size is unknown"),
    (["--before", "huge.tif"], "over a metre"),
]


@pytest.mark.parametrize("extra, message", BAD)
@pytest.mark.xdist_group("multimodal_wall")  # each wall rendered and run once, on one worker
def test_bad_input_ends_with_one_line(wall, tmp_path, extra, message):
    import tifffile

    _, files, folder = wall
    (tmp_path / "bad_landmarks.csv").write_text("x,y\n1,2\n")
    tifffile.imwrite(tmp_path / "nopixel.tif", np.zeros((20, 20), np.float32))
    huge = np.zeros((20, 20), np.float32)
    huge[3, 4] = 1e30
    tifffile.imwrite(tmp_path / "huge.tif", huge, imagej=True, resolution=(1 / 3.0, 1 / 3.0),
                     metadata={"unit": "um"})  # fmt: skip
    options = {"--before": str(files["before"]), "--after": str(files["after"]),
               "--transform": str(files["transform"])}  # fmt: skip
    given = dict(zip(extra[::2], extra[1::2], strict=True))
    if "--landmarks" in given:
        options.pop("--transform")
    for key, value in given.items():
        path = tmp_path / value
        options[key] = str(path) if key != "--frame" and path.exists() else value
    if options.get("--before") == "missing.tif":
        options["--before"] = str(tmp_path / "missing.tif")
    argv = [a for kv in options.items() for a in kv]
    done = _run(
        "multimodal", "strain", str(folder / "run"), *argv, "--out", str(tmp_path / "o"),
        check=False,
    )  # fmt: skip
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "o").exists()


def test_the_whole_chain_from_stacks_through_mpm3d(tmp_path):
    """The height maps measured by ``mpm3d analyze`` on rendered z-stacks, not given: the
    fold-aware strain is as close to the truth as mpm3d's surfaces allow (their steep fold
    walls come out a little smoother than the true ones: 0.009 here against 0.002 with
    the exact maps)."""
    from sample_data_synth.folds import folding_wall_stacks
    from sample_data_synth.stacks import write_stack

    case = make_folding_wall("mixed", n_frames=4, microscope_px=300)
    files = write_folding_wall(case, tmp_path)
    for stack in folding_wall_stacks(case):
        write_stack(tmp_path / f"{stack.params['state']}_stack.tif", stack)
        state = stack.params["state"]
        # the height maps and the surface's intensity are what multimodal reads: no mesh
        _run("mpm3d", "-q", "analyze", str(tmp_path / f"{state}_stack.tif"), "--no-figures",
             "--no-surface", "--out", str(tmp_path / f"mpm_{state}"))  # fmt: skip
    _run(
        "strain2d", "-q", "analyze", str(files["video"]), "--grid", "5x5", "--roi",
        "185,185,295,295", "--tracker", "dic", "--animation", "none", "--out",
        str(tmp_path / "run"),
    )  # fmt: skip
    # registered from mpm3d's surface-intensity projection against the camera's frame
    _run("multimodal", "-q", "register", str(files["video"]), str(tmp_path / "mpm_before"),
         "--out", str(tmp_path / "reg"))  # fmt: skip
    found = json.loads((tmp_path / "reg" / "transform.json").read_text())
    assert found["scale_um_per_px"] == pytest.approx(case.camera_um, rel=0.005)
    assert found["angle_deg"] == pytest.approx(case.transform["angle_deg"], abs=0.5)
    _run(
        "multimodal", "-q", "strain", str(tmp_path / "run"), "--before",
        str(tmp_path / "mpm_before"), "--after", str(tmp_path / "mpm_after"), "--transform",
        str(tmp_path / "reg" / "transform.json"), "--out", str(tmp_path / "fold"),
    )  # fmt: skip
    summary = json.loads((tmp_path / "fold" / "summary.json").read_text())
    true = case.wall.true_strain()
    means = summary["mean_strain"]
    assert summary["coverage"]["on_maps"] == 32
    assert summary["coverage"]["filled_share_mean"] < 0.05  # mpm3d measured nearly all
    assert means["projected"]["Exx"] < -0.2
    assert means["fold_aware"]["Exx"] == pytest.approx(true[0, 0], abs=0.015)
    assert means["fold_aware"]["Eyy"] == pytest.approx(true[1, 1], abs=0.005)
    for name in ("mesh_before.vtp", "mesh_after.vtp", "surface_before.vtp", "surface_after.vtp"):
        assert (tmp_path / "fold" / name).stat().st_size > 1000


def test_register_finds_the_known_similarity(tmp_path):
    case = make_folding_wall("mixed", n_frames=2)
    files = write_folding_wall(case, tmp_path / "wall")
    out = tmp_path / "reg"
    _run("multimodal", "-q", "register", str(files["video"]), str(files["surface"]), "--out",
         str(out))  # fmt: skip
    found = json.loads((out / "transform.json").read_text())
    true = case.transform
    assert found["scale_um_per_px"] == pytest.approx(true["scale_um_per_px"], rel=0.005)
    assert found["angle_deg"] == pytest.approx(true["angle_deg"], abs=0.5)
    # the shift, as where the camera's centre lands, in camera pixels
    from multimodal import Similarity

    def similarity(d):
        return Similarity(d["scale_um_per_px"], d["angle_deg"], tuple(d["shift_um"]))

    centre = np.array([[240.0, 240.0], [180.0, 300.0]])
    moved = similarity(found).apply(centre) - similarity(true).apply(centre)
    assert np.hypot(*moved.T).max() / true["scale_um_per_px"] < 2.0
    assert found["inliers"] >= 100 and 0 < found["residual_um_rms"] < 3
    # its matches are landmark pairs, and its transform a --transform
    rows = (out / "matches.csv").read_text().splitlines()
    assert rows[0] == "camera_x,camera_y,microscope_x,microscope_y,residual_um"
    assert len(rows) == found["inliers"] + 1
    assert (out / "figures" / "registration.png").stat().st_size > 10_000


def test_register_mirrored_and_refused():
    from multimodal import Similarity
    from multimodal.registration import register_images
    from tissue_core.errors import InputError

    case = make_folding_wall("oblique", n_frames=2)
    true = Similarity(case.transform["scale_um_per_px"], case.transform["angle_deg"],
                      tuple(case.transform["shift_um"]))  # fmt: skip
    flipped = case.frames[0][::-1]
    found = register_images(flipped, case.surface_image, case.microscope_um, mirrored=True)
    points = np.array([[200.0, 200.0], [280.0, 260.0]])
    rows = np.column_stack([points[:, 0], flipped.shape[0] - 1 - points[:, 1]])
    moved = found.transform.apply(rows) - true.apply(points)
    assert np.hypot(*moved.T).max() / true.scale < 2.0
    noise = np.random.default_rng(0).normal(100, 20, case.surface_image.shape)
    with pytest.raises(InputError, match="could not register"):
        register_images(case.frames[0], noise, case.microscope_um)
    with pytest.raises(InputError, match="uniform"):
        register_images(case.frames[0], np.zeros((50, 50)), 1.0)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d: d / "none.tif", "does not exist"),
        (lambda d: _uncalibrated(d), "pixel size is unknown"),
    ],
)
def test_register_bad_input_ends_with_one_line(tmp_path, make, message):
    case = make_folding_wall("mixed", n_frames=2, size=240, microscope_px=120)
    files = write_folding_wall(case, tmp_path / "wall")
    done = _run("multimodal", "register", str(files["video"]), str(make(tmp_path)), "--out",
                str(tmp_path / "o"), check=False)  # fmt: skip
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert not (tmp_path / "o").exists()


def _uncalibrated(folder):
    import tifffile

    tifffile.imwrite(folder / "plain.tif", np.zeros((40, 40), np.uint8))
    return folder / "plain.tif"


@pytest.mark.xdist_group("multimodal_wall")  # each wall rendered and run once, on one worker
def test_more_bad_input_ends_with_one_line(wall, tmp_path):
    """What a hostile-input review found: each one line, exit status 2, no folder."""
    import shutil

    _, files, folder = wall
    maps = ["--before", str(files["before"]), "--after", str(files["after"])]
    (tmp_path / "mirrored.json").write_text(
        '{"scale_um_per_px": 6, "angle_deg": -12, "shift_um": [0, 0], "mirrored": "false"}'
    )
    (tmp_path / "self.csv").write_text("file,x_um,y_um\nself.csv,0,0\n")
    mm = files["landmarks"].read_text().splitlines()
    rows = [mm[0]] + [",".join(f"{float(v) / (1000 if k > 1 else 1):.9f}"
                               for k, v in enumerate(r.split(","))) for r in mm[1:]]  # fmt: skip
    (tmp_path / "mm.csv").write_text("\n".join(rows) + "\n")
    edited = tmp_path / "edited_run"
    shutil.copytree(folder / "run", edited)
    elements = (edited / "strain_elements.csv").read_text().splitlines()
    cells = elements[1].split(",")
    cells[2] = "999"
    elements[1] = ",".join(cells)
    (edited / "strain_elements.csv").write_text("\n".join(elements) + "\n")
    cases = [
        ([str(folder / "run"), *maps, "--transform", str(tmp_path / "mirrored.json")],
         "mirrored must be true or false"),
        ([str(folder / "run"), "--before", str(tmp_path / "self.csv"), "--after",
          str(files["after"]), "--transform", str(files["transform"])], "a mosaic itself"),
        ([str(folder / "run"), *maps, "--landmarks", str(tmp_path / "mm.csv")],
         "um per camera pixel"),
        ([str(edited), *maps, "--transform", str(files["transform"])], "outside 0.."),
    ]  # fmt: skip
    for argv, message in cases:
        out = tmp_path / "o"
        done = _run("multimodal", "strain", *argv, "--out", str(out), check=False)
        assert done.returncode == 2, (argv, done.stderr)
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and message in lines[0], done.stderr
        assert not out.exists()


@pytest.mark.xdist_group("multimodal_wall")  # each wall rendered and run once, on one worker
def test_a_grid_off_the_maps_is_flagged_not_a_crash(wall, tmp_path):
    _, files, folder = wall
    out = tmp_path / "off"
    done = _run(
        "multimodal", "strain", str(folder / "run"), "--before", str(files["before"]),
        "--after", str(files["after"]), "--transform", "6,-12,100000,100000", "--out", str(out),
    )  # fmt: skip
    assert "Traceback" not in done.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["coverage"]["on_maps"] == 0
    assert summary["mean_strain"]["fold_aware"]["Exx"] is None
    assert any("No triangle lies on both height maps" in f for f in summary["flags"])
    assert summary["mean_strain"]["corrected"]["Exx"] is not None


@pytest.mark.xdist_group("multimodal_wall")  # each wall rendered and run once, on one worker
@pytest.mark.parametrize(
    ("tilt_deg", "tolerance"),
    # tilted, the nodes' coordinates are not the 2D run's digits: the tables' 6 decimals
    [(0.0, 1e-9), (35.0, 1e-7)],
)
def test_a_flat_stereo_run_registered_in_3d_gives_the_2d_runs_strain(
    wall, tmp_path, tilt_deg, tolerance
):
    """The wall's camera run lifted into 3D (its plane facing the cameras at z = 450, or
    tilted 35 degrees; the camera's pixels as its units) and registered by the 3D similarity
    equal to the landmarks' 2D one: every triangle's strain, projected and along the
    surface, is the 2D run's, in the microscope's axes (a stereo run has no camera x-y to
    give them in)."""
    from multimodal.geometry import Similarity
    from multimodal.io import read_landmarks
    from multimodal.surface3d import Similarity3D
    from strain2d import load_run
    from surface_strain import Mesh
    from surface_strain import write_run as write_3d_run

    _, files, folder = wall
    flat = load_run(folder / "run")
    triangles = np.loadtxt(folder / "run" / "strain_elements.csv", delimiter=",", skiprows=1,
                           usecols=(2, 3, 4), dtype=int)  # fmt: skip
    header = (folder / "run" / "strain_elements.csv").read_text().splitlines()[0].split(",")
    assert header[:5] == ["frame", "triangle", "p0", "p1", "p2"]
    triangles = triangles[: len(triangles) // flat.n_frames]
    # the wall's plane in the cameras' frame: px (x, y, 0) -> W @ p + w
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2)
    W = Similarity3D(1.0, np.eye(3), np.zeros(3)).rotation
    if tilt_deg:
        from multimodal.surface3d import _rotation

        W = _rotation(np.radians(tilt_deg) * axis)
    w = np.array([10.0, -20.0, 450.0])
    on_plane = np.concatenate([flat.positions, np.zeros((*flat.positions.shape[:2], 1))], -1)
    points = on_plane @ W.T + w
    stereo = tmp_path / "stereo"
    (stereo / "strain").mkdir(parents=True)
    write_3d_run(stereo / "strain", points, flat.visible, Mesh(triangles, "grid", "grid"),
                 unit="px", figures=False)  # fmt: skip
    s2, _ = Similarity.from_landmarks(*read_landmarks(files["landmarks"]))
    # microscope (x, y, depth) -> px: the inverse of s2 in x-y, depth / scale off the plane;
    # then onto the cameras' plane
    a = np.radians(s2.angle_deg)
    inverse_turn = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
    B = np.eye(3)
    B[:2, :2] = inverse_turn
    k = 1.0 / s2.scale
    shift = w - k * W @ np.array([*(inverse_turn @ np.asarray(s2.shift_um)), 0.0])
    registration = {"transform": Similarity3D(k, W @ B, shift).as_dict()}
    (tmp_path / "registration.json").write_text(json.dumps(registration), encoding="utf-8")
    # chords: the geodesic paths are found to a tolerance, about 1e-8 of strain
    common = ["--before", str(files["before"]), "--after", str(files["after"]), "--frame",
              str(flat.n_frames - 1), "--path", "chord"]  # fmt: skip
    _run("multimodal", "strain", str(folder / "run"), *common, "--transform",
         f"{s2.scale},{s2.angle_deg},{s2.shift_um[0]},{s2.shift_um[1]}",
         "--out", str(tmp_path / "two"))  # fmt: skip
    done = _run("multimodal", "strain", str(stereo), *common, "--transform",
                str(tmp_path / "registration.json"), "--out", str(tmp_path / "three"))  # fmt: skip
    assert "registered in 3D" in done.stderr + done.stdout
    two = np.genfromtxt(tmp_path / "two" / "fold_strain.csv", delimiter=",", names=True)
    three = np.genfromtxt(tmp_path / "three" / "fold_strain.csv", delimiter=",", names=True)
    turn = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])  # camera -> microscope

    def tensors(table, kind):
        xx, yy, xy = (table[f"E{c}_{kind}"] for c in ("xx", "yy", "xy"))
        return np.stack([np.stack([xx, xy], -1), np.stack([xy, yy], -1)], -2)

    for kind in ("projected", "surface", "corrected"):
        E2, E3 = tensors(two, kind), tensors(three, kind)
        assert np.isfinite(E2).all(axis=(1, 2)).sum() > 20, kind
        if kind == "surface":  # its frame's first axis lies over the other x: the two
            # frames differ by a turn within the tangent plane, close to the maps' turn
            np.testing.assert_allclose(np.trace(E3, axis1=1, axis2=2),
                                       np.trace(E2, axis1=1, axis2=2), atol=tolerance)  # fmt: skip
            z2 = (E2[:, 0, 0] - E2[:, 1, 1]) / 2 + 1j * E2[:, 0, 1]  # turns by twice the angle
            z3 = (E3[:, 0, 0] - E3[:, 1, 1]) / 2 + 1j * E3[:, 0, 1]
            np.testing.assert_allclose(np.abs(z3), np.abs(z2), atol=tolerance, err_msg=kind)
            big = np.abs(z2) > 1e-4
            assert big.sum() > 10
            turned = np.degrees(np.angle(z3[big] / z2[big])) / 2
            off = (turned - s2.angle_deg + 90) % 180 - 90
            assert np.abs(off).max() < 3, off  # an axis or a sign of Exy wrong: far off
        else:
            np.testing.assert_allclose(E3, turn @ E2 @ turn.T, atol=tolerance, err_msg=kind)
    summary = json.loads((tmp_path / "three" / "summary.json").read_text())
    assert summary["transform"]["from"] == "the 3D registration"
    assert summary["registration_3d"]["before"]["scale_per_um"] == pytest.approx(k)
    assert summary["units"]["camera"].startswith("um")
    # a 3D run refuses a 2D transform and landmarks, in one line
    elsewhere = tmp_path / "frame3.json"
    elsewhere.write_text(json.dumps({**registration, "frame": 3}), encoding="utf-8")
    for extra, message in (
        (["--transform", "6,-12,0,0"], "3D registration"),
        (["--landmarks", str(files["landmarks"])], "register3d first"),
        (["--transform", str(elsewhere)], "made on the run's frame 3, not 0"),
    ):
        done = _run("multimodal", "strain", str(stereo), *common, *extra, "--out",
                    str(tmp_path / "bad"), check=False)  # fmt: skip
        assert done.returncode == 2 and message in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1
