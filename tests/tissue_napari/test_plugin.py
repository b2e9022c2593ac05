"""The napari plugin, headless: readers, the strain widget from a drawn region to strain
layers (checked against the command line's run folder), cancel, bad input, the MPM widget."""

from __future__ import annotations

import csv
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sample_data_synth import make_case, make_stack_case, write_stack, write_video
from tissue_napari.readers import get_reader, read_path

#: ms a run through a widget may take (a child process: interpreter, tracking, figures)
RUN_MS = 180_000


@pytest.fixture(scope="module")
def video(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("napari_video")
    path = folder / "stretch.avi"
    write_video(make_case("equibiaxial", size=240, n_frames=8, rng=3).frames, path)
    return path


@pytest.fixture(scope="module")
def demo_video(tmp_path_factory) -> Path:
    """The demo's case (equibiaxial stretch to 1.5), made by ``sample_data_synth video`` as
    ``make demo`` makes it, at 400 x 400 px and 16 frames (a quarter of the demo's pixels
    and half its frames: the suite's time)."""
    folder = tmp_path_factory.mktemp("napari_demo")
    command = ["sample_data_synth", "video", "--case", "equibiaxial", "--formats", "avi",
               "--size", "400", "--frames", "16", "--out", str(folder / "data"), "-q"]  # fmt: skip
    subprocess.run([sys.executable, "-m", *command], check=True)
    return folder / "data" / "equibiaxial.avi"


@pytest.fixture(scope="module")
def run_folder(video, tmp_path_factory) -> Path:
    """A ``strain2d analyze`` run of the small video (4 x 4 grid, the default tracker)."""
    out = tmp_path_factory.mktemp("napari_run") / "run"
    command = ["strain2d", "analyze", str(video), "--grid", "4x4", "--roi", "61,61,178,178",
               "--out", str(out), "-q", "--animation", "none"]  # fmt: skip
    subprocess.run([sys.executable, "-m", *command], check=True)
    return out


def _nodes(folder: Path) -> dict[str, np.ndarray]:
    with open(folder / "strain_nodes.csv", newline="", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))]
    keys = ("frame", "point", "visible", "Exx", "Eyy")
    return {k: np.array([float(r[k]) for r in rows]) for k in keys}


def _viewer_with(make_napari_viewer, path: Path):
    from tissue_napari.widgets import add_layers

    viewer = make_napari_viewer()
    add_layers(viewer, read_path(str(path)))
    return viewer


# ----------------------------------------------------------------------------- readers


def test_readers_claim_what_they_read(video, tmp_path):
    assert get_reader(str(video)) is not None
    assert get_reader(str(tmp_path)) is None  # an empty folder
    assert get_reader(str(tmp_path / "notes.txt")) is None
    (frames, kwargs, kind), *_ = read_path(str(video))
    assert kind == "image" and frames.shape == (8, 240, 240)
    assert kwargs["metadata"]["source"] == str(video)


def test_a_stack_opens_with_its_voxel_size(tmp_path):
    case = make_stack_case("before", size=48, spacing=(4.0, 2.5, 2.5), rng=0)
    write_stack(tmp_path / "s.tif", case)
    layers = read_path(str(tmp_path / "s.tif"))
    assert [kind for *_, kind in layers] == ["image", "image"]  # one per channel
    data, kwargs, _ = layers[0]
    assert data.shape == case.stack[:, 0].shape
    assert kwargs["scale"] == (4.0, 2.5, 2.5)


@pytest.mark.xdist_group("napari_small_run")  # the run made once, on one worker
def test_a_run_folder_opens_as_tracks_nodes_and_mesh(run_folder):
    """The nodes carry every strain component of strain_nodes.csv as features, frame by
    frame; the mesh has one copy per frame coloured by Exx."""
    out = run_folder
    layers = {kind: (data, kwargs) for data, kwargs, kind in read_path(str(out))}
    assert set(layers) == {"tracks", "points", "surface"}
    nodes = _nodes(out)
    points, kwargs = layers["points"]
    seen = nodes["visible"] == 1
    assert len(nodes["Exx"]) == 8 * 16 and seen.sum() >= 0.9 * len(seen)
    assert len(points) == seen.sum()  # a lost point is not drawn
    assert np.allclose(kwargs["features"]["Exx"], nodes["Exx"][seen], equal_nan=True)
    assert np.array_equal(points[:, 0], nodes["frame"][seen])
    vertices, faces, values = layers["surface"][0]
    assert vertices.shape == (8 * 16, 3) and len(faces) == 8 * 18  # 2 triangles a cell
    assert np.allclose(values, np.nan_to_num(nodes["Exx"]))


# ----------------------------------------------------------------------------- widget


@pytest.mark.xdist_group("napari_demo_video")  # rendered once, on one worker
def test_strain_widget_runs_a_drawn_region_like_the_command_line(
    make_napari_viewer, qtbot, demo_video, tmp_path
):
    """On the demo's case: a rectangle drawn (the demo's region), a 5 x 5 grid, the
    default tracker: the widget's run folder is the one the command it shows makes, and
    its layers carry that strain."""
    from tissue_napari.widgets import StrainWidget

    viewer = _viewer_with(make_napari_viewer, demo_video)
    corners = np.array([[0, 101, 101], [0, 101, 298], [0, 298, 298], [0, 298, 101]])
    viewer.add_shapes([corners], shape_type="rectangle", name="region")
    widget = StrainWidget(viewer)
    assert widget.tracker.currentText() == "gdic"  # the default, from the registry
    widget.region.setCurrentText("region")
    widget.grid.setText("5x5")
    out = tmp_path / "widget_run"
    widget.out.setText(str(out))
    widget.preview()
    assert len(viewer.layers["grid preview"].data) == 25
    assert widget.run()
    qtbot.waitUntil(lambda: widget.last_status in ("done", "failed"), timeout=RUN_MS)
    assert widget.last_status == "done", widget.status.text()
    shown = shlex.split(widget.command_line.text())
    assert shown[:4] == ["python", "-m", "strain2d", "analyze"]
    assert "--roi" in shown and shown[shown.index("--roi") + 1] == "101.0,101.0,298.0,298.0"
    # the same command typed by hand, into another folder
    typed = shown[2:]
    typed[typed.index("--out") + 1] = str(tmp_path / "typed_run")
    subprocess.run([sys.executable, "-m", *typed, "-q"], check=True)
    by_hand, by_widget = _nodes(tmp_path / "typed_run"), _nodes(out)
    for key in by_hand:
        assert np.array_equal(by_hand[key], by_widget[key], equal_nan=True), key
    nodes = viewer.layers["widget_run nodes (Exx)"]
    seen = by_hand["visible"] == 1
    assert seen.all()  # the default keeps every point of the demo
    assert np.allclose(nodes.features["Exx"], by_hand["Exx"], equal_nan=True)
    last = by_hand["frame"] == 15  # the demo's stretch: Exx = (1.5^2 - 1) / 2 = 0.625
    assert np.allclose(by_hand["Exx"][last], 0.625, atol=0.005)
    assert "widget_run mesh (Exx)" in viewer.layers
    assert "results in" in widget.status.text()


def test_strain_widget_options_come_from_the_tracker_registry(make_napari_viewer):
    from strain2d.trackers import get_tracker
    from tissue_napari.widgets import StrainWidget

    widget = StrainWidget(make_napari_viewer())
    for name in ("klt", "dic", "gdic"):
        widget.tracker.setCurrentText(name)
        flags = {o.flag for o in get_tracker(name).options if not o.is_file}
        assert set(widget.option_fields) == flags


@pytest.mark.xdist_group("napari_demo_video")
def test_cancel_leaves_no_folder(make_napari_viewer, qtbot, demo_video, tmp_path):
    from tissue_napari.widgets import StrainWidget

    viewer = _viewer_with(make_napari_viewer, demo_video)
    widget = StrainWidget(viewer)
    widget.grid.setText("9x9")
    out = tmp_path / "cancelled"
    widget.out.setText(str(out))
    assert widget.run()
    qtbot.waitUntil(lambda: "tracking" in widget.status.text(), timeout=RUN_MS)
    widget.cancel_button.click()
    qtbot.waitUntil(lambda: widget.last_status != "running", timeout=RUN_MS)
    assert widget.last_status == "cancelled"
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no scratch left beside it
    assert widget.run_button.isEnabled() and not widget.cancel_button.isEnabled()


@pytest.mark.parametrize(
    ("setup", "message"),
    [
        (lambda w, tmp: None, "choose an output folder"),
        (lambda w, tmp: w.grid.setText("seven"), "grid"),
        (lambda w, tmp: w.video_path.setText(str(tmp / "missing.avi")), "no such video"),
        (lambda w, tmp: w.option_fields["--subset"].setText("huge"), "--subset"),
    ],
)
def test_bad_input_is_a_message_not_a_crash(make_napari_viewer, video, tmp_path, setup, message):
    from tissue_napari.widgets import StrainWidget

    viewer = _viewer_with(make_napari_viewer, video)
    widget = StrainWidget(viewer)
    if message != "choose an output folder":
        widget.out.setText(str(tmp_path / "out"))
    setup(widget, tmp_path)
    assert not widget.run()
    assert message in widget.status.text()
    assert widget.last_status == "refused" and not widget.runner.running
    assert not (tmp_path / "out").exists()


def test_a_failing_command_says_why(make_napari_viewer, qtbot, tmp_path):
    """A file that is no video: the command's own error line, the viewer alive."""
    from tissue_napari.widgets import StrainWidget

    bad = tmp_path / "broken.avi"
    bad.write_bytes(b"not a video at all")
    widget = StrainWidget(make_napari_viewer())
    widget.video_path.setText(str(bad))
    widget.out.setText(str(tmp_path / "out"))
    widget._frame_shape = lambda source: (240, 240)  # the run itself must find it out
    assert widget.run()
    qtbot.waitUntil(lambda: widget.last_status != "running", timeout=RUN_MS)
    assert widget.last_status == "failed"
    assert "broken.avi" in widget.status.text()
    assert not (tmp_path / "out").exists()


def test_mpm_widget_shows_the_surface_and_the_metrics(make_napari_viewer, qtbot, tmp_path):
    from tissue_napari.widgets import MpmWidget

    case = make_stack_case("after", size=96, spacing=(4.0, 5.0, 5.0), rng=1)
    write_stack(tmp_path / "after.tif", case)
    viewer = make_napari_viewer()
    widget = MpmWidget(viewer)
    widget.stack.setText(str(tmp_path / "after.tif"))
    widget.out.setText(str(tmp_path / "mpm"))
    assert widget.run()
    qtbot.waitUntil(lambda: widget.last_status != "running", timeout=RUN_MS)
    assert widget.last_status == "done", widget.status.text()
    import json

    metrics = json.loads((tmp_path / "mpm" / "metrics.json").read_text(encoding="utf-8"))
    table = {widget.table.item(r, 0).text(): widget.table.item(r, 1).text()
             for r in range(widget.table.rowCount())}  # fmt: skip
    assert table["Sq (um)"] == f"{metrics['Sq_um']:.4g}"
    height = viewer.layers["mpm height (um)"]
    assert tuple(height.scale) == (5.0, 5.0)
    assert "mpm surface" in viewer.layers


def test_points3d_and_multimodal_folders_open(tmp_path):
    """A stereo points3d.csv: the visible points over time in (t, z, y, x); a multimodal
    run's surfaces and the camera's mesh coloured by its Exx along the surface."""
    import pyvista as pv

    rows = ["frame,point,X,Y,Z,reproj_error,visible"]
    for t in range(3):
        for k in range(4):
            visible = 0 if (t, k) == (2, 3) else 1
            rows.append(f"{t},{k},{k * 1.0},{2.0 + t},{10.0 + k},0.1,{visible}")
    (tmp_path / "points3d.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    layers = read_path(str(tmp_path / "points3d.csv"))
    (points, _, kind), (tracks, _, kind2) = layers
    assert (kind, kind2) == ("points", "tracks")
    assert np.array_equal(np.unique(tracks[:, 0]), [0, 1, 2, 3])  # one track per point
    assert points.shape == (11, 4)  # the lost point left out
    assert np.array_equal(points[5], [1.0, 11.0, 3.0, 1.0])  # frame 1, point 1: t, Z, Y, X

    run = tmp_path / "fold"
    run.mkdir()
    (run / "fold_strain.csv").write_text("triangle,Exx_surface\n0,0.1\n", encoding="utf-8")
    grid = pv.Plane(i_resolution=3, j_resolution=3).triangulate()
    surface = grid.copy()
    surface.point_data["height_um"] = np.arange(surface.n_points, dtype=float)
    surface.save(run / "surface_before.vtp")
    mesh = grid.copy()  # as multimodal writes it: each triangle's strains as cell data
    mesh.cell_data["Exx_surface"] = np.linspace(-0.1, 0.1, mesh.n_cells)
    mesh.save(run / "mesh_after.vtp")
    layers = {kwargs["name"]: data for data, kwargs, _ in read_path(str(run))}
    assert set(layers) == {"fold surface before", "fold mesh after"}
    vertices, faces, values = layers["fold mesh after"]
    assert len(faces) == grid.n_cells and len(vertices) == 3 * grid.n_cells
    # each triangle flat in its own value
    assert np.allclose(values[faces], mesh.cell_data["Exx_surface"][:, None])
    assert np.allclose(vertices[faces[4]], np.asarray(grid.points)[grid.regular_faces[4]][:, ::-1])


def test_regions_follow_the_layers(make_napari_viewer, video, tmp_path):
    """A polygon previews without writing anything; a renamed layer stays the region; a
    labels layer painted on a later frame is the mask; a scaled shapes layer lands where
    it is seen; switches start off."""
    from tissue_napari.widgets import StrainWidget

    viewer = _viewer_with(make_napari_viewer, video)
    polygon = np.array([[0, 60, 60], [0, 60, 180], [0, 180, 120]])
    shapes = viewer.add_shapes([polygon], shape_type="polygon", name="outline")
    widget = StrainWidget(viewer)
    widget.region.setCurrentText("outline")
    widget.grid.setText("9x9")
    widget.out.setText(str(tmp_path / "run"))
    widget.preview()
    kept = len(viewer.layers["grid preview"].data)
    assert 0 < kept < 81  # the triangle keeps part of the grid
    assert list(tmp_path.iterdir()) == []  # a preview writes nothing
    argv = widget.command()
    assert argv[argv.index("--mask") + 1] == str(tmp_path / "run_region.csv")
    shapes.name = "tissue"
    assert widget.region.currentText() == "tissue"  # renamed, still chosen
    labels = np.zeros((8, 240, 240), np.uint8)
    labels[3, 50:150, 70:190] = 1  # painted on frame 3 only
    viewer.add_labels(labels, name="painted")
    widget.region.setCurrentText("painted")
    kind, mask = widget.drawn_region((240, 240))
    assert kind == "mask" and mask.sum() == 100 * 120
    rect = np.array([[0, 30, 30], [0, 30, 90], [0, 90, 90], [0, 90, 30]])
    viewer.add_shapes([rect], shape_type="rectangle", name="scaled", scale=(1, 2, 2))
    widget.region.setCurrentText("scaled")
    assert widget.drawn_region((240, 240)) == ("roi", (60.0, 60.0, 180.0, 180.0))
    widget.tracker.setCurrentText("cotracker3")
    switches = [f for f in widget.option_fields.values() if hasattr(f, "isChecked")]
    assert switches and not any(f.isChecked() for f in switches)


def test_a_refused_run_leaves_no_region_file(make_napari_viewer, qtbot, video, tmp_path):
    """The region's polygon is written for the run and removed when the run fails (here:
    the output folder exists and is not a result)."""
    from tissue_napari.widgets import StrainWidget

    viewer = _viewer_with(make_napari_viewer, video)
    viewer.add_shapes([np.array([[0, 60, 60], [0, 60, 180], [0, 180, 120]])],
                      shape_type="polygon", name="outline")  # fmt: skip
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("the user's", encoding="utf-8")
    widget = StrainWidget(viewer)
    widget.region.setCurrentText("outline")
    widget.out.setText(str(tmp_path / "mine"))
    assert widget.run()
    qtbot.waitUntil(lambda: widget.last_status != "running", timeout=RUN_MS)
    assert widget.last_status == "failed"
    assert "exists" in widget.status.text()
    assert not (tmp_path / "mine_region.csv").exists()
    assert (tmp_path / "mine" / "notes.txt").read_text(encoding="utf-8") == "the user's"


@pytest.mark.xdist_group("napari_small_run")
def test_run_numbers_show_the_selected_runs_report(make_napari_viewer, video, run_folder):
    """Selecting a layer of a run shows the numbers its report opens with (from the run's
    summary.json); a layer of no run shows nothing."""
    import json

    from tissue_napari.widgets import RunNumbersWidget, add_layers

    out = run_folder
    viewer = _viewer_with(make_napari_viewer, video)
    widget = RunNumbersWidget(viewer)
    assert widget.table.rowCount() == 0
    layers = add_layers(viewer, read_path(str(out)))
    viewer.layers.selection.active = layers[1]  # the nodes
    rows = {widget.table.item(r, 0).text(): widget.table.item(r, 1).text()
            for r in range(widget.table.rowCount())}  # fmt: skip
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert rows["tracker"] == "gdic" and rows["points"] == "16"
    mean = summary["statistics"]["nodal_strain"]["Exx"]["mean"]
    assert rows["Exx at the endpoint, mean (SD)"].startswith(f"{mean:.4g} (")
    viewer.layers.selection.active = viewer.layers["stretch"]
    assert widget.table.rowCount() == 0
